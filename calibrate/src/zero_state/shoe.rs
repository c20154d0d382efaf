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
//!
//! **Adaptive threshold.** A fast walker's foot is never that still: on a public 200 Hz
//! recording of brisk walking (1.85 m/s) the quietest window of each step has `T` near 1e5, so
//! a fixed 3e4 finds almost no stance (docs/real-data.md). The threshold is therefore
//! `max(gamma, adaptive_factor * T_min)`, with `T_min` the smallest statistic of the last
//! `adaptive_horizon_s` (longer than a stride): every step's quietest moment and what is as
//! quiet within that factor count as stance, while a sensor standing still (T_min near the
//! noise, tens) keeps the fixed threshold.

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
    /// Threshold on the statistic (its floor, with the adaptive part).
    pub gamma: f64,
    /// Factor on the recent minimum statistic of the adaptive threshold (0: fixed `gamma`).
    pub adaptive_factor: f64,
    /// How far back the recent minimum looks, s (longer than a stride).
    pub adaptive_horizon_s: f64,
}

impl Default for ShoeConfig {
    /// OpenShoe's scales and threshold (sigma_a 0.01 m/s^2, sigma_g 0.1 deg/s, gamma 3e4) over
    /// windows of 5 samples (25 ms at 200 Hz: a tenth of the shortest stance), adaptive with a
    /// factor of 3 over the last 2 s.
    fn default() -> Self {
        Self {
            window: 5,
            accel_sigma_mps2: 0.01,
            gyro_sigma_rps: 0.1_f64.to_radians(),
            gamma: 3e4,
            adaptive_factor: 3.0,
            adaptive_horizon_s: 2.0,
        }
    }
}

/// Highest sample rate the recent-statistics ring is sized for, Hz.
const MAX_RATE_HZ: f64 = 8000.0;

/// The SHOE test with its settings, local gravity and the recent statistics of its adaptive
/// threshold (a ring allocated once).
#[derive(Debug, Clone)]
pub(crate) struct ShoeRule {
    config: ShoeConfig,
    gravity_mps2: f64,
    /// (window end time ns, statistic) of the recent windows, oldest first from `head`.
    recent: Vec<(u64, f64)>,
    head: usize,
    len: usize,
}

impl ShoeRule {
    /// The test for local gravity `gravity_mps2`.
    pub fn new(config: ShoeConfig, gravity_mps2: f64) -> Self {
        let capacity =
            (config.adaptive_horizon_s * MAX_RATE_HZ / config.window as f64).ceil() as usize + 1;
        Self {
            config,
            gravity_mps2,
            recent: vec![(0, 0.0); capacity],
            head: 0,
            len: 0,
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

    /// The window's verdict against the adaptive threshold, after adding it to the recent
    /// statistics.
    pub fn decide(&mut self, accel: &WindowStats, gyro: &WindowStats) -> Decision {
        let t = self.statistic(accel, gyro);
        let cap = self.recent.len();
        self.recent[self.head] = (accel.t_end_ns, t);
        self.head = (self.head + 1) % cap;
        self.len = (self.len + 1).min(cap);
        let horizon_ns = (self.config.adaptive_horizon_s * 1e9) as u64;
        let since = accel.t_end_ns.saturating_sub(horizon_ns);
        let recent_min = (0..self.len)
            .map(|i| self.recent[(self.head + cap - 1 - i) % cap])
            .take_while(|&(t_ns, _)| t_ns >= since)
            .map(|(_, t)| t)
            .fold(f64::INFINITY, f64::min);
        let threshold = self
            .config
            .gamma
            .max(self.config.adaptive_factor * recent_min);
        Decision {
            rest: t <= threshold,
            vibrating: false,
            mean_mps2: accel.mean,
            std_mps2: accel.std,
        }
    }

    /// Forgets the recent statistics (after a gap).
    pub fn clear(&mut self) {
        self.len = 0;
    }
}
