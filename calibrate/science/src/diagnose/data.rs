//! The diagnosis's data: sessions (raw recordings or six-position means), what the samples
//! themselves show about the acquisition (torn reads, repeated samples, gaps), and the
//! observations the models are fitted to.
//!
//! An observation is the mean reading (g, sensor frame) of a *block*: `block_s` seconds of
//! consecutive samples inside one static segment, cut at gaps; or one pose of a means file. It
//! carries its white-noise variance predicted from the samples themselves (`sigma^2 / n`, with
//! `sigma` the session's robust per-sample noise, [`difference_sigma`] over its static
//! segments, which torn reads and slow drifts do not inflate; or the file's `std^2 / n`, pooled
//! per axis over its poses), its elapsed time since its time origin (s: the session's first
//! sample, or the first sample of the power-on it shares with other sessions, see
//! `share_power_on`), its mean die temperature (degC, when every sample has one), its gravity
//! label and orientation class, and its validation fold.

use ipc_types::{RawImuSample, raw_flags};
use nalgebra::Vector3;

use crate::fit::Pose;
use crate::segments::{
    SampleSeries, SegmentConfig, SegmentError, StaticSegment, detect_static_segments_in,
};
use crate::session::nearest_axis;
use calibrate::noise_level::difference_sigma;
use calibrate::repair::{TEAR_COUNTS, detect_tears};
use ipc_types::units::{AccelRange, quantize};

/// One input session.
#[derive(Debug, Clone)]
pub enum SessionInput {
    /// A raw recording (any format `recording::load_raw` reads), in time order.
    Raw {
        /// Its name in messages (usually the file).
        name: String,
        /// The samples.
        samples: Vec<RawImuSample>,
    },
    /// A six-position means file: one labelled pose per row, no sample times.
    Means {
        /// Its name in messages.
        name: String,
        /// The poses (labels in `truth_g`; `n` unknown for the thesis's files).
        poses: Vec<Pose>,
    },
}

impl SessionInput {
    /// The session's name.
    pub fn name(&self) -> &str {
        match self {
            SessionInput::Raw { name, .. } | SessionInput::Means { name, .. } => name,
        }
    }
}

/// Shortest static segment (pose) the diagnosis uses by default, s: multi-position protocols
/// (imu_tk, Tedaldi et al.) hold each pose 1-4 s, and a 2 s hold leaves a segment of about
/// 1.5 s once the windows at its edges are trimmed.
pub const DEFAULT_MIN_SEGMENT_S: f64 = 1.0;

/// Settings of the data preparation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DataConfig {
    /// Block length, s.
    pub block_s: f64,
    /// Number of validation folds when no test data is given.
    pub folds: usize,
    /// Samples behind each pose of a means file that does not say (the thesis: 30 s at about
    /// 180 Hz).
    pub pose_samples: usize,
    /// A sample interval longer than this many median intervals is a gap.
    pub gap_factor: f64,
    /// ... and longer than this, s.
    pub gap_min_s: f64,
    /// Static-segment detection.
    pub segments: SegmentConfig,
    /// Accelerometer sensitivity of the recordings, counts per g: a torn read is off by a
    /// whole high-byte step of these counts (`calibrate::repair`).
    pub accel_lsb_per_g: f64,
}

impl Default for DataConfig {
    fn default() -> Self {
        Self {
            block_s: 1.0,
            folds: 5,
            pose_samples: 5400,
            gap_factor: 10.0,
            gap_min_s: 0.05,
            segments: SegmentConfig::with_min_duration(DEFAULT_MIN_SEGMENT_S),
            accel_lsb_per_g: AccelRange::G2.lsb_per_g(),
        }
    }
}

/// Torn reads undone on the accelerometer axes of a session.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TornFindings {
    /// Samples repaired per axis.
    pub repaired: [usize; 3],
    /// Of those, the samples that read too high (by a multiple of 256 counts).
    pub high: [usize; 3],
}

impl TornFindings {
    /// Repairs over all axes.
    pub fn total(&self) -> usize {
        self.repaired.iter().sum()
    }
}

/// Finds torn reads in accelerometer values (g, `[x, y, z]` per sample, quantized at
/// `lsb_per_g` counts per g) with `calibrate::repair::detect_tears` and undoes them in place.
fn repair_torn_values(values: &mut [[f64; 3]], lsb_per_g: f64) -> TornFindings {
    let mut found = TornFindings::default();
    for axis in 0..3 {
        let counts: Vec<i16> = values
            .iter()
            .map(|v| quantize(v[axis] * lsb_per_g))
            .collect();
        for &(k, shift) in &detect_tears(&counts).fixes {
            values[k][axis] -= f64::from(shift * TEAR_COUNTS) / lsb_per_g;
            found.repaired[axis] += 1;
            if shift > 0 {
                found.high[axis] += 1;
            }
        }
    }
    found
}

/// Why the data cannot be diagnosed.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// Static-segment detection failed.
    #[error("{name}: {source}")]
    Segments {
        /// The session.
        name: String,
        /// The detector's error.
        source: SegmentError,
    },
    /// No static segment long enough.
    #[error(
        "{name}: no static segment of at least {min_s} s (the diagnosis needs the sensor at rest; \
         --min-segment-s sets the shortest pose it uses)"
    )]
    NoRest {
        /// The session.
        name: String,
        /// Shortest segment accepted, s.
        min_s: f64,
    },
    /// Sessions said to share a power-on are not on one running clock.
    #[error(
        "{name}: --same-power-on needs the sessions of one power-on in time order on one clock \
         (the samples' stamps): {reason}"
    )]
    PowerOn {
        /// The session.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// A means file holds a non-finite value or a zero std.
    #[error("{name}: pose {pose} has a non-finite value or a std that is not > 0")]
    BadPose {
        /// The session.
        name: String,
        /// 1-based pose (row) number.
        pose: usize,
    },
}

/// The six orientation classes: the signed sensor axis nearest to "up" (0: +x, 1: -x, 2: +y,
/// 3: -y, 4: +z, 5: -z).
pub fn orientation_class(up: &Vector3<f64>) -> usize {
    let (axis, _) = nearest_axis(up);
    let i = axis.iamax();
    2 * i + usize::from(axis[i] < 0.0)
}

/// The unit vector of an orientation class.
pub fn class_axis(class: usize) -> Vector3<f64> {
    let mut v = Vector3::zeros();
    v[class / 2] = if class.is_multiple_of(2) { 1.0 } else { -1.0 };
    v
}

/// What the samples of one raw session show about the acquisition.
#[derive(Debug, Clone, PartialEq)]
pub struct AcquisitionFindings {
    /// The session.
    pub name: String,
    /// Samples.
    pub samples: usize,
    /// Median sample interval, s.
    pub median_dt_s: f64,
    /// Torn reads found and undone (`calibrate::repair::detect_tears`).
    pub torn: TornFindings,
    /// Outliers farther than 5 robust sigmas from the median of their 8 neighbours, per axis.
    pub outliers: [usize; 3],
    /// Median distance of those outliers from the neighbours' median, counts at 16384/g
    /// (256 for torn reads).
    pub outlier_offset_counts: [f64; 3],
    /// Samples whose three axes all equal the previous sample's.
    pub repeats: usize,
    /// How many such repeats independent white noise of the measured sigma would give.
    pub repeats_expected: f64,
    /// Whether `repeats` is beyond chance (Poisson tail below 1e-6 and at least twice the
    /// expectation).
    pub repeats_significant: bool,
    /// Quantization step of the values, g (the greatest common step of the counts).
    pub step_g: f64,
    /// Gaps: intervals longer than the gap threshold.
    pub gaps: usize,
    /// The longest sample interval, s.
    pub longest_gap_s: f64,
    /// Time missing in gaps (their length minus one median interval), s.
    pub gap_time_s: f64,
}

/// A raw session prepared for the diagnosis.
#[derive(Debug, Clone)]
pub(crate) struct RawSession {
    pub name: String,
    pub t_ns: Vec<u64>,
    /// The time origin of the elapsed times, ns on the samples' clock: the first sample, or
    /// the first sample of the power-on the session belongs to (`share_power_on`).
    pub t0_ns: u64,
    pub a_raw: Vec<[f64; 3]>,
    pub a_repaired: Vec<[f64; 3]>,
    pub temp_c: Option<Vec<f64>>,
    /// Whether each sample repeats the previous one exactly.
    pub repeat: Vec<bool>,
    /// Per-sample noise per axis over the static segments (g), indexed by [`Fixes::index`].
    pub sigma: [[f64; 3]; 4],
    /// Sample indices `k` with a gap between samples `k - 1` and `k`.
    pub gap_at: Vec<usize>,
    /// Static segments (found on the repaired samples).
    pub segments: Vec<StaticSegment>,
    pub findings: AcquisitionFindings,
}

/// A prepared session.
#[derive(Debug, Clone)]
pub(crate) enum Session {
    Raw(Box<RawSession>),
    Means { name: String, poses: Vec<Pose> },
}

impl Session {
    pub fn name(&self) -> &str {
        match self {
            Session::Raw(r) => &r.name,
            Session::Means { name, .. } => name,
        }
    }

    /// Mean reading (g) of each static pose: segments of a raw session, rows of a means file.
    pub fn pose_means(&self) -> Vec<Vector3<f64>> {
        match self {
            Session::Raw(r) => r.segments.iter().map(|s| Vector3::from(s.mean_g)).collect(),
            Session::Means { poses, .. } => poses.iter().map(|p| p.mean_g).collect(),
        }
    }
}

/// Greatest common divisor of two non-negative integers.
fn gcd(mut a: u64, mut b: u64) -> u64 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// Samples repeating the previous one exactly, and whether there are more of them than white
/// noise quantized with `step_g` would give.
struct Repeats {
    /// Whether each sample repeats the previous one.
    repeat: Vec<bool>,
    count: usize,
    expected: f64,
    significant: bool,
    /// Indices of the samples that do not repeat.
    distinct: Vec<usize>,
}

fn find_repeats(a_raw: &[[f64; 3]], step_g: f64) -> Repeats {
    let n = a_raw.len();
    let mut repeat = vec![false; n];
    let mut count = 0;
    for k in 1..n {
        if a_raw[k] == a_raw[k - 1] {
            repeat[k] = true;
            count += 1;
        }
    }
    // Repeats are significant when independent white noise would rarely give as many; the
    // noise is measured here without them (they would make it look smaller).
    let distinct: Vec<usize> = (0..n).filter(|&k| !repeat[k]).collect();
    let expected = if count == 0 {
        0.0
    } else {
        let rough_sigma: [f64; 3] =
            std::array::from_fn(|i| difference_sigma(distinct.iter().map(|&k| a_raw[k][i])));
        repeat_probability(&rough_sigma, step_g) * n.saturating_sub(1) as f64
    };
    let significant = count as f64 >= 2.0 * expected && poisson_upper_tail(count, expected) < 1e-6;
    Repeats {
        repeat,
        count,
        expected,
        significant,
        distinct,
    }
}

/// Quantization step, g: the greatest common divisor of the counts (at `lsb` per g) of up to
/// 2000 samples; the thesis's values are multiples of 4 counts.
fn quantization_step_g(a_raw: &[[f64; 3]], lsb: f64) -> f64 {
    let step_counts = a_raw
        .iter()
        .take(2000)
        .flat_map(|a| a.iter().map(|v| (v * lsb).round().abs() as u64))
        .fold(0, gcd)
        .max(1);
    step_counts as f64 / lsb
}

/// The repaired samples, what the repair found, and the static segments (found on them).
struct Repaired {
    a: Vec<[f64; 3]>,
    torn: TornFindings,
    segments: Vec<StaticSegment>,
}

/// Torn-read repair and static segments on the distinct samples when repeats are significant
/// (both measure the noise from successive differences), mapped back to all samples.
fn repair(
    name: &str,
    samples: &[RawImuSample],
    a_raw: &[[f64; 3]],
    repeats: &Repeats,
    cfg: &DataConfig,
) -> Result<Repaired, DataError> {
    let n = samples.len();
    let kept: Vec<usize> = if repeats.significant {
        repeats.distinct.clone()
    } else {
        (0..n).collect()
    };
    let mut work_a: Vec<[f64; 3]> = kept.iter().map(|&k| a_raw[k]).collect();
    let torn = repair_torn_values(&mut work_a, cfg.accel_lsb_per_g);
    let seg_error = |source| DataError::Segments {
        name: name.to_string(),
        source,
    };
    let work = Kept {
        samples,
        kept: &kept,
        a: &work_a,
    };
    let detection = detect_static_segments_in(&work, &cfg.segments).map_err(seg_error)?;
    if detection.segments.is_empty() {
        return Err(DataError::NoRest {
            name: name.to_string(),
            min_s: cfg.segments.min_duration_s,
        });
    }
    let mut a_repaired = a_raw.to_vec();
    for (j, &k) in kept.iter().enumerate() {
        a_repaired[k] = work_a[j];
    }
    for k in 1..n {
        if !repeats.significant {
            break;
        }
        if repeats.repeat[k] {
            a_repaired[k] = a_repaired[k - 1];
        }
    }
    let segments: Vec<StaticSegment> = detection
        .segments
        .iter()
        .map(|s| StaticSegment {
            start: kept[s.start],
            end: kept[s.end - 1] + 1,
            ..*s
        })
        .collect();
    Ok(Repaired {
        a: a_repaired,
        torn,
        segments,
    })
}

/// Gaps in the time stamps: intervals longer than `gap_factor` median intervals (at least
/// `gap_min_s`).
struct Gaps {
    median_dt_s: f64,
    /// Sample indices `k` with a gap between samples `k - 1` and `k`.
    at: Vec<usize>,
    longest_s: f64,
    /// Time missing in gaps, s.
    time_s: f64,
}

fn find_gaps(t_ns: &[u64], cfg: &DataConfig) -> Gaps {
    let mut dts: Vec<u64> = t_ns.windows(2).map(|w| w[1] - w[0]).collect();
    let median_dt_s = if dts.is_empty() {
        0.0
    } else {
        let mid = dts.len() / 2;
        *dts.select_nth_unstable(mid).1 as f64 * 1e-9
    };
    let gap_threshold_s = (cfg.gap_factor * median_dt_s).max(cfg.gap_min_s);
    let mut at = Vec::new();
    let mut longest_s: f64 = 0.0;
    let mut time_s = 0.0;
    for k in 1..t_ns.len() {
        let dt = (t_ns[k] - t_ns[k - 1]) as f64 * 1e-9;
        longest_s = longest_s.max(dt);
        if dt > gap_threshold_s {
            at.push(k);
            time_s += dt - median_dt_s;
        }
    }
    Gaps {
        median_dt_s,
        at,
        longest_s,
        time_s,
    }
}

/// Noise per axis over the static segments (robust to tears and slow drift), g, for each
/// choice of fixes (indexed by [`Fixes::index`]).
fn noise_per_fixes(
    a_raw: &[[f64; 3]],
    r: &Repaired,
    repeats: &Repeats,
    step_g: f64,
) -> [[f64; 3]; 4] {
    let mut sigma = [[0.0; 3]; 4];
    for torn_fix in [false, true] {
        for dedup in [false, true] {
            let fixes = Fixes {
                torn: torn_fix,
                dedup,
            };
            // A fix that changes nothing has the noise of the data without it.
            let same_as = if torn_fix && r.torn.total() == 0 {
                Some(Fixes { torn: false, dedup })
            } else if dedup && !repeats.significant {
                Some(Fixes {
                    torn: torn_fix,
                    dedup: false,
                })
            } else {
                None
            };
            sigma[fixes.index()] = match same_as {
                Some(other) => sigma[other.index()],
                None => {
                    let a = if torn_fix { &r.a[..] } else { a_raw };
                    std::array::from_fn(|i| {
                        let values = r.segments.iter().flat_map(|s| {
                            (s.start..s.end)
                                .filter(|&k| !(dedup && repeats.repeat[k]))
                                .map(move |k| a[k][i])
                        });
                        difference_sigma(values).max(step_g / 12f64.sqrt())
                    })
                }
            };
        }
    }
    sigma
}

/// Prepares a raw session: torn-read repair, static segments, repeats, gaps and outliers.
pub(crate) fn prepare_raw(
    name: &str,
    samples: &[RawImuSample],
    cfg: &DataConfig,
) -> Result<RawSession, DataError> {
    let n = samples.len();
    let t_ns: Vec<u64> = samples.iter().map(|s| s.stamps.sample_ns).collect();
    let a_raw: Vec<[f64; 3]> = samples.iter().map(|s| s.accel_g).collect();
    let lsb = cfg.accel_lsb_per_g;
    let step_g = quantization_step_g(&a_raw, lsb);
    let repeats = find_repeats(&a_raw, step_g);
    let repaired = repair(name, samples, &a_raw, &repeats, cfg)?;
    let temp_c = samples
        .iter()
        .all(|s| s.flags & raw_flags::TEMP_VALID != 0)
        .then(|| samples.iter().map(|s| s.temp_c).collect());
    let gaps = find_gaps(&t_ns, cfg);
    let sigma = noise_per_fixes(&a_raw, &repaired, &repeats, step_g);
    let (outliers, outlier_offset_counts) =
        offset_outliers(&a_raw, &sigma[Fixes::default().index()], lsb);

    let findings = AcquisitionFindings {
        name: name.to_string(),
        samples: n,
        median_dt_s: gaps.median_dt_s,
        torn: repaired.torn,
        outliers,
        outlier_offset_counts,
        repeats: repeats.count,
        repeats_expected: repeats.expected,
        repeats_significant: repeats.significant,
        step_g,
        gaps: gaps.at.len(),
        longest_gap_s: gaps.longest_s,
        gap_time_s: gaps.time_s,
    };
    Ok(RawSession {
        name: name.to_string(),
        t0_ns: t_ns[0],
        t_ns,
        a_raw,
        a_repaired: repaired.a,
        temp_c,
        repeat: repeats.repeat,
        sigma,
        gap_at: gaps.at,
        segments: repaired.segments,
        findings,
    })
}

/// Gives `sessions` (in the order given: calibration, then test) one time origin, the first
/// sample of the first: they are recordings of one power-on, so a bias that drifts from
/// power-on continues from one to the next. Their stamps must be on one clock (the live
/// driver's `CLOCK_MONOTONIC`), each session starting after the previous one ends; a means
/// file (no sample times) or a session that starts before the previous one ends is refused.
pub(crate) fn share_power_on(sessions: &mut [Session]) -> Result<(), DataError> {
    let mut origin_and_end: Option<(u64, u64, String)> = None;
    for s in sessions.iter_mut() {
        let r = match s {
            Session::Raw(r) => r,
            Session::Means { name, .. } => {
                return Err(DataError::PowerOn {
                    name: name.clone(),
                    reason: "a means file has no sample times".into(),
                });
            }
        };
        let (first, last) = (r.t_ns[0], r.t_ns[r.t_ns.len() - 1]);
        match &origin_and_end {
            Some((_, end, previous)) if first <= *end => {
                return Err(DataError::PowerOn {
                    name: r.name.clone(),
                    reason: format!(
                        "its first sample at {:.3} s is not after the last of {previous} at {:.3} s",
                        first as f64 * 1e-9,
                        *end as f64 * 1e-9
                    ),
                });
            }
            Some((origin, ..)) => r.t0_ns = *origin,
            None => {}
        }
        origin_and_end = Some((r.t0_ns, last, r.name.clone()));
    }
    Ok(())
}

/// Probability that two successive samples repeat on all three axes under white noise
/// `sigma` (g per axis) quantized with step `step_g`: per axis about `q / (2 sqrt(pi) sigma)`
/// (the difference of two samples has std `sqrt(2) sigma`), at most 1.
fn repeat_probability(sigma: &[f64; 3], step_g: f64) -> f64 {
    sigma
        .iter()
        .map(|s| (step_g / (2.0 * std::f64::consts::PI.sqrt() * s)).min(1.0))
        .product()
}

/// The samples `kept` of a series with their (repaired) accelerometer values `a`.
struct Kept<'a> {
    samples: &'a [RawImuSample],
    kept: &'a [usize],
    a: &'a [[f64; 3]],
}

impl SampleSeries for Kept<'_> {
    fn len(&self) -> usize {
        self.kept.len()
    }

    fn t_ns(&self, k: usize) -> u64 {
        self.samples[self.kept[k]].stamps.sample_ns
    }

    fn accel_g(&self, k: usize) -> [f64; 3] {
        self.a[k]
    }

    fn temp_c(&self, k: usize) -> Option<f64> {
        self.samples[..].temp_c(self.kept[k])
    }
}

/// `P(X >= k)` for `X ~ Poisson(lambda)`.
fn poisson_upper_tail(k: usize, lambda: f64) -> f64 {
    use statrs::distribution::{DiscreteCDF, Poisson};
    if k == 0 {
        return 1.0;
    }
    if lambda <= 0.0 {
        return 0.0;
    }
    Poisson::new(lambda).map_or(0.0, |p| p.sf(k as u64 - 1))
}

/// Outliers per axis (farther than 5 sigma from the median of their 8 neighbours) and the
/// median of their distance, counts at `lsb` per g.
fn offset_outliers(a: &[[f64; 3]], sigma: &[f64; 3], lsb: f64) -> ([usize; 3], [f64; 3]) {
    const HALF: usize = 4;
    let n = a.len();
    let mut counts = [0usize; 3];
    let mut offsets = [f64::NAN; 3];
    let mut buf = [0.0; 2 * HALF];
    for axis in 0..3 {
        let limit = 5.0 * sigma[axis];
        let mut found: Vec<f64> = Vec::new();
        for k in 0..n {
            let lo = k.saturating_sub(HALF);
            let hi = (k + HALF + 1).min(n);
            let c = a[k][axis];
            let mut m = 0;
            let mut far = false;
            for v in a[lo..k].iter().chain(&a[k + 1..hi]) {
                buf[m] = v[axis];
                m += 1;
                far |= (v[axis] - c).abs() > limit;
            }
            // The median lies within the neighbours' range: if none is farther than the
            // limit, neither is the median.
            if !far || m == 0 {
                continue;
            }
            let part = &mut buf[..m];
            part.sort_by(f64::total_cmp);
            let med = if m % 2 == 1 {
                part[m / 2]
            } else {
                0.5 * (part[m / 2 - 1] + part[m / 2])
            };
            let d = (c - med).abs();
            if d > limit {
                found.push(d * lsb);
            }
        }
        counts[axis] = found.len();
        if !found.is_empty() {
            let mid = found.len() / 2;
            offsets[axis] = *found.select_nth_unstable_by(mid, f64::total_cmp).1;
        }
    }
    (counts, offsets)
}

/// One observation (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Obs {
    /// Mean reading, g.
    pub m: [f64; 3],
    /// White-noise variance of the mean, g^2.
    pub v: [f64; 3],
    /// Samples averaged.
    pub n: usize,
    /// Gravity label, g (labelled data).
    pub label: Option<[f64; 3]>,
    /// Orientation class (see [`orientation_class`]).
    pub class: usize,
    /// Index of the session (calibration sessions first, then test sessions).
    pub session: usize,
    /// Index of the static pose (segment or row) over all sessions.
    pub pose: usize,
    /// Mean elapsed time since the time origin (the session's first sample, or its
    /// power-on's), s.
    pub t_s: Option<f64>,
    /// Mean die temperature, degC.
    pub temp_c: Option<f64>,
    /// Gaps in the session before this block.
    pub gap_index: usize,
    /// Validation fold (calibration observations).
    pub fold: usize,
    /// Whether the observation belongs to the test data.
    pub test: bool,
}

/// How a raw session's samples are turned into observations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct Fixes {
    /// Use the torn-read-repaired values.
    pub torn: bool,
    /// Leave out samples that repeat the previous one.
    pub dedup: bool,
}

impl Fixes {
    /// 0..4, for tables indexed by the choice of fixes.
    pub fn index(self) -> usize {
        2 * usize::from(self.torn) + usize::from(self.dedup)
    }
}

/// Where labels come from when observations are built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Labelling {
    /// Nearest axis of each pose.
    NearestAxis,
    /// No labels.
    None,
}

/// Builds the observations of one session. `session` and `first_pose` number it among all
/// sessions; test observations get `test = true`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn observations(
    session: &Session,
    index: usize,
    first_pose: usize,
    test: bool,
    labelling: Labelling,
    fixes: Fixes,
    cfg: &DataConfig,
    out: &mut Vec<Obs>,
) {
    match session {
        Session::Means { poses, .. } => {
            // The variance of a pose mean, pooled per axis over the file's poses: a pose's
            // std also holds its torn reads, whose number depends on how near a byte boundary
            // that pose puts each axis, so pose-by-pose weights would follow the acquisition
            // rather than the noise. Pooled, every pose weighs the same (the thesis's
            // unweighted fit).
            let pooled: [f64; 3] = std::array::from_fn(|i| {
                poses
                    .iter()
                    .map(|p| {
                        p.std_g[i] * p.std_g[i] / p.n.unwrap_or(cfg.pose_samples).max(1) as f64
                    })
                    .sum::<f64>()
                    / poses.len().max(1) as f64
            });
            for (k, p) in poses.iter().enumerate() {
                let n = p.n.unwrap_or(cfg.pose_samples).max(1);
                out.push(Obs {
                    m: p.mean_g.into(),
                    v: pooled,
                    n,
                    label: Some(p.truth_g.into()),
                    class: orientation_class(&p.truth_g),
                    session: index,
                    pose: first_pose + k,
                    t_s: None,
                    temp_c: None,
                    gap_index: 0,
                    // Leave-one-pose-out: each pose is its own fold.
                    fold: k,
                    test,
                });
            }
        }
        Session::Raw(r) => raw_observations(r, index, first_pose, test, labelling, fixes, cfg, out),
    }
}

#[allow(clippy::too_many_arguments)]
fn raw_observations(
    r: &RawSession,
    index: usize,
    first_pose: usize,
    test: bool,
    labelling: Labelling,
    fixes: Fixes,
    cfg: &DataConfig,
    out: &mut Vec<Obs>,
) {
    let a = if fixes.torn { &r.a_repaired } else { &r.a_raw };
    let use_sample = |k: usize| !(fixes.dedup && r.repeat[k]);
    let sigma = r.sigma[fixes.index()];
    let t0 = r.t0_ns;
    let block_ns = (cfg.block_s * 1e9) as u64;
    let mut gap_iter = r.gap_at.iter().peekable();
    let mut gaps_before = 0usize;
    for (seg_index, seg) in r.segments.iter().enumerate() {
        let up = Vector3::from(seg.mean_g);
        let class = orientation_class(&up);
        let label = match labelling {
            Labelling::NearestAxis => Some(class_axis(class).into()),
            Labelling::None => None,
        };
        let mut acc = BlockAcc::default();
        let mut block_in_segment = 0usize;
        let mut emit = |acc: &mut BlockAcc, gaps_before: usize, block_in_segment: &mut usize| {
            if acc.n >= 5 {
                let n = acc.n as f64;
                out.push(Obs {
                    m: acc.sum.map(|s| s / n),
                    v: sigma.map(|s| s * s / n),
                    n: acc.n,
                    label,
                    class,
                    session: index,
                    pose: first_pose + seg_index,
                    t_s: Some(acc.t_sum / n),
                    temp_c: r.temp_c.as_ref().map(|_| acc.temp_sum / n),
                    gap_index: gaps_before,
                    fold: *block_in_segment % cfg.folds.max(1),
                    test,
                });
                *block_in_segment += 1;
            }
            *acc = BlockAcc::default();
        };
        for k in seg.start..seg.end {
            while gap_iter.peek().is_some_and(|&&g| g <= k) {
                let g = *gap_iter.next().expect("peeked");
                gaps_before += 1;
                if g > seg.start && g == k {
                    // A gap inside the segment ends the current block.
                    emit(&mut acc, gaps_before - 1, &mut block_in_segment);
                }
            }
            if acc.n > 0 && r.t_ns[k] - acc.start_ns >= block_ns {
                emit(&mut acc, gaps_before, &mut block_in_segment);
            }
            if !use_sample(k) {
                continue;
            }
            if acc.n == 0 {
                acc.start_ns = r.t_ns[k];
            }
            acc.n += 1;
            for (sum, x) in acc.sum.iter_mut().zip(a[k]) {
                *sum += x;
            }
            acc.t_sum += (r.t_ns[k] - t0) as f64 * 1e-9;
            if let Some(temp) = &r.temp_c {
                acc.temp_sum += temp[k];
            }
        }
        emit(&mut acc, gaps_before, &mut block_in_segment);
    }
}

/// Running sums of one block.
#[derive(Debug, Clone, Copy, Default)]
struct BlockAcc {
    n: usize,
    start_ns: u64,
    sum: [f64; 3],
    t_sum: f64,
    temp_sum: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classes_and_axes_round_trip() {
        for c in 0..6 {
            assert_eq!(orientation_class(&class_axis(c)), c);
        }
        assert_eq!(orientation_class(&Vector3::new(0.1, 0.05, 0.77)), 4);
        assert_eq!(orientation_class(&Vector3::new(-0.9, 0.05, -0.24)), 1);
    }

    #[test]
    fn poisson_tail_matches_the_series() {
        // P(X >= 3) for lambda = 0.5: 1 - e^-0.5 (1 + 0.5 + 0.125).
        let want = 1.0 - (-0.5f64).exp() * (1.0 + 0.5 + 0.125);
        assert!((poisson_upper_tail(3, 0.5) - want).abs() < 1e-12);
        assert_eq!(poisson_upper_tail(0, 0.5), 1.0);
    }

    #[test]
    fn gcd_of_counts() {
        assert_eq!([8u64, 12, 20].into_iter().fold(0, gcd), 4);
    }
}
