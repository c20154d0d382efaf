//! Residual diagnosis: fit the baseline model, test its held-out residuals against candidate
//! effects the model lacks, add the one that explains them (if any), and say when structure
//! remains that no candidate explains. `mems-calibrate diagnose` is the command line.
//!
//! # Method
//!
//! **Data.** Each session is cut into observations (module `data`): block means of `block_s`
//! seconds inside static segments (raw recordings) or the poses of a six-position means file,
//! each with the white-noise variance of its mean that the samples themselves predict, and its
//! elapsed time (s) since a time origin: the session's first sample, or with
//! [`DiagnoseConfig::same_power_on`] the first sample of the first session (the sessions are
//! then one power-on on one clock, so a drift or warm-up continues from file to file). What
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
//!
//! # Steps
//!
//! [`diagnose`] chooses the baseline (`baseline`), builds the observations of each choice of
//! fixes (`observations`), evaluates the baseline and each candidate on held-out data
//! (`evaluate`, `candidates`), fits the selected model on all calibration data (`final_fit`)
//! and gathers what the diagnosis reports beside the models (`report`).

mod baseline;
mod candidates;
mod data;
mod effects;
mod evaluate;
mod final_fit;
mod linear;
mod magnitude;
mod observations;
pub mod plots;
mod report;

use std::collections::BTreeMap;

use serde::Serialize;

pub use data::{
    AcquisitionFindings, DEFAULT_MIN_SEGMENT_S, DataConfig, DataError, SessionInput, class_axis,
    orientation_class,
};
pub use effects::Effect;

use baseline::{check_test, choose_kind};
use calibrate::model::{AccelModel, ParamCovariance};
use calibrate::terms::ReadingTerms;
use candidates::select;
use data::Session;
use evaluate::Eval;
use observations::ObsSet;

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
    /// Whether the raw sessions (calibration, then test, in the order given) are recordings
    /// of one power-on: they then share one time origin, the first sample of the first, so
    /// that the time terms (bias drift, warm-up) continue from file to file (see
    /// `data::share_power_on`).
    pub same_power_on: bool,
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
            same_power_on: false,
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
    /// Elapsed time since the time origin (the session's first sample, or its power-on's), s.
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
    if cfg.same_power_on {
        data::share_power_on(&mut sessions)?;
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

impl Diagnoser<'_> {
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
}
