//! The static reference both detectors learn from the first rest in the data: per-channel means
//! and noise of the accelerometer (m/s^2) and gyroscope (rad/s), sensor frame, from whole
//! batches.
//!
//! The learner slides a window of the last `duration_s` seconds of batches over the stream and
//! takes the first window that passes its checks, so a recording that starts in motion is
//! learned from its first rest of that length. The checks:
//! - the mean specific force must have the magnitude of local gravity (within
//!   `max_gravity_error`: 5 % for a calibrated accelerometer, [`UNCALIBRATED_GRAVITY_ERROR`]
//!   for one without a calibration, `--max-gravity-error` either way);
//! - the gyroscope's mean rate must lie within a MEMS part's zero-rate offset on every axis
//!   ([`MAX_GYRO_OFFSET_DPS`], `--max-gyro-offset-dps`): a faster steady rate is a turn;
//! - the batch means must be *steady*. Their scatter against what the within-batch noise
//!   predicts, `R = var(batch mean) n / sigma^2`, is 1 for white noise. A real sensor's own
//!   low-pass filter (the MPU-9250's DLPF, other IMUs' internal filters) correlates successive
//!   samples and raises `R` well above 1 at rest: that alone is not motion. What motion adds is
//!   variation that is slow against a batch, so successive batch means follow each other. A
//!   channel passes when `R <= max_correlation` (white-like), or when the von Neumann ratio of
//!   its batch means, `V = sum (m_i+1 - m_i)^2 / (2 sum (m_i - m)^2)` (1 for independent means,
//!   `1 - r` for means with lag-1 correlation `r`, near 0 for a trend), is at least
//!   `1 - 3.09 / sqrt(k) - max_batch_correlation` (`k` batches; 3.09 sigma is a 1e-3 false
//!   alarm for independent means, `max_batch_correlation` allows noise correlated across batch
//!   boundaries). With the default 0.35 that limit is at most 0 for fewer than 23 batches: a
//!   window that short (half a second below 920 Hz) passes whatever its `R` (docs/detectors.md,
//!   "What a short learning cannot refuse").
//!
//!   Before either, no batch mean may lie more than [`MAX_OUTLIER_SIGMA`] robust standard
//!   deviations (1.4826 times the median absolute deviation, at least the white-noise scatter
//!   `sigma / sqrt(n)`) from their median: one batch of a turn is not noise, however the rest
//!   of the window looks.
//!
//! The learned `correlation` of a channel (how much more a window mean scatters than white
//! noise of `sigma` would make it, used by the detectors' thresholds) is `R` for a white-like
//! channel and `R (1 + 2 max(0, 1 - V))` otherwise (the lag-1 correlation of the batch means
//! carried to the longer window). Correlated samples also make a batch's within-batch sum of
//! squares scatter more than `chi2(n - 1)`: its effective degrees of freedom, `2 E[ss]^2 /
//! var(ss)` over the learned batches (at most `n - 1`), go with the reference for the GLRT's
//! scatter test. A sensor that cruises steadily on a smooth floor, or turns at a constant
//! rate about gravity slower than [`MAX_GYRO_OFFSET_DPS`], passes every check: no
//! accelerometer or gyroscope test can tell that from rest.

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

/// Highest sample rate the learning window is sized for, Hz (the MPU-9250's gyro at 8 kHz).
pub const MAX_RATE_HZ: f64 = 8000.0;

/// Largest relative difference between a rest's specific force and local gravity that a
/// calibrated accelerometer shows: 2 % (the corpus's factory-calibrated parts read 0.1-1.3 % off
/// with no calibration of ours; a fitted part is within 0.5 %). Beyond it the calibration stage
/// flags its samples `GRAVITY_OFF`.
pub const CALIBRATED_GRAVITY_ERROR: f64 = 0.02;

/// Largest relative difference between a rest's specific force and local gravity that an
/// accelerometer without a calibration is learned with: a sensitivity error of up to 4 % (the
/// MPU-6050 and MPU-9250 datasheets give +-3 %; cheap MPU-6050 boards read |g| 2-4 % low) and a
/// zero-g offset of up to 0.2 g per axis (the thesis's uncalibrated MPU-9250 read 0.1-0.2 g
/// off), whose vector, `0.2 sqrt(3)` = 0.35 g, may lie along gravity: 39 %. (With 0.2 g on one
/// axis only, 24 %, a corpus car's part that reads 6 % off on its own, f1tenth-ds5, given 4 %
/// and 0.15 g per axis more by `tools/real-data/perturb.py`, read 20-31 % off while it drove
/// and was learned only at 6.4 s instead of 3.3 s.)
pub const UNCALIBRATED_GRAVITY_ERROR: f64 = 0.39;

/// Standard normal quantile of the steadiness test's false alarm (1e-3, one-sided).
const STEADY_Z: f64 = 3.09;

/// Largest distance of a batch mean from the window's median, robust standard deviations.
pub const MAX_OUTLIER_SIGMA: f64 = 6.0;

/// Settings of the learning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnConfig {
    /// Length of the static interval learned from, s.
    pub duration_s: f64,
    /// A shorter first interval, s, when the rule should not wait for `duration_s` of rest:
    /// the rule is built from the first window of this length that passes, and built again
    /// from the first window of `duration_s` that passes and is much quieter
    /// (`super::ZeroStateDetector`, "learning again"). `None`: `duration_s` alone.
    pub first_s: Option<f64>,
    /// Local gravity, m/s^2 (from the calibration file).
    pub gravity_mps2: f64,
    /// Largest relative difference between the learned specific force's magnitude and local
    /// gravity.
    pub max_gravity_error: f64,
    /// Largest ratio `R` a channel passes with unconditionally (white-like noise); above it,
    /// the channel must pass the von Neumann steadiness test.
    pub max_correlation: f64,
    /// Lag-1 correlation of successive batch means that steady noise may have (a filter whose
    /// correlation time is a good part of a batch: an MPU-9250 at 1 kHz with its 20 Hz DLPF
    /// gives about 0.3).
    pub max_batch_correlation: f64,
    /// Largest ratio of a channel's learned per-sample noise to the sensor's measured white
    /// noise (the calibration file's `[noise]` table, when it has one for this rate): a window
    /// that noisy is a vehicle cruising with its vibration, not a rest.
    pub max_noise_ratio: f64,
    /// Largest standard deviation of the accelerometer's samples (any axis, over the whole
    /// learning window about its mean) a rest shows, m/s^2, whatever the sensor: `None` for no
    /// such ceiling (see [`REST_ACCEL_SIGMA_MPS2`]).
    pub max_accel_sigma_mps2: Option<f64>,
    /// Largest magnitude of the gyroscope's mean rate on any axis a rest may show, rad/s
    /// (default [`MAX_GYRO_OFFSET_DPS`]).
    pub max_gyro_offset_rps: f64,
}

/// The largest zero-rate offset of a cheap MEMS gyroscope, deg/s: the LSM9DS1's typical
/// zero-rate level at its +-2000 deg/s range (ST DocID025715 rev 3, table 3, `G_TyOff`),
/// above the MPU-6050's initial tolerance of +-20 deg/s (PS-MPU-6000A-00 rev 3.4, table 6.1)
/// and the MPU-9250's +-5 deg/s (PS-MPU-9250A-01 rev 1.1, table 3.1). A window whose mean
/// rate lies beyond it on some axis turns steadily (a robot that starts driving in a curve:
/// the F1TENTH car of docs/real-data.md learned 44-53 deg/s about up that way), which the
/// steadiness tests cannot see; taken for rest, the turn became the stage's gyroscope bias.
pub const MAX_GYRO_OFFSET_DPS: f64 = 30.0;

/// A ceiling on the per-sample accelerometer noise of a rest whatever the part, m/s^2 (15 mg):
/// above the white noise of the project's and the corpus's parts at any rate they run at (a
/// datasheet density times the root of the sample rate, the most a sampled white noise can
/// carry: the MPU-9250's and MPU-6500's 300 ug/sqrt(Hz) at 1 kHz, 9.5 mg; the MPU-6050's
/// 400 ug/sqrt(Hz) at 1 kHz, 12.6 mg; the LIS331DLH's 218 ug/sqrt(Hz) at 1 kHz, 6.9 mg), and
/// below a walker's hand, whose bounce scatters 0.2-0.65 m/s^2 per sample within 0.2 s (10th
/// to 90th percentile on the simulated hand-held walk; the Tyrex phones' walks the same or
/// more) and more over the half second a robot's detector learns from. A window that shakes more is no rest, however steady its batch means
/// look: a steady turn on a walk has steady gyro means, and its bounce makes the white-noise
/// scatter test too wide to see the turn. A vehicle idling vibrates by 50-90 mg: the ceiling
/// is for a hand's profile only (`odometry::profile`), not a vehicle's.
pub const REST_ACCEL_SIGMA_MPS2: f64 = 0.15;

impl LearnConfig {
    /// Defaults: 5 s (at least two batches at any rate), 5% of gravity (a calibrated sensor is
    /// within 0.5%), correlation 3 (white noise gives 1 +- 0.1 over 250 batches), batch-mean
    /// correlation 0.35, noise ratio 1.5.
    pub fn new(gravity_mps2: f64) -> Self {
        Self {
            duration_s: 5.0,
            first_s: None,
            gravity_mps2,
            max_gravity_error: 0.05,
            max_correlation: 3.0,
            max_batch_correlation: 0.35,
            max_noise_ratio: 1.5,
            max_accel_sigma_mps2: None,
            max_gyro_offset_rps: MAX_GYRO_OFFSET_DPS.to_radians(),
        }
    }

    /// The interval the rule is first built from, s: `first_s` when shorter than
    /// `duration_s`, else `duration_s`.
    pub fn first_window_s(&self) -> f64 {
        self.first_s
            .map_or(self.duration_s, |f| f.min(self.duration_s))
    }

    /// Whether the rule is built again from a longer rest after its first window.
    pub fn learns_again(&self) -> bool {
        self.first_window_s() < self.duration_s
    }

    /// This configuration for its first window alone.
    pub fn first(self) -> Self {
        Self {
            duration_s: self.first_window_s(),
            first_s: None,
            ..self
        }
    }
}

/// What the rest taught: the references and noise of the six channels.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StaticReference {
    /// Mean specific force, m/s^2, sensor frame (gravity's reaction at the rest's attitude).
    pub accel_mean_mps2: [f64; 3],
    /// Mean angular rate, rad/s (the gyroscope bias left after calibration).
    pub gyro_mean_rps: [f64; 3],
    /// Per-sample noise (pooled within-batch standard deviation), m/s^2.
    pub accel_sigma_mps2: [f64; 3],
    /// Per-sample noise, rad/s.
    pub gyro_sigma_rps: [f64; 3],
    /// How much more a window mean scatters than white noise of `sigma` would make it, per
    /// accelerometer axis, at least 1 (see the module documentation).
    pub accel_correlation: [f64; 3],
    /// The same for the gyroscope axes.
    pub gyro_correlation: [f64; 3],
    /// Effective degrees of freedom of one batch's within-batch sum of squares per
    /// accelerometer axis (`n - 1` for white noise, fewer for correlated samples).
    pub accel_batch_dof: [f64; 3],
    /// The same for the gyroscope axes.
    pub gyro_batch_dof: [f64; 3],
    /// Mean of the batch means' magnitudes, m/s^2.
    pub magnitude_mps2: f64,
    /// Standard deviation of the batch means' magnitudes, m/s^2.
    pub magnitude_std_mps2: f64,
    /// Number of batches learned from.
    pub batches: usize,
    /// Length of the learned interval, s.
    pub duration_s: f64,
    /// Time of the learned interval's first sample, ns.
    pub t_start_ns: u64,
}

impl StaticReference {
    /// The accelerometer's per-sample noise, summed over the axes, (m/s^2)^2.
    pub fn accel_noise_var(&self) -> f64 {
        self.accel_sigma_mps2.iter().map(|s| s * s).sum()
    }

    /// The stream's sample rate over the learned interval, Hz.
    pub fn rate_hz(&self) -> f64 {
        (self.batches * super::BATCH_LEN) as f64 / self.duration_s
    }
}

/// Why a learning window was refused.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LearnRejection {
    /// The mean specific force's magnitude is not local gravity (m/s^2).
    Gravity {
        /// Learned magnitude, m/s^2.
        magnitude_mps2: f64,
        /// Local gravity, m/s^2.
        gravity_mps2: f64,
        /// The largest relative difference allowed.
        limit: f64,
    },
    /// The batch means of channel `channel` (0-2 accelerometer x, y, z; 3-5 gyroscope x, y,
    /// z) scatter more than white noise and follow each other as motion does.
    Unsteady {
        /// The channel.
        channel: usize,
        /// Its ratio `R = var(batch mean) n / sigma^2`.
        ratio: f64,
        /// Its batch means' von Neumann ratio `V`.
        von_neumann: f64,
        /// The smallest `V` steady noise passes with.
        limit: f64,
    },
    /// A batch mean of channel `channel` lies far from the others (a jolt, a short turn).
    Outlier {
        /// The channel.
        channel: usize,
        /// Its distance from the median, robust standard deviations.
        sigmas: f64,
    },
    /// Channel `channel` is noisier than the sensor's measured noise allows for a rest.
    TooNoisy {
        /// The channel.
        channel: usize,
        /// Its learned noise over the measured noise.
        ratio: f64,
        /// The largest ratio allowed.
        limit: f64,
    },
    /// The accelerometer's axis `channel` shakes more than a rest does
    /// ([`LearnConfig::max_accel_sigma_mps2`]).
    Shaking {
        /// The axis (0-2: x, y, z).
        channel: usize,
        /// Its samples' standard deviation over the window, m/s^2.
        sigma_mps2: f64,
        /// The largest allowed, m/s^2.
        limit_mps2: f64,
    },
    /// The gyroscope's axis `channel` turns steadily faster than a part's zero-rate offset
    /// ([`LearnConfig::max_gyro_offset_rps`]).
    Turning {
        /// The axis (0-2: x, y, z).
        channel: usize,
        /// Its mean rate over the window, deg/s.
        rate_dps: f64,
        /// The largest allowed, deg/s.
        limit_dps: f64,
    },
    /// A gap in the data interrupted learning.
    Interrupted,
}

impl std::fmt::Display for LearnRejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        const CHANNELS: [&str; 6] = [
            "accel x", "accel y", "accel z", "gyro x", "gyro y", "gyro z",
        ];
        match self {
            Self::Gravity {
                magnitude_mps2,
                gravity_mps2,
                limit,
            } => write!(
                f,
                "mean specific force {magnitude_mps2:.4} m/s^2 is not local gravity \
                 ({gravity_mps2} m/s^2, {:+.1} % off, at most {:.0} %: --max-gravity-error \
                 widens that)",
                100.0 * (magnitude_mps2 / gravity_mps2 - 1.0),
                100.0 * limit
            ),
            Self::Unsteady {
                channel,
                ratio,
                von_neumann,
                limit,
            } => write!(
                f,
                "{} not steady: its batch means scatter {ratio:.1}x what white noise gives and \
                 follow each other (von Neumann ratio {von_neumann:.2}, steady noise >= \
                 {limit:.2})",
                CHANNELS[*channel]
            ),
            Self::Outlier { channel, sigmas } => write!(
                f,
                "{} not steady: a batch mean lies {sigmas:.1} robust standard deviations from \
                 the others (at most {MAX_OUTLIER_SIGMA})",
                CHANNELS[*channel]
            ),
            Self::TooNoisy {
                channel,
                ratio,
                limit,
            } => write!(
                f,
                "{} is {ratio:.2}x as noisy as the sensor's measured noise (a rest is at most \
                 {limit}x): vibration of a moving vehicle",
                CHANNELS[*channel]
            ),
            Self::Shaking {
                channel,
                sigma_mps2,
                limit_mps2,
            } => write!(
                f,
                "{} scatters {sigma_mps2:.3} m/s^2 about its mean (a rest at most {limit_mps2} \
                 m/s^2): the sensor is carried, not at rest",
                CHANNELS[*channel]
            ),
            Self::Turning {
                channel,
                rate_dps,
                limit_dps,
            } => write!(
                f,
                "{} reads {rate_dps:+.1} deg/s on average, beyond a MEMS gyroscope's zero-rate \
                 offset (at most {limit_dps:.0} deg/s: --max-gyro-offset-dps widens that): a \
                 steady turn, not a rest",
                CHANNELS[*channel + 3]
            ),
            Self::Interrupted => write!(f, "a gap in the data interrupted learning"),
        }
    }
}

/// One batch as the learner keeps it.
#[derive(Debug, Clone, Copy, Default)]
struct Batch {
    t_start_ns: u64,
    t_end_ns: u64,
    n: usize,
    mean: [f64; 6],
    /// Within-batch sums of squared deviations.
    ss: [f64; 6],
}

/// Slides a window of whole batches over the stream and learns a [`StaticReference`] from the
/// first one that passes the checks (see the module documentation). Its ring is allocated once,
/// in [`StaticLearner::new`], for [`MAX_RATE_HZ`].
#[derive(Debug, Clone)]
pub struct StaticLearner {
    config: LearnConfig,
    /// The sensor's measured noise, the ceiling's reference.
    noise: Option<super::NoiseFloor>,
    ring: Vec<Batch>,
    /// Scratch for the medians, as long as the ring.
    scratch: Vec<f64>,
    head: usize,
    len: usize,
    refused: usize,
    last_rejection: Option<LearnRejection>,
}

impl StaticLearner {
    /// A learner with `config`; with the sensor's measured `noise`, windows noisier than
    /// `config.max_noise_ratio` times it are refused.
    pub fn new(config: LearnConfig, noise: Option<super::NoiseFloor>) -> Self {
        let capacity = (config.duration_s * MAX_RATE_HZ / super::BATCH_LEN as f64).ceil() as usize;
        Self {
            config,
            noise,
            ring: vec![Batch::default(); capacity.max(2) + 1],
            scratch: vec![0.0; capacity.max(2) + 1],
            head: 0,
            len: 0,
            refused: 0,
            last_rejection: None,
        }
    }

    /// Discards the window (a gap in the data, the end of a stream). Recorded as the reason
    /// only when batches were held and no window was refused for a reason of its own.
    pub fn restart(&mut self) {
        if self.len > 0 && self.last_rejection.is_none() {
            self.last_rejection = Some(LearnRejection::Interrupted);
        }
        self.len = 0;
    }

    /// Forgets everything (a new sensor session), keeping the ring's storage.
    pub fn clear(&mut self) {
        self.len = 0;
        self.refused = 0;
        self.last_rejection = None;
    }

    /// How many learning windows were refused, and why the last one was.
    pub fn rejections(&self) -> (usize, Option<LearnRejection>) {
        (self.refused, self.last_rejection)
    }

    /// The window's batches, oldest first: each one's sample count, per-channel means and
    /// within-batch sums of squares (accelerometer x, y, z then gyroscope x, y, z), the parts
    /// of the GLRT's batches.
    pub(crate) fn window(&self) -> impl Iterator<Item = (f64, [f64; 6], [f64; 6])> + '_ {
        (0..self.len).map(|i| {
            let b = self.batch(i);
            (b.n as f64, b.mean, b.ss)
        })
    }

    /// The `i`-th batch of the window, oldest first.
    fn batch(&self, i: usize) -> &Batch {
        let cap = self.ring.len();
        &self.ring[(self.head + cap - self.len + i) % cap]
    }

    /// Adds one batch (accelerometer in m/s^2, gyroscope in rad/s, same samples); returns the
    /// reference once the window covers the learning interval and passes the checks.
    pub fn push(&mut self, accel: &WindowStats, gyro: &WindowStats) -> Option<StaticReference> {
        let n = accel.n as f64;
        let mut b = Batch {
            t_start_ns: accel.t_start_ns,
            t_end_ns: accel.t_end_ns,
            n: accel.n,
            ..Batch::default()
        };
        for c in 0..3 {
            b.mean[c] = accel.mean[c];
            b.mean[c + 3] = gyro.mean[c];
            b.ss[c] = accel.std[c] * accel.std[c] * (n - 1.0);
            b.ss[c + 3] = gyro.std[c] * gyro.std[c] * (n - 1.0);
        }
        let cap = self.ring.len();
        self.ring[self.head] = b;
        self.head = (self.head + 1) % cap;
        self.len = (self.len + 1).min(cap);
        // Keep the shortest suffix of batches that covers the learning interval.
        while self.len > 2 && self.covered_s(1) >= self.config.duration_s {
            self.len -= 1;
        }
        if self.len < 2 || self.covered_s(0) < self.config.duration_s {
            return None;
        }
        match self.finish() {
            Ok(reference) => Some(reference),
            Err(why) => {
                self.refused += 1;
                self.last_rejection = Some(why);
                None
            }
        }
    }

    /// The interval the window covers without its `skip` oldest batches: first to last sample
    /// plus one sample period, s.
    fn covered_s(&self, skip: usize) -> f64 {
        let first = self.batch(skip);
        let last = self.batch(self.len - 1);
        let period_ns = (last.t_end_ns - last.t_start_ns) as f64 / (last.n as f64 - 1.0).max(1.0);
        ((last.t_end_ns - first.t_start_ns) as f64 + period_ns) * 1e-9
    }

    /// The largest distance of channel `c`'s batch means from their median, in robust
    /// standard deviations (1.4826 MAD, at least `white_scatter`).
    fn outlier_sigmas(&mut self, c: usize, white_scatter: f64) -> f64 {
        let k = self.len;
        for i in 0..k {
            self.scratch[i] = self.batch(i).mean[c];
        }
        let values = &mut self.scratch[..k];
        let median = *values.select_nth_unstable_by(k / 2, f64::total_cmp).1;
        for v in values.iter_mut() {
            *v = (*v - median).abs();
        }
        let largest = values.iter().copied().fold(0.0, f64::max);
        let mad = *values.select_nth_unstable_by(k / 2, f64::total_cmp).1;
        largest / (1.4826 * mad).max(white_scatter)
    }

    fn finish(&mut self) -> Result<StaticReference, LearnRejection> {
        let k = self.len;
        let magnitudes = || {
            (0..k).map(|i| {
                let m = &self.batch(i).mean;
                norm(&[m[0], m[1], m[2]])
            })
        };
        let magnitude = magnitudes().sum::<f64>() / k as f64;
        let g = self.config.gravity_mps2;
        if (magnitude - g).abs() > self.config.max_gravity_error * g {
            return Err(LearnRejection::Gravity {
                magnitude_mps2: magnitude,
                gravity_mps2: g,
                limit: self.config.max_gravity_error,
            });
        }
        let magnitude_var =
            magnitudes().map(|m| (m - magnitude).powi(2)).sum::<f64>() / (k as f64 - 1.0);
        let n = self.batch(k - 1).n as f64;
        let sigma: [f64; 6] = std::array::from_fn(|c| self.sigma(c));
        self.check_noise(&sigma, k as f64 * n / self.covered_s(0))?;
        for (c, s) in sigma.iter().enumerate() {
            let sigmas = self.outlier_sigmas(c, s / n.sqrt());
            if sigmas > MAX_OUTLIER_SIGMA {
                return Err(LearnRejection::Outlier { channel: c, sigmas });
            }
        }
        let mut mean = [0.0; 6];
        let mut correlation = [1.0; 6];
        let mut batch_dof = [n - 1.0; 6];
        for c in 0..6 {
            (mean[c], correlation[c], batch_dof[c]) = self.channel(c, sigma[c])?;
        }
        let limit = self.config.max_gyro_offset_rps;
        if let Some(channel) = (0..3).find(|c| mean[c + 3].abs() > limit) {
            return Err(LearnRejection::Turning {
                channel,
                rate_dps: mean[channel + 3].to_degrees(),
                limit_dps: limit.to_degrees(),
            });
        }
        let part = |a: &[f64; 6], off: usize| [a[off], a[off + 1], a[off + 2]];
        Ok(StaticReference {
            accel_mean_mps2: part(&mean, 0),
            gyro_mean_rps: part(&mean, 3),
            accel_sigma_mps2: part(&sigma, 0),
            gyro_sigma_rps: part(&sigma, 3),
            accel_correlation: part(&correlation, 0),
            gyro_correlation: part(&correlation, 3),
            accel_batch_dof: part(&batch_dof, 0),
            gyro_batch_dof: part(&batch_dof, 3),
            magnitude_mps2: magnitude,
            magnitude_std_mps2: magnitude_var.sqrt(),
            batches: k,
            duration_s: self.covered_s(0),
            t_start_ns: self.batch(0).t_start_ns,
        })
    }

    /// Refuses an accelerometer whose samples spread over the window more than
    /// [`LearnConfig::max_accel_sigma_mps2`], and learned noise `sigma` above the measured
    /// noise's ceiling when that is known for a stream at `rate_hz` (within 10%, as
    /// [`super::NoiseFloor::apply`]).
    fn check_noise(&self, sigma: &[f64; 6], rate_hz: f64) -> Result<(), LearnRejection> {
        if let Some(limit_mps2) = self.config.max_accel_sigma_mps2
            && let Some((channel, sigma_mps2)) = (0..3)
                .map(|c| (c, self.spread(c)))
                .find(|(_, s)| *s > limit_mps2)
        {
            return Err(LearnRejection::Shaking {
                channel,
                sigma_mps2,
                limit_mps2,
            });
        }
        let Some(noise) = &self.noise else {
            return Ok(());
        };
        if (rate_hz / noise.sample_rate_hz - 1.0).abs() > 0.1 {
            return Ok(());
        }
        let measured = noise.accel_sigma_mps2.iter().chain(&noise.gyro_sigma_rps);
        let limit = self.config.max_noise_ratio;
        for (c, (s, m)) in sigma.iter().zip(measured).enumerate() {
            if let Some(m) = m
                && *s > limit * m
            {
                return Err(LearnRejection::TooNoisy {
                    channel: c,
                    ratio: s / m,
                    limit,
                });
            }
        }
        Ok(())
    }

    /// Channel `c`'s standard deviation over the whole window, about the window's mean (the
    /// within-batch sums of squares and the batch means' spread together): a rate's batches
    /// may be too short to hold a slow motion, the window is not.
    fn spread(&self, c: usize) -> f64 {
        let batches = (0..self.len).map(|i| self.batch(i));
        let (n, sum) = batches.clone().fold((0.0, 0.0), |(n, s), b| {
            (n + b.n as f64, s + b.n as f64 * b.mean[c])
        });
        let mean = sum / n;
        let ss = batches.fold(0.0, |s, b| {
            s + b.ss[c] + b.n as f64 * (b.mean[c] - mean).powi(2)
        });
        (ss / (n - 1.0).max(1.0)).sqrt()
    }

    /// Channel `c`'s per-sample noise: the pooled within-batch standard deviation, at least
    /// the quantization floor.
    fn sigma(&self, c: usize) -> f64 {
        let floor = if c < 3 {
            ACCEL_SIGMA_FLOOR_MPS2
        } else {
            GYRO_SIGMA_FLOOR_RPS
        };
        let (ss, dof) = (0..self.len)
            .map(|i| self.batch(i))
            .fold((0.0, 0.0), |(s, d), b| (s + b.ss[c], d + b.n as f64 - 1.0));
        (ss / dof).sqrt().max(floor)
    }

    /// Channel `c`'s mean, correlation and batch degrees of freedom, or why it is not steady
    /// (see the module documentation); `sigma` is its per-sample noise.
    fn channel(&self, c: usize, sigma: f64) -> Result<(f64, f64, f64), LearnRejection> {
        let k = self.len;
        let kf = k as f64;
        let batches = || (0..k).map(|i| self.batch(i));
        let n = self.batch(k - 1).n as f64;
        let mean_ss = batches().map(|b| b.ss[c]).sum::<f64>() / kf;
        let var_ss = batches().map(|b| (b.ss[c] - mean_ss).powi(2)).sum::<f64>() / (kf - 1.0);
        let batch_dof = if var_ss > 0.0 {
            (2.0 * mean_ss * mean_ss / var_ss).clamp(1.0, n - 1.0)
        } else {
            n - 1.0
        };
        let mean = batches().map(|b| b.mean[c]).sum::<f64>() / kf;
        let scatter = batches().map(|b| (b.mean[c] - mean).powi(2)).sum::<f64>();
        let ratio = scatter / (kf - 1.0) * n / (sigma * sigma);
        if ratio <= self.config.max_correlation {
            return Ok((mean, ratio.max(1.0), batch_dof));
        }
        let successive = (1..k)
            .map(|i| (self.batch(i).mean[c] - self.batch(i - 1).mean[c]).powi(2))
            .sum::<f64>();
        let von_neumann = successive / (2.0 * scatter);
        let limit = 1.0 - STEADY_Z / kf.sqrt() - self.config.max_batch_correlation;
        if von_neumann < limit {
            return Err(LearnRejection::Unsteady {
                channel: c,
                ratio,
                von_neumann,
                limit,
            });
        }
        let correlation = ratio * (1.0 + 2.0 * (1.0 - von_neumann).max(0.0));
        Ok((mean, correlation, batch_dof))
    }
}

/// Euclidean norm of a 3-vector.
pub(crate) fn norm(v: &[f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}
