//! The SHOE stance detector for foot-mounted sensors (Skog, Handel, Nilsson, Rantakokko, "Zero-
//! velocity detection: an algorithm evaluation", IEEE Trans. Biomed. Eng. 57(11), 2010, the
//! detector of OpenShoe): over a window of `W` samples with mean specific force `a_bar`,
//!
//! ```text
//! T = 1/W sum_k ( |a_k - g a_bar / |a_bar||^2 / sigma_a^2 + |w_k|^2 / sigma_g^2 )  <= gamma
//! ```
//!
//! A foot at stance is still for 0.2-0.5 s, far too short for the learned detectors' windows
//! (half a second at least, plus their learning), and it is not still to the sensor's noise: the
//! walker's weight rolls over it. So SHOE needs no learning and tests against fixed, loose
//! scales: with OpenShoe's values (`sigma_a` 0.01 m/s^2, `sigma_g` 0.1 deg/s, `gamma` 3e4) a
//! window passes while the angular rate stays under about 17 deg/s and the specific force
//! within about 1.7 m/s^2 of gravity's magnitude (its direction is free: the foot lands at a
//! different tilt every step). Computed from the window's per-axis means and standard
//! deviations (divisor `W - 1`):
//! `sum_k |a_k - g u|^2 / W = sum_i (W - 1) / W s_i^2 + (|a_bar| - g)^2` and
//! `sum_k |w_k|^2 / W = sum_i ((W - 1) / W s_i^2 + w_bar_i^2)`.
//! Units: m/s^2 and rad/s, sensor frame.

use super::Decision;
use crate::window::WindowStats;

/// Settings of the SHOE detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShoeConfig {
    /// Window length, samples (non-overlapping windows; the stage's latency).
    pub window: usize,
    /// Scale of the specific force's deviation from gravity, m/s^2.
    pub accel_sigma_mps2: f64,
    /// Scale of the angular rate, rad/s.
    pub gyro_sigma_rps: f64,
    /// Threshold on the statistic.
    pub gamma: f64,
}

impl Default for ShoeConfig {
    /// OpenShoe's scales and threshold (sigma_a 0.01 m/s^2, sigma_g 0.1 deg/s, gamma 3e4) over
    /// windows of 5 samples (25 ms at 200 Hz: a tenth of the shortest stance).
    fn default() -> Self {
        Self {
            window: 5,
            accel_sigma_mps2: 0.01,
            gyro_sigma_rps: 0.1_f64.to_radians(),
            gamma: 3e4,
        }
    }
}

/// The SHOE test with its settings and local gravity.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ShoeRule {
    config: ShoeConfig,
    gravity_mps2: f64,
}

impl ShoeRule {
    /// The test for local gravity `gravity_mps2`.
    pub fn new(config: ShoeConfig, gravity_mps2: f64) -> Self {
        Self {
            config,
            gravity_mps2,
        }
    }

    /// The statistic `T` of one window (see the module documentation).
    pub fn statistic(&self, accel: &WindowStats, gyro: &WindowStats) -> f64 {
        let n = accel.n as f64;
        let spread = |w: &WindowStats| w.std.iter().map(|s| s * s).sum::<f64>() * (n - 1.0) / n;
        let magnitude = accel.mean.iter().map(|m| m * m).sum::<f64>().sqrt();
        let t_accel = spread(accel) + (magnitude - self.gravity_mps2).powi(2);
        let t_gyro = spread(gyro) + gyro.mean.iter().map(|m| m * m).sum::<f64>();
        t_accel / self.config.accel_sigma_mps2.powi(2) + t_gyro / self.config.gyro_sigma_rps.powi(2)
    }

    /// The window's verdict.
    pub fn decide(&self, accel: &WindowStats, gyro: &WindowStats) -> Decision {
        Decision {
            rest: self.statistic(accel, gyro) <= self.config.gamma,
            mean_mps2: accel.mean,
            std_mps2: accel.std,
        }
    }
}
