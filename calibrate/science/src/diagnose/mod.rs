//! Residual diagnosis: fit the baseline model, test its held-out residuals against candidate
//! effects the model lacks, add the one that explains them (if any), and say when structure
//! remains that no candidate explains. `mems-calibrate diagnose` is the command line.
//!
//! # Method
//!
//! **Data.** Each session is cut into observations ([`data`]): block means of `block_s`
//! seconds inside static segments (raw recordings) or the poses of a six-position means file,
//! each with the white-noise variance of its mean that the samples themselves predict. What
//! the samples show about the acquisition is reported per session: torn reads, outliers at a
//! fixed count offset, samples repeating the previous one, gaps.
//!
//! **Baseline.** Chosen from the calibration data:
//! - [`BaselineKind::Full`]: every pose axis aligned (labels from a means file or the nearest
//!   axis) and the labels determine model 3: `m = S a + b`, linear least squares per axis;
//! - [`BaselineKind::LabelFree`]: at least 9 orientations that are not all axis aligned:
//!   `|S^-1 (m - b)| = 1 g` (upper-triangular `S^-1`), Levenberg-Marquardt on the block means;
//! - [`BaselineKind::SessionMean`]: every session in one orientation (static recordings): a
//!   free constant per session; only effects that vary within a session can show.
//!
//! **Validation.** Every model is judged on data not used to fit it: the test sessions when
//! given; otherwise k-fold validation over interleaved blocks of each static segment
//! (`fold = block index mod k`), over whole sessions when a static baseline has at least k of
//! them (`fold = session mod k`; a held-out session's own constant is refitted on it and
//! counted), or leave-one-pose-out for means files. Residuals are measured minus predicted
//! reading, g (the magnitude error for the label-free model), reported in m/s^2 with
//! `--gravity`.
//!
//! **Scores.** With `v` the white-noise variance of each held-out residual and `h` its
//! prediction variance (from the fit's covariance), a model's held-out `chi2 = sum r^2 / v`
//! would be `E = sum (1 + h / v) - (constants fitted on held-out data)` if the model were
//! complete. A candidate's score is its held-out chi-square gain over the baseline,
//! `chi2_base - chi2_cand`, divided by `max(1, chi2_cand / E_cand)` so that structure neither
//! model explains does not inflate it, less the extra constants fitted on held-out data (each
//! absorbs about one unit).
//! Held-out residuals already charge each extra parameter (on clean data a candidate with `p`
//! parameters scores about `-p`), so a candidate counts only when its score exceeds
//! `select_threshold` (12: about 1e-3 false alarms per candidate whatever `p`). Its share of
//! the baseline's excess `chi2_base - E_base` is reported (`explained`); a selected candidate
//! must reach `explain_fraction` of it (default 0: a real but small effect on top of noise
//! that no candidate describes is still worth adding, and the remaining structure is reported
//! separately). Among those, the best score wins, except that a candidate with fewer
//! parameters within `select_threshold` of the best is preferred (the simpler explanation of
//! the same residual).
//!
//! What the validation can and cannot tell apart: in a session of a few poses held one after
//! another, a slow time term can mimic pose-by-pose offsets (blocks are held out within each
//! pose); the label-free baseline with enough poses therefore holds out whole poses. In six
//! axis-aligned poses, `reference_tilt` (free offsets across each class's label) can fit any
//! pose-by-pose pattern, a scale nonlinearity included: it wins only when it fits
//! significantly better than the simpler candidates. On one session, a linear drift cannot
//! be told from a random walk of the bias; several sessions held out whole (e.g. the start-up
//! runs) test whether a time term repeats.
//!
//! **Unexplained structure.** The final model's held-out rms is compared with what white
//! noise and parameter uncertainty predict (`expected_rms_mps2`): structure remains when it
//! is more than `unexplained_ratio` times that and the chi-square test of the standardized
//! residuals has a p-value below `unexplained_p`. `noise_floor_mps2` is the rms of the held-out
//! observations' own white noise (`sqrt(mean v)`).

mod data;
mod effects;
mod linear;
mod magnitude;
pub mod plots;

use std::collections::BTreeMap;

use nalgebra::{DVector, Matrix3, Vector3};
use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

pub use data::{
    AcquisitionFindings, DataConfig, DataError, SessionInput, class_axis, orientation_class,
};
pub use effects::Effect;

use crate::labelfree::distinct_orientations;
use crate::session::{AXIS_ALIGNED_MAX_DEG, nearest_axis};
use calibrate::model::{AccelModel, ModelKind, ParamCovariance, bias_index, scale_index};
use calibrate::terms::ReadingTerms;
use data::{Fixes, Labelling, Obs, Session};
use effects::{Tag, direction, has_columns, regressor};
use linear::{Design, Round};
use magnitude::Term;

/// Which baseline model the data allow (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BaselineKind {
    /// Model 3, `m = S a + b`, on labelled poses.
    Full,
    /// `|S^-1 (m - b)| = 1 g` on poses in unknown orientations.
    LabelFree,
    /// A constant per session (static recordings).
    SessionMean,
}

impl BaselineKind {
    /// The name used in the output.
    pub fn name(self) -> &'static str {
        match self {
            BaselineKind::Full => "full",
            BaselineKind::LabelFree => "label_free",
            BaselineKind::SessionMean => "session_mean",
        }
    }
}

/// Settings of the diagnosis (see the module documentation for the thresholds).
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnoseConfig {
    /// Data preparation.
    pub data: DataConfig,
    /// Effects already known to be present: part of the baseline (e.g. a fix found by an
    /// earlier run).
    pub apply: Vec<Effect>,
    /// Smallest score that counts.
    pub select_threshold: f64,
    /// Smallest share of the baseline's excess chi-square a selected candidate must explain.
    pub explain_fraction: f64,
    /// Held-out rms over its expectation above which structure remains...
    pub unexplained_ratio: f64,
    /// ...when the chi-square test's p-value is also below this.
    pub unexplained_p: f64,
    /// Local gravity for reporting in m/s^2.
    pub gravity_mps2: f64,
    /// Number of warm-up time constants tried (log-spaced from twice the block length to
    /// twice the longest elapsed time).
    pub warm_up_grid: usize,
}

impl Default for DiagnoseConfig {
    fn default() -> Self {
        Self {
            data: DataConfig::default(),
            apply: Vec::new(),
            select_threshold: 12.0,
            explain_fraction: 0.0,
            unexplained_ratio: 1.2,
            unexplained_p: 1e-3,
            gravity_mps2: ipc_types::units::STANDARD_GRAVITY_MPS2,
            warm_up_grid: 16,
        }
    }
}

/// Why the diagnosis could not run.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    /// A session could not be prepared.
    #[error(transparent)]
    Data(#[from] DataError),
    /// No calibration data.
    #[error("no calibration sessions given")]
    NoInput,
    /// The calibration data determine no baseline model.
    #[error(
        "the calibration data determine no baseline model: {0} (the diagnosis needs axis-aligned \
         poses covering +-x, +-y and +-z for model 3, at least 9 orientations for a label-free \
         fit, or static recordings in a single orientation each)"
    )]
    NoBaseline(String),
    /// A test session does not fit the baseline's kind.
    #[error("test session {name}: {reason}")]
    Test {
        /// The session.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// The baseline could not be fitted or validated.
    #[error("baseline ({kind}): {reason}")]
    Baseline {
        /// The baseline kind.
        kind: &'static str,
        /// What went wrong.
        reason: String,
    },
    /// An effect to apply is not applicable to the data.
    #[error("--apply {effect}: {reason}")]
    Apply {
        /// The effect.
        effect: Effect,
        /// Why it cannot be applied.
        reason: String,
    },
}

/// Held-out figures of one model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModelScore {
    /// The model: the baseline's name, then `+effect` for each effect it includes.
    pub model: String,
    /// Root-mean-square held-out residual, m/s^2.
    pub rms_mps2: f64,
    /// The same per axis, m/s^2 (labelled and static models; the label-free model's residual
    /// is the magnitude error).
    pub rms_axes_mps2: Option<[f64; 3]>,
    /// The rms white noise and parameter uncertainty alone would give, m/s^2.
    pub expected_rms_mps2: f64,
    /// Held-out `sum r^2 / v`.
    pub chi2: f64,
    /// Its expectation for a complete model.
    pub expected_chi2: f64,
    /// p-value of the chi-square test of the standardized held-out residuals.
    pub p_value: f64,
    /// Number of held-out residuals (observations times axes; observations for the
    /// label-free model).
    pub residuals: usize,
    /// Constants fitted on held-out data.
    pub local_params: usize,
}

/// Whether and how a candidate was evaluated.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CandidateStatus {
    /// Evaluated on held-out data.
    Evaluated,
    /// The data hold nothing the effect could act on (no temperature, no times, no gaps...).
    NotApplicable(String),
    /// The data cannot tell the effect apart from the baseline under this validation.
    NotIdentifiable(String),
}

/// One candidate's result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CandidateResult {
    /// The effect.
    pub effect: Effect,
    /// Whether it was evaluated.
    pub status: CandidateStatus,
    /// Held-out figures of the baseline plus this effect (when evaluated).
    pub result: Option<ModelScore>,
    /// Score (see the module documentation); NaN when not evaluated.
    pub score: f64,
    /// Share of the baseline's excess chi-square it explains.
    pub explained: f64,
    /// Parameters it adds (the rank it adds on the calibration data, plus 1 for a fitted
    /// time constant; 0 for fixes).
    pub params: usize,
}

/// One held-out residual with its regressors (for plots), g.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResidualPoint {
    /// Residual per axis (label-free: the magnitude error in `[0]`, NaN elsewhere), g.
    pub resid_g: [f64; 3],
    /// White-noise sigma of each residual, g.
    pub sigma_g: [f64; 3],
    /// Elapsed time since the session's first sample, s.
    pub t_s: Option<f64>,
    /// Die temperature, degC.
    pub temp_c: Option<f64>,
    /// Orientation class (see [`orientation_class`]).
    pub class: usize,
    /// The specific-force direction the scale terms use (label, class axis or estimate).
    pub direction: [f64; 3],
    /// Session index.
    pub session: usize,
    /// Whether from the test data.
    pub test: bool,
}

/// Deviations of the samples from their block means, counts at 16384/g, per axis: histograms
/// of the raw and of the torn-read-repaired values.
#[derive(Debug, Clone, PartialEq)]
pub struct SampleHistogram {
    /// Lower edge of the first bin, counts.
    pub start_counts: f64,
    /// Bin width, counts.
    pub bin_counts: f64,
    /// Raw values: per axis, count per bin.
    pub raw: [Vec<u64>; 3],
    /// Repaired values: per axis, count per bin.
    pub repaired: [Vec<u64>; 3],
}

/// The final model fitted on all calibration data.
#[derive(Debug, Clone, PartialEq)]
pub struct FinalFit {
    /// Baseline kind.
    pub kind: BaselineKind,
    /// Effects included (applied ones and the selected one).
    pub effects: Vec<Effect>,
    /// `S` and `b` (model 3 or label-free; none for a static baseline).
    pub model: Option<AccelModel>,
    /// Their covariance in the 12-parameter layout (white-noise sigmas, scaled up by the
    /// reduced chi-square when that exceeds 1).
    pub covariance: Option<ParamCovariance>,
    /// The fitted reading terms (temperature, time, nonlinearity) in calibration-file form.
    pub terms: ReadingTerms,
    /// Reference-tilt offsets per orientation class (g on the two axes across the label).
    pub tilt_g: Vec<(usize, [f64; 3])>,
    /// In-sample residual per pose (mean over its blocks), g.
    pub per_pose_residual_g: Vec<[f64; 3]>,
    /// Weighted in-sample chi-square.
    pub chi2: f64,
    /// Residual degrees of freedom.
    pub dof: usize,
    /// Number of calibration poses.
    pub poses: usize,
    /// Torn reads undone in the data the fit used.
    pub repaired_samples: usize,
    /// Die temperature range of the calibration data, degC.
    pub temperature_range_c: Option<[f64; 2]>,
}

/// The result of a diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnosis {
    /// The baseline kind.
    pub kind: BaselineKind,
    /// How held-out data were chosen.
    pub validation: String,
    /// The baseline (with the applied effects).
    pub baseline: ModelScore,
    /// Every candidate.
    pub candidates: Vec<CandidateResult>,
    /// The selected effect.
    pub selected: Option<Effect>,
    /// The final model (baseline plus the selected effect).
    pub final_model: ModelScore,
    /// Rms of the held-out observations' own white noise, m/s^2.
    pub noise_floor_mps2: f64,
    /// Whether residuals stay well above what noise explains.
    pub unexplained_structure: bool,
    /// What the samples show about the acquisition, per raw session.
    pub acquisition: Vec<AcquisitionFindings>,
    /// The final model fitted on all calibration data.
    pub final_fit: FinalFit,
    /// The same without the terms a calibration file cannot carry (`reference_tilt`, a
    /// property of the set-up; `gaps`, steps of one session): what `--out` writes.
    pub calibration_fit: FinalFit,
    /// Held-out residuals of the baseline.
    pub baseline_points: Vec<ResidualPoint>,
    /// Held-out residuals of the final model.
    pub final_points: Vec<ResidualPoint>,
    /// Sample deviations (raw sessions only).
    pub histogram: Option<SampleHistogram>,
    /// Local gravity of the m/s^2 figures.
    pub gravity_mps2: f64,
}

impl Diagnosis {
    /// The JSON summary: `{"baseline": {"model", "rms_mps2"}, "candidates": [{"effect",
    /// "rms_mps2", "score"}], "selected_effect", "final": {"model", "rms_mps2"},
    /// "noise_floor_mps2", "unexplained_structure"}` (evaluated candidates only).
    pub fn to_json(&self) -> serde_json::Value {
        let candidates: Vec<serde_json::Value> = self
            .candidates
            .iter()
            .filter_map(|c| {
                c.result.as_ref().map(|r| {
                    serde_json::json!({
                        "effect": c.effect.name(),
                        "rms_mps2": r.rms_mps2,
                        "score": c.score,
                    })
                })
            })
            .collect();
        serde_json::json!({
            "baseline": {"model": self.baseline.model, "rms_mps2": self.baseline.rms_mps2},
            "candidates": candidates,
            "selected_effect": self.selected.map_or("none", Effect::name),
            "final": {"model": self.final_model.model, "rms_mps2": self.final_model.rms_mps2},
            "noise_floor_mps2": self.noise_floor_mps2,
            "unexplained_structure": self.unexplained_structure,
        })
    }
}

/// One model's held-out residuals, flattened.
#[derive(Debug, Clone, Default)]
struct Eval {
    /// (observation, axis or `None` for a magnitude residual).
    entries: Vec<(usize, Option<usize>)>,
    resid: Vec<f64>,
    v: Vec<f64>,
    pv: Vec<f64>,
    local: usize,
}

/// The observations of one choice of fixes.
#[derive(Debug, Clone)]
struct ObsSet {
    obs: Vec<Obs>,
    m: Vec<[f64; 3]>,
    v: Vec<[f64; 3]>,
    n: Vec<usize>,
    pose: Vec<usize>,
    calib_rows: Vec<usize>,
    rounds: Vec<Round>,
    /// Reference temperature (mean over the calibration observations), degC.
    t_ref_c: Option<f64>,
    /// Longest elapsed time in the calibration observations, s.
    t_max_s: Option<f64>,
    /// Corrected direction of each observation under the label-free baseline fitted on all
    /// calibration data (label-free kind only).
    dir_est: Option<Vec<[f64; 3]>>,
    /// Label-free baseline fitted on all calibration data (its starting point).
    lf_start: Option<DVector<f64>>,
}

/// A label-free fit for one warm-up time constant: its chi-square, the fit, its terms and
/// the time constant.
type MagnitudeChoice = (f64, magnitude::MagnitudeFit, Vec<(Effect, Term)>, f64);

/// Why a model was not evaluated.
enum Skip {
    NotApplicable(String),
    NotIdentifiable(String),
}

/// What the validation folds hold out (without test data; see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Folds {
    /// Interleaved blocks of every static segment.
    Blocks,
    /// Whole sessions (static baselines with at least k sessions).
    Sessions,
    /// Whole poses (label-free baselines with enough poses that every training set keeps 9).
    Poses,
}

struct Diagnoser<'a> {
    cfg: &'a DiagnoseConfig,
    kind: BaselineKind,
    sessions: Vec<Session>,
    n_calib: usize,
    folds: Folds,
    sets: BTreeMap<(bool, bool), ObsSet>,
}

/// Runs the diagnosis on calibration sessions `calib` and optional test sessions `test`.
pub fn diagnose(
    calib: &[SessionInput],
    test: &[SessionInput],
    cfg: &DiagnoseConfig,
) -> Result<Diagnosis, DiagnoseError> {
    if calib.is_empty() {
        return Err(DiagnoseError::NoInput);
    }
    let prepare = |s: &SessionInput| -> Result<Session, DataError> {
        match s {
            SessionInput::Raw { name, samples } => Ok(Session::Raw(Box::new(data::prepare_raw(
                name, samples, &cfg.data,
            )?))),
            SessionInput::Means { name, poses } => {
                for (k, p) in poses.iter().enumerate() {
                    let finite = p
                        .mean_g
                        .iter()
                        .chain(p.truth_g.iter())
                        .chain(p.std_g.iter())
                        .all(|x| x.is_finite());
                    if !finite || p.std_g.iter().any(|s| *s <= 0.0) {
                        return Err(DataError::BadPose {
                            name: name.clone(),
                            pose: k + 1,
                        });
                    }
                }
                Ok(Session::Means {
                    name: name.clone(),
                    poses: poses.clone(),
                })
            }
        }
    };
    let mut sessions = Vec::new();
    for s in calib {
        sessions.push(prepare(s)?);
    }
    for s in test {
        sessions.push(prepare(s)?);
    }
    let n_calib = calib.len();
    let kind = choose_kind(&sessions[..n_calib])?;
    check_test(kind, &sessions[n_calib..])?;
    let poses: usize = sessions[..n_calib]
        .iter()
        .map(|s| s.pose_means().len())
        .sum();
    let folds = if !test.is_empty() {
        Folds::Blocks
    } else if kind == BaselineKind::SessionMean && n_calib >= cfg.data.folds {
        Folds::Sessions
    } else if kind == BaselineKind::LabelFree
        && poses >= crate::labelfree::MIN_POSES + poses.div_ceil(cfg.data.folds)
    {
        Folds::Poses
    } else {
        Folds::Blocks
    };
    let mut d = Diagnoser {
        cfg,
        kind,
        sessions,
        n_calib,
        folds,
        sets: BTreeMap::new(),
    };
    d.run()
}

/// Whether every pose of a raw session lies in one orientation.
fn single_orientation(s: &Session) -> bool {
    match s {
        Session::Means { .. } => false,
        Session::Raw(r) => {
            let first = Vector3::from(r.segments[0].mean_g).normalize();
            r.segments
                .iter()
                .all(|g| Vector3::from(g.mean_g).normalize().dot(&first) > 10f64.to_radians().cos())
        }
    }
}

fn choose_kind(calib: &[Session]) -> Result<BaselineKind, DiagnoseError> {
    if calib.iter().all(single_orientation) {
        return Ok(BaselineKind::SessionMean);
    }
    let mut labels: Vec<Vector3<f64>> = Vec::new();
    let mut aligned = true;
    for s in calib {
        match s {
            Session::Means { poses, .. } => labels.extend(poses.iter().map(|p| p.truth_g)),
            Session::Raw(_) => {
                for m in s.pose_means() {
                    let (axis, angle) = nearest_axis(&m);
                    aligned &= angle <= AXIS_ALIGNED_MAX_DEG;
                    labels.push(axis);
                }
            }
        }
    }
    if aligned {
        // Model 3 needs [a_x, a_y, a_z, 1] of rank 4.
        let x = nalgebra::DMatrix::from_fn(
            labels.len(),
            4,
            |r, c| {
                if c < 3 { labels[r][c] } else { 1.0 }
            },
        );
        let sv = x.svd(false, false).singular_values;
        if sv.len() == 4 && sv.min() > 1e-6 * sv.max() {
            return Ok(BaselineKind::Full);
        }
    }
    if calib.iter().any(|s| matches!(s, Session::Means { .. })) {
        return Err(DiagnoseError::NoBaseline(
            "a means file's labels do not determine model 3".into(),
        ));
    }
    let poses: Vec<crate::fit::Pose> = calib
        .iter()
        .flat_map(|s| s.pose_means())
        .map(|m| crate::fit::Pose {
            truth_g: Vector3::zeros(),
            mean_g: m,
            std_g: Vector3::repeat(1e-3),
            n: None,
        })
        .collect();
    let distinct = distinct_orientations(&poses);
    if distinct >= crate::labelfree::MIN_POSES {
        return Ok(BaselineKind::LabelFree);
    }
    Err(DiagnoseError::NoBaseline(format!(
        "{} static poses in {distinct} distinct orientations, {}",
        poses.len(),
        if aligned {
            "axis aligned but not covering every axis"
        } else {
            "not all axis aligned"
        }
    )))
}

fn check_test(kind: BaselineKind, test: &[Session]) -> Result<(), DiagnoseError> {
    for s in test {
        let err = |reason: String| DiagnoseError::Test {
            name: s.name().to_string(),
            reason,
        };
        match (kind, s) {
            (BaselineKind::SessionMean, Session::Means { .. }) => {
                return Err(err(
                    "a static baseline is tested on static recordings, not on a means file".into(),
                ));
            }
            (BaselineKind::SessionMean, _) if !single_orientation(s) => {
                return Err(err(
                    "a static baseline is tested on static recordings in one orientation".into(),
                ));
            }
            (BaselineKind::Full, Session::Raw(_)) => {
                for (k, m) in s.pose_means().iter().enumerate() {
                    let (_, angle) = nearest_axis(m);
                    if angle > AXIS_ALIGNED_MAX_DEG {
                        return Err(err(format!(
                            "static segment {k} is {angle:.0} degrees from the nearest axis; model 3 \
                             is tested on axis-aligned poses"
                        )));
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Weighted mean of per-observation values.
fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    s / n.max(1) as f64
}

impl Diagnoser<'_> {
    fn labelling(&self) -> Labelling {
        match self.kind {
            BaselineKind::Full => Labelling::NearestAxis,
            _ => Labelling::None,
        }
    }

    /// The observations with the given fixes (built once).
    fn set(&mut self, fixes: Fixes) -> Result<&ObsSet, DiagnoseError> {
        let key = (fixes.torn, fixes.dedup);
        if !self.sets.contains_key(&key) {
            let set = self.build_set(fixes)?;
            self.sets.insert(key, set);
        }
        Ok(&self.sets[&key])
    }

    fn build_set(&self, fixes: Fixes) -> Result<ObsSet, DiagnoseError> {
        let mut obs = Vec::new();
        let mut first_pose = 0;
        for (k, s) in self.sessions.iter().enumerate() {
            let test = k >= self.n_calib;
            data::observations(
                s,
                k,
                first_pose,
                test,
                self.labelling(),
                fixes,
                &self.cfg.data,
                &mut obs,
            );
            first_pose += s.pose_means().len();
        }
        for o in &mut obs {
            match self.folds {
                Folds::Sessions => o.fold = o.session % self.cfg.data.folds,
                Folds::Poses => o.fold = o.pose % self.cfg.data.folds,
                Folds::Blocks => {}
            }
        }
        let calib_rows: Vec<usize> = (0..obs.len()).filter(|&o| !obs[o].test).collect();
        let rounds = validation_rounds(&obs, &calib_rows);
        let t_ref_c = obs
            .iter()
            .all(|o| o.temp_c.is_some())
            .then(|| mean(calib_rows.iter().map(|&o| obs[o].temp_c.expect("checked"))));
        let t_max_s = obs.iter().all(|o| o.t_s.is_some()).then(|| {
            calib_rows
                .iter()
                .map(|&o| obs[o].t_s.expect("checked"))
                .fold(0.0, f64::max)
        });
        let m: Vec<[f64; 3]> = obs.iter().map(|o| o.m).collect();
        let v: Vec<[f64; 3]> = obs.iter().map(|o| o.v).collect();
        let n: Vec<usize> = obs.iter().map(|o| o.n).collect();
        let pose: Vec<usize> = obs.iter().map(|o| o.pose).collect();
        let (dir_est, lf_start) = if self.kind == BaselineKind::LabelFree {
            let (dirs, x) = self.label_free_start(&m, &v, &n, &pose, &calib_rows)?;
            (Some(dirs), Some(x))
        } else {
            (None, None)
        };
        Ok(ObsSet {
            obs,
            m,
            v,
            n,
            pose,
            calib_rows,
            rounds,
            t_ref_c,
            t_max_s,
            dir_est,
            lf_start,
        })
    }

    /// The label-free baseline's fit on all calibration rows: each observation's direction
    /// (its corrected reading, normalized) and the parameters, the start of later fits.
    fn label_free_start(
        &self,
        m: &[[f64; 3]],
        v: &[[f64; 3]],
        n: &[usize],
        pose: &[usize],
        calib_rows: &[usize],
    ) -> Result<(Vec<[f64; 3]>, DVector<f64>), DiagnoseError> {
        let baseline_error = |e: String| DiagnoseError::Baseline {
            kind: self.kind.name(),
            reason: e,
        };
        let x0 = magnitude::start(m, v, n, pose, calib_rows)
            .map_err(|e| baseline_error(e.to_string()))?;
        let f = magnitude::fit(m, v, &[], calib_rows, &x0)
            .map_err(|e| baseline_error(e.to_string()))?;
        let (t, b) = (f.t(), f.bias());
        let dirs = m
            .iter()
            .map(|mm| {
                let c = (t * (Vector3::from(*mm) - b)).normalize();
                [c.x, c.y, c.z]
            })
            .collect();
        Ok((dirs, f.x))
    }

    fn fixes_of(effects: &[Effect]) -> Fixes {
        Fixes {
            torn: effects.contains(&Effect::TornReads),
            dedup: effects.contains(&Effect::RepeatedSamples),
        }
    }

    /// Whether `effect` can act on the data; the reason when not.
    fn applicability(&self, effect: Effect, set: &ObsSet) -> Result<(), Skip> {
        let raw: Vec<&data::RawSession> = self
            .sessions
            .iter()
            .filter_map(|s| match s {
                Session::Raw(r) => Some(r.as_ref()),
                Session::Means { .. } => None,
            })
            .collect();
        // The fewest poses any training set of this validation holds.
        let min_train_poses = set
            .rounds
            .iter()
            .map(|r| {
                r.train
                    .iter()
                    .map(|&o| set.obs[o].pose)
                    .collect::<std::collections::BTreeSet<_>>()
                    .len()
            })
            .min()
            .unwrap_or(0);
        match effect {
            Effect::TemperatureBias | Effect::TemperatureScale if set.t_ref_c.is_none() => Err(
                Skip::NotApplicable("the data carry no die temperature".into()),
            ),
            // A nonlinearity acts pose by pose: with the label-free model's 9 parameters it
            // needs 12 poses in every training set (blocks of one pose are one orientation).
            Effect::ScaleNonlinearity
                if self.kind == BaselineKind::LabelFree
                    && min_train_poses < crate::labelfree::MIN_POSES + 3 =>
            {
                Err(Skip::NotIdentifiable(format!(
                    "a label-free fit with a nonlinearity needs 12 poses in every training set, \
                     this validation leaves {min_train_poses}"
                )))
            }
            Effect::BiasDrift | Effect::WarmUp if set.t_max_s.is_none() => Err(
                Skip::NotApplicable("the data carry no sample times (means file)".into()),
            ),
            Effect::ScaleNonlinearity if self.kind == BaselineKind::SessionMean => {
                Err(Skip::NotIdentifiable(
                    "one orientation per session: a_i^2 is constant within each session".into(),
                ))
            }
            Effect::ReferenceTilt if self.kind != BaselineKind::Full => Err(Skip::NotApplicable(
                "the data carry no gravity labels".into(),
            )),
            Effect::Gaps if self.kind == BaselineKind::LabelFree => Err(Skip::NotApplicable(
                "bias steps at gaps are not modelled with the label-free baseline".into(),
            )),
            Effect::Gaps if !set.obs.iter().any(|o| o.gap_index > 0) => {
                Err(Skip::NotApplicable("no gaps inside the static data".into()))
            }
            Effect::TornReads if raw.iter().all(|r| r.findings.torn.total() == 0) => {
                Err(Skip::NotApplicable("no torn reads found".into()))
            }
            Effect::RepeatedSamples if !raw.iter().any(|r| r.findings.repeats_significant) => Err(
                Skip::NotApplicable("repeated samples are as frequent as noise allows".into()),
            ),
            _ => Ok(()),
        }
    }

    /// The best score of bias steps placed at the same number of times as the gaps but a third
    /// and two thirds of each session later (cyclically), or 0 when those score below 0. Steps
    /// anywhere absorb some low-frequency noise, which held-out blocks or whole held-out
    /// sessions do not charge fully; a step at a gap counts by what it gains beyond them.
    fn placebo_gap_score(&self, set: &ObsSet, effects: &[Effect], baseline: &ModelScore) -> f64 {
        let mut best: f64 = 0.0;
        for fraction in [1.0 / 3.0, 2.0 / 3.0] {
            let mut placebo = set.clone();
            for o in &mut placebo.obs {
                let Session::Raw(r) = &self.sessions[o.session] else {
                    continue;
                };
                let t0 = r.t_ns[0];
                let duration = (r.t_ns[r.t_ns.len() - 1] - t0) as f64 * 1e-9;
                let t = o.t_s.expect("raw sessions have times");
                o.gap_index = r
                    .gap_at
                    .iter()
                    .map(|&g| ((r.t_ns[g] - t0) as f64 * 1e-9 + fraction * duration) % duration)
                    .filter(|&p| p <= t)
                    .count();
            }
            if let Ok(e) = self.evaluate(&placebo, effects) {
                let s = self.score(&e, effects);
                let scale = (s.chi2 / s.expected_chi2.max(1.0)).max(1.0);
                let score = (baseline.chi2 - s.chi2) / scale
                    - (s.local_params as f64 - baseline.local_params as f64);
                best = best.max(score);
            }
        }
        best
    }

    /// The warm-up time constants tried, s.
    fn tau_grid(&self, set: &ObsSet) -> Vec<f64> {
        let lo = (2.0 * self.cfg.data.block_s).max(0.5);
        let hi = (2.0 * set.t_max_s.unwrap_or(lo)).max(2.0 * lo);
        let k = self.cfg.warm_up_grid.max(2);
        (0..k)
            .map(|j| lo * (hi / lo).powf(j as f64 / (k - 1) as f64))
            .collect()
    }

    /// The linear design of a model with `effects` on `set` (warm-up time constant `tau_s`).
    fn linear_design(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau_s: f64,
    ) -> (Design, [Vec<Tag>; 3]) {
        let obs = &set.obs;
        let gaps = effects.contains(&Effect::Gaps);
        let mut columns: [Vec<Vec<f64>>; 3] = Default::default();
        let mut tags: [Vec<Tag>; 3] = Default::default();
        let groups = match self.kind {
            BaselineKind::Full if !gaps => None,
            _ => {
                let mut ids: BTreeMap<(usize, usize), usize> = BTreeMap::new();
                Some(
                    obs.iter()
                        .map(|o| {
                            let key = (o.session, if gaps { o.gap_index } else { 0 });
                            let next = ids.len();
                            *ids.entry(key).or_insert(next)
                        })
                        .collect(),
                )
            }
        };
        let classes: std::collections::BTreeSet<usize> =
            set.calib_rows.iter().map(|&o| obs[o].class).collect();
        for axis in 0..3 {
            if self.kind == BaselineKind::Full {
                for j in 0..3 {
                    columns[axis].push(obs.iter().map(|o| o.label.expect("labelled")[j]).collect());
                    tags[axis].push(Tag::Base(j));
                }
                if groups.is_none() {
                    columns[axis].push(vec![1.0; obs.len()]);
                    tags[axis].push(Tag::Base(3));
                }
            }
            for &e in effects.iter().filter(|e| has_columns(**e)) {
                if e == Effect::ReferenceTilt {
                    for &c in classes.iter().filter(|&&c| c / 2 != axis) {
                        columns[axis].push(
                            obs.iter()
                                .map(|o| f64::from(u8::from(o.class == c)))
                                .collect(),
                        );
                        tags[axis].push(Tag::Effect(e, c));
                    }
                    continue;
                }
                let t_ref = set.t_ref_c.unwrap_or(0.0);
                columns[axis].push(
                    obs.iter()
                        .enumerate()
                        .map(|(k, o)| {
                            let dir = direction(o, set.dir_est.as_ref().map(|d| &d[k]));
                            regressor(e, o, axis, t_ref, tau_s, &dir)
                        })
                        .collect(),
                );
                tags[axis].push(Tag::Effect(e, 0));
            }
        }
        (Design { columns, groups }, tags)
    }

    /// The label-free terms of a model with `effects` (warm-up time constant `tau_s`).
    fn magnitude_terms(&self, set: &ObsSet, effects: &[Effect], tau_s: f64) -> Vec<(Effect, Term)> {
        let t_ref = set.t_ref_c.unwrap_or(0.0);
        let mut terms = Vec::new();
        for &e in effects.iter().filter(|e| has_columns(**e)) {
            for axis in 0..3 {
                let values = set
                    .obs
                    .iter()
                    .enumerate()
                    .map(|(k, o)| {
                        let dir = direction(o, set.dir_est.as_ref().map(|d| &d[k]));
                        regressor(e, o, axis, t_ref, tau_s, &dir)
                    })
                    .collect();
                terms.push((e, Term { axis, values }));
            }
        }
        terms
    }

    /// Held-out evaluation of the model with `effects` on `set`, choosing the warm-up time
    /// constant per round on the training data.
    fn evaluate(&self, set: &ObsSet, effects: &[Effect]) -> Result<Eval, Skip> {
        let taus = if effects.contains(&Effect::WarmUp) {
            self.tau_grid(set)
        } else {
            vec![1.0]
        };
        let mut eval = Eval::default();
        for round in &set.rounds {
            let x0 = match self.kind {
                BaselineKind::LabelFree => Some(
                    magnitude::start(&set.m, &set.v, &set.n, &set.pose, &round.train)
                        .map_err(|e| Skip::NotIdentifiable(format!("training poses: {e}")))?,
                ),
                _ => None,
            };
            // The label-free fit is nonlinear: the time constant is chosen by the first-order
            // fit of each, then fitted once.
            let taus = match &x0 {
                Some(x0) if taus.len() > 1 => {
                    vec![self.best_tau_magnitude(set, effects, &round.train, x0, &taus)]
                }
                _ => taus.clone(),
            };
            let mut best: Option<(f64, Eval)> = None;
            for &tau in &taus {
                let (train_chi2, e) = match &x0 {
                    Some(x0) => self.evaluate_magnitude(set, effects, tau, round, x0)?,
                    _ => {
                        let (design, _) = self.linear_design(set, effects, tau);
                        let held = linear::cross_validate(
                            &set.m,
                            &set.v,
                            &design,
                            std::slice::from_ref(round),
                        )
                        .map_err(|_| {
                            Skip::NotIdentifiable(
                                "the training data do not determine the held-out predictions"
                                    .into(),
                            )
                        })?;
                        let mut e = Eval {
                            local: held.local_params,
                            ..Eval::default()
                        };
                        for &o in &round.eval {
                            for axis in 0..3 {
                                e.entries.push((o, Some(axis)));
                                e.resid.push(held.resid[o][axis]);
                                e.v.push(set.v[o][axis]);
                                e.pv.push(held.pred_var[o][axis]);
                            }
                        }
                        (held.train_chi2, e)
                    }
                };
                if best.as_ref().is_none_or(|(c, _)| train_chi2 < *c) {
                    best = Some((train_chi2, e));
                }
            }
            let (_, e) = best.expect("at least one time constant");
            eval.entries.extend(e.entries);
            eval.resid.extend(e.resid);
            eval.v.extend(e.v);
            eval.pv.extend(e.pv);
            eval.local += e.local;
        }
        Ok(eval)
    }

    /// The warm-up time constant of `taus` whose first-order label-free fit on `rows` leaves
    /// the smallest chi-square.
    fn best_tau_magnitude(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        rows: &[usize],
        x0: &DVector<f64>,
        taus: &[f64],
    ) -> f64 {
        taus.iter()
            .map(|&tau| {
                let terms: Vec<Term> = self
                    .magnitude_terms(set, effects, tau)
                    .into_iter()
                    .map(|(_, t)| t)
                    .collect();
                (
                    magnitude::linearized_chi2(&set.m, &set.v, &terms, rows, x0),
                    tau,
                )
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or(1.0, |(_, tau)| tau)
    }

    fn evaluate_magnitude(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau: f64,
        round: &Round,
        x0: &DVector<f64>,
    ) -> Result<(f64, Eval), Skip> {
        let terms: Vec<Term> = self
            .magnitude_terms(set, effects, tau)
            .into_iter()
            .map(|(_, t)| t)
            .collect();
        let fit = magnitude::fit(&set.m, &set.v, &terms, &round.train, x0)
            .map_err(|e| Skip::NotIdentifiable(e.to_string()))?;
        let trained: Vec<bool> = terms
            .iter()
            .map(|t| round.train.iter().any(|&o| t.values[o] != 0.0))
            .collect();
        let mut e = Eval::default();
        for &o in &round.eval {
            let (r, pv) =
                magnitude::predict(&fit, &terms, &set.m[o], o, &trained).ok_or_else(|| {
                    Skip::NotIdentifiable("a held-out term is not determined by training".into())
                })?;
            let sigma = magnitude::magnitude_sigma(&fit.x, &terms, &set.m[o], &set.v[o], o);
            e.entries.push((o, None));
            e.resid.push(r);
            e.v.push(sigma * sigma);
            e.pv.push(pv);
        }
        Ok((fit.chi2, e))
    }

    fn model_name(&self, effects: &[Effect]) -> String {
        let mut name = self.kind.name().to_string();
        for e in effects {
            name.push('+');
            name.push_str(e.name());
        }
        name
    }

    fn score(&self, e: &Eval, effects: &[Effect]) -> ModelScore {
        let n = e.resid.len().max(1);
        let g = self.cfg.gravity_mps2;
        let ss: f64 = e.resid.iter().map(|r| r * r).sum();
        let chi2: f64 = e.resid.iter().zip(&e.v).map(|(r, v)| r * r / v).sum();
        let expected_chi2 =
            e.v.iter()
                .zip(&e.pv)
                .map(|(v, pv)| 1.0 + pv / v)
                .sum::<f64>()
                - e.local as f64;
        let mean_v = e.v.iter().sum::<f64>() / n as f64;
        let expected_ss =
            e.v.iter().zip(&e.pv).map(|(v, pv)| v + pv).sum::<f64>() - e.local as f64 * mean_v;
        let z2: f64 = e
            .resid
            .iter()
            .zip(e.v.iter().zip(&e.pv))
            .map(|(r, (v, pv))| r * r / (v + pv))
            .sum();
        let dof = (n as f64 - e.local as f64).max(1.0);
        let p_value = ChiSquared::new(dof).map_or(f64::NAN, |c| c.sf(z2));
        let rms_axes_mps2 = (self.kind != BaselineKind::LabelFree).then(|| {
            std::array::from_fn(|i| {
                let (ss, k) = e
                    .entries
                    .iter()
                    .zip(&e.resid)
                    .filter(|((_, axis), _)| *axis == Some(i))
                    .fold((0.0, 0usize), |(ss, k), (_, r)| (ss + r * r, k + 1));
                (ss / k.max(1) as f64).sqrt() * g
            })
        });
        ModelScore {
            model: self.model_name(effects),
            rms_mps2: (ss / n as f64).sqrt() * g,
            rms_axes_mps2,
            expected_rms_mps2: (expected_ss.max(0.0) / n as f64).sqrt() * g,
            chi2,
            expected_chi2,
            p_value,
            residuals: e.resid.len(),
            local_params: e.local,
        }
    }

    fn points(&self, set: &ObsSet, e: &Eval) -> Vec<ResidualPoint> {
        let mut by_obs: BTreeMap<usize, ResidualPoint> = BTreeMap::new();
        for (k, &(o, axis)) in e.entries.iter().enumerate() {
            let ob = &set.obs[o];
            let p = by_obs.entry(o).or_insert_with(|| ResidualPoint {
                resid_g: [f64::NAN; 3],
                sigma_g: [f64::NAN; 3],
                t_s: ob.t_s,
                temp_c: ob.temp_c,
                class: ob.class,
                direction: direction(ob, set.dir_est.as_ref().map(|d| &d[o])),
                session: ob.session,
                test: ob.test,
            });
            let i = axis.unwrap_or(0);
            p.resid_g[i] = e.resid[k];
            p.sigma_g[i] = e.v[k].sqrt();
        }
        by_obs.into_values().collect()
    }

    /// Builds the observation sets of the applied fixes, and of each fix the data call for
    /// (a fix without findings is not applicable and needs none); returns the applied fixes.
    fn prepare_sets(&mut self, applied: &[Effect]) -> Result<Fixes, DiagnoseError> {
        let base_fixes = Self::fixes_of(applied);
        self.set(base_fixes)?;
        let raw = |f: fn(&AcquisitionFindings) -> bool| {
            self.sessions.iter().any(|s| match s {
                Session::Raw(r) => f(&r.findings),
                Session::Means { .. } => false,
            })
        };
        let needed = [
            (
                raw(|a| a.torn.total() > 0),
                Fixes {
                    torn: true,
                    ..base_fixes
                },
            ),
            (
                raw(|a| a.repeats_significant),
                Fixes {
                    dedup: true,
                    ..base_fixes
                },
            ),
        ];
        for (need, fixes) in needed {
            if need {
                self.set(fixes)?;
            }
        }
        Ok(base_fixes)
    }

    /// The held-out evaluation of the applied effects, refused when one of them does not
    /// apply to the data or the baseline cannot be evaluated.
    fn baseline_eval(&self, base_set: &ObsSet, applied: &[Effect]) -> Result<Eval, DiagnoseError> {
        for &e in applied {
            if let Err(Skip::NotApplicable(reason) | Skip::NotIdentifiable(reason)) =
                self.applicability(e, base_set)
            {
                return Err(DiagnoseError::Apply { effect: e, reason });
            }
        }
        self.evaluate(base_set, applied).map_err(|s| {
            let (Skip::NotApplicable(reason) | Skip::NotIdentifiable(reason)) = s;
            DiagnoseError::Baseline {
                kind: self.kind.name(),
                reason,
            }
        })
    }

    /// The parameters `effect` adds to `effects` minus itself (`base_rank`: the baseline's
    /// rank), refused when the calibration data cannot tell it from the baseline.
    fn added_params(
        &self,
        set: &ObsSet,
        effect: Effect,
        effects: &[Effect],
        base_rank: usize,
    ) -> Result<usize, Skip> {
        if effect.is_fix() {
            return Ok(0);
        }
        if self.kind == BaselineKind::LabelFree {
            return Ok(3 + usize::from(effect == Effect::WarmUp));
        }
        let (_, rank) = self.final_fit(set, effects);
        let added = rank.saturating_sub(base_rank);
        if added == 0 {
            return Err(Skip::NotIdentifiable(
                "the calibration data cannot tell it from the baseline".into(),
            ));
        }
        Ok(added + usize::from(effect == Effect::WarmUp))
    }

    /// Evaluates the applied effects plus `effect` against the baseline; also returns the
    /// evaluation and the effects when it was evaluated.
    fn candidate(
        &self,
        effect: Effect,
        applied: &[Effect],
        base_set: &ObsSet,
        base_rank: usize,
        baseline: &ModelScore,
    ) -> (CandidateResult, Option<(Eval, Vec<Effect>)>) {
        let mut effects = applied.to_vec();
        effects.push(effect);
        let fixes = Self::fixes_of(&effects);
        // Applicability depends on the sessions, not on the fixes: judged on the baseline's
        // observations, so that a fix's observations are only needed when it applies.
        let outcome = self.applicability(effect, base_set).and_then(|()| {
            let set = &self.sets[&(fixes.torn, fixes.dedup)];
            let params = self.added_params(set, effect, &effects, base_rank)?;
            self.evaluate(set, &effects).map(|e| (e, params))
        });
        match outcome {
            Ok((eval, params)) => {
                let s = self.score(&eval, &effects);
                // Constants fitted on held-out data absorb about one unit each of the
                // scaled chi-square: charged after scaling.
                let scale = (s.chi2 / s.expected_chi2.max(1.0)).max(1.0);
                let mut score = (baseline.chi2 - s.chi2) / scale
                    - (s.local_params as f64 - baseline.local_params as f64);
                if effect == Effect::Gaps {
                    score -= self.placebo_gap_score(base_set, &effects, baseline);
                }
                let excess = baseline.chi2 - baseline.expected_chi2;
                let explained = if excess > 0.0 {
                    (baseline.chi2 - s.chi2) / excess
                } else if score > 0.0 {
                    1.0
                } else {
                    0.0
                };
                let result = CandidateResult {
                    effect,
                    status: CandidateStatus::Evaluated,
                    result: Some(s),
                    score,
                    explained,
                    params,
                };
                (result, Some((eval, effects)))
            }
            Err(skip) => {
                let result = CandidateResult {
                    effect,
                    status: match skip {
                        Skip::NotApplicable(r) => CandidateStatus::NotApplicable(r),
                        Skip::NotIdentifiable(r) => CandidateStatus::NotIdentifiable(r),
                    },
                    result: None,
                    score: f64::NAN,
                    explained: f64::NAN,
                    params: 0,
                };
                (result, None)
            }
        }
    }

    fn run(&mut self) -> Result<Diagnosis, DiagnoseError> {
        let applied = self.cfg.apply.clone();
        let base_fixes = self.prepare_sets(&applied)?;
        let base_set = &self.sets[&(base_fixes.torn, base_fixes.dedup)];
        let base_eval = self.baseline_eval(base_set, &applied)?;
        let baseline = self.score(&base_eval, &applied);
        let (_, base_rank) = self.final_fit(base_set, &applied);

        let mut candidates = Vec::new();
        let mut evals: BTreeMap<Effect, (Eval, Vec<Effect>)> = BTreeMap::new();
        for effect in Effect::ALL {
            if applied.contains(&effect) {
                continue;
            }
            let (result, eval) = self.candidate(effect, &applied, base_set, base_rank, &baseline);
            if let Some(eval) = eval {
                evals.insert(effect, eval);
            }
            candidates.push(result);
        }

        let selected = select(&candidates, self.cfg);
        let (final_model, final_eval, final_effects) = match selected {
            Some(e) => {
                let (eval, effects) = evals.remove(&e).expect("evaluated");
                (self.score(&eval, &effects), eval, effects)
            }
            None => (baseline.clone(), base_eval.clone(), applied.clone()),
        };
        let (final_fit, calibration_fit) = self.final_fits(&final_effects);
        let fixes = Self::fixes_of(&final_effects);
        let final_set = &self.sets[&(fixes.torn, fixes.dedup)];
        let noise_floor_mps2 =
            (final_eval.v.iter().sum::<f64>() / final_eval.v.len().max(1) as f64).sqrt()
                * self.cfg.gravity_mps2;
        let unexplained_structure = final_model.rms_mps2
            > self.cfg.unexplained_ratio * final_model.expected_rms_mps2
            && final_model.p_value < self.cfg.unexplained_p;
        Ok(Diagnosis {
            kind: self.kind,
            validation: self.validation_text(base_set),
            baseline_points: self.points(base_set, &base_eval),
            final_points: self.points(final_set, &final_eval),
            baseline,
            candidates,
            selected,
            final_model,
            noise_floor_mps2,
            unexplained_structure,
            acquisition: self.acquisition(),
            final_fit,
            calibration_fit,
            histogram: self.histogram(),
            gravity_mps2: self.cfg.gravity_mps2,
        })
    }

    /// The final fit of `final_effects`, and the one a calibration file can carry: not the
    /// set-up's label errors nor the steps of one session's gaps.
    fn final_fits(&self, final_effects: &[Effect]) -> (FinalFit, FinalFit) {
        let fixes = Self::fixes_of(final_effects);
        let final_set = &self.sets[&(fixes.torn, fixes.dedup)];
        let (final_fit, _) = self.final_fit(final_set, final_effects);
        let sensor_effects: Vec<Effect> = final_effects
            .iter()
            .copied()
            .filter(|e| !matches!(e, Effect::ReferenceTilt | Effect::Gaps))
            .collect();
        let calibration_fit = if sensor_effects == final_effects {
            final_fit.clone()
        } else {
            self.final_fit(final_set, &sensor_effects).0
        };
        (final_fit, calibration_fit)
    }

    /// The acquisition findings of the raw sessions.
    fn acquisition(&self) -> Vec<AcquisitionFindings> {
        self.sessions
            .iter()
            .filter_map(|s| match s {
                Session::Raw(r) => Some(r.findings.clone()),
                Session::Means { .. } => None,
            })
            .collect()
    }

    fn validation_text(&self, set: &ObsSet) -> String {
        let n_test = set.obs.iter().filter(|o| o.test).count();
        if n_test > 0 {
            return format!(
                "fitted on the calibration data ({} observations), evaluated on the test data ({n_test})",
                set.calib_rows.len()
            );
        }
        if self
            .sessions
            .iter()
            .any(|s| matches!(s, Session::Means { .. }))
        {
            return format!(
                "leave-one-pose-out over {} poses (a means file: {} samples per pose assumed \
                 for the noise)",
                set.calib_rows.len(),
                self.cfg.data.pose_samples
            );
        }
        let kind = match self.folds {
            Folds::Sessions => {
                "whole sessions (session mod k; each held-out session's own constant refitted on it)"
            }
            Folds::Poses => "whole poses (pose mod k)",
            Folds::Blocks => "interleaved blocks of each static segment (block mod k)",
        };
        format!(
            "{} rounds over {kind}, {} observations of {} s",
            set.rounds.len(),
            set.calib_rows.len(),
            self.cfg.data.block_s
        )
    }

    /// Fits the model with `effects` on all calibration observations of `set`; also returns
    /// the total rank it uses (linear: shared rank over the axes plus group constants;
    /// label-free: its parameter count).
    fn final_fit(&self, set: &ObsSet, effects: &[Effect]) -> (FinalFit, usize) {
        let tau_grid = if effects.contains(&Effect::WarmUp) {
            self.tau_grid(set)
        } else {
            vec![1.0]
        };
        let mut out = self.empty_fit(set, effects);
        let solved = match self.kind {
            BaselineKind::LabelFree => self.final_label_free(set, effects, tau_grid, &mut out),
            _ => Some(self.final_linear(set, effects, &tau_grid, &mut out)),
        };
        let Some(solved) = solved else {
            return (out, 0);
        };
        out.per_pose_residual_g = per_pose_residual(set, &solved.resid);
        out.terms = reading_terms(set, &solved.coef, solved.tau);
        (out, solved.rank)
    }

    /// A final fit of `effects` on `set`'s calibration observations with what the data say
    /// (poses, repaired samples, temperature range) and nothing fitted yet.
    fn empty_fit(&self, set: &ObsSet, effects: &[Effect]) -> FinalFit {
        let rows = &set.calib_rows;
        let repaired_samples = if effects.contains(&Effect::TornReads) {
            self.sessions[..self.n_calib]
                .iter()
                .map(|s| match s {
                    Session::Raw(r) => r.findings.torn.total(),
                    Session::Means { .. } => 0,
                })
                .sum()
        } else {
            0
        };
        let temps: Vec<f64> = rows.iter().filter_map(|&o| set.obs[o].temp_c).collect();
        let temperature_range_c = (!temps.is_empty()).then(|| {
            [
                temps.iter().copied().fold(f64::INFINITY, f64::min),
                temps.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            ]
        });
        let poses: std::collections::BTreeSet<usize> =
            rows.iter().map(|&o| set.obs[o].pose).collect();
        FinalFit {
            kind: self.kind,
            effects: effects.to_vec(),
            model: None,
            covariance: None,
            terms: ReadingTerms::default(),
            tilt_g: Vec::new(),
            per_pose_residual_g: Vec::new(),
            chi2: 0.0,
            dof: 0,
            poses: poses.len(),
            repaired_samples,
            temperature_range_c,
        }
    }

    /// The label-free final fit (the best warm-up time constant of `tau_grid`): the model,
    /// its covariance and chi-square go into `out`; `None` if no fit converged.
    fn final_label_free(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau_grid: Vec<f64>,
        out: &mut FinalFit,
    ) -> Option<Solved> {
        let rows = &set.calib_rows;
        let x0 = set.lf_start.clone().expect("label-free start");
        let tau_grid = if tau_grid.len() > 1 {
            vec![self.best_tau_magnitude(set, effects, rows, &x0, &tau_grid)]
        } else {
            tau_grid
        };
        let mut best: Option<MagnitudeChoice> = None;
        for &t in &tau_grid {
            let terms = self.magnitude_terms(set, effects, t);
            let plain: Vec<Term> = terms.iter().map(|(_, t)| t.clone()).collect();
            if let Ok(f) = magnitude::fit(&set.m, &set.v, &plain, rows, &x0)
                && best.as_ref().is_none_or(|b| f.chi2 < b.0)
            {
                best = Some((f.chi2, f, terms, t));
            }
        }
        let (chi2, f, terms, tau) = best?;
        let mut solved = Solved::new(set, tau, f.x.len());
        for (c, (e, term)) in terms.iter().enumerate() {
            solved.coef.entry(*e).or_insert([0.0; 3])[term.axis] = f.x[9 + c];
        }
        let plain: Vec<Term> = terms.into_iter().map(|(_, t)| t).collect();
        for &o in rows {
            let z = magnitude::corrected(&f.x, &plain, &set.m[o], o);
            solved.resid[o] = [z.norm() - 1.0, 0.0, 0.0];
        }
        let t_mat = f.t();
        let s = t_mat.try_inverse().unwrap_or_else(Matrix3::identity);
        out.model = AccelModel::new(ModelKind::Full, s, f.bias()).ok();
        let dof = rows.len().saturating_sub(f.x.len());
        let scale = if dof > 0 {
            (chi2 / dof as f64).max(1.0)
        } else {
            1.0
        };
        out.covariance = Some(label_free_covariance(&s, &f.cov, scale));
        out.chi2 = chi2;
        out.dof = dof;
        Some(solved)
    }

    /// The linear final fit (the best warm-up time constant of `tau_grid`): the model (full
    /// baseline), its covariance, the reference tilts and chi-square go into `out`.
    fn final_linear(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau_grid: &[f64],
        out: &mut FinalFit,
    ) -> Solved {
        let rows = &set.calib_rows;
        let mut best: Option<(f64, linear::AxisFit, [Vec<Tag>; 3], f64)> = None;
        for &t in tau_grid {
            let (design, tags) = self.linear_design(set, effects, t);
            let f = linear::fit(&set.m, &set.v, &design, rows);
            let c: f64 = f.chi2.iter().sum();
            if best.as_ref().is_none_or(|b| c < b.0) {
                best = Some((c, f, tags, t));
            }
        }
        let (chi2, f, tags, tau) = best.expect("at least one time constant");
        let mut solved = Solved::new(set, tau, f.rank.iter().sum::<usize>() + 3 * f.groups);
        let (design, _) = self.linear_design(set, effects, tau);
        let mut unpacked = Unpacked::default();
        let dof = 3 * rows.len() - solved.rank.min(3 * rows.len());
        let red = if dof > 0 {
            (chi2 / dof as f64).max(1.0)
        } else {
            1.0
        };
        for (axis, axis_tags) in tags.iter().enumerate() {
            let th = &f.theta[axis];
            let layout_index = unpacked.axis(axis, th, axis_tags, &mut solved.coef);
            for &(a, ka) in &layout_index {
                for &(b, kb) in &layout_index {
                    unpacked.cov[(ka, kb)] = red * f.cov[axis][(a, b)];
                }
            }
            let consts: BTreeMap<usize, f64> = f.group_const[axis]
                .iter()
                .map(|(g, a, _)| (*g, *a))
                .collect();
            for &o in rows {
                let pred: f64 = design.columns[axis]
                    .iter()
                    .zip(th)
                    .map(|(col, t)| col[o] * t)
                    .sum::<f64>()
                    + design.groups.as_ref().map_or(0.0, |g| consts[&g[o]]);
                solved.resid[o][axis] = set.m[o][axis] - pred;
            }
            if self.kind == BaselineKind::Full && design.groups.is_some() {
                // With bias steps at gaps, b is the constant before the first gap.
                unpacked.bias[axis] = f.group_const[axis].first().map_or(0.0, |e| e.1);
            }
        }
        if self.kind == BaselineKind::Full {
            out.model = AccelModel::new(ModelKind::Full, unpacked.scale, unpacked.bias).ok();
            out.covariance = Some(unpacked.cov);
        }
        out.tilt_g = unpacked.tilt.into_iter().collect();
        out.chi2 = chi2;
        out.dof = dof;
        solved
    }

    /// Histogram of sample deviations from their block means in every raw session.
    fn histogram(&self) -> Option<SampleHistogram> {
        const START: f64 = -520.0;
        const WIDTH: f64 = 8.0;
        const BINS: usize = 130;
        let mut h = SampleHistogram {
            start_counts: START,
            bin_counts: WIDTH,
            raw: std::array::from_fn(|_| vec![0; BINS]),
            repaired: std::array::from_fn(|_| vec![0; BINS]),
        };
        let mut any = false;
        let lsb = self.cfg.data.accel_lsb_per_g;
        let block = (self.cfg.data.block_s * 1e9) as u64;
        for s in &self.sessions {
            let Session::Raw(r) = s else { continue };
            any = true;
            for seg in &r.segments {
                let mut k0 = seg.start;
                while k0 < seg.end {
                    let mut k1 = k0;
                    while k1 < seg.end && r.t_ns[k1] - r.t_ns[k0] < block {
                        k1 += 1;
                    }
                    for (values, hist) in [(&r.a_raw, &mut h.raw), (&r.a_repaired, &mut h.repaired)]
                    {
                        let block = &values[k0..k1];
                        let mut mean = [0.0; 3];
                        for a in block {
                            for (m, x) in mean.iter_mut().zip(a) {
                                *m += x;
                            }
                        }
                        let mean = mean.map(|m| m / block.len() as f64);
                        for a in block {
                            for (i, (x, m)) in a.iter().zip(&mean).enumerate() {
                                let bin = ((x - m) * lsb - START) / WIDTH;
                                if bin >= 0.0 && bin < BINS as f64 {
                                    hist[i][bin as usize] += 1;
                                }
                            }
                        }
                    }
                    k0 = k1;
                }
            }
        }
        any.then_some(h)
    }
}

/// The validation rounds: the test observations against all calibration rows when there are
/// any, otherwise one round per fold of the calibration rows.
fn validation_rounds(obs: &[Obs], calib_rows: &[usize]) -> Vec<Round> {
    let test_rows: Vec<usize> = (0..obs.len()).filter(|&o| obs[o].test).collect();
    if !test_rows.is_empty() {
        return vec![Round {
            train: calib_rows.to_vec(),
            eval: test_rows,
        }];
    }
    let folds: std::collections::BTreeSet<usize> =
        calib_rows.iter().map(|&o| obs[o].fold).collect();
    folds
        .iter()
        .map(|&f| Round {
            train: calib_rows
                .iter()
                .copied()
                .filter(|&o| obs[o].fold != f)
                .collect(),
            eval: calib_rows
                .iter()
                .copied()
                .filter(|&o| obs[o].fold == f)
                .collect(),
        })
        .collect()
}

/// What a final fit's solver leaves for the terms and residuals it reports.
struct Solved {
    /// The effects' coefficients per axis.
    coef: BTreeMap<Effect, [f64; 3]>,
    /// Residual of each observation (calibration rows only), g.
    resid: Vec<[f64; 3]>,
    /// Total rank used.
    rank: usize,
    /// The warm-up time constant used, s.
    tau: f64,
}

impl Solved {
    fn new(set: &ObsSet, tau: f64, rank: usize) -> Self {
        Self {
            coef: BTreeMap::new(),
            resid: vec![[0.0; 3]; set.obs.len()],
            rank,
            tau,
        }
    }
}

/// The linear fit's columns sorted into model 3 (scale matrix, bias, their covariance in the
/// 12-parameter layout) and reference tilts per orientation class.
struct Unpacked {
    scale: Matrix3<f64>,
    bias: Vector3<f64>,
    cov: ParamCovariance,
    tilt: BTreeMap<usize, [f64; 3]>,
}

impl Default for Unpacked {
    fn default() -> Self {
        Self {
            scale: Matrix3::zeros(),
            bias: Vector3::zeros(),
            cov: ParamCovariance::zeros(),
            tilt: BTreeMap::new(),
        }
    }
}

impl Unpacked {
    /// Sorts one axis' coefficients `th` (columns tagged `tags`); effects' coefficients go
    /// into `coef`. Returns the (column, parameter index) pairs of model 3's parameters.
    fn axis(
        &mut self,
        axis: usize,
        th: &[f64],
        tags: &[Tag],
        coef: &mut BTreeMap<Effect, [f64; 3]>,
    ) -> Vec<(usize, usize)> {
        let mut layout_index = Vec::new();
        for (c, tag) in tags.iter().enumerate() {
            match tag {
                Tag::Base(j) if *j < 3 => {
                    self.scale[(axis, *j)] = th[c];
                    layout_index.push((c, scale_index(axis, *j)));
                }
                Tag::Base(_) => {
                    self.bias[axis] = th[c];
                    layout_index.push((c, bias_index(axis)));
                }
                Tag::Effect(Effect::ReferenceTilt, class) => {
                    self.tilt.entry(*class).or_insert([0.0; 3])[axis] = th[c];
                }
                Tag::Effect(e, _) => {
                    coef.entry(*e).or_insert([0.0; 3])[axis] = th[c];
                }
            }
        }
        layout_index
    }
}

/// Mean residual per pose over the calibration observations, g.
fn per_pose_residual(set: &ObsSet, resid: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut per_pose: BTreeMap<usize, ([f64; 3], usize)> = BTreeMap::new();
    for &o in &set.calib_rows {
        let e = per_pose.entry(set.obs[o].pose).or_insert(([0.0; 3], 0));
        for (sum, r) in e.0.iter_mut().zip(resid[o]) {
            *sum += r;
        }
        e.1 += 1;
    }
    per_pose
        .values()
        .map(|(s, n)| s.map(|x| x / *n as f64))
        .collect()
}

/// The reading terms of the fitted effects' coefficients (`tau`: the warm-up's time constant,
/// s).
fn reading_terms(set: &ObsSet, coef: &BTreeMap<Effect, [f64; 3]>, tau: f64) -> ReadingTerms {
    let t_ref = set.t_ref_c;
    let mut terms = ReadingTerms::default();
    if let Some(c) = coef.get(&Effect::TemperatureBias) {
        terms.reference_c = t_ref;
        terms.temp_bias_g_per_c = Some(Vector3::from(*c));
    }
    if let Some(c) = coef.get(&Effect::TemperatureScale) {
        terms.reference_c = t_ref;
        terms.temp_scale_per_c = Some(Vector3::from(*c));
    }
    if let Some(c) = coef.get(&Effect::BiasDrift) {
        terms.drift = Some((Vector3::from(*c), set.t_max_s.unwrap_or(0.0)));
    }
    if let Some(c) = coef.get(&Effect::WarmUp) {
        terms.warm_up = Some((Vector3::from(*c), tau));
    }
    if let Some(c) = coef.get(&Effect::ScaleNonlinearity) {
        terms.quadratic_g_per_g2 = Some(Vector3::from(*c));
    }
    terms
}

/// Covariance of `S = T^-1` and `b` in the 12-parameter layout from the covariance of
/// `[b, T upper triangle, ...]`: `dS = -S dT S`, scaled by `scale`.
fn label_free_covariance(
    s: &Matrix3<f64>,
    cov: &nalgebra::DMatrix<f64>,
    scale: f64,
) -> ParamCovariance {
    const T_INDEX: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
    // Jacobian of the 12 layout parameters with respect to the 9 fitted ones.
    let mut j = nalgebra::SMatrix::<f64, 12, 9>::zeros();
    for a in 0..3 {
        j[(bias_index(a), a)] = 1.0;
    }
    for (k, &(r, c)) in T_INDEX.iter().enumerate() {
        let mut e = Matrix3::zeros();
        e[(r, c)] = 1.0;
        let ds = -s * e * s;
        for row in 0..3 {
            for col in 0..3 {
                j[(scale_index(row, col), 3 + k)] = ds[(row, col)];
            }
        }
    }
    let c9 = nalgebra::SMatrix::<f64, 9, 9>::from_fn(|r, c| cov[(r, c)]);
    j * c9 * j.transpose() * scale
}

/// The selection rule (see the module documentation).
fn select(candidates: &[CandidateResult], cfg: &DiagnoseConfig) -> Option<Effect> {
    let eligible: Vec<&CandidateResult> = candidates
        .iter()
        .filter(|c| {
            c.status == CandidateStatus::Evaluated
                && c.score >= cfg.select_threshold
                && c.explained >= cfg.explain_fraction
        })
        .collect();
    let best = eligible
        .iter()
        .map(|c| c.score)
        .fold(f64::NEG_INFINITY, f64::max);
    eligible
        .into_iter()
        .filter(|c| c.score >= best - cfg.select_threshold)
        .min_by(|a, b| a.params.cmp(&b.params).then(b.score.total_cmp(&a.score)))
        .map(|c| c.effect)
}
