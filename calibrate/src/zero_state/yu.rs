//! Yu et al.'s zero-state detector (thesis chapter 2, "Zero-State Detection"): non-overlapping
//! batches of 20 accelerometer samples; a batch is at rest when its mean and its standard
//! deviation are both within thresholds derived from a reference static period.
//!
//! Our orientation-invariant form (the thesis does not give Yu's formulas):
//! - **mean**: the magnitude of the batch mean against the magnitude learned at rest,
//!   `| |m| - M | <= z_{1 - a/2} s_M sqrt(1 + 1/K)`, with `s_M` the scatter of the learned
//!   batches' magnitudes (K of them). The magnitude does not depend on the attitude, so a sensor
//!   that comes to rest tilted differently is still recognised; the price is that a horizontal
//!   acceleration `h` changes the magnitude only by about `h^2 / (2 g)`.
//! - **std**: each axis' batch std against that axis' learned per-sample noise `sigma_i`,
//!   `s_i <= sigma_i sqrt(chi2_{19}^-1(1 - a) / 19)` (white noise is a property of each sensor
//!   axis, whatever the attitude).
//!
//! `a` is the configured per-batch false-alarm rate split evenly over the four tests
//! (Bonferroni). Kept current at rest: `M` and `sigma_i^2` are running means over rest batches.

use statrs::distribution::{ChiSquared, ContinuousCDF, Normal};

use super::learn::{ACCEL_SIGMA_FLOOR_MPS2, StaticReference, norm};
use super::{BATCH_LEN, Decision};
use crate::window::WindowStats;

/// Settings of Yu et al.'s detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct YuConfig {
    /// Probability that a batch at rest is called motion (all four tests together).
    pub false_alarm: f64,
}

impl Default for YuConfig {
    /// A false-alarm rate of 1e-2 per batch (one missed batch in 2 s of rest at 1 kHz).
    fn default() -> Self {
        Self { false_alarm: 1e-2 }
    }
}

/// Yu et al.'s learned thresholds.
#[derive(Debug, Clone)]
pub(crate) struct YuRule {
    magnitude_mps2: f64,
    magnitude_tol_mps2: f64,
    variance: [f64; 3],
    std_factor: f64,
    accel_mean_mps2: [f64; 3],
    gyro_mean_rps: [f64; 3],
}

impl YuRule {
    /// Thresholds from the start-up reference.
    pub fn new(r: &StaticReference, config: &YuConfig) -> Self {
        let alpha = config.false_alarm / 4.0;
        let dof = (BATCH_LEN - 1) as f64;
        let chi = ChiSquared::new(dof).expect("dof > 0");
        let z = Normal::standard().inverse_cdf(1.0 - alpha / 2.0);
        let k = r.batches as f64;
        let s_m = r
            .magnitude_std_mps2
            .max(ACCEL_SIGMA_FLOOR_MPS2 / (BATCH_LEN as f64).sqrt());
        Self {
            magnitude_mps2: r.magnitude_mps2,
            magnitude_tol_mps2: z * s_m * (1.0 + 1.0 / k).sqrt(),
            variance: r.accel_sigma_mps2.map(|s| s * s),
            std_factor: (chi.inverse_cdf(1.0 - alpha) / dof).sqrt(),
            accel_mean_mps2: r.accel_mean_mps2,
            gyro_mean_rps: r.gyro_mean_rps,
        }
    }

    /// The batch's verdict.
    pub fn decide(&self, accel: &WindowStats) -> Decision {
        let mean_ok = (norm(&accel.mean) - self.magnitude_mps2).abs() <= self.magnitude_tol_mps2;
        let std_ok = (0..3).all(|i| accel.std[i] <= self.std_factor * self.variance[i].sqrt());
        Decision {
            rest: mean_ok && std_ok,
            vibrating: mean_ok && !std_ok,
            mean_mps2: accel.mean,
            std_mps2: accel.std,
        }
    }

    /// Keeps the references current with a rest batch (running-mean gain `gain`).
    pub fn update(&mut self, accel: &WindowStats, gyro: &WindowStats, gain: f64) {
        self.magnitude_mps2 += gain * (norm(&accel.mean) - self.magnitude_mps2);
        for i in 0..3 {
            self.variance[i] += gain * (accel.std[i] * accel.std[i] - self.variance[i]);
            self.accel_mean_mps2[i] += gain * (accel.mean[i] - self.accel_mean_mps2[i]);
            self.gyro_mean_rps[i] += gain * (gyro.mean[i] - self.gyro_mean_rps[i]);
        }
    }

    /// The specific force at rest, m/s^2 (tracked for reporting, not tested).
    pub fn accel_mean_mps2(&self) -> [f64; 3] {
        self.accel_mean_mps2
    }

    /// The gyroscope mean at rest, rad/s (tracked for reporting, not tested).
    pub fn gyro_mean_rps(&self) -> [f64; 3] {
        self.gyro_mean_rps
    }
}
