//! How correlated a sensor's noise is at rest, per axis, from the samples of the rest the
//! filter aligns on: the per-sample variance, the lag-1 and lag-2 autocorrelations and the
//! effective-sample factor that follows from them. Units are those of the samples (m/s^2 for the accelerometer,
//! rad/s for the gyroscope), sensor frame; no sign convention is involved.
//!
//! A sensor's own low-pass filter (the MPU-9250's DLPF, other IMUs' internal filters) makes
//! successive samples correlated: `n` of them carry the information of about `n / nu`
//! independent ones, `nu` the mean-variance factor (how much more their mean scatters than the
//! mean of `n` white samples of the same per-sample variance, for `n` well beyond the
//! correlation time). The filter's per-sample rest updates use `nu` so that a rest counts for
//! its effective number of samples, not for its sample count (see `navigator`).
//!
//! The noise's autocorrelation is taken to decay geometrically from lag 1 on, `rho(k) = r1
//! f^(k-1)` (an ARMA(1,1) process: white noise through one pole and one zero), so that
//! `nu = 1 + 2 sum_k rho(k) = 1 + 2 r1 / (1 - f)`, with `r1` and `f = r2 / r1` from the rest's
//! lag-1 and lag-2 autocorrelations. That is exact for a first-order low-pass, whether
//! sampled as a pole alone (`r1 = f = p`: `(1 + p) / (1 - p)`) or, as the simulator models the
//! MPU-9250's DLPF (`mems_sim::dlpf`), as the bilinear transform of one, whose zero at the
//! Nyquist frequency smooths successive samples so that `r1` exceeds the pole: the pole alone
//! (`(1 + r1) / (1 - r1)`) would overstate `nu` there by about 2.3 times (32-39 against 15 for
//! the 20 Hz setting at 1 kHz). It needs nothing of the part's configuration, so it applies
//! to IMUs whose internal filter is unknown. Slow motion during the rest (a drift) raises the
//! correlations and the factor: fewer effective samples, weaker rest updates, a wider 1-sigma.
//! White samples give `nu` = 1: their `r1` scatters about 0 by `1 / sqrt(n)`, and one within
//! 3 of those of 0 counts as white.

use nalgebra::Vector3;

/// Largest decay `f` from lag 1 to lag 2 used: a rest whose correlation decays more slowly is
/// dominated by something slower than noise.
pub const MAX_DECAY: f64 = 0.99;

/// Standard errors of a white series' lag-1 autocorrelation within which it counts as white
/// (one series in 740 beyond, one-sided).
pub const WHITE_Z: f64 = 3.0;

/// Largest mean-variance factor returned.
pub const MAX_FACTOR: f64 = 199.0;

/// Running sums over one rest's samples, per axis, taken about the rest's first sample so that
/// the sums stay small (a gravity reading of 9.8 m/s^2 against noise of a few mm/s^2).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RestNoise {
    n: u64,
    first: Vector3<f64>,
    /// The second sample's deviation, and the last two samples' (newest first).
    second: Vector3<f64>,
    prev: Vector3<f64>,
    prev2: Vector3<f64>,
    sum: Vector3<f64>,
    sum_sq: Vector3<f64>,
    /// `sum d[k] d[k-1]` and `sum d[k] d[k-2]`.
    sum_lag1: Vector3<f64>,
    sum_lag2: Vector3<f64>,
}

impl RestNoise {
    /// Adds the next sample of the rest.
    pub fn push(&mut self, x: Vector3<f64>) {
        if self.n == 0 {
            self.first = x;
        }
        let d = x - self.first;
        if self.n == 1 {
            self.second = d;
        }
        if self.n >= 1 {
            self.sum_lag1 += d.component_mul(&self.prev);
        }
        if self.n >= 2 {
            self.sum_lag2 += d.component_mul(&self.prev2);
        }
        self.sum += d;
        self.sum_sq += d.component_mul(&d);
        self.prev2 = self.prev;
        self.prev = d;
        self.n += 1;
    }

    /// Number of samples added.
    pub fn len(&self) -> u64 {
        self.n
    }

    /// Whether no sample was added.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Mean of the samples.
    pub fn mean(&self) -> Vector3<f64> {
        self.first + self.sum / self.n.max(1) as f64
    }

    /// Per-sample variance about the mean (divided by `n`), at least 0.
    pub fn variance(&self) -> Vector3<f64> {
        let n = self.n.max(1) as f64;
        let m = self.sum / n;
        (self.sum_sq / n - m.component_mul(&m)).map(|v| v.max(0.0))
    }

    /// Lag-1 and lag-2 autocorrelations per axis, `sum (x[k] - m)(x[k-L] - m) / sum (x[k] -
    /// m)^2` (zeros with fewer than 4 samples or no variance).
    pub fn autocorrelation(&self) -> (Vector3<f64>, Vector3<f64>) {
        if self.n < 4 {
            return (Vector3::zeros(), Vector3::zeros());
        }
        let n = self.n as f64;
        let m = self.sum / n;
        let ss = self.sum_sq - m.component_mul(&m) * n;
        // The first deviation is 0 (the reference). Lag 1: the later members of the pairs sum
        // to `sum`, the earlier ones to `sum - prev`; lag 2: `sum - second` and
        // `sum - prev - prev2`.
        let lag1 = self.sum_lag1 - m.component_mul(&(2.0 * self.sum - self.prev))
            + m.component_mul(&m) * (n - 1.0);
        let lag2 = self.sum_lag2
            - m.component_mul(&(2.0 * self.sum - self.second - self.prev - self.prev2))
            + m.component_mul(&m) * (n - 2.0);
        let ratio =
            |l: Vector3<f64>| Vector3::from_fn(|i, _| if ss[i] > 0.0 { l[i] / ss[i] } else { 0.0 });
        (ratio(lag1), ratio(lag2))
    }

    /// Mean-variance factor per axis, at least 1 (white samples), at most [`MAX_FACTOR`]:
    /// `1 + 2 r1 / (1 - f)`, the sum `1 + 2 sum_k r1 f^(k-1)` of the module documentation's
    /// model, with `r1` the lag-1 autocorrelation and `f = r2 / r1` the decay from lag 1 to
    /// lag 2, at most [`MAX_DECAY`]. An `r1` within [`WHITE_Z`] standard errors (`1 / sqrt(n)`
    /// for white samples, Bartlett) of zero gives 1: white samples, whose `r2 / r1` would be
    /// noise over noise.
    pub fn mean_variance_factor(&self) -> Vector3<f64> {
        let (r1, r2) = self.autocorrelation();
        let white = WHITE_Z / (self.n.max(1) as f64).sqrt();
        Vector3::from_fn(|i, _| {
            if r1[i] <= white {
                return 1.0;
            }
            let f = (r2[i] / r1[i]).clamp(0.0, MAX_DECAY);
            (1.0 + 2.0 * r1[i].min(1.0) / (1.0 - f)).min(MAX_FACTOR)
        })
    }

    /// The variance of the mean per axis: the sample variance over `n`, times
    /// [`RestNoise::mean_variance_factor`] when the samples count as effective samples
    /// (`OdometryConfig::effective_samples`).
    pub fn mean_variance(&self, effective_samples: bool) -> Vector3<f64> {
        let v = self.variance() / self.len() as f64;
        if effective_samples {
            v.component_mul(&self.mean_variance_factor())
        } else {
            v
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_constant_or_short_rest_counts_as_white() {
        let mut r = RestNoise::default();
        assert_eq!(r.mean_variance_factor(), Vector3::repeat(1.0));
        for _ in 0..10 {
            r.push(Vector3::new(0.0, 0.0, 9.8));
        }
        assert_eq!(r.variance(), Vector3::zeros());
        assert_eq!(r.mean_variance_factor(), Vector3::repeat(1.0));
    }

    #[test]
    fn alternating_samples_are_anticorrelated_and_count_as_white() {
        let mut r = RestNoise::default();
        for k in 0..100 {
            let s = if k % 2 == 0 { 1.0 } else { -1.0 };
            r.push(Vector3::new(5.0 + s, 0.0, 0.0));
        }
        assert!((r.mean().x - 5.0).abs() < 1e-12);
        assert!((r.variance().x - 1.0).abs() < 1e-12);
        assert_eq!(r.mean_variance_factor().x, 1.0);
    }
}
