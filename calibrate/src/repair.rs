//! Repair of torn high/low-byte reads: the "wings" at +-256 counts in the thesis's histograms.
//!
//! The MPU-9250 holds each axis in two 8-bit registers. A driver that reads the low and the high
//! byte in separate transactions can combine the low byte of one conversion `A` with the high
//! byte of the next conversion `B`. When `A` and `B` lie on opposite sides of a multiple of 256
//! counts, the value read is `A +- 256` exactly (same low byte, high byte off by one). Measured
//! on the thesis's files: the outliers sit at 256 counts from the local level, their count per
//! axis follows how close that axis' level is to a multiple of 256 (about 13% of samples on the
//! y axis of the static files, whose level is 16 counts below 1024), and after undoing them the
//! remaining noise is white (lag-1 autocorrelation below 0.05).
//!
//! Rule, per sample and axis: with `ref` the median of the `half_window` samples on each side
//! and `sigma` the per-sample noise, a sample `c` with `d = c - ref` is replaced by
//! `c' = c - 256 sign(d)` when
//! 1. `c'` is the likelier value: under Gaussian noise and a prior probability `prior` of a torn
//!    read, `|d| > (256^2 - 2 sigma_e^2 ln prior) / 512` with `sigma_e^2 = 1.2 sigma^2` (the
//!    reference's own noise included); and
//! 2. a tear is possible there: the multiple of 256 between `c'` and `c` lies within
//!    `boundary_sigmas * sigma` of `ref` (both conversions must straddle it).
//!
//! `sigma` comes from the first differences (their robust variance `D(1) = 2 sigma^2 (1 -
//! rho(1))`, insensitive to tears and to motion) with the lag-1 autocorrelation `rho(1)` the
//! series' own [`NoiseLevel`] estimates: zero for white samples (the thesis's, after repair),
//! about 0.5 for an MPU-9250 at 1 kHz through its 184 Hz DLPF, whose first differences alone
//! would give 0.68 of its noise and a threshold that "repairs" noise. For correlated samples
//! `sigma_e` is then an upper bound (the neighbours' median follows the sample), which only
//! makes the rule more cautious.
//!
//! Torn reads that land inside the noise (an axis whose level sits halfway between byte
//! boundaries, where `A +- 256` is only ~2 sigma from the level) cannot be told apart from noise
//! sample by sample and are left. An axis whose `sigma` exceeds `max_sigma_counts` (default
//! [`MAX_TEAR_SIGMA_COUNTS`]) is left entirely: there 256 counts is too few sigmas and the rule
//! would mostly "repair" noise (at 100 counts, the simulated MPU-9250 at 1 kHz with its 184 Hz
//! DLPF at +-2 g, it moves 2-3% of a tear-free series' samples). Since `A` and `B` are
//! exchangeable, tears are zero-mean in expectation; repairing them removes variance (the wings), and the small bias that repairing
//! only the visible ones leaves is constant while the level is, so it cancels in any method that
//! subtracts a static reference taken from the same data.

use ipc_types::RawImuSample;
use ipc_types::raw_flags;

use crate::noise_level::NoiseLevel;

/// Settings of the torn-read repair.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TornReadConfig {
    /// Counts per g of the recording's range (16384 for +-2 g).
    pub lsb_per_g: f64,
    /// Prior probability of a torn read near a byte boundary.
    pub prior: f64,
    /// Neighbours on each side for the local reference.
    pub half_window: usize,
    /// How far (in noise sigmas) the byte boundary may be from the local reference.
    pub boundary_sigmas: f64,
    /// Axes noisier than this (counts, `sigma`) are not repaired.
    pub max_sigma_counts: f64,
}

/// Noisiest axis (`sigma`, counts at 16384/g) the torn-read repair is tried on by default: a
/// tear (256 counts) must lie at least 3.2 sigmas from the level to be told from noise (the
/// thesis's z axis, 60 to 66 counts, is; the simulated MPU-9250 at 1 kHz through its 184 Hz
/// DLPF, 100 counts, is not).
pub const MAX_TEAR_SIGMA_COUNTS: f64 = 80.0;

impl Default for TornReadConfig {
    fn default() -> Self {
        Self {
            lsb_per_g: 16384.0,
            prior: 0.1,
            half_window: 4,
            boundary_sigmas: 5.0,
            max_sigma_counts: MAX_TEAR_SIGMA_COUNTS,
        }
    }
}

/// What the repair changed.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RepairReport {
    /// Samples repaired per axis.
    pub repaired: [usize; 3],
    /// Of those, how many read 256 counts too high (repaired downwards).
    pub high: [usize; 3],
    /// Per-sample noise sigma per axis used by the rule, counts.
    pub noise_counts: [f64; 3],
    /// Axes left alone as too noisy for the rule (`max_sigma_counts`).
    pub too_noisy: [bool; 3],
    /// Total samples examined.
    pub samples: usize,
}

impl RepairReport {
    /// Total number of values repaired (all axes).
    pub fn total(&self) -> usize {
        self.repaired.iter().sum()
    }
}

/// Robust white-noise sigma of a series: `1.4826 MAD(first differences) / sqrt(2)` (the MAD is
/// taken about zero, as the differences of a static series have zero median). Independent of
/// how much of the series is at rest, insensitive to isolated outliers; assumes near-white noise.
/// Returns 0 for fewer than 2 values.
pub fn difference_sigma(values: impl Iterator<Item = f64>) -> f64 {
    let mut d: Vec<f64> = Vec::with_capacity(values.size_hint().0);
    let mut prev: Option<f64> = None;
    for v in values {
        if let Some(p) = prev {
            d.push((v - p).abs());
        }
        prev = Some(v);
    }
    if d.is_empty() {
        return 0.0;
    }
    let mid = d.len() / 2;
    let (_, m, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *m / std::f64::consts::SQRT_2
}

/// Median of a small buffer (sorted in place).
fn median(buf: &mut [f64]) -> f64 {
    buf.sort_by(f64::total_cmp);
    let n = buf.len();
    if n % 2 == 1 {
        buf[n / 2]
    } else {
        0.5 * (buf[n / 2 - 1] + buf[n / 2])
    }
}

/// Detects and undoes torn reads in place (see the module documentation), updating `accel_g`
/// and `accel_counts` and setting [`raw_flags::REPAIRED`] on changed samples.
pub fn repair_torn_reads(samples: &mut [RawImuSample], cfg: &TornReadConfig) -> RepairReport {
    let mut values: Vec<[f64; 3]> = samples.iter().map(|s| s.accel_g).collect();
    let report = repair_torn_values(&mut values, cfg);
    if report.total() > 0 {
        for (s, v) in samples.iter_mut().zip(&values) {
            if s.accel_g != *v {
                s.accel_g = *v;
                s.accel_counts = v.map(|x| ipc_types::units::quantize(x * cfg.lsb_per_g));
                s.flags |= raw_flags::REPAIRED;
            }
        }
    }
    report
}

/// [`repair_torn_reads`] on bare accelerometer values (g, one `[x, y, z]` per sample).
pub fn repair_torn_values(values: &mut [[f64; 3]], cfg: &TornReadConfig) -> RepairReport {
    let mut report = RepairReport {
        samples: values.len(),
        ..Default::default()
    };
    let n = values.len();
    if n < 3 {
        return report;
    }
    let mut buf = vec![0.0; 2 * cfg.half_window];
    for axis in 0..3 {
        let counts: Vec<f64> = values
            .iter()
            .map(|s| (s[axis] * cfg.lsb_per_g).round())
            .collect();
        let sigma = per_sample_sigma(&counts).max(1.0);
        report.noise_counts[axis] = sigma;
        let sigma_e2 = 1.2 * sigma * sigma;
        let threshold = (65536.0 - 2.0 * sigma_e2 * cfg.prior.ln()) / 512.0;
        if sigma > cfg.max_sigma_counts {
            report.too_noisy[axis] = true;
            continue;
        }
        for k in 0..n {
            let c = counts[k];
            // The median lies within the neighbours' range: when every neighbour is within the
            // threshold of c, so is the median, and the sort can be skipped.
            let lo = k.saturating_sub(cfg.half_window);
            let hi = (k + cfg.half_window + 1).min(n);
            let far = counts[lo..hi]
                .iter()
                .fold(0.0f64, |m, v| m.max((v - c).abs()))
                > threshold;
            if !far {
                continue;
            }
            let reference = neighbour_median(&counts, k, cfg.half_window, &mut buf);
            let d = c - reference;
            if d.abs() <= threshold {
                continue;
            }
            let repaired = c - 256.0 * d.signum();
            let boundary = 256.0 * (c.max(repaired) / 256.0).floor();
            if (boundary - reference).abs() > cfg.boundary_sigmas * sigma {
                continue;
            }
            values[k][axis] = repaired / cfg.lsb_per_g;
            report.repaired[axis] += 1;
            if d > 0.0 {
                report.high[axis] += 1;
            }
        }
    }
    report
}

/// The per-sample noise of a series: [`difference_sigma`] over `sqrt(1 - rho(1))`, with the
/// lag-1 autocorrelation [`NoiseLevel`] estimates (none for white noise).
fn per_sample_sigma(values: &[f64]) -> f64 {
    let rho1 = NoiseLevel::of(values)
        .autocorrelation
        .first()
        .map_or(0.0, |r| r.clamp(0.0, 0.99));
    difference_sigma(values.iter().copied()) / (1.0 - rho1).sqrt()
}

/// Median of the up to `half_window` samples on each side of sample `k` (not `k` itself).
fn neighbour_median(counts: &[f64], k: usize, half_window: usize, buf: &mut [f64]) -> f64 {
    let lo = k.saturating_sub(half_window);
    let hi = (k + half_window + 1).min(counts.len());
    let (before, after) = (&counts[lo..k], &counts[k + 1..hi]);
    let m = before.len() + after.len();
    buf[..before.len()].copy_from_slice(before);
    buf[before.len()..m].copy_from_slice(after);
    median(&mut buf[..m])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// A simulated torn-read acquisition: conversions at 8x the read rate, the low byte taken
    /// from one conversion and the high byte from the next with probability `p_tear`.
    fn simulate(
        level: f64,
        sigma: f64,
        p_tear: f64,
        n: usize,
        seed: u64,
    ) -> (Vec<RawImuSample>, Vec<f64>, usize) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, sigma).unwrap();
        let mut out = Vec::with_capacity(n);
        let mut truth = Vec::with_capacity(n);
        let mut tears = 0;
        for k in 0..n {
            let a = (level + noise.sample(&mut rng)).round() as i64;
            let b = (level + noise.sample(&mut rng)).round() as i64;
            let read = if rng.random::<f64>() < p_tear {
                let v = (b >> 8) * 256 + (a & 0xff);
                if v != a {
                    tears += 1;
                }
                v
            } else {
                a
            };
            truth.push(a as f64);
            let mut s = RawImuSample {
                seq: k as u64,
                ..Default::default()
            };
            s.accel_g = [read as f64 / 16384.0, level / 16384.0, 1.0];
            out.push(s);
        }
        (out, truth, tears)
    }

    #[test]
    fn visible_tears_are_undone_exactly_and_clean_data_is_untouched() {
        // Level 16 counts below a byte boundary, noise 34 counts: the thesis's y axis.
        let (mut samples, truth, tears) = simulate(1008.0, 34.0, 0.25, 20_000, 3);
        assert!(tears > 1000, "simulation produced {tears} tears");
        let report = repair_torn_reads(&mut samples, &TornReadConfig::default());
        let wrong = samples
            .iter()
            .zip(&truth)
            .filter(|(s, t)| (s.accel_g[0] * 16384.0 - **t).abs() > 0.5)
            .count();
        // With noise 34 counts, 256 is 7.5 sigma: nearly every tear is visible and undone.
        assert!(wrong * 50 < tears, "{wrong} of {tears} tears left or wrong");
        assert!((report.repaired[0] as i64 - tears as i64).abs() * 50 < tears as i64);
        assert_eq!(report.repaired[1] + report.repaired[2], 0);
        // No tears, same noise: (almost) nothing is touched.
        let (mut clean, _, _) = simulate(1008.0, 34.0, 0.0, 20_000, 4);
        let r = repair_torn_reads(&mut clean, &TornReadConfig::default());
        assert!(
            r.repaired[0] <= 2,
            "{} clean samples changed",
            r.repaired[0]
        );
        assert!(
            clean
                .iter()
                .filter(|s| s.flags & raw_flags::REPAIRED != 0)
                .count()
                <= 2
        );
    }

    #[test]
    fn axes_noisier_than_the_limit_are_left_alone() {
        // The same tears under 155 counts of noise (the simulator's 1 kHz output): 256 counts
        // is 1.7 sigma, so the rule would mostly move noise; with the limit nothing changes.
        let (mut samples, _, tears) = simulate(1008.0, 155.0, 0.25, 20_000, 5);
        assert!(tears > 1000);
        let before = samples.clone();
        let r = repair_torn_reads(&mut samples, &TornReadConfig::default());
        assert_eq!((r.total(), r.too_noisy), (0, [true, false, false]));
        assert!(r.noise_counts[0] > 150.0);
        assert_eq!(samples, before);
        // Without the limit the rule does act (and is not to be trusted there).
        let no_limit = TornReadConfig {
            max_sigma_counts: f64::INFINITY,
            ..TornReadConfig::default()
        };
        assert!(repair_torn_reads(&mut samples, &no_limit).total() > 0);
    }

    #[test]
    fn far_from_a_byte_boundary_no_tear_is_possible() {
        // Level in the middle of a byte (128 counts from either boundary), tiny noise: a large
        // outlier there is not a torn read and must be left alone.
        let mut samples: Vec<RawImuSample> = (0..100)
            .map(|k| {
                let mut s = RawImuSample {
                    seq: k,
                    ..Default::default()
                };
                s.accel_g = [(1152.0 + (k % 3) as f64) / 16384.0, 0.0, 1.0];
                s
            })
            .collect();
        samples[50].accel_g[0] = (1152.0 + 256.0) / 16384.0;
        let r = repair_torn_reads(&mut samples, &TornReadConfig::default());
        assert_eq!(r.repaired[0], 0);
    }

    #[test]
    fn difference_sigma_estimates_white_noise() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, 2.5).unwrap();
        let v: Vec<f64> = (0..50_000)
            .map(|k| 100.0 + 1e-4 * k as f64 + noise.sample(&mut rng))
            .collect();
        let s = difference_sigma(v.iter().copied());
        assert!((s - 2.5).abs() < 0.05, "{s}");
    }
}
