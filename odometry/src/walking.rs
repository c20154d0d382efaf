//! Hand-held walking: pedestrian dead reckoning for a sensor carried in the hand of a walker
//! (a phone held in front for texting or held up for augmented reality), the odometry mode of
//! the `walking` profile ([`crate::profile::Profile::Walking`]).
//!
//! Such a sensor is never still while its carrier walks, and the quiet instants between steps
//! are no rests: the mode takes no zero-velocity update while the walker walks (a step within
//! [`WALKING_HOLD_S`]). Instead, at each step ([`crate::steps`]) the filter's velocity is
//! measured in a walking frame:
//! - forward speed `L / T` (m/s), `L` the step's length by Weinberg's model with constant
//!   [`WEINBERG_K`] and `T` its interval (s, held to [`crate::steps::CADENCE_S`]'s lower end and
//!   [`MAX_STEP_S`]); the forward row carries the filter's scale state `1 + k`, whose prior
//!   1-sigma is [`STEP_SCALE_SIGMA`], so the step-length constant's uncertainty grows the
//!   position's 1-sigma with the distance walked;
//! - zero lateral and zero vertical velocity.
//!
//! Frames: the navigation frame is the filter's (z up, heading fixed at alignment); the walking
//! frame has x forward and z up, y = z x x (left). Forward is the horizontal part, at the
//! filter's attitude, of the sensor's `+y (1 - u_x^2) - z` axis, `u` the up direction in the
//! sensor frame: a phone held in front with its screen toward its carrier's face and its top
//! away from them points `+y` forward when held flat (texting) and `-z` (its back camera)
//! forward when held upright (augmented reality), and the horizontal parts of both point
//! forward at any tilt between (`cos` and `sin` of the tilt). A phone held in landscape (its x
//! along the vertical: four of the six Tyrex augmented-reality walks, `|u_x|` 0.8-1.0) has its
//! top sideways, so `+y` is dropped as `u_x^2` nears 1: with `+y - z` its steps ran 45 degrees
//! off the walking direction.
//! The heading is the filter's, integrated from the gyro. (The horizontal acceleration's
//! principal axis, the other common estimate, lies along the phone's x, the walker's lateral
//! sway, on 2 of the 6 Tyrex texting walks: it was not used.)
//!
//! The velocity measurement's 1-sigma: [`FORWARD_SIGMA_MPS`] forward (the hand's velocity
//! swings about the step's mean within a step), vertical [`VERTICAL_SIGMA_MPS`], lateral
//! [`LATERAL_SIGMA_MPS`] plus [`LATERAL_SIGMA_PER_MPS`] times the speed (the phone points
//! 15 degrees off the walking direction, 1-sigma: `tan 15 deg = 0.27`).
//!
//! Tilt. The filter's roll and pitch drift with the gyro's errors under the hand's turns (a
//! phone's gyro, its scale and axes uncalibrated, looking around at tens of deg/s), far beyond
//! what its noise model holds: at each step their variance is widened by a random walk of
//! [`HAND_TILT_WALK_DPS`], so that the step's velocity measures the tilt. Without it the
//! filter took its tilt as known to a hundredth of a degree, the gravity its drifting tilt
//! leaked into the velocity (10-40 m/s between steps on the Tyrex augmented-reality walks) was
//! learned as accelerometer bias at each step and rest (1-5 m/s^2 where a phone's is a few
//! 0.01), and the steps' innovations ran at 138-432 per degree of freedom.
//!
//! A walker standing with the sensor in hand (no step for [`WALKING_HOLD_S`], the detector
//! flagging no rest) moves it slowly: a zero-velocity update of [`STANDING_SIGMA_MPS`] every
//! [`STANDING_UPDATE_S`]. A rest the detector flags while the walker stands is a rest.
//!
//! Alignment. A rest aligns as on any platform; a walker who never stands still aligns on
//! whole steps: the mean specific force from one step to a later one at least
//! [`STRIDE_ALIGN_S`] on, the walk in cadence between (no interval over [`MAX_STEP_S`]), is
//! gravity (a walker's mean velocity is the same at every step), with the gyro bias unknown
//! (zero, 1-sigma [`GYRO_BIAS_SIGMA_DPS`]).

use nalgebra::{Matrix3, Vector3};

use crate::eskf::{Eskf, TH, V};
use crate::steps::{CADENCE_S, Step, StepDetector};

/// Weinberg's constant, m/(m/s^2)^(1/4): the median over the 12 Tyrex walks (texting and
/// augmented reality, three walkers, two phones) of the truth's distance over the sum of
/// `(a_max - a_min)^(1/4)` of the detected steps (docs/odometry.md, "Hand-held walking").
pub const WEINBERG_K: f64 = 0.28;
/// 1-sigma of the step length relative to the model's (the filter's scale state's prior):
/// the Tyrex walks' constants spread by about this much about their median.
pub const STEP_SCALE_SIGMA: f64 = 0.33;
/// Random walk of the hand's velocity about the walk's, m/s per square root of s: the
/// filter's velocity is widened by it at each step (module documentation).
pub const HAND_VELOCITY_WALK_MPS: f64 = 0.3;
/// Random walk of the filter's tilt (roll and pitch) while walking, deg per square root of s:
/// its attitude error is widened by it at each step (module documentation, "Tilt").
pub const HAND_TILT_WALK_DPS: f64 = 2.0;
/// 1-sigma of the velocity at an alignment on whole steps, m/s per axis (a walk's speed).
pub const ALIGN_VELOCITY_SIGMA_MPS: f64 = 1.0;
/// A walker whose last step was this long ago is walking, s.
pub const WALKING_HOLD_S: f64 = 1.2;
/// Longest step interval taken for a step's speed, s (a longer one: the walker paused).
pub const MAX_STEP_S: f64 = 1.2;
/// 1-sigma of a step's length about the model's, relative, step to step.
pub const STEP_LENGTH_SIGMA: f64 = 0.15;
/// 1-sigma of the forward speed at a step, m/s.
pub const FORWARD_SIGMA_MPS: f64 = 0.15;
/// 1-sigma of the vertical velocity at a step, m/s.
pub const VERTICAL_SIGMA_MPS: f64 = 0.15;
/// 1-sigma of the lateral velocity at a step, m/s, at no speed.
pub const LATERAL_SIGMA_MPS: f64 = 0.1;
/// Its growth with the speed (`tan 15 deg`), per m/s.
pub const LATERAL_SIGMA_PER_MPS: f64 = 0.27;
/// 1-sigma of a standing walker's hand velocity, m/s.
pub const STANDING_SIGMA_MPS: f64 = 0.3;
/// Interval of the standing walker's updates, s.
pub const STANDING_UPDATE_S: f64 = 0.5;
/// Whole steps the alignment in motion spans at least, s.
pub const STRIDE_ALIGN_S: f64 = 3.0;
/// Step updates the innovations' widening waits for (module documentation, "Position").
pub const STEP_NIS_MIN_UPDATES: u64 = 10;
/// 1-sigma of the gyro bias when aligned in motion, deg/s: a phone's gyroscope after its
/// system's bias calibration (the MPU-6500 family's datasheet zero-rate offset is +-5 deg/s
/// before it).
pub const GYRO_BIAS_SIGMA_DPS: f64 = 5.0;

/// The mode's settings (`OdometryConfig::walking`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WalkingConfig {
    /// Weinberg's constant, m/(m/s^2)^(1/4).
    pub weinberg_k: f64,
    /// 1-sigma of the step length relative to the model's.
    pub step_scale_sigma: f64,
}

impl Default for WalkingConfig {
    fn default() -> Self {
        Self {
            weinberg_k: WEINBERG_K,
            step_scale_sigma: STEP_SCALE_SIGMA,
        }
    }
}

/// What the mode did, for the summaries.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct WalkingStats {
    /// Steps detected.
    pub steps: u64,
    /// Steps whose speed updated the filter.
    pub step_updates: u64,
    /// Steps walked after the alignment (each adds its length to the position).
    pub walked_steps: u64,
    /// Sum of their lengths, m.
    pub step_length_sum_m: f64,
    /// Weinberg's constant used, m/(m/s^2)^(1/4).
    pub weinberg_k: f64,
    /// Whether the filter aligned on whole steps (no rest).
    pub aligned_on_steps: bool,
    /// The step updates' normalized innovation squared per degree of freedom, mean (1 when
    /// their 1-sigma is honest).
    pub step_nis_per_dof: f64,
}

impl WalkingStats {
    /// Mean length of the steps, m.
    pub fn mean_step_m(&self) -> Option<f64> {
        (self.walked_steps > 0).then(|| self.step_length_sum_m / self.walked_steps as f64)
    }
}

impl std::fmt::Display for WalkingStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "hand-held walking (pedestrian dead reckoning): {} steps, {} step updates",
            self.steps, self.step_updates
        )?;
        if let Some(m) = self.mean_step_m() {
            write!(f, ", mean step {m:.2} m")?;
        }
        write!(f, " (Weinberg's K {:.3})", self.weinberg_k)?;
        if self.aligned_on_steps {
            write!(f, ", aligned on whole steps (no rest)")?;
        }
        Ok(())
    }
}

/// The mode's state in a navigator: fixed size, no allocation.
#[derive(Debug, Clone, Copy)]
pub struct Walk {
    cfg: WalkingConfig,
    detector: StepDetector,
    /// Specific force summed since the first step of the walk in cadence (m/s^2), its sample
    /// count, and that step's time (ns), for the alignment on whole steps.
    stride_sum: Vector3<f64>,
    stride_n: u64,
    stride_start_ns: Option<u64>,
    /// Time of the last standing update, ns.
    last_standing_ns: u64,
    /// The walk's horizontal position, m, navigation frame: the sum of the steps.
    position: Vector3<f64>,
    /// Variance of the steps' lengths about the model's, summed, m^2.
    length_var: f64,
    /// The steps' lengths times the heading's 1-sigma at each, summed, m.
    heading_sd_sum: f64,
    stats: WalkingStats,
}

impl Walk {
    /// The mode with `cfg`.
    pub fn new(cfg: WalkingConfig) -> Self {
        Self {
            cfg,
            detector: StepDetector::default(),
            stride_sum: Vector3::zeros(),
            stride_n: 0,
            stride_start_ns: None,
            last_standing_ns: 0,
            position: Vector3::zeros(),
            length_var: 0.0,
            heading_sd_sum: 0.0,
            stats: WalkingStats {
                weinberg_k: cfg.weinberg_k,
                ..WalkingStats::default()
            },
        }
    }

    /// What it did so far.
    pub fn stats(&self) -> WalkingStats {
        self.stats
    }

    /// Takes a sample's specific force `f` (m/s^2, sensor frame) at `t_ns`; returns the step
    /// it ends, if any.
    pub fn push(&mut self, t_ns: u64, f: &Vector3<f64>) -> Option<Step> {
        let step = self.detector.push(t_ns, f.norm());
        self.stats.steps += u64::from(step.is_some());
        step
    }

    /// Whether the walker is walking at `t_ns` (a step within [`WALKING_HOLD_S`]).
    pub fn walking(&self, t_ns: u64) -> bool {
        self.detector
            .last_step_ns()
            .is_some_and(|l| t_ns.saturating_sub(l) as f64 * 1e-9 <= WALKING_HOLD_S)
    }

    /// Before alignment: gathers the sample `f` (m/s^2, sensor frame) and, at a `step`, returns
    /// the mean specific force over whole steps once they span [`STRIDE_ALIGN_S`].
    pub fn stride_mean(&mut self, f: &Vector3<f64>, step: Option<&Step>) -> Option<Vector3<f64>> {
        if let Some(step) = step {
            let broken = step.interval_s.is_none_or(|i| i > MAX_STEP_S);
            match self.stride_start_ns {
                Some(t0) if !broken && self.stride_n > 0 => {
                    if step.t_ns.saturating_sub(t0) as f64 * 1e-9 >= STRIDE_ALIGN_S {
                        let mean = self.stride_sum / self.stride_n as f64;
                        self.stats.aligned_on_steps = true;
                        return Some(mean);
                    }
                }
                _ => {
                    self.stride_sum = Vector3::zeros();
                    self.stride_n = 0;
                    self.stride_start_ns = Some(step.t_ns);
                }
            }
        }
        if self.stride_start_ns.is_some() {
            self.stride_sum += f;
            self.stride_n += 1;
        }
        None
    }

    /// The gyro bias's 1-sigma after an alignment on whole steps, rad/s per axis.
    pub fn gyro_bias_sigma() -> Vector3<f64> {
        Vector3::repeat(GYRO_BIAS_SIGMA_DPS.to_radians())
    }

    /// The walk's position, m, navigation frame: the steps' sum horizontally, and 0 vertically
    /// (a walk on one floor: steps measure no height, and the filter's height between steps
    /// drifts with its tilt).
    pub fn position(&self) -> Vector3<f64> {
        Vector3::new(self.position.x, self.position.y, 0.0)
    }

    /// Distance walked, m (the steps' lengths summed).
    pub fn distance_m(&self) -> f64 {
        self.stats.step_length_sum_m
    }

    /// The position's 1-sigma, m, navigation frame (z: the filter's `z_sigma_m`; module
    /// documentation, "Position"), widened by the step updates' innovations
    /// ([`Self::innovation_factor`]).
    pub fn position_sigma(&self, z_sigma_m: f64) -> Vector3<f64> {
        let s = self.cfg.step_scale_sigma;
        let common = self.length_var + self.heading_sd_sum.powi(2);
        let p = &self.position;
        let lambda = self.innovation_factor();
        Vector3::new(
            (lambda * (common + (s * p.x).powi(2))).sqrt(),
            (lambda * (common + (s * p.y).powi(2))).sqrt(),
            z_sigma_m,
        )
    }

    /// The factor on the position's variance from the step updates' innovations: their mean
    /// normalized innovation squared per degree of freedom `m` once [`STEP_NIS_MIN_UPDATES`]
    /// were made and `m` exceeds 1 by more than three standard deviations of such a mean
    /// (`sqrt(2 / (3 n))` for `n` updates of 3 degrees of freedom), else 1.
    pub fn innovation_factor(&self) -> f64 {
        let n = self.stats.step_updates;
        let m = self.stats.step_nis_per_dof;
        let significant = m > 1.0 + 3.0 * (2.0 / (3.0 * n as f64)).sqrt();
        if n >= STEP_NIS_MIN_UPDATES && significant {
            m
        } else {
            1.0
        }
    }

    /// After the prediction of an aligned filter: a step's velocity update, or a standing
    /// walker's (module documentation). `rest`: the sample is taken as rest (no update here).
    pub fn update(&mut self, kf: &mut Eskf, t_ns: u64, step: Option<&Step>, rest: bool) {
        if let Some(step) = step {
            self.step_update(kf, step);
            return;
        }
        if rest || self.walking(t_ns) {
            self.last_standing_ns = t_ns;
            return;
        }
        if t_ns.saturating_sub(self.last_standing_ns) as f64 * 1e-9 >= STANDING_UPDATE_S {
            kf.zero_velocity(STANDING_SIGMA_MPS);
            self.last_standing_ns = t_ns;
        }
    }

    fn step_update(&mut self, kf: &mut Eskf, step: &Step) {
        let Some(r_ws) = walking_frame(kf) else {
            return;
        };
        let length_m = step.length_m(self.cfg.weinberg_k);
        let forward = kf.x.q * r_ws.row(0).transpose();
        self.position += length_m * Vector3::new(forward.x, forward.y, 0.0);
        self.length_var += (STEP_LENGTH_SIGMA * length_m).powi(2);
        self.heading_sd_sum += length_m * kf.cov[(TH + 2, TH + 2)].max(0.0).sqrt();
        self.stats.step_length_sum_m += length_m;
        self.stats.walked_steps += 1;
        let Some(interval_s) = step.interval_s.filter(|&i| i <= MAX_STEP_S * 2.0) else {
            return;
        };
        // The hand's velocity wanders about the walk's between steps, and the filter's
        // integration with it: its velocity is widened by a random walk over the step.
        kf.propagate();
        for i in 0..3 {
            kf.cov[(V + i, V + i)] += HAND_VELOCITY_WALK_MPS.powi(2) * interval_s;
        }
        // The tilt drifts with the gyro's errors under the hand's turns (module
        // documentation, "Tilt"): widened so that the step measures it, not the bias.
        for i in 0..2 {
            kf.cov[(TH + i, TH + i)] += HAND_TILT_WALK_DPS.to_radians().powi(2) * interval_s;
        }
        let speed = length_m / interval_s.clamp(CADENCE_S.0, MAX_STEP_S);
        let v_w = kf.body_velocity(&r_ws);
        // The scale state stays at zero (its variance is zero from the alignment on).
        let residual = Vector3::new(speed - v_w.x, -v_w.y, -v_w.z);
        let sigma = Vector3::new(
            FORWARD_SIGMA_MPS,
            LATERAL_SIGMA_MPS + LATERAL_SIGMA_PER_MPS * speed,
            VERTICAL_SIGMA_MPS,
        );
        if let Some(nis) = kf.body_velocity_update(&r_ws, residual, sigma) {
            let n = self.stats.step_updates as f64;
            self.stats.step_nis_per_dof = (self.stats.step_nis_per_dof * n + nis / 3.0) / (n + 1.0);
        }
        self.stats.step_updates += 1;
    }
}

/// The rotation from the sensor frame to the walking frame at the filter's attitude (rows: the
/// walking frame's axes in the sensor frame); `None` when the phone's pointing axis (module
/// documentation) is vertical.
fn walking_frame(kf: &Eskf) -> Option<Matrix3<f64>> {
    let up = kf.x.q.inverse_transform_vector(&Vector3::z());
    // `+y (1 - up_x^2) - z`: a phone held in landscape (its x along the vertical) has its top
    // sideways, and its back camera alone points forward.
    let pointing = Vector3::new(0.0, 1.0 - up.x * up.x, -1.0);
    let forward = (pointing - up * up.dot(&pointing)).try_normalize(1e-3)?;
    let left = up.cross(&forward);
    Some(Matrix3::from_rows(&[
        forward.transpose(),
        left.transpose(),
        up.transpose(),
    ]))
}
