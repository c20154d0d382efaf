//! A generalised-likelihood-ratio rest test on accelerometer and gyroscope, in the spirit of
//! the SHOE detector (Skog et al., as in OpenShoe), but against the gravity vector and the
//! gyroscope bias *learned at rest* rather than gravity's direction taken from each window
//! (which tests only the magnitude and misses steady horizontal acceleration).
//!
//! Over a sliding window of the last `window_batches` batches (`N` samples), with references
//! `mu_c` (specific force at rest, gyroscope bias) and per-sample noise `sigma_c` of the six
//! channels `c`, and `rho_c` the learned excess scatter of means over white noise (1 for white
//! noise), and `delta_c` the tolerance on each reference (its drift between rests):
//!
//! ```text
//! T_mean    = sum_c (mean_c - mu_c)^2 / (rho_c sigma_c^2 / N + delta_c^2) ~ chi2(6) at rest
//! T_scatter = sum_c (W_c d_c / (n - 1) + B_c / rho_c) / sigma_c^2  ~ chi2(sum_c K d_c + K - 1)
//! ```
//!
//! where `W_c` is the window's within-batch sum of squares and `B_c` its between-batch part
//! (`sum_b n_b (mean_bc - mean_c)^2`): noise correlated by the sensor's own filter scatters the
//! batch means `rho_c` times more than white noise, which is not motion; it also leaves each
//! batch's within sum of squares fewer effective degrees of freedom `d_c` than `n - 1` (`K`
//! batches of `n` samples; `d_c = n - 1` for white noise, both learned at rest).
//!
//! - [`GlrtStatistic::Split`] (default): rest iff each is below its `1 - a/2` chi-squared
//!   quantile. The mean part (6 degrees of freedom) is what catches steady acceleration, turns
//!   and the low-frequency (wheel) part of vibration; the scatter part catches vibration.
//! - [`GlrtStatistic::Combined`]: SHOE's single sum `T_mean + T_scatter ~ chi2(6 N)` against
//!   its `1 - a` quantile, which dilutes the 6 mean degrees of freedom among `6 N`.
//!
//! **Accelerometer only** ([`super::DetectorKind::GlrtAccel`], for a sensor run without its
//! gyroscope, as the MPU-9250 at 4 kHz): the same test on the three accelerometer channels,
//! `chi2(3)` and `chi2(3 (N - 1))`. It still sees acceleration and tilt against the learned
//! gravity vector and vibration in the scatter, but not a rotation about gravity.
//!
//! `a` is the configured false-alarm rate per window at rest. The noise levels stay as learned
//! at start-up (a part's noise density does not drift); the gravity vector and gyroscope bias
//! are kept current as running means over rest batches (temperature moves them).

use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::learn::StaticReference;
use super::{BATCH_LEN, Decision};
use crate::window::WindowStats;

/// How the two parts of the test are combined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum GlrtStatistic {
    /// Mean and scatter tested separately, each at half the false-alarm rate.
    Split,
    /// One sum of both (SHOE).
    Combined,
}

/// Settings of the GLRT.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlrtConfig {
    /// Probability that a window at rest is called motion.
    pub false_alarm: f64,
    /// Window length in batches of [`BATCH_LEN`] samples (slides by one batch).
    pub window_batches: usize,
    /// How mean and scatter are combined.
    pub statistic: GlrtStatistic,
    /// How far the learned specific force at rest may be off between rests, m/s^2 (1-sigma per
    /// axis, added to the window mean's variance). 0 by default: the mean test is what
    /// separates slow cruising from rest, and any tolerance here costs that (measured in
    /// docs/detectors.md).
    pub accel_tolerance_mps2: f64,
    /// The same for the gyroscope bias, rad/s: an uncompensated gyroscope's bias moves by a few
    /// hundredths of a deg/s as the part warms up between rests, which is several times the
    /// window mean's own noise; a reference held tighter than that calls every later rest
    /// motion.
    pub gyro_tolerance_rps: f64,
}

impl Default for GlrtConfig {
    /// False-alarm rate 1e-2 per window, 25 batches (500 ms at 1 kHz), split statistic: the
    /// best trade-off measured on simulated drives (docs/detectors.md); reference tolerances of
    /// 0 for the accelerometer and 0.02 deg/s for the gyroscope.
    fn default() -> Self {
        Self {
            false_alarm: 1e-2,
            window_batches: 25,
            statistic: GlrtStatistic::Split,
            accel_tolerance_mps2: 0.0,
            gyro_tolerance_rps: 0.02_f64.to_radians(),
        }
    }
}

/// One batch's six channels: sample count, means and within-batch sums of squares.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct BatchSums {
    n: f64,
    mean: [f64; 6],
    ss: [f64; 6],
}

impl BatchSums {
    fn new(accel: &WindowStats, gyro: &WindowStats) -> Self {
        let n = accel.n as f64;
        let mut b = Self {
            n,
            ..Self::default()
        };
        for i in 0..3 {
            b.mean[i] = accel.mean[i];
            b.mean[i + 3] = gyro.mean[i];
            b.ss[i] = accel.std[i] * accel.std[i] * (n - 1.0);
            b.ss[i + 3] = gyro.std[i] * gyro.std[i] * (n - 1.0);
        }
        b
    }
}

/// The learned GLRT: references, noise, thresholds and the window ring.
#[derive(Debug, Clone)]
pub(crate) struct GlrtRule {
    statistic: GlrtStatistic,
    /// Channels tested: 6 (accelerometer and gyroscope) or 3 (accelerometer only).
    channels: usize,
    reference: [f64; 6],
    inv_var: [f64; 6],
    inv_rho: [f64; 6],
    /// Effective over nominal degrees of freedom of a batch's within sum of squares.
    dof_factor: [f64; 6],
    /// Variance of each reference's drift between rests (tolerance squared).
    drift_var: [f64; 6],
    mean_quantile: f64,
    scatter_quantile: f64,
    combined_quantile: f64,
    /// Ring of the last batches, allocated once.
    ring: Vec<BatchSums>,
    head: usize,
    filled: usize,
}

impl GlrtRule {
    /// The test from the start-up reference; `ring` (capacity at least `window_batches`) becomes
    /// the window, so that learning allocates nothing. `accel_only` leaves the gyroscope out.
    pub fn new(
        r: &StaticReference,
        config: &GlrtConfig,
        mut ring: Vec<BatchSums>,
        accel_only: bool,
    ) -> Self {
        let channels = if accel_only { 3 } else { 6 };
        let dof = channels as f64;
        let k = config.window_batches;
        let n = (k * BATCH_LEN) as f64;
        let quantile =
            |dof: f64, p: f64| ChiSquared::new(dof).expect("dof > 0").inverse_cdf(1.0 - p);
        let a = config.false_alarm;
        let mut reference = [0.0; 6];
        let mut inv_var = [0.0; 6];
        let mut inv_rho = [0.0; 6];
        let mut drift_var = [0.0; 6];
        let mut dof_factor = [1.0; 6];
        let nominal = (BATCH_LEN - 1) as f64;
        for i in 0..3 {
            dof_factor[i] = r.accel_batch_dof[i] / nominal;
            dof_factor[i + 3] = r.gyro_batch_dof[i] / nominal;
            drift_var[i] = config.accel_tolerance_mps2.powi(2);
            drift_var[i + 3] = config.gyro_tolerance_rps.powi(2);
            reference[i] = r.accel_mean_mps2[i];
            reference[i + 3] = r.gyro_mean_rps[i];
            inv_var[i] = 1.0 / (r.accel_sigma_mps2[i] * r.accel_sigma_mps2[i]);
            inv_var[i + 3] = 1.0 / (r.gyro_sigma_rps[i] * r.gyro_sigma_rps[i]);
            inv_rho[i] = 1.0 / r.accel_correlation[i];
            inv_rho[i + 3] = 1.0 / r.gyro_correlation[i];
        }
        Self {
            statistic: config.statistic,
            channels,
            reference,
            inv_var,
            inv_rho,
            dof_factor,
            drift_var,
            mean_quantile: quantile(dof, a / 2.0),
            scatter_quantile: quantile(
                dof_factor[..channels]
                    .iter()
                    .map(|f| k as f64 * f * nominal + k as f64 - 1.0)
                    .sum(),
                a / 2.0,
            ),
            combined_quantile: quantile(dof * n, a),
            ring: {
                ring.clear();
                ring.resize(k, BatchSums::default());
                ring
            },
            head: 0,
            filled: 0,
        }
    }

    /// Adds the batch to the window and decides; not at rest until the window is full.
    pub fn decide(&mut self, accel: &WindowStats, gyro: &WindowStats) -> Decision {
        let k = self.ring.len();
        self.ring[self.head] = BatchSums::new(accel, gyro);
        self.head = (self.head + 1) % k;
        self.filled = (self.filled + 1).min(k);

        // Window statistics: pooled means, and within-batch plus between-batch sums of squares.
        let n: f64 = self.ring[..self.filled].iter().map(|b| b.n).sum();
        let mut mean = [0.0; 6];
        for b in &self.ring[..self.filled] {
            for (m, bm) in mean.iter_mut().zip(&b.mean) {
                *m += b.n * bm / n;
            }
        }
        let (mut within, mut between) = ([0.0; 6], [0.0; 6]);
        for b in &self.ring[..self.filled] {
            for c in 0..6 {
                let d = b.mean[c] - mean[c];
                within[c] += b.ss[c];
                between[c] += b.n * d * d;
            }
        }
        let mut t_mean = 0.0;
        let mut t_scatter = 0.0;
        for c in 0..self.channels {
            let d = mean[c] - self.reference[c];
            // The window mean's variance about the reference: its own noise plus the
            // reference's drift since it was learned.
            let var = 1.0 / (n * self.inv_var[c] * self.inv_rho[c]) + self.drift_var[c];
            t_mean += d * d / var;
            t_scatter +=
                (within[c] * self.dof_factor[c] + between[c] * self.inv_rho[c]) * self.inv_var[c];
        }
        let quiet = match self.statistic {
            GlrtStatistic::Split => {
                t_mean <= self.mean_quantile && t_scatter <= self.scatter_quantile
            }
            GlrtStatistic::Combined => t_mean + t_scatter <= self.combined_quantile,
        };
        Decision {
            rest: quiet && self.filled == k,
            mean_mps2: [mean[0], mean[1], mean[2]],
            std_mps2: std::array::from_fn(|i| ((within[i] + between[i]) / (n - 1.0)).sqrt()),
        }
    }

    /// Keeps gravity and the gyroscope bias current with a rest batch (running-mean gain).
    pub fn update(&mut self, accel: &WindowStats, gyro: &WindowStats, gain: f64) {
        for i in 0..3 {
            self.reference[i] += gain * (accel.mean[i] - self.reference[i]);
            self.reference[i + 3] += gain * (gyro.mean[i] - self.reference[i + 3]);
        }
    }

    /// Gives the window's storage back (for the next session).
    pub fn into_ring(self) -> Vec<BatchSums> {
        self.ring
    }

    /// Empties the window (after a gap).
    pub fn clear_window(&mut self) {
        self.head = 0;
        self.filled = 0;
    }

    /// The gravity reference, m/s^2.
    pub fn accel_mean_mps2(&self) -> [f64; 3] {
        [self.reference[0], self.reference[1], self.reference[2]]
    }

    /// The gyroscope bias reference, rad/s.
    pub fn gyro_mean_rps(&self) -> [f64; 3] {
        [self.reference[3], self.reference[4], self.reference[5]]
    }
}
