//! Repair and accounting of corrupted raw samples: torn reads (repaired), repeated samples
//! (counted).
//!
//! **Torn reads.** The MPU-9250 holds each axis in two 8-bit registers. A reader that fetches
//! the high and the low byte in separate bus transactions can combine the high byte of one
//! sensor sample with the low byte of the next when the value crosses a multiple of 256 counts
//! in between: the result is off by exactly +-256 counts (a whole high-byte step), and its low
//! byte is correct, so it sits near 0x00 or 0xFF. The thesis recordings show this as detached
//! "wings" at +-256 counts around each axis' core (up to 13% of the samples of an axis whose
//! value hovers near such a boundary).
//!
//! [`detect_tears`] finds them per axis: a sample is torn when it lies a multiple of 256 counts
//! away from the median of its twelve nearest neighbours, further than a decision threshold,
//! and its low byte is on the right side of the wrap-around (a value 256 too high was just
//! below a boundary, low byte near 0xFF; one 256 too low just above, near 0x00). The threshold is the maximum-a-posteriori boundary
//! between "core sample with noise sigma" and "core sample shifted by 256" given the estimated
//! noise and tear rate, so a noisy axis (where core and wings overlap) is not over-repaired.
//! Runs of up to six adjacent torn samples are repaired (the median of twelve tolerates five
//! outliers), and repeated passes let repaired neighbours clear up the rest. The median of a
//! symmetric window follows a linear trend, so slow motion is not mistaken for tears.
//!
//! Limits, measured on simulated torn reads (see the tests): on an axis 16 counts below a
//! boundary with 35 counts of noise and a fifth of the samples torn, one tear remains and the
//! variance is restored within 0.1%; where the core sits half-way between boundaries with 50
//! counts of noise, a torn value can land inside the core (and a core tail can look torn), and
//! the variance is restored within 4% (2.7% low in the test).
//! [`repair_torn_reads`] applies the repair to recorded samples and sets
//! [`raw_flags::REPAIRED`].
//!
//! **Repeats.** A sample whose every valid axis equals the previous sample's (the reader polled
//! faster than the sensor updated, or re-read a stale register) is counted by
//! [`count_repeats`] and left in place: it is a zero-order hold of the sensor output, and
//! removing it would make the sampling irregular.

use std::collections::BTreeMap;

use ipc_types::units::{AccelRange, GyroRange};
use ipc_types::{RawImuSample, raw_flags};
use serde::{Deserialize, Serialize};
use statrs::function::erf::erfc;

/// Size of a torn-read error, counts: one step of the high byte.
pub const TEAR_COUNTS: i32 = 256;

/// Neighbours on each side of a sample whose median is its reference value.
const HALF_WINDOW: usize = 6;

/// Half a tear: a sample further than this from its reference is closer to the shifted value.
const HALF_TEAR: i32 = TEAR_COUNTS / 2;

/// How much costlier a wrong repair is than a missed tear, as a log ratio (nats). Decisions
/// near the threshold depend on how close the local level is to a byte boundary, so both kinds
/// of error follow the slow noise and distort the Allan curve at the reference window's time
/// scale; a wrong repair does more harm there. On the thesis' 60 pooled start-up runs one nat
/// gives the smallest misfit of the noise model summed over the three axes (chi2/dof 1.6, 5.1,
/// 2.4; with 0 nats: 1.2, 5.1, 3.2; with 2: 2.2, 5.1, 2.3; with 3: 3.6, 5.1, 3.2).
const FALSE_REPAIR_LOG_COST: f64 = 1.0;

/// Samples whose reference is computed exactly to estimate an axis' noise (a subsample of a
/// long record is enough for a robust scale estimate).
const NOISE_SUBSAMPLE: usize = 65_536;

/// Sensitivities of the recording, needed to convert a repair in counts into the sample's
/// values in g and deg/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RepairConfig {
    /// Accelerometer sensitivity, counts per g (16384 at +-2 g, the thesis' range).
    pub accel_lsb_per_g: f64,
    /// Gyroscope sensitivity, counts per deg/s (131 at +-250 deg/s).
    pub gyro_lsb_per_dps: f64,
}

impl Default for RepairConfig {
    /// The ranges the thesis recordings and the canonical CSV reader assume: +-2 g, +-250 deg/s.
    fn default() -> Self {
        Self {
            accel_lsb_per_g: AccelRange::G2.lsb_per_g(),
            gyro_lsb_per_dps: GyroRange::Dps250.lsb_per_dps(),
        }
    }
}

/// The torn samples found on one axis and the statistics the decision used.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AxisTears {
    /// `(index, k)`: sample `index` read `k * 256` counts too high (`k` may be negative).
    pub fixes: Vec<(usize, i32)>,
    /// Robust standard deviation of the samples around their neighbours' median, counts.
    pub noise_counts: f64,
    /// Distance from the reference beyond which a sample was considered torn, counts; `None`
    /// when the axis is too noisy for a tear to be told from noise (see [`MAX_NOISE_COUNTS`]).
    pub threshold_counts: Option<f64>,
}

/// What torn-read repair did to one axis.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct AxisRepair {
    /// Samples repaired on this axis.
    pub repaired: usize,
    /// Robust noise of the axis around its local median, counts.
    pub noise_counts: f64,
    /// Decision threshold used, counts (see the module documentation); `None` when the axis
    /// was too noisy to repair.
    pub threshold_counts: Option<f64>,
}

/// What [`repair_torn_reads`] did to a recording.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TornReport {
    /// Accelerometer x, y, z.
    pub accel: [AxisRepair; 3],
    /// Gyroscope x, y, z; `None` when the gyro was not repaired (not every sample has
    /// `GYRO_VALID`).
    pub gyro: Option<[AxisRepair; 3]>,
    /// Samples with at least one axis repaired (each now carries `raw_flags::REPAIRED`).
    pub samples_repaired: usize,
}

/// Repeated samples in a recording (see the module documentation).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RepeatReport {
    /// Samples equal on every valid axis to the sample before them.
    pub repeats: usize,
    /// The longest run of consecutive repeats (copies after the first).
    pub longest_run: usize,
}

/// Finds torn reads in one axis' counts (see the module documentation). Records shorter than
/// thirteen samples have no reference and give no fixes.
///
/// Runs in up to [`MAX_PASSES`] passes: each repairs what it can decide and the next sees the
/// repaired neighbours, so that an axis with many tears (where up to half of a sample's
/// neighbours may be torn) converges. Later passes look only at the previous pass' undecided
/// candidates and at the neighbourhoods of its repairs: elsewhere no reference changed.
pub fn detect_tears(counts: &[i16]) -> AxisTears {
    let n = counts.len();
    if n < 2 * HALF_WINDOW + 1 {
        return AxisTears::default();
    }
    let sigma = noise_scale(counts);
    if sigma > MAX_NOISE_COUNTS {
        return AxisTears {
            fixes: Vec::new(),
            noise_counts: sigma,
            threshold_counts: None,
        };
    }
    let mut c = counts.to_vec();
    let mut shifts: BTreeMap<usize, i32> = BTreeMap::new();
    let mut last = PassStatistics {
        sigma,
        threshold: None,
    };
    let mut examine: Option<Vec<usize>> = None;
    for pass_index in 0..MAX_PASSES {
        // The first pass reuses the noise estimated above; later ones re-estimate it on the
        // partly repaired samples.
        let sigma = if pass_index == 0 {
            sigma
        } else {
            noise_scale(&c)
        };
        let pass = tear_pass(&c, sigma, shifts.len(), examine.as_deref());
        last = pass.statistics;
        if pass.fixes.is_empty() {
            break;
        }
        let mut next = pass.undecided;
        for (i, k) in pass.fixes {
            c[i] = shifted(c[i], k);
            *shifts.entry(i).or_insert(0) += k;
            next.extend(i.saturating_sub(2 * HALF_WINDOW)..(i + 2 * HALF_WINDOW + 1).min(n));
        }
        next.sort_unstable();
        next.dedup();
        examine = Some(next);
    }
    AxisTears {
        fixes: shifts.into_iter().filter(|&(_, k)| k != 0).collect(),
        noise_counts: last.sigma,
        threshold_counts: last.threshold,
    }
}

/// Robust noise of counts around their neighbours' median, counts: 1.4826 * MAD (a Gaussian
/// sigma) over a subsample of at most [`NOISE_SUBSAMPLE`] samples.
fn noise_scale(c: &[i16]) -> f64 {
    let n = c.len();
    let stride = n.div_ceil(NOISE_SUBSAMPLE).max(1);
    let mut deviations: Vec<f64> = (0..n)
        .step_by(stride)
        .map(|i| (f64::from(c[i]) - neighbour_median(c, i)).abs())
        .collect();
    let mid = deviations.len() / 2;
    1.4826 * *deviations.select_nth_unstable_by(mid, f64::total_cmp).1
}

/// Passes of [`detect_tears`] at most.
pub const MAX_PASSES: usize = 4;

#[derive(Debug, Clone, Copy, Default)]
struct PassStatistics {
    sigma: f64,
    threshold: Option<f64>,
}

/// Above this noise (counts, a third of a tear) the wings of torn reads are buried in the core
/// and no decision is better than leaving the samples alone: such an axis is not repaired.
pub const MAX_NOISE_COUNTS: f64 = TEAR_COUNTS as f64 / 3.0;

/// What one pass decided.
struct Pass {
    /// `(index, k)` to repair.
    fixes: Vec<(usize, i32)>,
    /// Candidates (at least half a tear from their reference) left alone.
    undecided: Vec<usize>,
    statistics: PassStatistics,
}

/// One pass over counts `c` with noise `sigma` (counts), of which `repaired` samples were
/// already repaired, looking at the samples in `examine` (every sample when `None`).
fn tear_pass(c: &[i16], sigma: f64, repaired: usize, examine: Option<&[usize]>) -> Pass {
    let n = c.len();
    let deviation = |i: usize| f64::from(c[i]) - neighbour_median(c, i);
    let candidates: Vec<(usize, f64)> = match examine {
        Some(indices) => indices
            .iter()
            .map(|&i| (i, deviation(i)))
            .filter(|(_, d)| d.abs() >= f64::from(HALF_TEAR))
            .collect(),
        None => all_candidates(c),
    };

    // MAP boundary between "core with noise sigma" and "core + k*256", biased towards
    // leaving a sample alone: torn iff |d| > 128 + sigma^2 (ln((1 - p) / p) + c) / 256
    // (equal-variance Gaussians 256 apart, a wrong repair costing e^c times a missed tear).
    // The tear fraction p is the excess of samples beyond half a tear over what Gaussian
    // noise puts there (at least one sample's worth), plus those repaired by earlier passes.
    let half = f64::from(HALF_TEAR);
    let noise_beyond = n as f64 * erfc(half / (sigma * std::f64::consts::SQRT_2));
    let excess = (candidates.len() as f64 - noise_beyond).max(1.0);
    let p = ((repaired as f64 + excess) / n as f64).min(0.5);
    let log_odds = ((1.0 - p) / p).ln() + FALSE_REPAIR_LOG_COST;
    let threshold = (half + sigma * sigma * log_odds / f64::from(TEAR_COUNTS))
        .clamp(half, f64::from(TEAR_COUNTS) - 1.0);
    let statistics = PassStatistics {
        sigma,
        threshold: Some(threshold),
    };
    // A torn value keeps the true low byte, and the true value was crossing a high-byte
    // boundary: a value read 256 too high (k > 0) was just below a boundary (low byte near
    // 0xFF), one read 256 too low (k < 0) just above one (low byte near 0x00), whichever byte
    // the reader fetched first. Allow four noise sigmas of motion between the two byte reads.
    let boundary_window = (4.0 * sigma + 8.0).min(half);

    let mut fixes = Vec::new();
    let mut undecided = Vec::new();
    for (i, d) in candidates {
        let k = (d / f64::from(TEAR_COUNTS)).round() as i32;
        let low = f64::from(i32::from(c[i]).rem_euclid(TEAR_COUNTS));
        let consistent = match k.signum() {
            1 => f64::from(TEAR_COUNTS) - low <= boundary_window,
            -1 => low < boundary_window,
            _ => false,
        };
        if d.abs() >= threshold && consistent {
            fixes.push((i, k));
        } else {
            undecided.push(i);
        }
    }
    Pass {
        fixes,
        undecided,
        statistics,
    }
}

/// The samples at least half a tear from the median of their neighbours, with that deviation.
///
/// A sample can be that far from the median only if at least `HALF_WINDOW` of its neighbours
/// are that far on the same side: this count (a few compares per sample) spares the median
/// for almost every sample of a long record.
fn all_candidates(c: &[i16]) -> Vec<(usize, f64)> {
    let n = c.len();
    let mut candidates = Vec::new();
    let mut check = |i: usize| {
        let d = f64::from(c[i]) - neighbour_median(c, i);
        if d.abs() >= f64::from(HALF_TEAR) {
            candidates.push((i, d));
        }
    };
    // The ends have shifted windows: always look.
    let interior = HALF_WINDOW..n - HALF_WINDOW;
    (0..HALF_WINDOW).for_each(&mut check);
    // Blocks of counts that stay in the first-level cache; the loops over a block vectorise.
    let (mut below, mut above) = ([0u8; PREFILTER_BLOCK], [0u8; PREFILTER_BLOCK]);
    let mut start = interior.start;
    while start < interior.end {
        let len = PREFILTER_BLOCK.min(interior.end - start);
        let (below, above) = (&mut below[..len], &mut above[..len]);
        below.fill(0);
        above.fill(0);
        let centre = &c[start..start + len];
        for offset in 1..=HALF_WINDOW {
            for side in [
                &c[start - offset..start - offset + len],
                &c[start + offset..start + offset + len],
            ] {
                for (((b, a), &v), &w) in
                    below.iter_mut().zip(above.iter_mut()).zip(centre).zip(side)
                {
                    let (v, w) = (i32::from(v), i32::from(w));
                    *b += u8::from(w <= v - HALF_TEAR);
                    *a += u8::from(w >= v + HALF_TEAR);
                }
            }
        }
        let enough = HALF_WINDOW as u8;
        for j in 0..len {
            if below[j] >= enough || above[j] >= enough {
                check(start + j);
            }
        }
        start += len;
    }
    (interior.end..n).for_each(&mut check);
    candidates
}

/// Samples per block of the candidate pre-filter.
const PREFILTER_BLOCK: usize = 4096;

/// Median of the `2 * HALF_WINDOW` samples nearest to `i` (the window is shifted inside the
/// record at its ends), excluding `i` itself. Needs `c.len() > 2 * HALF_WINDOW`.
fn neighbour_median(c: &[i16], i: usize) -> f64 {
    let start = i
        .saturating_sub(HALF_WINDOW)
        .min(c.len() - 1 - 2 * HALF_WINDOW);
    let mut window = [0i16; 2 * HALF_WINDOW];
    let mut filled = 0;
    for (j, &v) in c[start..=start + 2 * HALF_WINDOW].iter().enumerate() {
        if start + j != i {
            window[filled] = v;
            filled += 1;
        }
    }
    window.sort_unstable();
    (f64::from(window[HALF_WINDOW - 1]) + f64::from(window[HALF_WINDOW])) / 2.0
}

/// Finds and repairs torn reads on every accelerometer axis, and on every gyro axis when all
/// samples have `GYRO_VALID`: the counts move by the detected multiple of 256, the values in g
/// (deg/s) by the same amount divided by the configured sensitivity, and the sample gets
/// `raw_flags::REPAIRED`.
pub fn repair_torn_reads(samples: &mut [RawImuSample], config: &RepairConfig) -> TornReport {
    let gyro_valid =
        !samples.is_empty() && samples.iter().all(|s| s.flags & raw_flags::GYRO_VALID != 0);
    let axes = if gyro_valid { 6 } else { 3 };
    // One pass over the samples (six would be memory-bound on long records).
    let mut counts: Vec<Vec<i16>> = (0..axes)
        .map(|_| Vec::with_capacity(samples.len()))
        .collect();
    for s in samples.iter() {
        for (a, column) in counts.iter_mut().enumerate() {
            column.push(if a < 3 {
                s.accel_counts[a]
            } else {
                s.gyro_counts[a - 3]
            });
        }
    }
    let tears = detect_axes(&counts);
    apply_to_samples(samples, &tears, config)
}

/// [`detect_tears`] on each column (accelerometer x, y, z, then gyro x, y, z if present),
/// one thread per column.
pub fn detect_axes(counts: &[Vec<i16>]) -> Vec<AxisTears> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = counts
            .iter()
            .map(|c| scope.spawn(move || detect_tears(c)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("tear detection does not panic"))
            .collect()
    })
}

/// Applies the tears of [`detect_axes`] (3 accelerometer columns, then 3 gyro columns if
/// present) to the samples: counts, values (with the configured sensitivities) and
/// `raw_flags::REPAIRED`.
pub fn apply_to_samples(
    samples: &mut [RawImuSample],
    tears: &[AxisTears],
    config: &RepairConfig,
) -> TornReport {
    let mut touched = vec![false; samples.len()];
    for (a, axis_tears) in tears.iter().enumerate() {
        for &(i, k) in &axis_tears.fixes {
            let s = &mut samples[i];
            if a < 3 {
                s.accel_counts[a] = shifted(s.accel_counts[a], k);
                s.accel_g[a] -= f64::from(k * TEAR_COUNTS) / config.accel_lsb_per_g;
            } else {
                s.gyro_counts[a - 3] = shifted(s.gyro_counts[a - 3], k);
                s.gyro_dps[a - 3] -= f64::from(k * TEAR_COUNTS) / config.gyro_lsb_per_dps;
            }
            touched[i] = true;
        }
    }
    for (s, &t) in samples.iter_mut().zip(&touched) {
        if t {
            s.flags |= raw_flags::REPAIRED;
        }
    }
    TornReport {
        accel: std::array::from_fn(|a| summary(&tears[a])),
        gyro: (tears.len() == 6).then(|| std::array::from_fn(|a| summary(&tears[3 + a]))),
        samples_repaired: touched.iter().filter(|&&t| t).count(),
    }
}

/// `count - k * 256`, saturated to the 16-bit range.
fn shifted(count: i16, k: i32) -> i16 {
    (i32::from(count) - k * TEAR_COUNTS).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16
}

fn summary(tears: &AxisTears) -> AxisRepair {
    AxisRepair {
        repaired: tears.fixes.len(),
        noise_counts: tears.noise_counts,
        threshold_counts: tears.threshold_counts,
    }
}

/// Whether `b` repeats `a`: equal accelerometer counts, and equal gyro counts when both have
/// `GYRO_VALID`.
pub fn is_repeat(a: &RawImuSample, b: &RawImuSample) -> bool {
    let both_gyro = a.flags & b.flags & raw_flags::GYRO_VALID != 0;
    a.accel_counts == b.accel_counts && (!both_gyro || a.gyro_counts == b.gyro_counts)
}

/// Counts samples equal on every valid axis (accelerometer counts, and gyro counts when both
/// samples have `GYRO_VALID`) to the sample before them.
pub fn count_repeats(samples: &[RawImuSample]) -> RepeatReport {
    let mut report = RepeatReport::default();
    let mut run = 0;
    for pair in samples.windows(2) {
        if is_repeat(&pair[0], &pair[1]) {
            report.repeats += 1;
            run += 1;
            report.longest_run = report.longest_run.max(run);
        } else {
            run = 0;
        }
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// A sensor sampled at 1 kHz internally, its output low-pass filtered (an AR(1) process
    /// with coefficient 0.6 and stationary sigma `sigma` around `mean` counts), read at every
    /// 5th internal sample; with probability `tear_rate` a read combines the previous internal
    /// sample's high byte with the current one's low byte (the physical torn read).
    /// Returns (recorded counts, true counts).
    fn torn_record(
        mean: f64,
        sigma: f64,
        tear_rate: f64,
        n: usize,
        seed: u64,
    ) -> (Vec<i16>, Vec<i16>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let phi: f64 = 0.6;
        let drive = Normal::new(0.0, sigma * (1.0 - phi * phi).sqrt()).unwrap();
        let mut state = Normal::new(0.0, sigma).unwrap().sample(&mut rng);
        let mut recorded = Vec::with_capacity(n);
        let mut truth = Vec::with_capacity(n);
        let mut current = (mean + state).round() as i32;
        for _ in 0..n {
            let mut previous = current;
            for _ in 0..5 {
                previous = current;
                state = phi * state + drive.sample(&mut rng);
                current = (mean + state).round() as i32;
            }
            truth.push(current as i16);
            let read = if rng.random::<f64>() < tear_rate {
                (previous & !0xFF) | (current & 0xFF)
            } else {
                current
            };
            recorded.push(read as i16);
        }
        (recorded, truth)
    }

    fn variance(values: &[i16]) -> f64 {
        let n = values.len() as f64;
        let mean = values.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
        values
            .iter()
            .map(|&v| (f64::from(v) - mean).powi(2))
            .sum::<f64>()
            / (n - 1.0)
    }

    #[test]
    fn restores_tears_near_a_byte_boundary() {
        // Like the thesis' y axis: mean 16 counts below 1024, sigma 35 counts, and more tears
        // (22% of the samples) than its 13%.
        let (mut recorded, truth) = torn_record(1008.0, 35.0, 0.5, 20_000, 1);
        let wrong_before = recorded.iter().zip(&truth).filter(|(r, t)| r != t).count();
        assert!(
            wrong_before > 1000,
            "the simulation must produce tears: {wrong_before}"
        );
        let tears = detect_tears(&recorded);
        for &(i, k) in &tears.fixes {
            recorded[i] = shifted(recorded[i], k);
        }
        let wrong_after = recorded.iter().zip(&truth).filter(|(r, t)| r != t).count();
        assert!(
            wrong_after * 50 < wrong_before,
            "{wrong_after} of {wrong_before} torn samples left"
        );
        let ratio = variance(&recorded) / variance(&truth);
        assert!((ratio - 1.0).abs() < 0.02, "variance ratio {ratio}");
    }

    #[test]
    fn leaves_an_axis_far_from_boundaries_alone() {
        // Mean 0x680 + noise 20 counts: 6 sigma from the boundaries, the value never crosses a
        // multiple of 256, so no tear happens.
        let (recorded, truth) = torn_record(1664.0, 20.0, 0.5, 20_000, 2);
        assert!(
            recorded == truth,
            "no tear can happen without a boundary crossing"
        );
        assert!(detect_tears(&recorded).fixes.is_empty());
    }

    #[test]
    fn noisy_axis_keeps_its_variance() {
        // Like the thesis' z axis: sigma 50 counts, 124 counts above a boundary. Core tails and
        // wings overlap; the MAP threshold must keep the variance close to the truth's.
        let (mut recorded, truth) = torn_record(12_668.0, 50.0, 1.0, 40_000, 3);
        let raw_ratio = variance(&recorded) / variance(&truth);
        assert!(
            raw_ratio > 1.1,
            "tears must inflate the raw variance: {raw_ratio}"
        );
        let tears = detect_tears(&recorded);
        for &(i, k) in &tears.fixes {
            recorded[i] = shifted(recorded[i], k);
        }
        let ratio = variance(&recorded) / variance(&truth);
        assert!(
            (ratio - 1.0).abs() < 0.04,
            "variance ratio after repair {ratio}"
        );
    }

    #[test]
    fn leaves_a_very_noisy_axis_alone() {
        // 120 counts of noise: tears (here a quarter of the reads) are buried in the core.
        let (recorded, _) = torn_record(1024.0, 120.0, 1.0, 20_000, 4);
        let tears = detect_tears(&recorded);
        assert!(tears.fixes.is_empty());
        assert_eq!(tears.threshold_counts, None);
        assert!(
            tears.noise_counts > MAX_NOISE_COUNTS,
            "{}",
            tears.noise_counts
        );
    }

    #[test]
    fn repairs_runs_of_adjacent_tears() {
        // Values 1016 .. 1032 straddle the boundary at 1024. A read 256 too high needs a value
        // just below it (1016, 1020), one 256 too low a value just above (1024 .. 1032).
        let mut counts: Vec<i16> = (0..200).map(|i| 1016 + (i % 5) as i16 * 4).collect();
        let truth = counts.clone();
        for i in [50, 51, 55, 56, 120, 121] {
            assert!(counts[i] < 1024);
            counts[i] += 256;
        }
        for i in [12, 13, 14] {
            assert!(counts[i] >= 1024);
            counts[i] -= 256;
        }
        let mut fixes = detect_tears(&counts).fixes;
        fixes.sort_unstable();
        assert_eq!(
            fixes,
            vec![
                (12, -1),
                (13, -1),
                (14, -1),
                (50, 1),
                (51, 1),
                (55, 1),
                (56, 1),
                (120, 1),
                (121, 1)
            ]
        );
        for (i, k) in fixes {
            counts[i] = shifted(counts[i], k);
        }
        assert_eq!(counts, truth);
    }

    #[test]
    fn ignores_shifts_a_tear_cannot_produce() {
        // 256 too high on a value just above the boundary (low byte 0x04): a reader cannot
        // produce it, so it is left alone (it is some other glitch).
        let mut counts: Vec<i16> = (0..200).map(|i| 1016 + (i % 5) as i16 * 4).collect();
        counts[53] += 256; // 1028 -> 1284
        assert!(detect_tears(&counts).fixes.is_empty());
    }

    #[test]
    fn repair_updates_values_counts_and_flags() {
        let mut samples: Vec<RawImuSample> = (0..100)
            .map(|i| {
                let counts = [1020 + (i % 3) as i16 * 4, 500, -16_000];
                RawImuSample {
                    accel_counts: counts,
                    accel_g: counts.map(|c| f64::from(c) / 16384.0),
                    gyro_counts: [0, 3, -3],
                    gyro_dps: [0.0, 3.0 / 131.0, -3.0 / 131.0],
                    flags: raw_flags::GYRO_VALID,
                    ..Default::default()
                }
            })
            .collect();
        let clean = samples.clone();
        // Tears consistent with the values (1020 is just below 1024, -3 just below 0).
        samples[39].accel_counts[0] += 256;
        samples[39].accel_g[0] += 256.0 / 16384.0;
        samples[70].gyro_counts[2] += 256;
        samples[70].gyro_dps[2] += 256.0 / 131.0;
        let report = repair_torn_reads(&mut samples, &RepairConfig::default());
        assert_eq!(report.accel.map(|a| a.repaired), [1, 0, 0]);
        assert_eq!(report.gyro.unwrap().map(|a| a.repaired), [0, 0, 1]);
        assert_eq!(report.samples_repaired, 2);
        for (i, (s, c)) in samples.iter().zip(&clean).enumerate() {
            assert_eq!(s.accel_counts, c.accel_counts, "sample {i}");
            assert_eq!(s.gyro_counts, c.gyro_counts, "sample {i}");
            for k in 0..3 {
                assert!((s.accel_g[k] - c.accel_g[k]).abs() < 1e-12, "sample {i}");
                assert!((s.gyro_dps[k] - c.gyro_dps[k]).abs() < 1e-12, "sample {i}");
            }
            let flagged = s.flags & raw_flags::REPAIRED != 0;
            assert_eq!(flagged, i == 39 || i == 70, "sample {i}");
        }
    }

    #[test]
    fn counts_repeats_and_runs() {
        let mut samples: Vec<RawImuSample> = (0..20)
            .map(|i| RawImuSample {
                accel_counts: [i, 0, 0],
                ..Default::default()
            })
            .collect();
        samples[5].accel_counts = samples[4].accel_counts;
        for i in 11..14 {
            samples[i].accel_counts = samples[10].accel_counts;
        }
        let report = count_repeats(&samples);
        assert_eq!(
            report,
            RepeatReport {
                repeats: 4,
                longest_run: 3
            }
        );
        // A differing gyro makes it a new sample when both have the gyro.
        for s in &mut samples {
            s.flags = raw_flags::GYRO_VALID;
        }
        samples[5].gyro_counts = [1, 0, 0];
        assert_eq!(count_repeats(&samples).repeats, 3);
    }
}
