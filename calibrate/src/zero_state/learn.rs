//! The static reference both detectors learn from the start-up rest: per-channel means and
//! noise of the accelerometer (m/s^2) and gyroscope (rad/s), sensor frame, from whole batches.
//!
//! The learner assumes the sensor is still while it learns and checks what it can: the mean
//! specific force must have the magnitude of local gravity (within `max_gravity_error`), and the
//! batch means must scatter no more than `max_correlation` times what the within-batch noise
//! predicts (`var(batch mean) n / sigma^2`, 1 for white noise; a moving sensor's changing
//! acceleration, turn rate and the wheel-frequency part of its vibration raise it). When a check
//! fails, learning starts again from the next batch. A sensor that cruises steadily on a smooth
//! floor passes both checks: no accelerometer or gyroscope test can tell that from rest.

use crate::window::WindowStats;

/// Quantization of the MPU-9250's finest accelerometer range (+-2 g: 1/16384 g) as a standard
/// deviation, `LSB / sqrt(12)`, m/s^2: the floor of a learned noise level (an ideal, noiseless
/// simulated part would otherwise learn 0 and divide by it).
pub const ACCEL_SIGMA_FLOOR_MPS2: f64 =
    ipc_types::units::STANDARD_GRAVITY_MPS2 / 16384.0 / 3.464_101_615_137_754_6;

/// Quantization of the finest gyroscope range (+-250 deg/s: 1/131 deg/s) as a standard
/// deviation, rad/s.
pub const GYRO_SIGMA_FLOOR_RPS: f64 =
    (1.0 / 131.0) * (std::f64::consts::PI / 180.0) / 3.464_101_615_137_754_6;

/// Settings of the start-up learning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnConfig {
    /// Length of the initial static interval, s.
    pub duration_s: f64,
    /// Local gravity, m/s^2 (from the calibration file).
    pub gravity_mps2: f64,
    /// Largest relative difference between the learned specific force's magnitude and local
    /// gravity.
    pub max_gravity_error: f64,
    /// Largest ratio between the scatter of the batch means and what the within-batch noise
    /// predicts (per channel).
    pub max_correlation: f64,
}

impl LearnConfig {
    /// Defaults: 5 s, 5% of gravity (a calibrated sensor is within 0.5%), correlation 3 (white
    /// noise gives 1 +- 0.1 over 250 batches; low-pass filtered sensor noise a little more).
    pub fn new(gravity_mps2: f64) -> Self {
        Self {
            duration_s: 5.0,
            gravity_mps2,
            max_gravity_error: 0.05,
            max_correlation: 3.0,
        }
    }
}

/// What the start-up rest taught: the references and noise of the six channels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticReference {
    /// Mean specific force, m/s^2, sensor frame (gravity's reaction at the start-up attitude).
    pub accel_mean_mps2: [f64; 3],
    /// Mean angular rate, rad/s (the gyroscope bias left after calibration).
    pub gyro_mean_rps: [f64; 3],
    /// Per-sample noise (pooled within-batch standard deviation), m/s^2.
    pub accel_sigma_mps2: [f64; 3],
    /// Per-sample noise, rad/s.
    pub gyro_sigma_rps: [f64; 3],
    /// `var(batch mean) n / sigma^2` per accelerometer axis, at least 1: how much more a mean
    /// scatters than white noise of `sigma` would make it (sample correlation).
    pub accel_correlation: [f64; 3],
    /// The same for the gyroscope axes.
    pub gyro_correlation: [f64; 3],
    /// Mean of the batch means' magnitudes, m/s^2.
    pub magnitude_mps2: f64,
    /// Standard deviation of the batch means' magnitudes, m/s^2.
    pub magnitude_std_mps2: f64,
    /// Number of batches learned from.
    pub batches: usize,
    /// Length of the learned interval, s.
    pub duration_s: f64,
}

/// Why a learning attempt was discarded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LearnRejection {
    /// The mean specific force's magnitude is not local gravity (m/s^2).
    Gravity {
        /// Learned magnitude, m/s^2.
        magnitude_mps2: f64,
    },
    /// Batch means scatter more than noise explains on channel `channel` (0-2 accelerometer
    /// x, y, z; 3-5 gyroscope x, y, z).
    Unsteady {
        /// The channel.
        channel: usize,
        /// Its ratio `var(batch mean) n / sigma^2`.
        ratio: f64,
    },
    /// A gap in the data interrupted learning.
    Interrupted,
}

/// Running sums of one channel over the learning interval.
#[derive(Debug, Clone, Copy, Default)]
struct ChannelSums {
    /// Welford mean and M2 of the batch means.
    mean_of_means: f64,
    m2_of_means: f64,
    /// Sum of within-batch squared deviations and of their degrees of freedom.
    within_ss: f64,
    within_dof: f64,
}

/// Accumulates whole batches of the start-up rest into a [`StaticReference`].
#[derive(Debug, Clone)]
pub struct StaticLearner {
    config: LearnConfig,
    channels: [ChannelSums; 6],
    magnitude_mean: f64,
    magnitude_m2: f64,
    batches: usize,
    batch_len: usize,
    t_start_ns: u64,
    restarts: usize,
    last_rejection: Option<LearnRejection>,
}

impl StaticLearner {
    /// A learner with `config`.
    pub fn new(config: LearnConfig) -> Self {
        Self {
            config,
            channels: [ChannelSums::default(); 6],
            magnitude_mean: 0.0,
            magnitude_m2: 0.0,
            batches: 0,
            batch_len: 0,
            t_start_ns: 0,
            restarts: 0,
            last_rejection: None,
        }
    }

    /// Discards what was accumulated; `why` is recorded when an attempt was under way.
    pub fn restart(&mut self, why: LearnRejection) {
        if self.batches > 0 {
            self.restarts += 1;
            self.last_rejection = Some(why);
        }
        let config = self.config;
        let (restarts, last) = (self.restarts, self.last_rejection);
        *self = Self::new(config);
        self.restarts = restarts;
        self.last_rejection = last;
    }

    /// How many learning attempts were discarded, and why the last one was.
    pub fn rejections(&self) -> (usize, Option<LearnRejection>) {
        (self.restarts, self.last_rejection)
    }

    /// Adds one batch (accelerometer in m/s^2, gyroscope in rad/s, same samples); returns the
    /// reference once the batches cover the learning interval and pass the checks (a failed
    /// check restarts learning).
    pub fn push(&mut self, accel: &WindowStats, gyro: &WindowStats) -> Option<StaticReference> {
        if self.batches == 0 {
            self.t_start_ns = accel.t_start_ns;
            self.batch_len = accel.n;
        }
        self.batches += 1;
        let k = self.batches as f64;
        let n = accel.n as f64;
        for (c, sums) in self.channels.iter_mut().enumerate() {
            let (mean, std) = if c < 3 {
                (accel.mean[c], accel.std[c])
            } else {
                (gyro.mean[c - 3], gyro.std[c - 3])
            };
            let delta = mean - sums.mean_of_means;
            sums.mean_of_means += delta / k;
            sums.m2_of_means += delta * (mean - sums.mean_of_means);
            sums.within_ss += std * std * (n - 1.0);
            sums.within_dof += n - 1.0;
        }
        let magnitude = norm(&accel.mean);
        let delta = magnitude - self.magnitude_mean;
        self.magnitude_mean += delta / k;
        self.magnitude_m2 += delta * (magnitude - self.magnitude_mean);

        // The interval covered: first to last sample plus one sample period.
        let period_ns = (accel.t_end_ns - accel.t_start_ns) as f64 / (n - 1.0).max(1.0);
        let covered_s = ((accel.t_end_ns - self.t_start_ns) as f64 + period_ns) * 1e-9;
        if covered_s < self.config.duration_s || self.batches < 2 {
            return None;
        }
        match self.finish(covered_s) {
            Ok(reference) => Some(reference),
            Err(why) => {
                self.restart(why);
                None
            }
        }
    }

    fn finish(&self, covered_s: f64) -> Result<StaticReference, LearnRejection> {
        let g = self.config.gravity_mps2;
        if (self.magnitude_mean - g).abs() > self.config.max_gravity_error * g {
            return Err(LearnRejection::Gravity {
                magnitude_mps2: self.magnitude_mean,
            });
        }
        let k = self.batches as f64;
        let n = self.batch_len as f64;
        let mut mean = [0.0; 6];
        let mut sigma = [0.0; 6];
        let mut correlation = [1.0; 6];
        for (c, sums) in self.channels.iter().enumerate() {
            let floor = if c < 3 {
                ACCEL_SIGMA_FLOOR_MPS2
            } else {
                GYRO_SIGMA_FLOOR_RPS
            };
            mean[c] = sums.mean_of_means;
            sigma[c] = (sums.within_ss / sums.within_dof).sqrt().max(floor);
            let ratio = sums.m2_of_means / (k - 1.0) * n / (sigma[c] * sigma[c]);
            if ratio > self.config.max_correlation {
                return Err(LearnRejection::Unsteady { channel: c, ratio });
            }
            correlation[c] = ratio.max(1.0);
        }
        let part = |a: &[f64; 6], off: usize| [a[off], a[off + 1], a[off + 2]];
        Ok(StaticReference {
            accel_mean_mps2: part(&mean, 0),
            gyro_mean_rps: part(&mean, 3),
            accel_sigma_mps2: part(&sigma, 0),
            gyro_sigma_rps: part(&sigma, 3),
            accel_correlation: part(&correlation, 0),
            gyro_correlation: part(&correlation, 3),
            magnitude_mps2: self.magnitude_mean,
            magnitude_std_mps2: (self.magnitude_m2 / (k - 1.0)).sqrt(),
            batches: self.batches,
            duration_s: covered_s,
        })
    }
}

/// Euclidean norm of a 3-vector.
pub(crate) fn norm(v: &[f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}
