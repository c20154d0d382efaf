//! Zero-state (rest) detectors for the live calibration stage: plain state machines that take
//! one calibrated sample at a time and return a verdict for every completed batch of
//! [`BATCH_LEN`] samples. No allocation per sample (the GLRT's window ring is allocated once).
//!
//! Inputs are calibrated specific force in m/s^2 and angular rate in rad/s, sensor frame, with
//! strictly increasing sample times in ns. Both detectors:
//! 1. learn a [`StaticReference`] from the first rest in the data ([`learn`]: a sliding window
//!    of `learn.duration_s`, noise correlated by the sensor's own filter accepted); until then
//!    every verdict says not ready and not at rest;
//! 2. then decide each batch at its last sample, so a sample's verdict is known at most
//!    `BATCH_LEN - 1` samples after it (the calibration stage's latency);
//! 3. keep their references current from the batches they call rest (running means with a
//!    memory of `memory_s` seconds of rest, see [`rest_gain`]).
//!
//! **Learning again.** A detector whose first window is shorter than its learning
//! (`learn.first_s` below `learn.duration_s`: a robot's half second under `--learn-s 5`) does
//! not wait for a rest as long as the learning, which a robot that stops for 2 s never gives:
//! it builds its rule from the first window of `first_s`, and keeps looking for a window of
//! `duration_s` that passes the same checks. The first one whose accelerometer noise is at
//! most [`RELEARN_NOISE_RATIO`] of what the first window learned builds the rule again, once:
//! a first window learned while the robot drove (the F1TENTH car of docs/real-data.md drives
//! off at once) is replaced by the rest that comes later. A rest like the first window is not
//! (the rule has pooled its noise over the rests since, which a window of a few seconds would
//! throw away), nor is a long steady cruise, which passes every check but is noisier than a
//! rest.
//!
//! With the calibration file's noise parameters ([`NoiseFloor`], set by the calibration stage
//! from the `[noise]` table), the learned per-sample noise of each channel is raised to the
//! sensor's measured noise where it came out lower: a few seconds of learning can catch a
//! quiet stretch, and thresholds set on it call later rests motion. Noisier learned levels
//! (torn reads, a vibrating mount) are kept; the learned means, and learning itself, are
//! unchanged. Both detectors' thresholds (the GLRT's sigmas, Yu's std thresholds and magnitude
//! tolerance) follow.
//!
//! - [`DetectorKind::Yu`]: Yu et al.'s batches of 20 accelerometer samples ([`yu`]).
//! - [`DetectorKind::Glrt`]: a generalised-likelihood-ratio test on accelerometer and gyroscope
//!   over a sliding window of whole batches against the gravity vector and gyroscope bias
//!   learned at rest ([`glrt`]).
//! - [`DetectorKind::GlrtAccel`]: the same test on the accelerometer alone, for a sensor run
//!   without its gyroscope (the MPU-9250 at 4 kHz), where Yu's 20-sample batch lasts 5 ms, too
//!   short to hold a vibration period (measured in docs/detectors.md).

pub mod args;
pub mod glrt;
pub mod learn;
pub mod shoe;
pub mod yu;

use crate::window::{WindowAccumulator, WindowStats};
pub use glrt::{GlrtConfig, GlrtStatistic};
use learn::StaticLearner;
pub use learn::{LearnConfig, LearnRejection, StaticReference};
pub use shoe::ShoeConfig;
pub use yu::YuConfig;

/// Samples per batch (Yu et al.'s 20).
pub const BATCH_LEN: usize = 20;

/// Which detector.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DetectorKind {
    /// Yu et al.: accelerometer batch mean and std against learned thresholds.
    Yu,
    /// GLRT on accelerometer and gyroscope against the gravity vector and gyro bias learned
    /// at rest.
    Glrt,
    /// The GLRT on the accelerometer alone, against the gravity vector learned at rest.
    GlrtAccel,
    /// SHOE (Skog et al.): stance of a foot-mounted sensor, against fixed scales, no learning.
    Shoe,
}

impl DetectorKind {
    /// The name used on command lines.
    pub fn name(self) -> &'static str {
        match self {
            Self::Yu => "yu",
            Self::Glrt => "glrt",
            Self::GlrtAccel => "glrt-accel",
            Self::Shoe => "shoe",
        }
    }

    /// Whether its rest means still, as the bias refinement at rest assumes: the learned
    /// detectors test against the sensor's noise, while a SHOE stance admits a foot that rolls
    /// over at tens of deg/s (refining the gyro bias there took the real walks of
    /// docs/real-data.md from 0.2-0.6 % to 1-2 % of the distance).
    pub fn rest_is_still(self) -> bool {
        !matches!(self, Self::Shoe)
    }

    /// Whether the detector needs gyroscope samples.
    pub fn needs_gyro(self) -> bool {
        matches!(self, Self::Glrt | Self::Shoe)
    }
}

/// The sensor's per-sample white noise from the noise parameters, as a floor for the learned
/// levels (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseFloor {
    /// Sample rate the levels refer to, Hz: they are applied only to a stream within 10% of it
    /// (a density measured at one rate, aliasing and filtering included, does not give the
    /// per-sample noise at another).
    pub sample_rate_hz: f64,
    /// Accelerometer per-sample sigma per axis, m/s^2 (`None`: not resolved).
    pub accel_sigma_mps2: [Option<f64>; 3],
    /// Gyroscope per-sample sigma per axis, rad/s (`None`: not resolved or no gyro).
    pub gyro_sigma_rps: [Option<f64>; 3],
}

impl NoiseFloor {
    /// The per-sample sigmas `N sqrt(rate)` (Kalibr's discrete-time convention) of the
    /// resolved white noise densities of `params`; accelerometer values converted to the
    /// gravity `gravity_mps2` the detector works in.
    pub fn from_params(params: &crate::noise_params::NoiseParams, gravity_mps2: f64) -> Self {
        let root_rate = params.sample_rate_hz.sqrt();
        let scale = gravity_mps2 / params.gravity_mps2;
        let sigmas = |sensor: Option<&crate::noise_params::SensorNoise>, scale: f64| {
            let axes = sensor.map(|s| s.axes());
            std::array::from_fn(|i| {
                axes.and_then(|a| a[i].white_noise_density)
                    .map(|n| n.value * root_rate * scale)
            })
        };
        Self {
            sample_rate_hz: params.sample_rate_hz,
            accel_sigma_mps2: sigmas(Some(&params.accel), scale),
            gyro_sigma_rps: sigmas(params.gyro.as_ref(), 1.0),
        }
    }

    /// `reference` with each channel's noise raised to the floor where it is lower, when the
    /// stream's rate (from the learned batches) is within 10% of the floor's; the scatter of
    /// the batch means (`correlation sigma^2`) is kept as learned.
    pub fn apply(&self, mut reference: StaticReference) -> StaticReference {
        if (reference.rate_hz() / self.sample_rate_hz - 1.0).abs() > 0.1 {
            return reference;
        }
        let raise = |sigma: &mut f64, correlation: &mut f64, floor: Option<f64>| {
            if let Some(f) = floor
                && f > *sigma
            {
                *correlation = (*correlation * *sigma * *sigma / (f * f)).max(1.0);
                *sigma = f;
            }
        };
        for i in 0..3 {
            raise(
                &mut reference.accel_sigma_mps2[i],
                &mut reference.accel_correlation[i],
                self.accel_sigma_mps2[i],
            );
            raise(
                &mut reference.gyro_sigma_rps[i],
                &mut reference.gyro_correlation[i],
                self.gyro_sigma_rps[i],
            );
        }
        // The batch magnitude's white-noise scatter along the learned gravity direction.
        let m = learn::norm(&reference.accel_mean_mps2);
        let along: f64 = (0..3)
            .map(|i| (reference.accel_mean_mps2[i] / m * reference.accel_sigma_mps2[i]).powi(2))
            .sum();
        reference.magnitude_std_mps2 = reference
            .magnitude_std_mps2
            .max((along / BATCH_LEN as f64).sqrt());
        reference
    }
}

/// Settings of a detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorConfig {
    /// Which detector.
    pub kind: DetectorKind,
    /// The start-up learning.
    pub learn: LearnConfig,
    /// Memory of the running references, seconds of rest.
    pub memory_s: f64,
    /// Yu et al.'s settings.
    pub yu: YuConfig,
    /// The GLRT's settings.
    pub glrt: GlrtConfig,
    /// SHOE's settings.
    pub shoe: ShoeConfig,
    /// The sensor's noise from the calibration file, a floor for the learned levels.
    pub noise: Option<NoiseFloor>,
    /// Rest the part's noise is known from beyond the learning, s (0: only what was learned):
    /// the GLRT's mean test takes its quantile with the degrees of freedom of at least this
    /// much rest, so that a short learning (whose few batches leave the F quantile loose) does
    /// not let motion through. The vehicle profile sets 5 s (`odometry::profile`): the part's
    /// noise is the calibration file's `[noise]` table or the datasheet's, and what the first
    /// second of rest shows is taken at that confidence until pooled rests exceed it.
    pub noise_prior_s: f64,
    /// The accelerometer is uncalibrated whatever its learned rest reads (`--uncalibrated`):
    /// an offset across gravity barely moves the magnitude (0.15 g across reads gravity 1.1 %
    /// off, within a calibrated part's [`learn::CALIBRATED_GRAVITY_ERROR`]), so a part with no
    /// calibration of its own can read gravity right and still carry 0.1 g that only a turn or
    /// a tilt shows ([`Self::uncalibrated`]).
    pub offset_unknown: bool,
}

impl DetectorConfig {
    /// Defaults for `kind` with local gravity `gravity_mps2`: 5 s learning, 20 s memory, the
    /// detector's own defaults ([`YuConfig::default`], [`GlrtConfig::default`]) and no noise
    /// floor (the calibration stage sets it from the calibration file).
    ///
    /// The memory is short because the references must follow an uncompensated part's
    /// temperature drift from rest to rest: with 60 s, a datasheet-level part's specific force
    /// at rest drifted away from the lagging reference after 3 minutes of driving, no rest was
    /// found again, and the odometry diverged (docs/detectors.md). 20 s of rest still averages
    /// the reference to a third of the window mean's noise at 200 Hz.
    pub fn new(kind: DetectorKind, gravity_mps2: f64) -> Self {
        Self {
            kind,
            learn: LearnConfig::new(gravity_mps2),
            memory_s: 20.0,
            yu: YuConfig::default(),
            glrt: GlrtConfig::default(),
            shoe: ShoeConfig::default(),
            noise: None,
            noise_prior_s: 0.0,
            offset_unknown: false,
        }
    }

    /// Whether the part whose learned rest is `learned` is taken as uncalibrated: declared so
    /// ([`Self::offset_unknown`]), or its rest read gravity more than
    /// [`learn::CALIBRATED_GRAVITY_ERROR`] off. Then the GLRT allows its offset across gravity
    /// (`glrt::GlrtConfig::uncalibrated_accel_bias_sigma_mps2`), the calibration stage takes
    /// the rest whole and flags its samples `GRAVITY_OFF`.
    pub fn uncalibrated(&self, learned: &StaticReference) -> bool {
        self.offset_unknown
            || (learned.magnitude_mps2 / self.learn.gravity_mps2 - 1.0).abs()
                > learn::CALIBRATED_GRAVITY_ERROR
    }
}

impl DetectorConfig {
    /// `self` with the learning's gravity check for the calibration `file`: widened to
    /// [`learn::UNCALIBRATED_GRAVITY_ERROR`] when its accelerometer was not fitted
    /// ([`crate::calibfile::CalibrationFile::accel_fitted`]).
    pub fn for_file(mut self, file: &crate::calibfile::CalibrationFile) -> Self {
        if !file.accel_fitted() {
            self.learn.max_gravity_error = self
                .learn
                .max_gravity_error
                .max(learn::UNCALIBRATED_GRAVITY_ERROR);
        }
        self
    }
}

/// Start-up learning of a robot's detector, s: the first half second of rest gives the
/// references (gravity in the sensor frame, the gyroscope bias), while the noise the test
/// holds them against is the part's own ([`ROBOT_NOISE_PRIOR_S`]), so the odometry aligns on
/// the half second of rest after it: a rest of 1 s aligns (`odometry::profile::ROBOT_ALIGN_S`).
/// At a rate where half a second is less than two batches (below 80 Hz) the learning takes
/// two batches (1 s at 40 Hz).
pub const ROBOT_LEARN_S: f64 = 0.5;

/// Largest ratio of a longer learning window's accelerometer noise (per-sample standard
/// deviation, root of the summed variance of the axes) to the first window's for the window
/// to replace the rule's reference (the module's "Learning again"): half. A first window learned
/// in motion carries its vibration, several times a rest's noise (a car idling: 50-90 mg
/// against a part's 5-10 mg); a rest like the rule's comes out within a few tens of percent
/// of it even from the fewest samples a window holds (2 batches of 20: 40 samples per axis,
/// the summed variance's standard error 13 %). Replacing on any quieter window (ratio 1) took
/// wid-car-06 of docs/real-data.md from 1.9 % to 181 % of its distance with `--learn-s 1`: a
/// second of its idling at 18 s replaced the noise pooled over its 15 s parked.
pub const RELEARN_NOISE_RATIO: f64 = 0.5;

/// Rest the part's noise counts for in a robot's detector beyond its half second of learning, s
/// ([`DetectorConfig::noise_prior_s`]): the 5 s of learning it replaces. Without it, the F
/// quantile of one second's 9 batches at 200 Hz let a robot's motions through as rest: a
/// simulated stop-and-go robot (`mems-sim drive --duration 120 --initial-rest 7 --rests 1,2
/// --legs 2,4 --max-motion 10 --cruise 0.2,0.5 --seed 1 --rate 200`, `mems-odometry offline`
/// without a calibration file) ended 3.2 m off after 24 m, and 0.05 m with it (0.012 m with
/// 5 s of learning, which its 1-2 s rests never give again once it has started).
pub const ROBOT_NOISE_PRIOR_S: f64 = 5.0;

impl DetectorConfig {
    /// A wheeled robot's or vehicle's detector, live (`mems-calibrate serve`) and offline
    /// (`mems-odometry`'s vehicle profile) alike: the GLRT learning from [`ROBOT_LEARN_S`]
    /// with a prior of [`ROBOT_NOISE_PRIOR_S`], the rest as [`DetectorConfig::new`]. A longer
    /// learning (`--learn-s`) still builds its first rule from [`ROBOT_LEARN_S`] and learns
    /// again when its rest comes (the module's "Learning again").
    pub fn robot(gravity_mps2: f64) -> Self {
        let mut config = Self::new(DetectorKind::Glrt, gravity_mps2);
        config.learn.duration_s = ROBOT_LEARN_S;
        config.learn.first_s = Some(ROBOT_LEARN_S);
        config.noise_prior_s = ROBOT_NOISE_PRIOR_S;
        config
    }
}

/// The verdict on one completed batch.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Verdict {
    /// The batch's accelerometer statistics, m/s^2.
    pub accel: WindowStats,
    /// The batch's gyroscope statistics, rad/s.
    pub gyro: WindowStats,
    /// Whether the detector has learned its thresholds.
    pub ready: bool,
    /// Whether the batch is at rest (never before `ready`).
    pub rest: bool,
    /// Whether the detector found the window steady but vibrating: the GLRT's mean test saw
    /// no acceleration or turn beyond the noise while its scatter test saw vibration above the
    /// rest's noise (a slow cruise on a smooth floor, a running motor). Such a window is
    /// motion (`rest` is false); it is counted ([`ZeroStateDetector::vibrating_s`]) so that a
    /// run says how much of it only vibration told from rest.
    pub vibrating: bool,
    /// Mean specific force over the window that decided (the batch for Yu, the sliding
    /// window for the GLRT), m/s^2.
    pub decided_mean_mps2: [f64; 3],
    /// Per-axis standard deviation over the same window, m/s^2.
    pub decided_std_mps2: [f64; 3],
    /// The reference learned at start-up, on the one verdict whose batch completed learning.
    pub learned: Option<StaticReference>,
}

/// The learned decision rule of one detector kind.
#[derive(Debug, Clone)]
// One rule per detector, set once at learning and never moved on the hot path; boxing the
// large variant would allocate when the detector learns.
#[allow(clippy::large_enum_variant)]
enum Rule {
    Yu(yu::YuRule),
    Glrt(glrt::GlrtRule),
    Shoe(shoe::ShoeRule),
}

/// A zero-state detector (either kind): batches, start-up learning, decision rule.
#[derive(Debug, Clone)]
pub struct ZeroStateDetector {
    config: DetectorConfig,
    accel: WindowAccumulator,
    gyro: WindowAccumulator,
    learner: StaticLearner,
    /// The learner of the longer window when the detector learns again
    /// ([`LearnConfig::learns_again`]); it looks until `relearned` is set.
    relearner: Option<StaticLearner>,
    /// The reference the rule was built again from, if it was.
    relearned: Option<StaticReference>,
    rule: Option<Rule>,
    /// What the rule was built from (learned, or resumed).
    learned: Option<StaticReference>,
    rest_s: f64,
    /// Batches found steady but vibrating, s.
    vibrating_s: f64,
    /// Storage for the GLRT's window, allocated once and handed to the rule when it is learned.
    ring: Vec<glrt::BatchSums>,
}

/// Gain of a running mean with a memory of `memory_s` seconds of rest, for a batch of
/// `batch_s` seconds after `seen_s` seconds of rest: `batch_s / min(seen_s + batch_s,
/// memory_s)`. It is the plain mean of everything seen until the memory fills, then an
/// exponential forgetting with time constant `memory_s`.
pub fn rest_gain(batch_s: f64, seen_s: f64, memory_s: f64) -> f64 {
    batch_s / (seen_s + batch_s).min(memory_s).max(batch_s)
}

/// The time a batch covers: first to last sample plus one sample period, s.
pub(crate) fn batch_duration_s(w: &WindowStats) -> f64 {
    let n = w.n as f64;
    (w.t_end_ns - w.t_start_ns) as f64 * 1e-9 * n / (n - 1.0)
}

impl ZeroStateDetector {
    /// A detector with `config`, not yet learned.
    ///
    /// # Panics
    /// If the false-alarm rate is not in (0, 1), the GLRT window is not positive, the
    /// SHOE window is not 2..=[`BATCH_LEN`] samples or the memory is not positive.
    pub fn new(config: DetectorConfig) -> Self {
        assert!(
            config.memory_s > 0.0,
            "memory_s must be > 0, got {}",
            config.memory_s
        );
        let alpha = match config.kind {
            DetectorKind::Yu => config.yu.false_alarm,
            DetectorKind::Glrt | DetectorKind::GlrtAccel | DetectorKind::Shoe => {
                config.glrt.false_alarm
            }
        };
        assert!(
            alpha > 0.0 && alpha < 1.0,
            "false-alarm rate must be in (0, 1), got {alpha}"
        );
        let shoe = config.kind == DetectorKind::Shoe;
        let window = if shoe { config.shoe.window } else { BATCH_LEN };
        assert!(
            (2..=BATCH_LEN).contains(&window),
            "the SHOE window must be 2..={BATCH_LEN} samples, got {window}"
        );
        assert!(
            config.glrt.window_s > 0.0,
            "the GLRT window must be > 0 s, got {}",
            config.glrt.window_s
        );
        Self {
            config,
            accel: WindowAccumulator::new(window),
            gyro: WindowAccumulator::new(window),
            learner: StaticLearner::new(config.learn.first(), config.noise),
            relearner: (!shoe && config.learn.learns_again())
                .then(|| StaticLearner::new(config.learn, config.noise)),
            relearned: None,
            rule: shoe
                .then(|| Rule::Shoe(shoe::ShoeRule::new(config.shoe, config.learn.gravity_mps2))),
            learned: None,
            rest_s: 0.0,
            vibrating_s: 0.0,
            ring: Vec::with_capacity(config.glrt.max_window_batches()),
        }
    }

    /// The settings.
    pub fn config(&self) -> &DetectorConfig {
        &self.config
    }

    /// Whether the thresholds are learned.
    pub fn is_ready(&self) -> bool {
        self.rule.is_some()
    }

    /// The reference the rule was built again from, from a longer rest than its first
    /// window's (the module's "Learning again"), if it was.
    pub fn relearned(&self) -> Option<StaticReference> {
        self.relearned
    }

    /// How many start-up learning attempts were discarded, and why the last one was.
    pub fn learn_rejections(&self) -> (usize, Option<LearnRejection>) {
        self.learner.rejections()
    }

    /// The current references: (specific force at rest m/s^2, gyroscope bias rad/s), once
    /// learned.
    pub fn references(&self) -> Option<([f64; 3], [f64; 3])> {
        match self.rule.as_ref()? {
            Rule::Yu(r) => Some((r.accel_mean_mps2(), r.gyro_mean_rps())),
            Rule::Glrt(r) => Some((r.accel_mean_mps2(), r.gyro_mean_rps())),
            Rule::Shoe(_) => None,
        }
    }

    /// What the rule stands on: the learned (or resumed) reference with its means as they are
    /// now (kept current at rest); `None` before learning and for SHOE, which learns nothing.
    pub fn reference(&self) -> Option<StaticReference> {
        let (accel, gyro) = self.references()?;
        self.learned.map(|r| StaticReference {
            accel_mean_mps2: accel,
            gyro_mean_rps: gyro,
            ..r
        })
    }

    /// How often the GLRT took its gravity reference as lost and measured it anew at a rest
    /// (`glrt`'s "A reference that was lost"); 0 for the other rules.
    pub fn gravity_reanchored(&self) -> u64 {
        match &self.rule {
            Some(Rule::Glrt(r)) => r.reanchored(),
            _ => 0,
        }
    }

    /// How often the GLRT held a rest against a gravity magnitude its reference does not hold
    /// (`glrt`'s "A magnitude the reference does not hold"); 0 for the other rules.
    pub fn gravity_held(&self) -> u64 {
        match &self.rule {
            Some(Rule::Glrt(r)) => r.held(),
            _ => 0,
        }
    }

    /// Time the detector found steady but vibrating, s ([`Verdict::vibrating`]): motion that
    /// only vibration told from rest.
    pub fn vibrating_s(&self) -> f64 {
        self.vibrating_s
    }

    /// Rest time the references have been kept current over, s (the learning included).
    pub fn rest_seen_s(&self) -> f64 {
        self.rest_s
    }

    /// Builds the rule from `reference`, kept current over `rest_seen_s` of rest, as the
    /// detector that made them had it (a restarted process going on with its predecessor's
    /// references). SHOE learns nothing and ignores it.
    pub fn resume(&mut self, reference: &StaticReference, rest_seen_s: f64) {
        if self.config.kind != DetectorKind::Shoe {
            // Nothing learned here is part of the resumed rest.
            self.learner.clear();
            if let Some(relearner) = self.relearner.as_mut() {
                relearner.clear();
            }
            self.install(*reference, false);
            self.rest_s = rest_seen_s;
        }
    }

    /// The batches of rest [`DetectorConfig::noise_prior_s`] stands for at the rate `learned`
    /// was learned at.
    fn prior_batches(&self, learned: &StaticReference) -> f64 {
        self.config.noise_prior_s * learned.rate_hz() / BATCH_LEN as f64
    }

    /// Makes `reference` (after the noise floor) the rule's; `again`: learned by the longer
    /// window's learner, whose batches seed the rule.
    fn install(&mut self, learned: StaticReference, again: bool) -> StaticReference {
        let reference = self.config.noise.map_or(learned, |f| f.apply(learned));
        self.rest_s = reference.duration_s;
        let ring = match self.rule.take() {
            Some(Rule::Glrt(rule)) => rule.into_ring(),
            _ => std::mem::take(&mut self.ring),
        };
        self.rule = Some(match self.config.kind {
            DetectorKind::Yu => Rule::Yu(yu::YuRule::new(&reference, &self.config.yu)),
            kind @ (DetectorKind::Glrt | DetectorKind::GlrtAccel) => {
                let mut config = self.config.glrt;
                let uncalibrated = self.config.uncalibrated(&reference);
                if uncalibrated {
                    // An uncalibrated part: its offset across gravity is unknown as well.
                    config.accel_bias_sigma_mps2 = config
                        .accel_bias_sigma_mps2
                        .max(config.uncalibrated_accel_bias_sigma_mps2);
                }
                let mut rule = glrt::GlrtRule::new(
                    &reference,
                    &learned,
                    &config,
                    ring,
                    kind == DetectorKind::GlrtAccel,
                    self.prior_batches(&learned),
                    uncalibrated,
                );
                // The batches just learned from (none when resumed) are a rest already.
                let learner = match self.relearner.as_ref() {
                    Some(relearner) if again => relearner,
                    _ => &self.learner,
                };
                rule.seed(
                    learner
                        .window()
                        .map(|(n, mean, ss)| glrt::BatchSums::from_parts(n, mean, ss)),
                );
                Rule::Glrt(rule)
            }
            DetectorKind::Shoe => unreachable!("SHOE is ready from the start"),
        });
        self.learned = Some(reference);
        reference
    }

    /// Adds one sample at `t_ns`: specific force `accel_mps2` (m/s^2) and angular rate
    /// `gyro_rps` (rad/s; ignored by Yu's detector), sensor frame. Returns the verdict when
    /// this sample completes a batch.
    pub fn push(&mut self, t_ns: u64, accel_mps2: [f64; 3], gyro_rps: [f64; 3]) -> Option<Verdict> {
        let a = self.accel.push(t_ns, accel_mps2);
        let g = self.gyro.push(t_ns, gyro_rps);
        let (Some(accel), Some(gyro)) = (a, g) else {
            return None;
        };
        let mut verdict = Verdict {
            accel,
            gyro,
            decided_mean_mps2: accel.mean,
            decided_std_mps2: accel.std,
            ..Verdict::default()
        };
        if self.learn_again(&accel, &gyro) {
            // The batch ends the window the rule was built again from, which seeded it: a rest.
            verdict.ready = true;
            verdict.rest = true;
            return Some(verdict);
        }
        let Some(rule) = self.rule.as_mut() else {
            if let Some(learned) = self.learner.push(&accel, &gyro) {
                verdict.ready = true;
                verdict.learned = Some(self.install(learned, false));
            }
            return Some(verdict);
        };
        verdict.ready = true;
        let decision = match rule {
            Rule::Yu(r) => r.decide(&accel),
            Rule::Glrt(r) => r.decide(&accel, &gyro),
            Rule::Shoe(r) => r.decide(&accel, &gyro),
        };
        verdict.rest = decision.rest;
        verdict.vibrating = decision.vibrating;
        if decision.vibrating {
            self.vibrating_s += batch_duration_s(&accel);
        }
        verdict.decided_mean_mps2 = decision.mean_mps2;
        verdict.decided_std_mps2 = decision.std_mps2;
        if decision.rest {
            let batch_s = batch_duration_s(&accel);
            let gain = rest_gain(batch_s, self.rest_s, self.config.memory_s);
            self.rest_s += batch_s;
            match rule {
                Rule::Yu(r) => r.update(&accel, &gyro, gain),
                Rule::Glrt(r) => r.update(&accel, &gyro, gain),
                Rule::Shoe(_) => {}
            }
        }
        Some(verdict)
    }

    /// Gives the batch to the longer window's learner while it looks; builds the rule again
    /// from its first window that passes and is much quieter than the first window (the
    /// module's "Learning again"); whether it did. Before the first rule, the first window
    /// builds it.
    fn learn_again(&mut self, accel: &WindowStats, gyro: &WindowStats) -> bool {
        let Some(relearner) = self.relearner.as_mut().filter(|_| self.relearned.is_none()) else {
            return false;
        };
        let Some(long) = relearner.push(accel, gyro) else {
            return false;
        };
        let Some(first) = self.learned else {
            return false;
        };
        if long.accel_noise_var() > RELEARN_NOISE_RATIO.powi(2) * first.accel_noise_var() {
            return false;
        }
        self.relearned = Some(long);
        self.install(long, true);
        true
    }

    /// A gap in the data: the partial batch is dropped (its samples get no verdict), the
    /// GLRT's window is emptied and learning in progress starts again; learned references stay.
    pub fn interrupt(&mut self) {
        self.accel.reset();
        self.gyro.reset();
        match self.rule.as_mut() {
            Some(Rule::Glrt(r)) => r.clear_window(),
            Some(Rule::Shoe(r)) => r.clear(),
            Some(Rule::Yu(_)) => {}
            None => self.learner.restart(),
        }
        if let Some(relearner) = self.relearner.as_mut() {
            relearner.restart();
        }
    }

    /// Forgets everything learned (a new sensor session): back to start-up learning. Allocates
    /// nothing (the window's storage is kept).
    pub fn reset(&mut self) {
        self.accel.reset();
        self.gyro.reset();
        self.learner.clear();
        if let Some(relearner) = self.relearner.as_mut() {
            relearner.clear();
        }
        self.relearned = None;
        self.learned = None;
        self.rest_s = 0.0;
        self.vibrating_s = 0.0;
        match self.rule.take() {
            Some(Rule::Glrt(rule)) => self.ring = rule.into_ring(),
            Some(Rule::Shoe(mut rule)) => {
                rule.clear();
                self.rule = Some(Rule::Shoe(rule));
            }
            Some(Rule::Yu(_)) | None => {}
        }
    }
}

/// A rule's decision on the latest batch.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Decision {
    pub rest: bool,
    /// Steady but vibrating: the GLRT's mean test passed (no acceleration or turn beyond the
    /// noise) and its scatter test did not (see [`Verdict::vibrating`]).
    pub vibrating: bool,
    pub mean_mps2: [f64; 3],
    pub std_mps2: [f64; 3],
}
