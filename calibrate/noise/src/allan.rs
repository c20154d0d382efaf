//! Overlapping Allan variance of a rate series (accelerometer or gyro axis), its equivalent
//! degrees of freedom, and chi-squared confidence intervals.
//!
//! For samples `y_0 .. y_{L-1}` taken every `tau0` seconds and a cluster of `m` samples
//! (`tau = m tau0`), the overlapping Allan variance is
//! `AVAR(tau) = 1 / (2 n) * sum_k (ybar_{k+m} - ybar_k)^2` over all `n = L - 2m + 1` starting
//! points `k`, where `ybar_k` is the mean of `y_k .. y_{k+m-1}`. With the cumulative sum `S`
//! (`S_0 = 0`, `S_{j+1} = S_j + y_j`) each term is `(S_{k+2m} - 2 S_{k+m} + S_k) / m`, so each
//! cluster time costs O(L). From [`STRIDED_FROM`] samples up, the sum takes every
//! [`stride`]`(m) = m / 16`-th starting point only (a partially overlapping estimator): there
//! neighbouring differences share all but a sixteenth of their data, so the estimate is the
//! fully overlapping one within a small fraction of its own spread (tested below), while the
//! three strided streams through the cumulative sums cost memory bandwidth only once per
//! `stride` cache lines; below it, each size streams through all the data. The unit is the
//! series' unit squared; the Allan deviation (ADEV) is
//! its square root. A record split at long gaps (see [`crate::series`]) pools the terms of all
//! segments; clusters never straddle a split.

use std::ops::Range;

use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// One cluster time of an Allan curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AllanPoint {
    /// Cluster size, samples.
    pub m: usize,
    /// Cluster time `m * tau0`, s.
    pub tau_s: f64,
    /// Overlapping Allan variance, (series unit)^2.
    pub avar: f64,
    /// Number of overlapping differences the estimate stands for, all segments together (the
    /// fully overlapping count, which the covariance of [`crate::fit`] uses; from
    /// [`STRIDED_FROM`] up every [`stride`]-th of them is summed).
    pub terms: usize,
}

/// The overlapping Allan variance of one series at log-spaced cluster times.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AllanCurve {
    /// Sample interval, s.
    pub tau0_s: f64,
    /// Samples in each gap-free segment that was analysed.
    pub segment_lengths: Vec<usize>,
    /// One entry per cluster size, increasing.
    pub points: Vec<AllanPoint>,
}

/// The three noise processes of the rate model, by their frequency-stability names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseKind {
    /// White rate noise (angle / velocity random walk; "white FM"): AVAR ~ 1/tau.
    White,
    /// Flicker rate noise (bias instability; "flicker FM"): AVAR flat.
    Flicker,
    /// Random-walk rate noise (rate random walk; "random-walk FM"): AVAR ~ tau.
    RandomWalk,
}

/// Samples processed per block: the block's cumulative sums stay in cache while every
/// cluster size uses them.
const BLOCK: usize = 8192;

/// The smallest cluster size whose sum is strided.
pub const STRIDED_FROM: usize = 128;

/// Spacing of the starting points summed at cluster size `m`: 1 below [`STRIDED_FROM`], else
/// `m / 16` (at least 8 doubles, one cache line).
pub fn stride(m: usize) -> usize {
    if m >= STRIDED_FROM { m / 16 } else { 1 }
}

/// Log-spaced cluster sizes, two per octave, from 1 up to `max_m`: 1, 2, 3, 4, 6, 8, 11, 16,
/// then 23, 32, 46, 64, ... where each size is exactly twice the one two places before it (so
/// that the covariance integrals of [`crate::fit`] see exact octaves).
pub fn cluster_sizes(max_m: usize) -> Vec<usize> {
    let mut sizes = vec![1, 2, 3, 4, 6, 8, 11, 16, 23];
    let mut i = sizes.len() - 2;
    while let Some(&base) = sizes.get(i) {
        let next = base * 2;
        if next > max_m {
            break;
        }
        sizes.push(next);
        i += 1;
    }
    sizes.retain(|&m| m <= max_m);
    sizes
}

/// The largest cluster size analysed for segments of these lengths: a quarter of the longest
/// segment, so that at least half its samples start a difference.
pub fn max_cluster(segment_lengths: &[usize]) -> usize {
    segment_lengths.iter().copied().max().unwrap_or(0) / 4
}

/// Overlapping Allan variance of `values` (any unit; sampled every `tau0_s` seconds) at
/// [`cluster_sizes`] up to [`max_cluster`], pooling the given segments (index ranges into
/// `values`). Cluster sizes no segment can hold are left out.
pub fn overlapping_avar(values: &[f64], segments: &[Range<usize>], tau0_s: f64) -> AllanCurve {
    let mut buffer = Vec::with_capacity(values.len() + 1);
    buffer.extend_from_slice(values);
    overlapping_avar_consuming(buffer, segments, tau0_s)
}

/// [`overlapping_avar`] that turns `values` into its cumulative sums in place instead of
/// allocating them (a long record's values are as large as the sums; give the vector a
/// capacity of one more than its length to avoid a reallocation).
pub fn overlapping_avar_consuming(
    mut values: Vec<f64>,
    segments: &[Range<usize>],
    tau0_s: f64,
) -> AllanCurve {
    let segment_lengths: Vec<usize> = segments.iter().map(|r| r.len()).collect();
    let sizes = cluster_sizes(max_cluster(&segment_lengths));
    // One cumulative sum over the whole record, centred on the mean so that the sums stay
    // small: S[k] = sum_{j<k} (y_j - mean). A segment [a, b) uses S[a..=b] only, and a
    // constant offset does not change second differences, so segments need no sums of their
    // own.
    let mean = values.iter().sum::<f64>() / values.len().max(1) as f64;
    let mut running = 0.0;
    for v in values.iter_mut() {
        let next = running + (*v - mean);
        *v = running;
        running = next;
    }
    values.push(running);
    let cumulative = values;

    let mut sums = vec![0.0; sizes.len()];
    let mut terms = vec![0usize; sizes.len()];
    let mut summed = vec![0usize; sizes.len()];
    let dense = sizes.partition_point(|&m| stride(m) == 1);
    for range in segments {
        let len = range.len();
        let s = &cumulative[range.start..=range.end];
        for (i, &m) in sizes.iter().enumerate() {
            if len >= 2 * m {
                let n = len - 2 * m + 1;
                terms[i] += n;
                summed[i] += n.div_ceil(stride(m));
            }
        }
        for (i, &m) in sizes.iter().enumerate().skip(dense) {
            if len >= 2 * m {
                let n = len - 2 * m + 1;
                sums[i] += (0..n)
                    .step_by(stride(m))
                    .map(|k| (s[k + 2 * m] - 2.0 * s[k + m] + s[k]).powi(2))
                    .sum::<f64>();
            }
        }
        let mut start = 0;
        while start < len {
            for (i, &m) in sizes[..dense].iter().enumerate() {
                if len < 2 * m {
                    break;
                }
                let n = len - 2 * m + 1;
                if start >= n {
                    continue;
                }
                let end = (start + BLOCK).min(n);
                sums[i] += second_difference_energy(s, m, start, end);
            }
            start += BLOCK;
        }
    }
    let points = (0..sizes.len())
        .filter(|&i| terms[i] > 0)
        .map(|i| AllanPoint {
            m: sizes[i],
            tau_s: sizes[i] as f64 * tau0_s,
            avar: sums[i] / (2.0 * (sizes[i] * sizes[i]) as f64 * summed[i] as f64),
            terms: terms[i],
        })
        .collect();
    AllanCurve {
        tau0_s,
        segment_lengths,
        points,
    }
}

/// `sum_{k in start..end} (S[k+2m] - 2 S[k+m] + S[k])^2`: the inner loop of the whole
/// analysis. With AVX2 (detected at run time) the same code runs four lanes wide.
fn second_difference_energy(s: &[f64], m: usize, start: usize, end: usize) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2, the only requirement of `energy_avx2`.
        return unsafe { energy_avx2(s, m, start, end) };
    }
    energy(s, m, start, end)
}

/// [`energy`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn energy_avx2(s: &[f64], m: usize, start: usize, end: usize) -> f64 {
    energy(s, m, start, end)
}

/// The kernel of [`second_difference_energy`]; eight independent accumulators let the compiler
/// vectorise it (the sum's rounding differs from a sequential one only in the last bits).
#[inline(always)]
fn energy(s: &[f64], m: usize, start: usize, end: usize) -> f64 {
    let a = &s[start..end];
    let b = &s[start + m..end + m];
    let c = &s[start + 2 * m..end + 2 * m];
    let (a8, a_rest) = a.as_chunks::<8>();
    let (b8, b_rest) = b.as_chunks::<8>();
    let (c8, c_rest) = c.as_chunks::<8>();
    let mut acc = [0.0f64; 8];
    for ((x, y), z) in a8.iter().zip(b8).zip(c8) {
        for lane in 0..8 {
            let d = z[lane] - 2.0 * y[lane] + x[lane];
            acc[lane] += d * d;
        }
    }
    let mut total = acc.iter().sum::<f64>();
    for ((x, y), z) in a_rest.iter().zip(b_rest).zip(c_rest) {
        let d = z - 2.0 * y + x;
        total += d * d;
    }
    total
}

/// Equivalent degrees of freedom of the overlapping Allan variance of one segment of `len`
/// rate samples at cluster size `m`, for a given dominant noise (Howe, Allan & Barnes 1981; as
/// tabulated in NIST SP 1065 "Handbook of Frequency Stability Analysis", section 5.2, with
/// `N = len + 1` phase points). At least 1.
pub fn edf(kind: NoiseKind, m: usize, len: usize) -> f64 {
    let n = len as f64 + 1.0;
    let m = m as f64;
    let value = match kind {
        NoiseKind::White => {
            (3.0 * (n - 1.0) / (2.0 * m) - 2.0 * (n - 2.0) / n) * 4.0 * m * m / (4.0 * m * m + 5.0)
        }
        NoiseKind::Flicker if m == 1.0 => 2.0 * (n - 2.0).powi(2) / (2.3 * n - 4.9),
        NoiseKind::Flicker => 5.0 * n * n / (4.0 * m * (n + 3.0 * m)),
        NoiseKind::RandomWalk => {
            (n - 2.0) / m * ((n - 1.0).powi(2) - 3.0 * m * (n - 1.0) + 4.0 * m * m)
                / (n - 3.0).powi(2)
        }
    };
    if value.is_finite() {
        value.max(1.0)
    } else {
        1.0
    }
}

/// Equivalent degrees of freedom of an Allan variance pooled over segments (each segment's
/// estimate weighted by its number of terms; Satterthwaite's approximation). Segments too short
/// for `m` do not count.
pub fn pooled_edf(kind: NoiseKind, m: usize, segment_lengths: &[usize]) -> f64 {
    let (mut weight, mut weighted) = (0.0, 0.0);
    for &len in segment_lengths.iter().filter(|&&len| len >= 2 * m) {
        let terms = (len - 2 * m + 1) as f64;
        weight += terms;
        weighted += terms * terms / edf(kind, m, len);
    }
    if weighted > 0.0 {
        weight * weight / weighted
    } else {
        1.0
    }
}

/// Two-sided probability outside a 1-sigma interval, per side.
const ONE_SIGMA_TAIL: f64 = 0.158_655_253_931_457_05;

/// The 68.27% (1-sigma) confidence interval of an Allan variance estimate `avar` with `edf`
/// degrees of freedom: `avar * edf / chi2_{0.841}(edf) .. avar * edf / chi2_{0.159}(edf)`.
/// Returns `(low, high)` in the unit of `avar`.
pub fn one_sigma_interval(avar: f64, edf: f64) -> (f64, f64) {
    let chi2 = ChiSquared::new(edf.max(1e-3)).expect("positive degrees of freedom");
    let low = avar * edf / chi2.inverse_cdf(1.0 - ONE_SIGMA_TAIL);
    let high = avar * edf / chi2.inverse_cdf(ONE_SIGMA_TAIL);
    (low, high)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    /// The definition, term by term, with explicit cluster means, every `step`-th starting
    /// point: (sum, terms summed, all terms).
    fn brute_force(values: &[f64], m: usize, step: usize) -> (f64, usize, usize) {
        let mean = |k: usize| values[k..k + m].iter().sum::<f64>() / m as f64;
        let n = values.len() - 2 * m + 1;
        let sum: f64 = (0..n)
            .step_by(step)
            .map(|k| (mean(k + m) - mean(k)).powi(2))
            .sum();
        (sum, n.div_ceil(step), n)
    }

    #[test]
    fn matches_the_definition_with_segments() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let values: Vec<f64> = (0..20_000)
            .map(|i| 3.0 + 1e-4 * i as f64 + Distribution::<f64>::sample(&StandardNormal, &mut rng))
            .collect();
        let segments = [0..12_000, 12_000..12_010, 12_010..20_000];
        let curve = overlapping_avar(&values, &segments, 0.01);
        assert_eq!(curve.segment_lengths, vec![12_000, 10, 7_990]);
        let sizes: Vec<usize> = curve.points.iter().map(|p| p.m).collect();
        assert_eq!(sizes, cluster_sizes(3_000));
        assert!(curve.points.iter().any(|p| stride(p.m) > 1));
        for p in &curve.points {
            let (mut sum, mut summed, mut terms) = (0.0, 0, 0);
            for r in &segments {
                if r.len() >= 2 * p.m {
                    let (s, k, n) = brute_force(&values[r.clone()], p.m, stride(p.m));
                    sum += s;
                    summed += k;
                    terms += n;
                }
            }
            let expected = sum / (2.0 * summed as f64);
            assert_eq!(p.terms, terms, "m = {}", p.m);
            assert!(
                ((p.avar - expected) / expected).abs() < 1e-9,
                "m = {}: {} vs {expected}",
                p.m,
                p.avar
            );
            assert!((p.tau_s - p.m as f64 * 0.01).abs() < 1e-15);
        }
    }

    /// The strided sum of the large cluster sizes against the fully overlapping one on white
    /// noise and on a random walk: they differ by a small fraction of the estimator's own
    /// 1-sigma spread (from its equivalent degrees of freedom).
    #[test]
    fn strided_sums_stay_close_to_the_fully_overlapping_ones() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let white: Vec<f64> = (0..1 << 16)
            .map(|_| Distribution::<f64>::sample(&StandardNormal, &mut rng))
            .collect();
        let walk: Vec<f64> = white
            .iter()
            .scan(0.0, |acc, w| {
                *acc += 0.01 * w;
                Some(*acc)
            })
            .collect();
        for (values, kind) in [(&white, NoiseKind::White), (&walk, NoiseKind::RandomWalk)] {
            let whole = std::iter::once(0..values.len()).collect::<Vec<_>>();
            let curve = overlapping_avar(values, &whole, 1.0);
            // Cluster means from a plain prefix sum (fast enough for every starting point).
            let prefix: Vec<f64> = std::iter::once(0.0)
                .chain(values.iter().scan(0.0, |acc, v| {
                    *acc += v;
                    Some(*acc)
                }))
                .collect();
            for p in curve.points.iter().filter(|p| stride(p.m) > 1) {
                let m = p.m;
                let mean = |k: usize| (prefix[k + m] - prefix[k]) / m as f64;
                let n = values.len() - 2 * m + 1;
                let full =
                    (0..n).map(|k| (mean(k + m) - mean(k)).powi(2)).sum::<f64>() / (2.0 * n as f64);
                let spread = (2.0 / edf(kind, p.m, values.len())).sqrt();
                let diff = (p.avar / full - 1.0).abs();
                assert!(
                    diff < 0.2 * spread,
                    "{kind:?} m = {}: strided {} full {full} (spread {spread})",
                    p.m,
                    p.avar
                );
            }
        }
    }

    #[test]
    fn vector_kernel_matches_the_portable_one() {
        let s: Vec<f64> = (0..5000)
            .map(|i| ((i * 7919) % 1013) as f64 * 1e-3)
            .collect();
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            for (m, start, end) in [(1, 0, 4998), (3, 5, 4000), (700, 17, 3500)] {
                // SAFETY: AVX2 was detected.
                let wide = unsafe { energy_avx2(&s, m, start, end) };
                assert_eq!(wide, energy(&s, m, start, end));
            }
        }
        // Either kernel against a plain sum.
        let plain: f64 = (10..900)
            .map(|k| (s[k + 64] - 2.0 * s[k + 32] + s[k]).powi(2))
            .sum();
        let fast = second_difference_energy(&s, 32, 10, 900);
        assert!((fast / plain - 1.0).abs() < 1e-12);
    }

    #[test]
    fn cluster_sizes_are_half_octaves() {
        let sizes = cluster_sizes(1000);
        assert_eq!(
            sizes,
            vec![
                1, 2, 3, 4, 6, 8, 11, 16, 23, 32, 46, 64, 92, 128, 184, 256, 368, 512, 736
            ]
        );
        for w in sizes[7..].windows(3) {
            assert_eq!(w[2], 2 * w[0]);
        }
        assert_eq!(cluster_sizes(5), vec![1, 2, 3, 4]);
    }

    #[test]
    fn edf_limits() {
        // White noise at m = 1: about 2N/3 (the variance of the mean squared first difference).
        let e = edf(NoiseKind::White, 1, 30_000);
        assert!((e / 20_000.0 - 1.0).abs() < 1e-3, "{e}");
        // Random walk at a quarter of the record: about 2.
        let e = edf(NoiseKind::RandomWalk, 25_000, 100_000);
        assert!((e - 2.0).abs() < 0.01, "{e}");
        // Pooling two equal segments doubles the degrees of freedom.
        for kind in [NoiseKind::White, NoiseKind::Flicker, NoiseKind::RandomWalk] {
            let one = edf(kind, 16, 5_000);
            let two = pooled_edf(kind, 16, &[5_000, 5_000]);
            assert!((two / one - 2.0).abs() < 1e-12);
            // A segment too short for m adds nothing.
            assert_eq!(pooled_edf(kind, 16, &[5_000, 20]), one);
        }
    }

    #[test]
    fn interval_brackets_the_estimate() {
        let (low, high) = one_sigma_interval(1.0, 10.0);
        // Independent values: chi2 quantiles for 10 degrees of freedom (0.1587: 5.7287...,
        // 0.8413: 14.1...).
        let chi2 = ChiSquared::new(10.0).unwrap();
        assert!((chi2.cdf(10.0 / low) - 0.841_344_7).abs() < 1e-6);
        assert!((chi2.cdf(10.0 / high) - 0.158_655_3).abs() < 1e-6);
        assert!(low < 1.0 && high > 1.0);
        // Many degrees of freedom: relative half-width about sqrt(2 / edf).
        let (low, high) = one_sigma_interval(1.0, 20_000.0);
        assert!(((high - low) / 2.0 / (2.0f64 / 20_000.0).sqrt() - 1.0).abs() < 0.01);
    }
}
