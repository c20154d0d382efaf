//! Streaming windowed statistics and the rest test built on them. [`WindowAccumulator`] is the
//! shared core of the offline static-segment detector (`calibrate_science::segments`) and of the live
//! zero-state detectors ([`crate::zero_state`]: non-overlapping batches of 20 samples), which
//! apply their own thresholds learned at start-up.
//!
//! [`WindowAccumulator`] takes one 3-axis sample at a time and, every `len` samples, returns the
//! mean and standard deviation of the window just completed (non-overlapping windows; Welford's
//! update, no allocation per sample). [`RestCriterion`] decides whether a window is at rest from
//! its std and from its mean's distance to a reference mean (the previous window's, offline).
//! Values are in whatever unit the caller feeds (g offline, SI live).

use crate::noise_level::NoiseLevel;
use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};

/// Statistics of one completed window.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WindowStats {
    /// Time of the window's first sample, ns.
    pub t_start_ns: u64,
    /// Time of the window's last sample, ns.
    pub t_end_ns: u64,
    /// Number of samples in the window.
    pub n: usize,
    /// Mean per axis (input units).
    pub mean: [f64; 3],
    /// Sample standard deviation per axis (divisor `n - 1`, input units).
    pub std: [f64; 3],
}

/// Accumulates samples into non-overlapping windows of a fixed number of samples.
#[derive(Debug, Clone)]
pub struct WindowAccumulator {
    len: usize,
    count: usize,
    t_start_ns: u64,
    mean: [f64; 3],
    m2: [f64; 3],
}

impl WindowAccumulator {
    /// A new accumulator for windows of `len` samples (at least 2, so that a std exists).
    ///
    /// # Panics
    /// If `len < 2`.
    pub fn new(len: usize) -> Self {
        assert!(len >= 2, "a window needs at least 2 samples, got {len}");
        Self {
            len,
            count: 0,
            t_start_ns: 0,
            mean: [0.0; 3],
            m2: [0.0; 3],
        }
    }

    /// The window length in samples.
    pub fn window_len(&self) -> usize {
        self.len
    }

    /// Discards the partial window (e.g. after a gap in the data).
    pub fn reset(&mut self) {
        self.count = 0;
        self.mean = [0.0; 3];
        self.m2 = [0.0; 3];
    }

    /// Adds one sample at time `t_ns`; returns the window's statistics when this sample
    /// completes it (and starts a new window with the next sample).
    pub fn push(&mut self, t_ns: u64, x: [f64; 3]) -> Option<WindowStats> {
        if self.count == 0 {
            self.t_start_ns = t_ns;
        }
        self.count += 1;
        let n = self.count as f64;
        for (i, xi) in x.iter().enumerate() {
            let delta = xi - self.mean[i];
            self.mean[i] += delta / n;
            self.m2[i] += delta * (xi - self.mean[i]);
        }
        if self.count < self.len {
            return None;
        }
        let denom = (self.count - 1) as f64;
        let stats = WindowStats {
            t_start_ns: self.t_start_ns,
            t_end_ns: t_ns,
            n: self.count,
            mean: self.mean,
            std: std::array::from_fn(|i| (self.m2[i].max(0.0) / denom).sqrt()),
        };
        self.reset();
        Some(stats)
    }
}

/// Thresholds that make a window "at rest": every axis' std at most `std_max` and every
/// axis' mean within `mean_tol` of a reference mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RestCriterion {
    /// Largest std per axis of a window at rest (input units).
    pub std_max: [f64; 3],
    /// Largest distance per axis of the window mean from the reference mean (input units).
    pub mean_tol: [f64; 3],
}

impl RestCriterion {
    /// Thresholds for white noise of per-sample std `sigma` (per axis) and windows of `len`
    /// samples, each test with false-alarm probability `alpha` per axis and window at rest:
    /// `std_max = sigma sqrt(chi2_{len-1}^-1(1 - alpha) / (len - 1))`, and for the mean
    /// compared with the *previous window's* mean (difference of two independent means)
    /// `mean_tol = z_{1 - alpha/2} sigma sqrt(2 / len)`.
    ///
    /// # Panics
    /// If `len < 2` or `alpha` is not in (0, 1).
    pub fn from_noise(sigma: [f64; 3], len: usize, alpha: f64) -> Self {
        Self::from_noise_level(&sigma.map(NoiseLevel::white), len, alpha)
    }

    /// [`Self::from_noise`] for noise that may be correlated from sample to sample (the
    /// MPU-9250's DLPF): the std test with the sample variance's effective degrees of freedom
    /// ([`NoiseLevel::variance_dof`]) in place of `len - 1`, and the mean tolerance widened by
    /// the square root of [`NoiseLevel::mean_variance_factor`] (neglecting the positive
    /// correlation of adjacent windows' means, which only narrows their difference).
    ///
    /// # Panics
    /// If `len < 2` or `alpha` is not in (0, 1).
    pub fn from_noise_level(noise: &[NoiseLevel; 3], len: usize, alpha: f64) -> Self {
        assert!(
            len >= 2 && alpha > 0.0 && alpha < 1.0,
            "len {len}, alpha {alpha}"
        );
        let z = Normal::standard().inverse_cdf(1.0 - alpha / 2.0);
        let std_max = noise.each_ref().map(|n| {
            let dof = n.variance_dof(len);
            let chi = ChiSquared::new(dof).expect("dof > 0");
            n.sigma * (chi.inverse_cdf(1.0 - alpha) / dof).sqrt()
        });
        let mean_tol = noise
            .each_ref()
            .map(|n| z * n.sigma * (2.0 * n.mean_variance_factor(len) / len as f64).sqrt());
        Self { std_max, mean_tol }
    }

    /// Whether window `w` is at rest: its std within `std_max` and, when a reference mean is
    /// given, its mean within `mean_tol` of it on every axis.
    pub fn is_rest(&self, w: &WindowStats, reference_mean: Option<&[f64; 3]>) -> bool {
        let std_ok = (0..3).all(|i| w.std[i] <= self.std_max[i]);
        let mean_ok = reference_mean
            .is_none_or(|r| (0..3).all(|i| (w.mean[i] - r[i]).abs() <= self.mean_tol[i]));
        std_ok && mean_ok
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal as RNormal};

    #[test]
    fn window_statistics_match_a_two_pass_computation() {
        let xs: Vec<[f64; 3]> = (0..10)
            .map(|k| [k as f64, (k * k) as f64 * 0.1, 1.0 - 0.5 * k as f64])
            .collect();
        let mut acc = WindowAccumulator::new(5);
        let mut out = Vec::new();
        for (k, x) in xs.iter().enumerate() {
            if let Some(w) = acc.push(1000 * k as u64, *x) {
                out.push(w);
            }
        }
        assert_eq!(out.len(), 2);
        for (w, chunk) in out.iter().zip(xs.chunks(5)) {
            assert_eq!(w.n, 5);
            for i in 0..3 {
                let m = chunk.iter().map(|x| x[i]).sum::<f64>() / 5.0;
                let v = chunk.iter().map(|x| (x[i] - m).powi(2)).sum::<f64>() / 4.0;
                assert!((w.mean[i] - m).abs() < 1e-12);
                assert!((w.std[i] - v.sqrt()).abs() < 1e-12);
            }
        }
        assert_eq!((out[1].t_start_ns, out[1].t_end_ns), (5000, 9000));
    }

    #[test]
    fn false_alarm_rate_on_white_noise_matches_alpha() {
        // Independent check of the thresholds: simulate white noise, count windows refused.
        let sigma = 0.002;
        let len = 50;
        let alpha = 0.01;
        let crit = RestCriterion::from_noise([sigma; 3], len, alpha);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = RNormal::new(0.0, sigma).unwrap();
        let mut acc = WindowAccumulator::new(len);
        let (mut windows, mut std_fail, mut mean_fail) = (0usize, 0usize, 0usize);
        let mut prev: Option<WindowStats> = None;
        for k in 0..400_000u64 {
            let x = [
                noise.sample(&mut rng),
                noise.sample(&mut rng),
                noise.sample(&mut rng),
            ];
            if let Some(w) = acc.push(k, x) {
                windows += 1;
                if !(0..3).all(|i| w.std[i] <= crit.std_max[i]) {
                    std_fail += 1;
                }
                if let Some(p) = prev
                    && !(0..3).all(|i| (w.mean[i] - p.mean[i]).abs() <= crit.mean_tol[i])
                {
                    mean_fail += 1;
                }
                prev = Some(w);
            }
        }
        // Three axes, each failing with probability alpha: 1 - (1 - alpha)^3 per window.
        let expect = 1.0 - (1.0 - alpha).powi(3);
        for fails in [std_fail, mean_fail] {
            let rate = fails as f64 / windows as f64;
            assert!(
                (rate - expect).abs() < 0.4 * expect,
                "rate {rate}, expected {expect}"
            );
        }
    }
}
