//! The residual loop on an odometry run (`mems-odometry diagnose`): from the run's rests
//! ([`evidence`]) it forms residuals the model should leave at its noise ([`rows`]: each
//! rest's specific-force magnitude against gravity, each motion's tilt from one rest to the
//! next against what the gyro carried), tests candidate effects the model lacks on them
//! ([`fit`]: held-out chi-square gain; [`rows::Candidate`]: the accelerometer's bias, scale
//! and bias with temperature, the gyro's scale, cross-axis sensitivity and rotation against
//! the accelerometer), selects what the data support, and says when what
//! remains still exceeds the noise and what the model carries ("unexplained"). The selection
//! is written into a calibration file ([`correct`]) for a rerun. Saturation, which no
//! calibration term models, is tested apart on the motions during which the gyro clipped
//! ([`saturation`]). An accelerometer lag behind the gyro shows in neither a rest nor a tilt:
//! it is tested on each motion's velocity change from rest to rest ([`velocity`]), and the
//! rerun applies it to the samples (`mems-odometry offline --accel-lag-s`, [`lag`]).
//! A lever arm between the IMU and the rear axle of a wheeled platform shows only in the
//! non-holonomic constraint's innovations: [`lever`] judges the profile of their chi-square
//! over the forward offset from reruns (`mems-odometry offline --lever-arm`).
//!
//! Selection, as `mems-calibrate diagnose` selects (docs/diagnosis.md): forward, one candidate
//! at a time, the one with the largest held-out gain over the current set, if that gain is
//! above [`Settings::threshold`] (12 white-noise units: about 1e-3 false alarms per
//! candidate of three parameters) and its fitted effect exceeds what the odometry already
//! carries for it ([`Settings::beyond_model`] times the configuration's 1-sigma on some axis,
//! and as many of its own 1-sigma) and is plausible for a real part (within the bounds
//! `calibrate::calibfile::plausibility::PLAUSIBLE` puts on a calibration file: a fit beyond
//! them, such as a gyro scale of -100 %, is a candidate explaining something else).
//! "Unexplained": the magnitude and tilt rows' chi-square after the selection, with each row's
//! noise and the model's carried 1-sigma added in quadrature, has a p-value below
//! [`Settings::unexplained_p`] (the velocity rows' own p-value is reported beside it).

pub mod correct;
pub mod evidence;
pub mod fit;
pub mod lag;
pub mod lever;
pub mod rows;
pub mod saturation;
pub mod velocity;

use nalgebra::Vector3;
use serde::Serialize;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use crate::config::OdometryConfig;
use evidence::Evidence;
use rows::{Candidate, Kind, Row};

/// How the diagnosis decides.
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    /// Held-out chi-square gain a candidate needs.
    pub threshold: f64,
    /// How many of the model's carried 1-sigma (and of its own) an effect must reach.
    pub beyond_model: f64,
    /// p-value below which what remains is unexplained.
    pub unexplained_p: f64,
    /// Temperature span across the rests the temperature candidate needs, degC.
    pub min_temp_span_c: f64,
    /// Rows per parameter a candidate needs once a rest (or motion) is held out: 7 rests
    /// for an accelerometer candidate (one row each), 4 motions for the gyro's (two each).
    pub min_rows_per_param: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            threshold: 12.0,
            beyond_model: 3.0,
            unexplained_p: 1e-3,
            min_temp_span_c: 1.0,
            min_rows_per_param: 2,
        }
    }
}

/// One candidate's test in the first round (against no correction).
#[derive(Debug, Clone, Serialize)]
pub struct Score {
    /// The candidate.
    pub candidate: Candidate,
    /// Why it could not be tested, if so.
    pub untestable: Option<String>,
    /// Held-out chi-square gain.
    pub gain: f64,
    /// Its fitted parameters alone (unit: [`Candidate::unit`]).
    pub params: [f64; 3],
    /// Their 1-sigma.
    pub sigma: [f64; 3],
    /// Whether the effect exceeds what the model carries.
    pub beyond_model: bool,
    /// Whether its parameters are plausible for a real part.
    pub plausible: bool,
}

/// Residual statistics of one kind of row.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Residuals {
    /// Rows.
    pub rows: usize,
    /// Rms before any correction (m/s^2 or rad).
    pub rms_before: f64,
    /// Rms after the selection's fit.
    pub rms_after: f64,
    /// Rms the rows' noise predicts.
    pub rms_noise: f64,
}

/// The diagnosis of a run.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    /// Rests used.
    pub rests: usize,
    /// Motions between them.
    pub motions: usize,
    /// Motions with clipped gyro samples (left out of the tilt rows, tested for saturation).
    pub motions_gyro_clipped: usize,
    /// Samples with any axis clipped.
    pub clipped_samples: usize,
    /// Reference temperature of the temperature candidate, degC (NaN without temperatures).
    pub t_ref_c: f64,
    /// First-round scores.
    pub scores: Vec<Score>,
    /// Selected effects and their parameters from the joint fit.
    pub selected: Vec<(Candidate, [f64; 3])>,
    /// Specific-force magnitude rows (m/s^2).
    pub magnitude: Residuals,
    /// Tilt rows (rad).
    pub tilt: Residuals,
    /// Velocity rows (m/s; their noise includes what the model carries), with the main
    /// selection's effects taken out before (and the lag, when found, after).
    pub velocity: Residuals,
    /// p-value of what remains on the velocity rows.
    pub velocity_p: f64,
    /// Chi-square of what remains (noise and carried 1-sigma), its degrees of freedom and
    /// p-value.
    pub chi2: f64,
    /// Degrees of freedom of `chi2`.
    pub dof: usize,
    /// p-value of `chi2`.
    pub p: f64,
    /// What remains exceeds noise and the model: no candidate explains it.
    pub unexplained: bool,
    /// The saturation candidate on the motions during which the gyro clipped.
    pub saturation: saturation::Saturation,
}

impl Diagnosis {
    /// The selected effects as [`correct::apply`] takes them.
    pub fn effects(&self) -> Vec<(Candidate, Vector3<f64>)> {
        self.selected
            .iter()
            .map(|(c, p)| (*c, Vector3::from(*p)))
            .collect()
    }
}

fn testable(c: Candidate, rows: &[Row], ev: &Evidence, s: &Settings) -> Option<String> {
    let groups = |kind| {
        let mut g: Vec<usize> = rows
            .iter()
            .filter(|r| r.kind == kind)
            .map(|r| r.group)
            .collect();
        g.dedup();
        g.len()
    };
    // Groups needed so that, one held out, the rest give `min_rows_per_param` rows per
    // parameter (three), with `per_group` rows each.
    let needed = |per_group: usize| (3 * s.min_rows_per_param).div_ceil(per_group) + 1;
    let span = temp_span(ev);
    match c {
        _ if c.is_gyro() && groups(Kind::Tilt) < needed(2) => Some(format!(
            "{} motions between rests with the gyro unclipped (needs {})",
            groups(Kind::Tilt),
            needed(2)
        )),
        _ if c.is_gyro() => None,
        _ if groups(Kind::Magnitude) < needed(1) => Some(format!(
            "{} rests (needs {})",
            groups(Kind::Magnitude),
            needed(1)
        )),
        Candidate::AccelTempBias if span.is_nan() || span < s.min_temp_span_c => Some(format!(
            "the rests' temperatures span {:.2} degC (needs {})",
            span.max(0.0),
            s.min_temp_span_c
        )),
        _ => None,
    }
}

/// The span of the rests' temperatures, degC (NaN or negative without any).
fn temp_span(ev: &Evidence) -> f64 {
    let temps = ev.rests.iter().map(|r| r.temp_c).filter(|t| t.is_finite());
    temps.clone().fold(f64::NEG_INFINITY, f64::max) - temps.fold(f64::INFINITY, f64::min)
}

/// The model's carried 1-sigma for each parameter of `c` (zero: the model has no such term):
/// for the gyro's, the configuration's `gyro_correction_sigma` (diagonal for the scale, the
/// larger of a pair's two off-diagonal entries for the cross-axis and rotation).
fn carried(c: Candidate, config: &OdometryConfig) -> [f64; 3] {
    match c {
        // The residual scale and misalignment read as a bias of g times it under gravity.
        Candidate::AccelBias => config
            .accel_bias_sigma_mps2
            .map(|b| b.hypot(config.gravity_mps2 * config.accel_residual_scale)),
        Candidate::AccelScale => [config.accel_residual_scale; 3],
        // The model has no such term; saturation is tested apart (`saturation`).
        Candidate::AccelTempBias | Candidate::GyroSaturation | Candidate::AccelLag => [0.0; 3],
        Candidate::GyroScale => std::array::from_fn(|i| config.gyro_correction_sigma[(i, i)]),
        // Parameter i acts on the pair of axes other than i (both entries of the pair).
        Candidate::GyroCrossAxis | Candidate::GyroRotation => std::array::from_fn(|i| {
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            let s = &config.gyro_correction_sigma;
            s[(j, k)].max(s[(k, j)])
        }),
    }
}

/// Whether the fitted parameters of the candidate at `slot` in `f` are plausible for a real
/// part (`PLAUSIBLE`: scale errors, bias; a temperature bias over `span_c` as a bias).
fn plausible(f: &fit::Fit, slot: usize, config: &OdometryConfig, span_c: f64) -> bool {
    let bounds = calibrate::calibfile::plausibility::PLAUSIBLE;
    let bias = bounds.accel_bias_g * config.gravity_mps2;
    let limit = match f.candidates[slot] {
        Candidate::AccelBias => bias,
        Candidate::AccelScale | Candidate::GyroScale => bounds.scale_error,
        Candidate::AccelTempBias => bias / span_c.max(1.0),
        // A rotation between the triads of one part is as small as its axes' misalignment.
        Candidate::GyroCrossAxis | Candidate::GyroRotation => bounds.cross_axis,
        Candidate::GyroSaturation => f64::INFINITY,
        Candidate::AccelLag => lag::MAX_LAG_S,
    };
    (0..3).all(|i| f.theta[3 * slot + i].abs() <= limit)
}

/// Whether the fitted parameters of the candidate at `slot` in `f` exceed the model.
fn beyond(f: &fit::Fit, slot: usize, config: &OdometryConfig, s: &Settings) -> bool {
    let floor = carried(f.candidates[slot], config);
    (0..3).any(|i| {
        let (p, sd) = (f.theta[3 * slot + i].abs(), f.sigma[3 * slot + i]);
        p > s.beyond_model * floor[i] && p > s.beyond_model * sd
    })
}

fn params(f: &fit::Fit, slot: usize) -> ([f64; 3], [f64; 3]) {
    (
        std::array::from_fn(|i| f.theta[3 * slot + i]),
        std::array::from_fn(|i| f.sigma[3 * slot + i]),
    )
}

fn residuals(rows: &[Row], after: &[f64], kind: Kind) -> Residuals {
    let idx: Vec<usize> = (0..rows.len()).filter(|&i| rows[i].kind == kind).collect();
    let rms = |f: &dyn Fn(usize) -> f64| {
        if idx.is_empty() {
            return 0.0;
        }
        (idx.iter().map(|&i| f(i).powi(2)).sum::<f64>() / idx.len() as f64).sqrt()
    };
    Residuals {
        rows: idx.len(),
        rms_before: rms(&|i| rows[i].r),
        rms_after: rms(&|i| after[i]),
        rms_noise: rms(&|i| rows[i].sigma),
    }
}

/// Diagnoses the run whose evidence is `ev`, under configuration `config`; `t_ref_c` is the
/// temperature candidate's reference (NaN: the first rest's).
pub fn diagnose(ev: &Evidence, config: &OdometryConfig, t_ref_c: f64, s: &Settings) -> Diagnosis {
    let t_ref_c = if t_ref_c.is_finite() {
        t_ref_c
    } else {
        ev.rests.first().map_or(f64::NAN, |r| r.temp_c)
    };
    let usable = |r: &Row| r.sigma > 0.0 && r.r.is_finite();
    let (clipped, rows): (Vec<Row>, Vec<Row>) = rows::rows(ev, config, t_ref_c)
        .into_iter()
        .filter(usable)
        .partition(|r| r.kind == Kind::ClippedTilt);
    let velocity: Vec<Row> = velocity::all(ev, config, t_ref_c)
        .into_iter()
        .filter(usable)
        .collect();
    let span = temp_span(ev);
    // The lag is tested apart, on the velocity rows (`lag_test`).
    let correctable = Candidate::ALL
        .into_iter()
        .filter(|&c| c.is_correctable() && c != Candidate::AccelLag);
    let open: Vec<Candidate> = correctable
        .clone()
        .filter(|&c| testable(c, &rows, ev, s).is_none())
        .collect();
    let mut scores: Vec<Score> = correctable
        .map(|c| score(c, &rows, testable(c, &rows, ev, s), config, s, span).0)
        .collect();
    let (chosen, fitted) = select(&rows, &open, config, s, span);
    let lag = lag_test(&velocity, &chosen, fitted.as_ref(), config, s);
    scores.push(lag.score.clone());
    let after = fitted.as_ref().map_or_else(
        || rows.iter().map(|r| r.r).collect(),
        |f| f.residuals.clone(),
    );
    let chi2: f64 = rows
        .iter()
        .zip(&after)
        .map(|(r, e)| e * e / (r.sigma.powi(2) + r.floor.powi(2)))
        .sum();
    let dof = rows.len().saturating_sub(3 * chosen.len()).max(1);
    let p = ChiSquared::new(dof as f64).map_or(1.0, |d| d.sf(chi2));
    let mut selected: Vec<(Candidate, [f64; 3])> = match &fitted {
        Some(f) => (0..chosen.len())
            .map(|k| (chosen[k], params(f, k).0))
            .collect(),
        None => Vec::new(),
    };
    if lag.found {
        selected.push((Candidate::AccelLag, lag.score.params));
    }
    Diagnosis {
        rests: ev.rests.len(),
        motions: ev.intervals.len(),
        motions_gyro_clipped: ev.intervals.iter().filter(|i| i.gyro_clipped > 0).count(),
        clipped_samples: ev
            .samples
            .iter()
            .filter(|x| x.raw_flags & ipc_types::raw_flags::SATURATED_AXES != 0)
            .count(),
        t_ref_c,
        scores,
        selected,
        magnitude: residuals(&rows, &after, Kind::Magnitude),
        tilt: residuals(&rows, &after, Kind::Tilt),
        velocity: lag.residuals,
        velocity_p: lag.p,
        chi2,
        dof,
        p,
        unexplained: p < s.unexplained_p,
        saturation: saturation::test(&clipped, &chosen, fitted.as_ref(), s),
    }
}

/// Candidate `c` alone on `rows` (`untestable`: why it cannot be), and its fit.
fn score(
    c: Candidate,
    rows: &[Row],
    untestable: Option<String>,
    config: &OdometryConfig,
    s: &Settings,
    span_c: f64,
) -> (Score, Option<fit::Fit>) {
    let f = untestable.is_none().then(|| fit::fit(rows, &[c])).flatten();
    let (params, sigma) = f.as_ref().map_or(([0.0; 3], [0.0; 3]), |f| params(f, 0));
    let score = Score {
        candidate: c,
        untestable,
        gain: f.as_ref().map_or(0.0, |f| f.gain),
        params,
        sigma,
        beyond_model: f.as_ref().is_some_and(|f| beyond(f, 0, config, s)),
        plausible: f.as_ref().is_some_and(|f| plausible(f, 0, config, span_c)),
    };
    (score, f)
}

/// `all`'s rows with the effect of `chosen`, fitted as `fitted`, taken out of each residual.
pub(crate) fn without(all: &[Row], chosen: &[Candidate], fitted: Option<&fit::Fit>) -> Vec<Row> {
    let slot = |c: &Candidate| Candidate::ALL.iter().position(|a| a == c).unwrap_or(0);
    all.iter()
        .map(|r| {
            let mut r = r.clone();
            if let Some(f) = fitted {
                for (k, c) in chosen.iter().enumerate() {
                    let d = r.design[slot(c)];
                    r.r -= (0..3).map(|i| d[i] * f.theta[3 * k + i]).sum::<f64>();
                }
            }
            r
        })
        .collect()
}

/// What the lag test found.
struct LagTest {
    score: Score,
    found: bool,
    residuals: Residuals,
    p: f64,
}

/// The accelerometer lag on the velocity rows `all`, with the main selection's effects
/// (`chosen`, fitted as `fitted`) taken out: found when its held-out gain passes the
/// threshold, it is beyond [`Settings::beyond_model`] of its own 1-sigma (the model carries
/// no lag) and plausible (within `lag::MAX_LAG_S`). Tested apart so that the velocity rows,
/// which every candidate acts on, leave the main selection as the rests and tilts make it.
fn lag_test(
    all: &[Row],
    chosen: &[Candidate],
    fitted: Option<&fit::Fit>,
    config: &OdometryConfig,
    s: &Settings,
) -> LagTest {
    let rows = without(all, chosen, fitted);
    let mut groups: Vec<usize> = rows.iter().map(|r| r.group).collect();
    groups.dedup();
    // Two rows per parameter once a motion is held out, three rows a motion.
    let needed = (3 * s.min_rows_per_param).div_ceil(3) + 1;
    let untestable = (groups.len() < needed).then(|| {
        format!(
            "{} motions between rests without a clip (needs {needed})",
            groups.len()
        )
    });
    let c = Candidate::AccelLag;
    let (score, f) = score(c, &rows, untestable, config, s, f64::NAN);
    let found = f.as_ref().is_some_and(|f| {
        f.gain > s.threshold && beyond(f, 0, config, s) && plausible(f, 0, config, f64::NAN)
    });
    let after: Vec<f64> = match (&f, found) {
        (Some(f), true) => f.residuals.clone(),
        _ => rows.iter().map(|r| r.r).collect(),
    };
    let chi2: f64 = rows
        .iter()
        .zip(&after)
        .map(|(r, e)| e * e / (r.sigma.powi(2) + r.floor.powi(2)))
        .sum();
    let dof = rows.len().saturating_sub(usize::from(found)).max(1);
    LagTest {
        score,
        found,
        residuals: residuals(&rows, &after, Kind::Velocity),
        p: ChiSquared::new(dof as f64).map_or(1.0, |d| d.sf(chi2)),
    }
}

/// Forward selection among `open`: the chosen candidates and their joint fit.
fn select(
    rows: &[Row],
    open: &[Candidate],
    config: &OdometryConfig,
    s: &Settings,
    span_c: f64,
) -> (Vec<Candidate>, Option<fit::Fit>) {
    let mut chosen: Vec<Candidate> = Vec::new();
    let mut current: Option<fit::Fit> = None;
    loop {
        let base = current.as_ref().map_or(0.0, |f| f.gain);
        let best = open
            .iter()
            .filter(|c| !chosen.contains(c))
            .filter_map(|&c| {
                let mut set = chosen.clone();
                set.push(c);
                let f = fit::fit(rows, &set)?;
                let slot = set.len() - 1;
                let ok = f.gain - base > s.threshold
                    && beyond(&f, slot, config, s)
                    && plausible(&f, slot, config, span_c);
                ok.then_some((c, f))
            })
            .max_by(|a, b| a.1.gain.total_cmp(&b.1.gain));
        match best {
            Some((c, f)) => {
                chosen.push(c);
                current = Some(f);
            }
            None => return (chosen, current),
        }
    }
}
