//! Frequency-domain integrals of the noise model, for the covariance of Allan variance
//! estimates at different cluster times.
//!
//! Frequencies `phi` are in cycles per sample (`-1/2 .. 1/2`); spectra are two-sided and in
//! (series unit)^2 per unit of `phi`, i.e. per-sample variance density. With coefficients
//! `p = (N^2, B^2, K^2)` and sample interval `tau0` the rate spectrum is
//! `S(phi) = sum_k p_k g_k(phi)` with the basis
//! - white: `g_0 = 1 / tau0` (variance `N^2 / tau0` per sample);
//! - flicker: `g_1 = 1 / (2 pi |phi|)` (IEEE Std 952's `B^2 / (2 pi f)`, which gives the
//!   Allan plateau `(2 ln 2 / pi) B^2`);
//! - random walk: `g_2 = tau0 / (4 sin^2(pi phi))` (a discrete random walk with increments of
//!   variance `K^2 tau0`).
//!
//! The Allan difference at cluster size `m` is a linear filter with squared gain
//! `|H_m(phi)|^2 = 4 sin^4(pi m phi) / (m^2 sin^2(pi phi))`, so
//! `AVAR(m) = 1/2 int S |H_m|^2`, and for a Gaussian series the covariance of two overlapping
//! estimates with `n_a`, `n_b` terms is, for records much longer than the clusters,
//! `n_min / (2 n_a n_b) * int S^2 |H_a|^2 |H_b|^2` (Parseval applied to the cross-covariance of
//! the two difference sequences). [`pair_integrals`] returns that integral for each pair of
//! basis spectra.
//!
//! The integrands oscillate with periods `1/m_a` and `1/m_b`. The quadrature is exact
//! (Gauss-Legendre panels a quarter period wide) where `phi < 8 / m`, and beyond that replaces
//! a fast factor `sin^4(pi m phi)` by its mean 3/8, or the product of both by the mean over
//! their common period: closed forms that keep the cost per pair at a few hundred panels even
//! for clusters of millions of samples. Hand-written because no maintained crate integrates
//! these oscillatory kernels at that cost.

use std::f64::consts::PI;

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

/// Periods of the slower oscillation integrated exactly before averaging takes over.
const EXACT_PERIODS: f64 = 8.0;

/// Number of distinct products `g_k g_l` (k <= l): 00, 01, 02, 11, 12, 22.
pub const PAIRS: usize = 6;

/// The `(k, l)` basis indices of each product, in the order [`pair_integrals`] returns them.
pub const PAIR_INDICES: [(usize, usize); PAIRS] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Squared gain of the Allan difference at cluster size `m`.
fn gain(m: f64, phi: f64) -> f64 {
    let s = (PI * phi).sin();
    let sm = (PI * m * phi).sin();
    let sm2 = sm * sm;
    4.0 * sm2 * sm2 / (m * m * s * s)
}

/// The basis spectra at `phi` (see the module documentation).
fn basis(phi: f64, tau0: f64) -> [f64; 3] {
    let s = (PI * phi).sin();
    [1.0 / tau0, 1.0 / (2.0 * PI * phi), tau0 / (4.0 * s * s)]
}

/// Gauss-Legendre quadrature of a vector-valued function over `[a, b]` (8 nodes).
fn panel<const N: usize>(a: f64, b: f64, f: &impl Fn(f64) -> [f64; N], out: &mut [f64; N]) {
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    for (&x, &w) in GL_NODES.iter().zip(&GL_WEIGHTS) {
        for phi in [mid - half * x, mid + half * x] {
            let v = f(phi);
            for (o, v) in out.iter_mut().zip(v) {
                *o += w * half * v;
            }
        }
    }
}

/// Integrates over `[a, b]` with panels no wider than `max_width` nor than a quarter of their
/// left end (so that power-law envelopes are resolved near 0). `a` may be 0.
fn integrate<const N: usize>(
    a: f64,
    b: f64,
    max_width: f64,
    f: &impl Fn(f64) -> [f64; N],
    out: &mut [f64; N],
) {
    let mut x = a;
    while x < b {
        let width = if x > 0.0 {
            max_width.min(0.25 * x)
        } else {
            max_width
        };
        let next = (x + width).min(b);
        panel(x, next, f, out);
        x = next;
    }
}

/// Mean of `sin^4(pi p x) sin^4(pi q x)` over a common period, for coprime-reduced integer
/// frequencies `p <= q`: 9/64 plus the resonant terms of the product of
/// `sin^4 t = (3 - 4 cos 2t + cos 4t) / 8`.
fn product_mean(p: usize, q: usize) -> f64 {
    let mut mean = 9.0;
    if p == q {
        mean += 8.5;
    }
    if q == 2 * p {
        mean -= 2.0;
    }
    mean / 64.0
}

fn gcd(mut a: usize, mut b: usize) -> usize {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// `2 int_0^{1/2} g_k g_l |H_a|^2 |H_b|^2 dphi` for the basis products in [`PAIR_INDICES`]
/// order; the full-band integral `int_{-1/2}^{1/2}` of the module documentation.
pub fn pair_integrals(ma: usize, mb: usize, tau0: f64) -> [f64; PAIRS] {
    let (ma, mb) = (ma.min(mb), ma.max(mb));
    let (fa, fb) = (ma as f64, mb as f64);
    let products = |g: [f64; 3], weight: f64| PAIR_INDICES.map(|(k, l)| g[k] * g[l] * weight);
    let exact = |phi: f64| products(basis(phi, tau0), gain(fa, phi) * gain(fb, phi));
    let mut out = [0.0; PAIRS];

    let phi_b = (EXACT_PERIODS / fb).min(0.5);
    let phi_a = (EXACT_PERIODS / fa).min(0.5);
    integrate(0.0, phi_b, 0.25 / fb, &exact, &mut out);
    if phi_a > phi_b {
        if mb >= 8 * ma {
            // The fast factor averages to 3/8 while the slow one is still resolved.
            let fast_mean = |phi: f64| {
                let s = (PI * phi).sin();
                let fast = 4.0 * 0.375 / (fb * fb * s * s);
                products(basis(phi, tau0), gain(fa, phi) * fast)
            };
            integrate(phi_b, phi_a, 0.25 / fa, &fast_mean, &mut out);
        } else {
            integrate(phi_b, phi_a, 0.25 / fb, &exact, &mut out);
        }
    }
    if phi_a < 0.5 {
        let g = gcd(ma, mb);
        let mean = product_mean(ma / g, mb / g);
        let both_mean = |phi: f64| {
            let s = (PI * phi).sin();
            let s2 = s * s;
            products(
                basis(phi, tau0),
                16.0 * mean / (fa * fa * fb * fb * s2 * s2),
            )
        };
        integrate(phi_a, 0.5, 0.5, &both_mean, &mut out);
    }
    out.map(|v| 2.0 * v)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LN2_FACTOR: f64 = 2.0 * std::f64::consts::LN_2 / PI;

    /// `int_0^{1/2} g_k |H_m|^2 dphi` for each basis spectrum: the Allan variance of the model per
    /// unit coefficient, `(1/tau, ~2 ln2 / pi, ~tau/3)`, as the discrete filter sees it.
    fn avar_basis(m: usize, tau0: f64) -> [f64; 3] {
        let mf = m as f64;
        let f = |phi: f64| {
            let g = gain(mf, phi);
            basis(phi, tau0).map(|b| b * g)
        };
        let mut out = [0.0; 3];
        let split = (EXACT_PERIODS / mf).min(0.5);
        integrate(0.0, split, 0.25 / mf, &f, &mut out);
        // Beyond: sin^4(pi m phi) -> 3/8.
        let smooth = |phi: f64| {
            let s = (PI * phi).sin();
            let g = 4.0 * 0.375 / (mf * mf * s * s);
            basis(phi, tau0).map(|b| b * g)
        };
        integrate(split, 0.5, 0.5, &smooth, &mut out);
        out
    }

    #[test]
    fn avar_basis_matches_closed_forms() {
        let tau0 = 0.01;
        for m in [1usize, 2, 5, 16, 100, 1000, 100_000] {
            let tau = m as f64 * tau0;
            let [white, flicker, rw] = avar_basis(m, tau0);
            // White: exactly 1/tau. Random walk: tau/3 + tau0^2/(6 tau) (the discrete walk).
            assert!(
                (white * tau - 1.0).abs() < 1e-3,
                "m {m}: white {}",
                white * tau
            );
            let rw_exact = tau / 3.0 + tau0 * tau0 / (6.0 * tau);
            assert!(
                (rw / rw_exact - 1.0).abs() < 1e-3,
                "m {m}: rw {}",
                rw / rw_exact
            );
            if m >= 100 {
                assert!(
                    (flicker / LN2_FACTOR - 1.0).abs() < 0.01,
                    "m {m}: {flicker}"
                );
            }
        }
    }

    /// `sum_L c(L)^2` for two difference kernels, computed in the time domain.
    fn lag_sum(ka: &[f64], kb: &[f64]) -> f64 {
        let (na, nb) = (ka.len() as isize, kb.len() as isize);
        (-nb..na)
            .map(|lag| {
                (0..na)
                    .filter_map(|i| {
                        let j = i - lag;
                        (0..nb)
                            .contains(&j)
                            .then(|| ka[i as usize] * kb[j as usize])
                    })
                    .sum::<f64>()
                    .powi(2)
            })
            .sum()
    }

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
        (1..2 * m)
            .map(|j| {
                if j < m {
                    j as f64 / mf
                } else {
                    (2 * m - j) as f64 / mf
                }
            })
            .collect()
    }

    #[test]
    fn pair_integrals_match_time_domain_sums() {
        let tau0 = 0.5;
        let pairs = [
            (1, 1),
            (1, 3),
            (2, 4),
            (3, 8),
            (16, 23),
            (23, 46),
            (32, 256),
            (64, 64),
            (92, 128),
        ];
        for (ma, mb) in pairs {
            let j = pair_integrals(ma, mb, tau0);
            // White with per-sample variance 1: S = 1 = p0 g0 with p0 = tau0.
            let white = j[0] * tau0 * tau0;
            let expected = lag_sum(&white_kernel(ma), &white_kernel(mb));
            assert!(
                (white / expected - 1.0).abs() < 0.03,
                "white ({ma}, {mb}): {white} vs {expected}"
            );
            // Random walk with unit increments: S = p2 g2 with p2 = 1 / tau0.
            let walk = j[5] / (tau0 * tau0);
            let expected = lag_sum(&walk_kernel(ma), &walk_kernel(mb));
            assert!(
                (walk / expected - 1.0).abs() < 0.03,
                "walk ({ma}, {mb}): {walk} vs {expected}"
            );
        }
    }

    #[test]
    fn white_variance_at_m1_is_exact() {
        // Var of the m = 1 estimate with n terms: 3 q^2 / n, i.e. int S^2 |H_1|^4 = 6 q^2.
        let j = pair_integrals(1, 1, 1.0);
        assert!((j[0] - 6.0).abs() < 1e-9, "{}", j[0]);
    }

    #[test]
    fn product_means() {
        // Numerical means over a common period.
        for (p, q) in [(1, 1), (1, 2), (2, 3), (1, 3), (3, 5)] {
            let n = 200_000;
            let mean = (0..n)
                .map(|i| {
                    let x = (i as f64 + 0.5) / n as f64;
                    (PI * p as f64 * x).sin().powi(4) * (PI * q as f64 * x).sin().powi(4)
                })
                .sum::<f64>()
                / n as f64;
            assert!(
                (mean - product_mean(p, q)).abs() < 1e-9,
                "({p}, {q}): {mean}"
            );
        }
    }
}
