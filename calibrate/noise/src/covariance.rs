//! The covariance of overlapping Allan variance estimates at different cluster sizes, for a
//! finite record and the three-term noise model.
//!
//! With the phase `X_k = sum_{j<k} y_j` (per-sample units), the Allan difference at cluster size
//! `m` is `D_k = (X_{k+2m} - 2 X_{k+m} + X_k) / m` and the estimate is
//! `A = 1/(2n) sum_{k<n} D_k^2`. For a Gaussian series,
//! `Cov(A_i, A_j) = 1/(2 n_i n_j) sum_L w(L) c_ij(L)^2`, where `c_ij(L) = Cov(D_k(m_i),
//! D_{k+L}(m_j))` and `w(L)` counts the pairs of terms `L` apart (this is exact for any record
//! length, which matters at cluster sizes near a quarter of the record). Second differences
//! of `X` are stationary for all three noises, so `c_ij` follows from a generalised covariance
//! `K` of `X` (`Cov(sum a X, sum b X) = sum sum a b K(t_a - s_b)` for coefficients that annihilate
//! lines):
//! - white rate noise, per-sample variance `q = N^2 / tau0`: `K(t) = -q |t| / 2`;
//! - flicker rate noise (`S = B^2 / (2 pi f)`): `K(t) = B^2 t^2 ln|t| / (2 pi)` (the continuous
//!   form, exact at the large lags where it matters; it reproduces the Allan plateau
//!   `(2 ln 2 / pi) B^2`);
//! - random-walk rate noise, increments of variance `r = K^2 tau0`: `K(t) = r (|t|^3 - |t|) / 12`.
//!
//! The sum over lags runs over the support of `c_ij` (plus a margin for flicker's decaying
//! tail), split at its breakpoints: short pieces are summed exactly, long ones (smooth,
//! polynomial for white and random-walk noise) by Gauss-Legendre quadrature, so a pair costs a
//! few hundred evaluations whatever the cluster sizes. Hand-written: no crate computes these
//! quadratic-form covariances.

use std::f64::consts::PI;

/// Distinct products of the three basis noises (k <= l): 00, 01, 02, 11, 12, 22.
pub const PAIRS: usize = 6;

/// The `(k, l)` basis indices of each product, in the order [`pair_sums`] returns them.
pub const PAIR_INDICES: [(usize, usize); PAIRS] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Gauss-Legendre nodes on `[-1, 1]` (8 points; positive half, mirrored).
const GL_NODES: [f64; 4] = [
    0.183_434_642_495_649_8,
    0.525_532_409_916_329,
    0.796_666_477_413_626_7,
    0.960_289_856_497_536_3,
];
/// Weights of [`GL_NODES`].
const GL_WEIGHTS: [f64; 4] = [
    0.362_683_783_378_362,
    0.313_706_645_877_887_3,
    0.222_381_034_453_374_5,
    0.101_228_536_290_376_3,
];

/// Pieces of the lag sum with at most this many lags are summed exactly.
const EXACT_LAGS: i64 = 64;

/// The second-difference coefficients of an Allan difference.
const ALPHA: [f64; 3] = [1.0, -2.0, 1.0];

/// Generalised covariances of the phase for unit coefficients (`N^2 = 1` with `tau0 = 1`,
/// `B^2 = 1`, `K^2 = 1` with `tau0 = 1`), at lag `t` samples.
fn generalised(t: f64) -> [f64; 3] {
    let a = t.abs();
    let flicker = if a > 0.0 {
        t * t * a.ln() / (2.0 * PI)
    } else {
        0.0
    };
    [-a / 2.0, flicker, (a * a * a - a) / 12.0]
}

/// `c_ij(L)` for each basis noise with unit per-sample coefficients.
fn cross(mi: f64, mj: f64, lag: f64) -> [f64; 3] {
    let mut c = [0.0; 3];
    for (a, &alpha) in ALPHA.iter().enumerate() {
        for (b, &beta) in ALPHA.iter().enumerate() {
            let k = generalised(lag + b as f64 * mj - a as f64 * mi);
            for (c, k) in c.iter_mut().zip(k) {
                *c += alpha * beta * k;
            }
        }
    }
    let scale = 1.0 / (mi * mj);
    c.map(|v| v * scale)
}

/// Number of term pairs `(k, k + L)` with `0 <= k < ni` and `0 <= k + L < nj` (`L` may be
/// fractional inside a piece, where the count is linear).
fn overlap(ni: f64, nj: f64, lag: f64) -> f64 {
    let low = 0f64.max(-lag);
    let high = (ni - 1.0).min(nj - 1.0 - lag);
    (high - low + 1.0).max(0.0)
}

/// `sum_segments sum_L w(L) c_k(L) c_l(L)` for cluster sizes `mi`, `mj` over segments of the
/// given lengths, in [`PAIR_INDICES`] order, for unit model coefficients `(N^2, B^2, K^2)` and
/// sample interval `tau0_s` (white noise per-sample variance `1 / tau0`, random-walk increment
/// variance `tau0`). `Cov(A_i, A_j) = sum_kl mult_kl p_k p_l S_kl / (2 n_i n_j)`.
///
/// The segments share one lag sum: their weights `w(L)` add up, and `c` does not depend on
/// the segment.
pub fn pair_sums(mi: usize, mj: usize, segment_lengths: &[usize], tau0_s: f64) -> [f64; PAIRS] {
    // Terms per segment for each size, where the segment holds both.
    let terms: Vec<(i64, i64)> = segment_lengths
        .iter()
        .filter(|&&len| len >= 2 * mi.max(mj))
        .map(|&len| ((len + 1 - 2 * mi) as i64, (len + 1 - 2 * mj) as i64))
        .collect();
    if terms.is_empty() {
        return [0.0; PAIRS];
    }
    let (mi_i, mj_i) = (mi as i64, mj as i64);
    // c vanishes outside (-2 mj, 2 mi) for white and random-walk noise; flicker's tail decays
    // as 1/L^2, so a margin of twice the combined width keeps all but a fraction of a percent.
    let margin = 2 * (mi_i + mj_i);
    let longest_i = terms.iter().map(|t| t.0).max().unwrap_or(0);
    let longest_j = terms.iter().map(|t| t.1).max().unwrap_or(0);
    let low = (-2 * mj_i - margin).max(-(longest_i - 1));
    let high = (2 * mi_i + margin).min(longest_j - 1);
    if low > high {
        return [0.0; PAIRS];
    }
    // Pieces: between the kinks of c (where an argument of K crosses 0) and of the weights.
    let mut cuts: Vec<i64> = vec![low, high + 1, 0, 2 * (mi_i - mj_i)];
    for a in 0..3 {
        for b in 0..3 {
            cuts.push(a * mi_i - b * mj_i);
        }
    }
    for &(ni, nj) in &terms {
        cuts.extend([-(ni - 1), nj]);
    }
    cuts.retain(|&c| (low..=high + 1).contains(&c));
    cuts.sort_unstable();
    cuts.dedup();
    let (fi, fj) = (mi as f64, mj as f64);
    let weights: Vec<(f64, f64)> = terms.iter().map(|&(a, b)| (a as f64, b as f64)).collect();
    let term = |lag: f64, weight: f64, out: &mut [f64; PAIRS]| {
        let w: f64 = weights.iter().map(|&(ni, nj)| overlap(ni, nj, lag)).sum();
        let c = cross(fi, fj, lag);
        for (o, &(k, l)) in out.iter_mut().zip(&PAIR_INDICES) {
            *o += weight * w * c[k] * c[l];
        }
    };
    let mut out = [0.0; PAIRS];
    for piece in cuts.windows(2) {
        let (start, end) = (piece[0], piece[1]);
        if end - start <= EXACT_LAGS {
            for lag in start..end {
                term(lag as f64, 1.0, &mut out);
            }
        } else {
            // The integers start..end as the integral over [start - 1/2, end - 1/2].
            let (a, b) = (start as f64 - 0.5, end as f64 - 0.5);
            let (half, mid) = (0.5 * (b - a), 0.5 * (a + b));
            for (&x, &w) in GL_NODES.iter().zip(&GL_WEIGHTS) {
                for lag in [mid - half * x, mid + half * x] {
                    term(lag, w * half, &mut out);
                }
            }
        }
    }
    let unit = [1.0 / tau0_s, 1.0, tau0_s];
    for (o, &(k, l)) in out.iter_mut().zip(&PAIR_INDICES) {
        *o *= unit[k] * unit[l];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Allan difference kernel on white rate samples: -1/m (m times), then +1/m (m times).
    fn white_kernel(m: usize) -> Vec<f64> {
        let mf = m as f64;
        (0..2 * m)
            .map(|i| if i < m { -1.0 / mf } else { 1.0 / mf })
            .collect()
    }

    /// The same difference on a random walk, as a kernel on its increments: a triangle.
    fn walk_kernel(m: usize) -> Vec<f64> {
        let mf = m as f64;
        (0..2 * m)
            .map(|j| {
                if j < m {
                    j as f64 / mf
                } else {
                    (2 * m - j) as f64 / mf
                }
            })
            .collect()
    }

    /// `Cov(D_k(mi), D_{k+L}(mj))` by direct convolution of the kernels (white: on the
    /// samples; random walk: on the increments).
    fn direct(ki: &[f64], kj: &[f64], lag: i64) -> f64 {
        (0..ki.len() as i64)
            .filter_map(|n| {
                let m = n - lag;
                (0..kj.len() as i64)
                    .contains(&m)
                    .then(|| ki[n as usize] * kj[m as usize])
            })
            .sum()
    }

    #[test]
    fn cross_covariances_match_direct_convolutions() {
        for (mi, mj) in [(1, 1), (1, 3), (2, 4), (3, 8), (5, 5), (7, 2)] {
            for lag in -20i64..20 {
                let c = cross(mi as f64, mj as f64, lag as f64);
                // For D_{k+L}(mj) the kernel starts L samples later.
                let white = direct(&white_kernel(mi), &white_kernel(mj), lag);
                let walk = direct(&walk_kernel(mi), &walk_kernel(mj), lag);
                assert!(
                    (c[0] - white).abs() < 1e-12,
                    "white ({mi},{mj}) lag {lag}: {} vs {white}",
                    c[0]
                );
                assert!(
                    (c[2] - walk).abs() < 1e-9,
                    "walk ({mi},{mj}) lag {lag}: {} vs {walk}",
                    c[2]
                );
            }
        }
    }

    /// `sum_{k<ni} sum_{l<nj} c(l - k)^2` by brute force.
    fn brute_sum(mi: usize, mj: usize, len: usize, kind: usize) -> f64 {
        let (ni, nj) = ((len + 1 - 2 * mi) as i64, (len + 1 - 2 * mj) as i64);
        let mut total = 0.0;
        for k in 0..ni {
            for l in 0..nj {
                let c = cross(mi as f64, mj as f64, (l - k) as f64)[kind];
                total += c * c;
            }
        }
        total
    }

    #[test]
    fn lag_sums_match_brute_force_including_quadrature() {
        // Long pieces (quadrature) appear for sizes above EXACT_LAGS / 2.
        for (mi, mj, len) in [
            (1, 1, 50),
            (3, 11, 60),
            (40, 90, 400),
            (64, 128, 600),
            (100, 100, 450),
        ] {
            let sums = pair_sums(mi, mj, &[len], 1.0);
            for (kind, index) in [(0, 0), (1, 3), (2, 5)] {
                let expected = brute_sum(mi, mj, len, kind);
                assert!(
                    (sums[index] / expected - 1.0).abs() < 2e-3,
                    "({mi}, {mj}, {len}) kind {kind}: {} vs {expected}",
                    sums[index]
                );
            }
        }
    }

    #[test]
    fn variances_reproduce_the_allan_variance_of_each_noise() {
        // c_ii(0) = Var(D) = 2 AVAR: white 2/m, random walk (2m^2+1)/(3m), flicker at large m
        // 4 ln 2 / pi.
        for m in [1.0, 7.0, 300.0] {
            let c = cross(m, m, 0.0);
            assert!((c[0] - 2.0 / m).abs() < 1e-12);
            assert!((c[2] - (2.0 * m * m + 1.0) / (3.0 * m)).abs() < 1e-9 * m);
        }
        let c = cross(1000.0, 1000.0, 0.0);
        assert!((c[1] / (4.0 * std::f64::consts::LN_2 / PI) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn white_variance_at_m1_is_exact() {
        // Var of the m = 1 estimate with n terms and q = 1: (12 n - 4) / (4 n^2).
        let len = 1001;
        let n = 1000.0;
        let sums = pair_sums(1, 1, &[len], 1.0);
        let var = sums[0] / (2.0 * n * n);
        assert!(
            (var - (12.0 * n - 4.0) / (4.0 * n * n)).abs() < 1e-12,
            "{var}"
        );
    }

    #[test]
    fn segments_add() {
        // Different lengths (one too short for the larger size) share one lag sum.
        let (a, b, short) = (
            pair_sums(8, 23, &[500], 0.01),
            pair_sums(8, 23, &[130], 0.01),
            pair_sums(8, 23, &[40], 0.01),
        );
        assert_eq!(short, [0.0; PAIRS]);
        let all = pair_sums(8, 23, &[500, 40, 130], 0.01);
        for k in 0..PAIRS {
            assert!((all[k] - a[k] - b[k]).abs() <= 1e-12 * all[k].abs(), "{k}");
        }
    }
}
