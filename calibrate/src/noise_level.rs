//! The per-sample noise level and autocorrelation of a series whose noise may be coloured
//! (an MPU-9250's samples through its DLPF are correlated: at 1 kHz with the 184 Hz setting
//! successive samples correlate about 0.5, with the 20 Hz setting about 0.9), estimated from
//! the series' own differences.
//!
//! For stationary noise of variance `sigma^2` and autocorrelation `rho(L)`, the lag-`L`
//! second differences `x[k+L] - 2 x[k] + x[k-L]` have variance
//! `S(L) = sigma^2 (6 - 8 rho(L) + 2 rho(2L))` and the first differences
//! `D(L) = 2 sigma^2 (1 - rho(L))`. Each is taken robustly, `(1.4826 MAD)^2` about zero (a
//! series' differences have zero median at rest, and motion or isolated outliers move the
//! median little while they are a minority). `S(L)` grows with `L` until the noise
//! decorrelates and then stays flat at `6 sigma^2`; the first doubling of `L` over which it
//! grows by less than [`PLATEAU_GROWTH`] gives `sigma^2 = S(L) / 6`, and
//! `rho(l) = 1 - D(l) / (2 sigma^2)` for the lags below. White noise plateaus at once (`L = 2`).
//!
//! Units are those of the series. Second differences are used for the level because smooth
//! motion hardly enters them (a rotation at 0.5 rad/s changes gravity's projection by 20 mg
//! over 40 ms but its second difference by 0.4 mg), while the first differences at the lags a
//! narrow filter needs would count part of the motion as noise (a session with 11% rotation
//! at 200 Hz: 3-9% high by lag 4-32 from first differences, within 1% from second ones).
/// Growth of `D(L)` over a doubling of `L` below which it counts as flat (the MAD's own
/// relative scatter is about `1.2 / sqrt(n)`, 0.3% for 1e5 samples).
pub const PLATEAU_GROWTH: f64 = 0.03;

/// Longest lag tried, samples (a first-order filter at 5 Hz and 1 kHz decorrelates to 1% in
/// about 150 samples).
pub const MAX_LAG: usize = 512;

/// The noise of one series.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseLevel {
    /// Per-sample standard deviation (the marginal one, what a window's std estimates).
    pub sigma: f64,
    /// `rho(1), rho(2), ...` below the lower end of the doubling where the estimate plateaued
    /// (empty for white noise).
    pub autocorrelation: Vec<f64>,
}

impl NoiseLevel {
    /// Estimates the noise of `values` (see the module documentation). Fewer than 3 values,
    /// or no plateau within [`MAX_LAG`] or a fifth of the series, give the estimate at the
    /// longest lag tried.
    pub fn of(values: &[f64]) -> Self {
        let n = values.len();
        let max_lag = MAX_LAG.min(n / 5).max(1);
        let mut s2 = vec![f64::NAN; max_lag + 1];
        let mut buf = Vec::with_capacity(n);
        let mut plateau = None;
        let mut lag = 1;
        while lag <= max_lag {
            s2[lag] = second_difference_variance(values, lag, &mut buf);
            if lag >= 2 && s2[lag] <= (1.0 + PLATEAU_GROWTH) * s2[lag / 2] {
                plateau = Some(lag);
                break;
            }
            lag *= 2;
        }
        let top = plateau.unwrap_or((lag / 2).max(1));
        let sigma2 = s2[top] / 6.0;
        if sigma2.is_nan() || sigma2 <= 0.0 {
            return Self {
                sigma: 0.0,
                autocorrelation: Vec::new(),
            };
        }
        // rho for every lag below the plateau's lower end (beyond it: zero). White noise has
        // none: its rho(1) from first differences would carry what little motion they hold
        // as a spurious negative correlation.
        let autocorrelation = (1..top / 2)
            .map(|l| {
                let dl = lag_difference_variance(values, l, &mut buf);
                (1.0 - dl / (2.0 * sigma2)).clamp(-1.0, 1.0)
            })
            .collect();
        Self {
            sigma: sigma2.sqrt(),
            autocorrelation,
        }
    }

    /// White noise of per-sample standard deviation `sigma`.
    pub fn white(sigma: f64) -> Self {
        Self {
            sigma,
            autocorrelation: Vec::new(),
        }
    }

    /// How much more the mean of `len` successive samples scatters than for white noise
    /// (variance ratio): `1 + 2 sum_k (1 - k / len) rho(k)`, at least `1 / len`.
    pub fn mean_variance_factor(&self, len: usize) -> f64 {
        (1.0 + 2.0 * self.triangle_sum(len, |w, r| w * r)).max(1.0 / len as f64)
    }

    /// Effective degrees of freedom of the sample variance of `len` successive samples:
    /// `(len - 1) / (1 + 2 sum_k (1 - k / len) rho(k)^2)` (Bartlett's approximation for a
    /// Gaussian series), `len - 1` for white noise.
    pub fn variance_dof(&self, len: usize) -> f64 {
        let n = len as f64;
        ((n - 1.0) / (1.0 + 2.0 * self.triangle_sum(len, |w, r| w * r * r))).max(1.0)
    }

    /// `sum_k term(1 - k / len, rho(k))` over the lags `k` of a window of `len` samples.
    fn triangle_sum(&self, len: usize, term: impl Fn(f64, f64) -> f64) -> f64 {
        let n = len as f64;
        self.autocorrelation
            .iter()
            .take(len.saturating_sub(1))
            .enumerate()
            .map(|(i, &r)| term(1.0 - (i + 1) as f64 / n, r))
            .sum()
    }
}

/// `(1.4826 MAD)^2` of the lag-`lag` second differences of `values`, about zero.
fn second_difference_variance(values: &[f64], lag: usize, buf: &mut Vec<f64>) -> f64 {
    buf.clear();
    buf.extend(
        values
            .windows(2 * lag + 1)
            .map(|w| (w[2 * lag] - 2.0 * w[lag] + w[0]).abs()),
    );
    robust_variance(buf)
}

/// `(1.4826 MAD)^2` of the lag-`lag` differences of `values`, about zero.
fn lag_difference_variance(values: &[f64], lag: usize, buf: &mut Vec<f64>) -> f64 {
    buf.clear();
    buf.extend(values.windows(lag + 1).map(|w| (w[lag] - w[0]).abs()));
    robust_variance(buf)
}

/// `(1.4826 median)^2` of absolute values (0 for none).
fn robust_variance(abs: &mut [f64]) -> f64 {
    if abs.is_empty() {
        return 0.0;
    }
    let mid = abs.len() / 2;
    let (_, m, _) = abs.select_nth_unstable_by(mid, f64::total_cmp);
    (1.4826 * *m).powi(2)
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// White noise through a first-order low-pass with pole `p` (unit gain at DC), scaled to
    /// per-sample std `sigma`: lag-k autocorrelation `p^k`.
    fn ar1(p: f64, sigma: f64, n: usize, seed: u64) -> Vec<f64> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let e = Normal::new(0.0, sigma * (1.0 - p * p).sqrt()).unwrap();
        let mut y = 0.0;
        (0..n + 100)
            .map(|_| {
                y = p * y + e.sample(&mut rng);
                y
            })
            .skip(100)
            .collect()
    }

    #[test]
    fn white_noise_gives_its_sigma_and_no_correlation() {
        let x = ar1(0.0, 2.0, 100_000, 1);
        let est = NoiseLevel::of(&x);
        assert!((est.sigma - 2.0).abs() < 0.03, "{est:?}");
        assert!(est.autocorrelation.iter().all(|r| r.abs() < 0.03));
        assert!((est.mean_variance_factor(500) - 1.0).abs() < 0.1);
    }

    #[test]
    fn correlated_noise_gives_its_marginal_sigma_and_mean_scatter() {
        // AR(1): rho(k) = p^k; the mean of n samples scatters (1 + p) / (1 - p) times more than
        // white noise's for n far beyond the correlation time (closed form, independent of
        // the estimator), and the first differences alone would say sigma sqrt(1 - p).
        for (p, seed) in [(0.5, 2), (0.9, 3)] {
            let x = ar1(p, 3.0, 200_000, seed);
            let est = NoiseLevel::of(&x);
            assert!((est.sigma - 3.0).abs() < 0.06, "p {p}: {est:?}");
            assert!((est.autocorrelation[0] - p).abs() < 0.02, "p {p}: {est:?}");
            let want = (1.0 + p) / (1.0 - p);
            let got = est.mean_variance_factor(2000);
            assert!((got - want).abs() < 0.1 * want, "p {p}: {got} vs {want}");
        }
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
