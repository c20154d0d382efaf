//! Dead reckoning on a static recording, the way a robot uses the sensor after it boots
//! (`mems-eval static`): calibrate from a six-position session; then, for each window start
//! `s`, take `align_s` seconds at rest for alignment followed by `window_s` seconds of dead
//! reckoning, and report each method's displacement at the end with the 1-sigma it predicts.
//! The truth is zero displacement. A method may use the alignment interval and anything
//! recorded before it (the six-position session, earlier recordings), never anything after.
//!
//! Methods (units m/s^2 and m; window times relative to the test file's first sample):
//! - `thesis_full`: model 3 (unweighted fit), subtract (0, 0, g), integrate from rest over the
//!   dead-reckoning part, in the sensor frame. Its sigma: white noise (per-sample std of the
//!   alignment interval) + the calibration's bias uncertainty (the fit covariance propagated
//!   through the correction at the alignment interval's mean reading) + bias drift. It cannot
//!   account for label errors of the six-position session (a table that is not level), which
//!   dominate its real error.
//! - `best`: torn reads repaired ([`calibrate::repair`]); model 3 applied; gravity alignment: the
//!   mean corrected reading over the alignment interval defines the vertical (the navigation
//!   frame's z axis; the minimal rotation from the sensor frame) and the magnitude of gravity,
//!   which is subtracted; a warm-up term where earlier recordings allow (the mean displacement
//!   those recordings show with the same timing since power-on, subtracted); then plain
//!   integration (no zero-velocity updates). Displacement in the navigation frame.
//!   Its sigma: white noise over the dead-reckoning part + the alignment mean's white-noise
//!   error + bias drift + the warm-up term's own uncertainty.
//!
//! Bias drift (see [`crate::drerror`]) comes from data before the window: with earlier static
//! recordings (`priors`, e.g. the thesis's start-up runs), as the excess of the spread of their
//! `best` displacements (same window timing) over what white noise and alignment explain;
//! without them, from the noise parameters: the bias instability `B` (flicker, referenced to
//! the alignment mean: [`crate::drerror::flicker_sigma_m`]) and rate random walk `K`
//! ([`crate::drerror::rrw_sigma_m`]) of a calibration file's `[noise]` table when one is given
//! (the one source of truth), else of an Allan analysis ([`noise::analyze`]) of the test file's
//! own data before the dead-reckoning part. Unresolved terms count at their 2-sigma upper limit
//! ([`noise::params::AxisNoise::values_or_limits`]): a 10 s rest cannot resolve them, so that
//! sigma is conservative. The sensor axes' variances are rotated into the navigation frame
//! (axes independent).

use std::path::PathBuf;

use indicatif::ProgressBar;
use nalgebra::{Matrix3, Rotation3, Vector3};
use recording::Recording;
use recording::thesis::SixPosition;

use crate::drerror::{bias_sigma_m, flicker_sigma_m, rrw_sigma_m, white_sigma_m};
use crate::fit::{FitError, LabelledFit, Weighting, fit_labelled};
use crate::integrate::DoubleIntegrator;
use crate::session::poses_from_six;
use calibrate::model::{AccelModel, ModelKind};
use calibrate::repair::{RepairConfig, TornReport, repair_torn_reads};
use noise::NoiseParams;

/// Settings of the evaluation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticEvalConfig {
    /// Alignment interval, s.
    pub align_s: f64,
    /// Dead-reckoning interval, s.
    pub window_s: f64,
    /// Spacing of window starts, s.
    pub step_s: f64,
    /// Local gravity, m/s^2.
    pub gravity_mps2: f64,
}

/// Why the evaluation could not run.
#[derive(Debug, thiserror::Error)]
pub enum StaticEvalError {
    /// The six-position fit failed.
    #[error("{}: {source}", path.display())]
    Fit {
        /// The six-position file.
        path: PathBuf,
        /// The fit error.
        source: FitError,
    },
    /// No window fits in the test file.
    #[error(
        "{}: the recording lasts {duration_s:.1} s, shorter than one alignment + dead-reckoning window ({needed_s:.1} s)",
        path.display()
    )]
    TooShort {
        /// The test file.
        path: PathBuf,
        /// Its duration, s.
        duration_s: f64,
        /// align_s + window_s.
        needed_s: f64,
    },
    /// A setting is out of range.
    #[error("invalid setting: {0}")]
    Config(String),
    /// The Allan analysis of the rest before a window failed.
    #[error("noise analysis: {0}")]
    Noise(String),
}

/// One method's result in one window.
#[derive(Debug, Clone, PartialEq)]
pub struct MethodResult {
    /// Displacement at the end of the dead-reckoning part, m.
    pub d: [f64; 3],
    /// Predicted 1-sigma of `d`, m.
    pub sigma: [f64; 3],
    /// Contributions to `sigma` (each a 1-sigma, m; they add in quadrature).
    pub terms: SigmaTerms,
    /// Displacement over time: (seconds since the start of dead reckoning, m), decimated.
    pub trajectory: Trajectory,
}

/// The contributions to a predicted sigma, m per axis.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SigmaTerms {
    /// White noise integrated over the dead-reckoning part.
    pub white: [f64; 3],
    /// Error of the bias reference (alignment mean, or the calibration's bias for thesis_full).
    pub reference: [f64; 3],
    /// Bias drift.
    pub drift: [f64; 3],
    /// Uncertainty of the warm-up term.
    pub warmup: [f64; 3],
}

impl SigmaTerms {
    fn total(&self) -> [f64; 3] {
        std::array::from_fn(|i| {
            (self.white[i].powi(2)
                + self.reference[i].powi(2)
                + self.drift[i].powi(2)
                + self.warmup[i].powi(2))
            .sqrt()
        })
    }
}

/// Results for one window start.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowResult {
    /// Window start, s after the test file's first sample.
    pub start_s: f64,
    /// Model 3 as the thesis used it.
    pub thesis_full: MethodResult,
    /// This project's pipeline.
    pub best: MethodResult,
}

/// The whole evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct StaticEvalReport {
    /// Per window.
    pub windows: Vec<WindowResult>,
    /// Root-mean-square displacement over windows per axis: (thesis_full, best), m.
    pub rms: ([f64; 3], [f64; 3]),
    /// Torn-read repairs in the test file.
    pub repair: TornReport,
    /// Earlier recordings that contributed to the drift and warm-up terms (per window, the
    /// smallest count).
    pub prior_runs: usize,
    /// Where the drift term of windows without earlier recordings came from.
    pub drift_source: DriftSource,
}

/// Where the bias drift term comes from when no earlier recordings cover a window.
#[derive(Debug, Clone, PartialEq)]
pub enum DriftSource {
    /// Every window had earlier recordings.
    Priors,
    /// The given noise parameters (a calibration file's `[noise]` table), from this source.
    NoiseTable(String),
    /// An Allan analysis of the test file's data before each dead-reckoning part.
    OwnRest,
}

impl StaticEvalReport {
    /// The JSON document of the issue: `{"windows": [{"start_s", "methods": {"thesis_full":
    /// {"d", "sigma"}, "best": {...}}}], "rms": {"thesis_full", "best"}}`, metres.
    pub fn to_json(&self) -> serde_json::Value {
        let windows: Vec<serde_json::Value> = self
            .windows
            .iter()
            .map(|w| {
                serde_json::json!({
                    "start_s": w.start_s,
                    "methods": {
                        "thesis_full": { "d": w.thesis_full.d, "sigma": w.thesis_full.sigma },
                        "best": { "d": w.best.d, "sigma": w.best.sigma },
                    }
                })
            })
            .collect();
        serde_json::json!({
            "windows": windows,
            "rms": { "thesis_full": self.rms.0, "best": self.rms.1 },
        })
    }

    /// A human-readable table with the sigma contributions.
    pub fn to_text(&self, cfg: &StaticEvalConfig) -> String {
        let f3 = |v: [f64; 3]| format!("[{:>8.3} {:>8.3} {:>8.3}]", v[0], v[1], v[2]);
        let mut out = format!(
            "static dead reckoning: align {} s, window {} s, step {} s, g = {} m/s^2; torn reads repaired x/y/z: {:?}; earlier recordings used: {}; drift without them: {}\n",
            cfg.align_s,
            cfg.window_s,
            cfg.step_s,
            cfg.gravity_mps2,
            self.repair.accel.map(|a| a.repaired),
            self.prior_runs,
            match &self.drift_source {
                DriftSource::Priors => "not needed".to_owned(),
                DriftSource::NoiseTable(source) => format!("noise parameters of {source}"),
                DriftSource::OwnRest =>
                    "Allan analysis of the rest before each window (upper limits)".to_owned(),
            }
        );
        for w in &self.windows {
            out.push_str(&format!("window start {:.1} s\n", w.start_s));
            for (name, m) in [("thesis_full", &w.thesis_full), ("best", &w.best)] {
                let z: [f64; 3] = std::array::from_fn(|i| m.d[i] / m.sigma[i]);
                out.push_str(&format!(
                    "  {name:<11} d {}  sigma {}  d/sigma [{:>6.2} {:>6.2} {:>6.2}]\n",
                    f3(m.d),
                    f3(m.sigma),
                    z[0],
                    z[1],
                    z[2]
                ));
                out.push_str(&format!(
                    "              terms: white {} reference {} drift {} warm-up {}\n",
                    f3(m.terms.white),
                    f3(m.terms.reference),
                    f3(m.terms.drift),
                    f3(m.terms.warmup)
                ));
            }
        }
        out.push_str(&format!(
            "rms thesis_full {}\nrms best        {}\n",
            f3(self.rms.0),
            f3(self.rms.1)
        ));
        out
    }
}

/// Displacement over time: (seconds since dead reckoning began, displacement m).
pub type Trajectory = Vec<(f64, [f64; 3])>;

/// A 3 x 3 matrix as rows (plain arrays keep the per-sample loops cheap in debug builds).
type M3 = [[f64; 3]; 3];

fn mat_vec(m: &M3, v: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[r][0] * v[0] + m[r][1] * v[1] + m[r][2] * v[2])
}

fn to_rows(m: &Matrix3<f64>) -> M3 {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// A recording as times (s since its first sample) and specific force (m/s^2, sensor frame).
struct Series {
    t: Vec<f64>,
    a: Vec<[f64; 3]>,
    /// The raw readings (g), for covariance propagation.
    raw_g: Vec<[f64; 3]>,
}

impl Series {
    fn new(samples: &[ipc_types::RawImuSample], model: &AccelModel, gravity: f64) -> Self {
        let t0 = samples.first().map_or(0, |s| s.stamps.sample_ns);
        let inv = to_rows(&(model.scale_inv() * gravity));
        let b = model.bias_g();
        Self {
            t: samples
                .iter()
                .map(|s| (s.stamps.sample_ns - t0) as f64 * 1e-9)
                .collect(),
            a: samples
                .iter()
                .map(|s| {
                    mat_vec(
                        &inv,
                        &[s.accel_g[0] - b.x, s.accel_g[1] - b.y, s.accel_g[2] - b.z],
                    )
                })
                .collect(),
            raw_g: samples.iter().map(|s| s.accel_g).collect(),
        }
    }

    fn duration(&self) -> f64 {
        self.t.last().copied().unwrap_or(0.0)
    }

    /// Index range of samples with `from <= t < to`.
    fn range(&self, from: f64, to: f64) -> std::ops::Range<usize> {
        let a = self.t.partition_point(|&t| t < from);
        let b = self.t.partition_point(|&t| t < to);
        a..b
    }
}

/// Mean, per-axis sample std and count of vectors.
fn mean_std(v: impl Iterator<Item = [f64; 3]> + Clone) -> ([f64; 3], [f64; 3], usize) {
    let (mut n, mut sum) = (0usize, [0.0; 3]);
    for x in v.clone() {
        n += 1;
        for i in 0..3 {
            sum[i] += x[i];
        }
    }
    let mean = sum.map(|s| s / n as f64);
    let mut ss = [0.0; 3];
    for x in v {
        for i in 0..3 {
            ss[i] += (x[i] - mean[i]).powi(2);
        }
    }
    (mean, ss.map(|s| (s / (n.max(2) - 1) as f64).sqrt()), n)
}

/// Integrates `f(k)` over the samples `range` from rest; returns the end displacement, the
/// decimated trajectory (every 10th sample and the last) and the duration.
fn integrate(
    series: &Series,
    range: std::ops::Range<usize>,
    f: impl Fn(usize) -> [f64; 3],
) -> ([f64; 3], Trajectory, f64) {
    let t_start = series.t[range.start];
    let mut integ = DoubleIntegrator::new();
    let mut traj = Vec::with_capacity(range.len() / 10 + 2);
    let last = range.end - 1;
    for k in range {
        integ.push(series.t[k], f(k));
        if (last - k).is_multiple_of(10) {
            traj.push((series.t[k] - t_start, integ.displacement()));
        }
    }
    (integ.displacement(), traj, series.t[last] - t_start)
}

/// The `best` method without the warm-up term on one window of a series: displacement,
/// trajectory, and the white and alignment sigma terms.
struct BestRaw {
    d: [f64; 3],
    trajectory: Trajectory,
    white: [f64; 3],
    align: [f64; 3],
    /// Alignment rotation (sensor to navigation frame).
    rot: M3,
}

/// [`BestRaw`] for the window starting at `start`; `None` if the window does not fit.
fn best_raw(series: &Series, start: f64, cfg: &StaticEvalConfig) -> Option<BestRaw> {
    if series.duration() < start + cfg.align_s + cfg.window_s {
        return None;
    }
    let align = series.range(start, start + cfg.align_s);
    let dr = series.range(
        start + cfg.align_s,
        start + cfg.align_s + cfg.window_s + 1e-9,
    );
    if align.len() < 10 || dr.len() < 10 {
        return None;
    }
    let (g_sensor, _, _) = mean_std(series.a[align.clone()].iter().copied());
    let g_sensor = Vector3::from(g_sensor);
    let rot = to_rows(
        Rotation3::rotation_between(&g_sensor, &Vector3::z())
            .unwrap_or_else(Rotation3::identity)
            .matrix(),
    );
    let g_norm = g_sensor.norm();
    let (_, sigma, n_align) = mean_std(series.a[align].iter().map(|a| mat_vec(&rot, a)));
    let (d, trajectory, t_dr) = integrate(series, dr.clone(), |k| {
        let v = mat_vec(&rot, &series.a[k]);
        [v[0], v[1], v[2] - g_norm]
    });
    let dt = t_dr / (dr.len() - 1) as f64;
    Some(BestRaw {
        d,
        trajectory,
        white: std::array::from_fn(|i| white_sigma_m(sigma[i], dt, t_dr)),
        align: std::array::from_fn(|i| bias_sigma_m(sigma[i] / (n_align as f64).sqrt(), t_dr)),
        rot,
    })
}

/// Drift and warm-up terms learned from earlier recordings for one window timing.
struct PriorTerms {
    runs: usize,
    /// Mean trajectory on a 0.05 s grid (the warm-up displacement), m.
    warmup: Vec<[f64; 3]>,
    /// 1-sigma of the warm-up mean at the end, m.
    warmup_sigma: [f64; 3],
    /// Drift 1-sigma at the end, m.
    drift: [f64; 3],
}

const GRID_S: f64 = 0.05;

/// Linear interpolation of a trajectory at time `tau`.
fn interp(traj: &[(f64, [f64; 3])], tau: f64) -> [f64; 3] {
    let k = traj.partition_point(|p| p.0 < tau);
    if k == 0 {
        return traj[0].1;
    }
    if k >= traj.len() {
        return traj[traj.len() - 1].1;
    }
    let (t0, a) = traj[k - 1];
    let (t1, b) = traj[k];
    let f = if t1 > t0 { (tau - t0) / (t1 - t0) } else { 0.0 };
    std::array::from_fn(|i| a[i] + f * (b[i] - a[i]))
}

fn prior_terms(priors: &[Series], start: f64, cfg: &StaticEvalConfig) -> Option<PriorTerms> {
    let runs: Vec<BestRaw> = priors
        .iter()
        .filter_map(|p| best_raw(p, start, cfg))
        .collect();
    if runs.len() < 3 {
        return None;
    }
    let n = runs.len() as f64;
    let grid = (cfg.window_s / GRID_S).floor() as usize + 1;
    let warmup: Vec<[f64; 3]> = (0..grid)
        .map(|j| {
            let tau = j as f64 * GRID_S;
            let sum = runs.iter().fold([0.0; 3], |acc, r| {
                let p = interp(&r.trajectory, tau);
                std::array::from_fn(|i| acc[i] + p[i])
            });
            sum.map(|s| s / n)
        })
        .collect();
    let mut drift = [0.0; 3];
    let mut warmup_sigma = [0.0; 3];
    for i in 0..3 {
        let mean = runs.iter().map(|r| r.d[i]).sum::<f64>() / n;
        let var = runs.iter().map(|r| (r.d[i] - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let explained = runs
            .iter()
            .map(|r| r.white[i].powi(2) + r.align[i].powi(2))
            .sum::<f64>()
            / n;
        drift[i] = (var - explained).max(0.0).sqrt();
        warmup_sigma[i] = (var / n).sqrt();
    }
    Some(PriorTerms {
        runs: runs.len(),
        warmup,
        warmup_sigma,
        drift,
    })
}

/// Drift 1-sigma (m) per navigation axis implied by noise parameters: bias instability and
/// rate random walk of each sensor axis (values or 2-sigma upper limits), referenced to the
/// alignment mean and integrated over `t_dr`, rotated by `rot` (sensor to navigation frame).
fn noise_drift(params: &NoiseParams, rot: &M3, cfg: &StaticEvalConfig, t_dr: f64) -> [f64; 3] {
    // The table's m/s^2 are g times its gravity; this evaluation's are g times cfg's.
    let scale = cfg.gravity_mps2 / params.gravity_mps2;
    let sensor_var: [f64; 3] = std::array::from_fn(|j| {
        let [_, b, k] = params.accel.axes()[j].values_or_limits();
        flicker_sigma_m(b * scale, cfg.align_s, t_dr).powi(2)
            + rrw_sigma_m((k * scale).powi(2), cfg.align_s, t_dr).powi(2)
    });
    std::array::from_fn(|i| {
        (0..3)
            .map(|j| rot[i][j] * rot[i][j] * sensor_var[j])
            .sum::<f64>()
            .sqrt()
    })
}

/// Noise parameters of the test file's own samples before `before_s` (s after its first
/// sample), from the Allan analysis `mems-calibrate allan` runs.
fn own_rest_noise(
    test: &Recording,
    before_s: f64,
    gravity_mps2: f64,
) -> Result<NoiseParams, StaticEvalError> {
    let t0 = test.samples.first().map_or(0, |s| s.stamps.sample_ns);
    let end_ns = t0 + (before_s * 1e9) as u64;
    let mut rest: Vec<ipc_types::RawImuSample> = test
        .samples
        .iter()
        .take_while(|s| s.stamps.sample_ns < end_ns)
        .copied()
        .collect();
    let source = format!("{} (first {before_s} s)", test.source.display());
    let options = noise::Options {
        gravity_mps2,
        ..noise::Options::default()
    };
    noise::analyze(&mut rest, &source, &options)
        .map(|report| report.params)
        .map_err(|e| StaticEvalError::Noise(e.to_string()))
}

/// The best method's trajectory with the prior runs' mean warm-up subtracted.
fn warmup_subtracted(trajectory: &Trajectory, p: &PriorTerms) -> Trajectory {
    trajectory
        .iter()
        .map(|&(tau, d)| {
            let j = ((tau / GRID_S).round() as usize).min(p.warmup.len() - 1);
            (tau, std::array::from_fn(|i| d[i] - p.warmup[j][i]))
        })
        .collect::<Vec<_>>()
}

/// The noise parameters a window without priors takes its drift from: the calibration file's
/// `[noise]` table if given, else the test recording's own rest before `rest_end_s`.
fn drift_noise(
    noise: Option<&NoiseParams>,
    test: &Recording,
    rest_end_s: f64,
    g: f64,
) -> Result<(NoiseParams, DriftSource), StaticEvalError> {
    Ok(match noise {
        Some(p) => (p.clone(), DriftSource::NoiseTable(p.source.clone())),
        None => (own_rest_noise(test, rest_end_s, g)?, DriftSource::OwnRest),
    })
}

/// thesis_full: model 3 on the raw samples, (0, 0, g) subtracted, sensor frame, over the
/// displacement range `dr` after aligning from `start` s.
fn thesis_full(
    raw_series: &Series,
    fit: &LabelledFit,
    start: f64,
    dr: std::ops::Range<usize>,
    drift: [f64; 3],
    cfg: &StaticEvalConfig,
) -> MethodResult {
    let g = cfg.gravity_mps2;
    let align = raw_series.range(start, start + cfg.align_s);
    let (mean_raw_g, _, _) = mean_std(raw_series.raw_g[align.clone()].iter().copied());
    let (_, sigma_raw, _) = mean_std(raw_series.a[align].iter().copied());
    let (_, cov_g) = fit.model.correct_with_covariance(
        &Vector3::from(mean_raw_g),
        &fit.covariance,
        &Matrix3::zeros(),
    );
    let (d_full, traj_full, t_full) = integrate(raw_series, dr.clone(), |k| {
        let a = raw_series.a[k];
        [a[0], a[1], a[2] - g]
    });
    let dt = t_full / (dr.len() - 1) as f64;
    let full_terms = SigmaTerms {
        white: std::array::from_fn(|i| white_sigma_m(sigma_raw[i], dt, t_full)),
        reference: std::array::from_fn(|i| bias_sigma_m(cov_g[(i, i)].sqrt() * g, t_full)),
        drift,
        warmup: [0.0; 3],
    };
    MethodResult {
        d: d_full,
        sigma: full_terms.total(),
        terms: full_terms,
        trajectory: traj_full,
    }
}

/// The earlier recordings, repaired, as series (`progress` advanced once per recording).
fn prior_series(
    priors: Vec<Recording>,
    model: &AccelModel,
    g: f64,
    progress: &ProgressBar,
) -> Vec<Series> {
    priors
        .into_iter()
        .map(|mut p| {
            repair_torn_reads(&mut p.samples, &RepairConfig::default());
            progress.inc(1);
            Series::new(&p.samples, model, g)
        })
        .collect()
}

/// The best method in one window (aligned from `start` s, displacement over `t_dr` s): its
/// warm-up subtracted along the trajectory where earlier recordings allow, its drift from
/// them or from the noise parameters. Also returns the drift's 1-sigma and, when the noise
/// parameters gave it, where they came from.
fn best_method(
    best: BestRaw,
    prior: Option<&PriorTerms>,
    noise: Option<&NoiseParams>,
    test: &Recording,
    start: f64,
    t_dr: f64,
    cfg: &StaticEvalConfig,
) -> Result<(MethodResult, [f64; 3], Option<DriftSource>), StaticEvalError> {
    let (drift, warmup_sigma, trajectory, source) = match prior {
        Some(p) => (
            p.drift,
            p.warmup_sigma,
            warmup_subtracted(&best.trajectory, p),
            None,
        ),
        None => {
            let (params, source) = drift_noise(noise, test, start + cfg.align_s, cfg.gravity_mps2)?;
            (
                noise_drift(&params, &best.rot, cfg, t_dr),
                [0.0; 3],
                best.trajectory.clone(),
                Some(source),
            )
        }
    };
    let d_best = trajectory.last().map_or(best.d, |p| p.1);
    let best_terms = SigmaTerms {
        white: best.white,
        reference: best.align,
        drift,
        warmup: warmup_sigma,
    };
    let result = MethodResult {
        d: d_best,
        sigma: best_terms.total(),
        terms: best_terms,
        trajectory,
    };
    Ok((result, drift, source))
}

/// Checks that the configuration's durations are positive.
fn check_config(cfg: &StaticEvalConfig) -> Result<(), StaticEvalError> {
    if !(cfg.align_s > 0.0 && cfg.window_s > 0.0 && cfg.step_s > 0.0) {
        return Err(StaticEvalError::Config(format!(
            "align, window and step must be positive (got {}, {}, {})",
            cfg.align_s, cfg.window_s, cfg.step_s
        )));
    }
    Ok(())
}

/// Runs the evaluation (see the module documentation). `priors` are earlier static
/// recordings of the same sensor (consumed: repaired in place); `noise` the sensor's noise
/// parameters (a calibration file's `[noise]` table), for windows without priors;
/// `progress` is advanced once per prior and per window.
pub fn evaluate_static(
    six: &SixPosition,
    test: &Recording,
    priors: Vec<Recording>,
    noise: Option<&NoiseParams>,
    cfg: &StaticEvalConfig,
    progress: &ProgressBar,
) -> Result<StaticEvalReport, StaticEvalError> {
    check_config(cfg)?;
    let poses = poses_from_six(six);
    let fit = fit_labelled(&poses, ModelKind::Full, Weighting::Unweighted).map_err(|source| {
        StaticEvalError::Fit {
            path: six.source.clone(),
            source,
        }
    })?;
    let model = fit.model;
    let g = cfg.gravity_mps2;

    let raw_series = Series::new(&test.samples, &model, g);
    let mut repaired = test.samples.clone();
    let repair = repair_torn_reads(&mut repaired, &RepairConfig::default());
    let series = Series::new(&repaired, &model, g);

    let prior_series = prior_series(priors, &model, g, progress);

    let needed = cfg.align_s + cfg.window_s;
    if series.duration() < needed {
        return Err(StaticEvalError::TooShort {
            path: test.source.clone(),
            duration_s: series.duration(),
            needed_s: needed,
        });
    }
    let n_windows = ((series.duration() - needed) / cfg.step_s).floor() as usize + 1;
    let mut windows = Vec::with_capacity(n_windows);
    let mut prior_runs = usize::MAX;
    let mut drift_source = DriftSource::Priors;
    for w in 0..n_windows {
        let start = w as f64 * cfg.step_s;
        let Some(best) = best_raw(&series, start, cfg) else {
            continue;
        };
        let dr = series.range(start + cfg.align_s, start + needed + 1e-9);
        let t_dr = series.t[dr.end - 1] - series.t[dr.start];
        let prior = prior_terms(&prior_series, start, cfg);
        prior_runs = prior_runs.min(prior.as_ref().map_or(0, |p| p.runs));

        let (best_result, drift, source) =
            best_method(best, prior.as_ref(), noise, test, start, t_dr, cfg)?;
        if let Some(source) = source {
            drift_source = source;
        }
        windows.push(WindowResult {
            start_s: start,
            thesis_full: thesis_full(&raw_series, &fit, start, dr, drift, cfg),
            best: best_result,
        });
        progress.inc(1);
    }
    let rms_of = |f: &dyn Fn(&WindowResult) -> [f64; 3]| -> [f64; 3] {
        std::array::from_fn(|i| {
            (windows.iter().map(|w| f(w)[i].powi(2)).sum::<f64>() / windows.len() as f64).sqrt()
        })
    };
    let rms = (rms_of(&|w| w.thesis_full.d), rms_of(&|w| w.best.d));
    Ok(StaticEvalReport {
        windows,
        rms,
        repair,
        prior_runs: if prior_runs == usize::MAX {
            0
        } else {
            prior_runs
        },
        drift_source,
    })
}
