//! Robot hints (`mems/robot/hint`, [`RobotHint`]) for the odometry stage: their configuration,
//! validation, the fixed-capacity buffers the stage keeps them in, and the IMU-to-body mounting
//! estimated from the first drive.
//!
//! Frames: the robot body frame `b` is x forward, y left, z up (REP 103); the IMU's sensor
//! frame `s` is the accelerometer's axes. The mounting `R_bs` rotates sensor-frame vectors
//! into the body frame (`v_b = R_bs v_s`). The speed and the non-holonomic constraint describe
//! the rear axle, at [`HintConfig::lever_arm_m`] from the IMU (body frame; zero: the IMU sits
//! on the axle): the velocity compared with them is the axle's, `v_b + omega_b x r_b`
//! (`crate::eskf`'s `lever` module), with the newest sample's rate (a hint is at most
//! [`HintConfig::max_age_s`] old). A lever arm left undeclared adds `omega x r` to the
//! body velocity during turns, which the non-holonomic constraint's 1-sigma has to cover.
//!
//! Times: a hint's `stamps.sample_ns` is the time it describes and `stamps.acquired_ns` when
//! the controller published it, both ns `CLOCK_MONOTONIC` like the IMU samples. The stage uses
//! a hint for the samples taken at least [`HintConfig::delivery_s`] after its publication (its
//! time of publication when `acquired_ns` is 0), whatever the order in which hints and samples
//! reach it: so a live run and a replay of the same recording make the same decisions, as long
//! as a hint reaches the odometry process within `delivery_s` of its publication (plus the
//! calibration stage's own latency, by which every sample arrives late).

use crate::eskf::Heading;
use ipc_types::{RobotHint, hint_flags};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// How the odometry stage uses robot hints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HintConfig {
    /// A hint older than this (sample time minus the hint's `sample_ns`) is stale: the stage
    /// falls back to the IMU alone and flags `HINT_STALE`, s.
    pub max_age_s: f64,
    /// A hint is used by samples taken at least this long after it was published, s (see the
    /// module documentation).
    pub delivery_s: f64,
    /// IMU-to-body mounting: rotates sensor-frame vectors into the body frame. `None`:
    /// estimated from the first drive ([`MountingEstimator`]); speed hints are only used once
    /// it is known (stationary hints need no mounting).
    pub mounting: Option<UnitQuaternion<f64>>,
    /// The mounting the IMU-only non-holonomic constraint of a wheeled platform uses
    /// ([`crate::nonholonomic`]): the one the user gave, else `None`, estimated from the first
    /// drive (the hints' identity default is no statement about the mounting).
    pub imu_mounting: Option<UnitQuaternion<f64>>,
    /// How a mounting that is not given is estimated: `false`, from the revised velocities
    /// of the first drives after a rest ([`MountingEstimator`]); `true`, from the horizontal
    /// specific force against the speed hints' changes and turns
    /// ([`crate::cruise::ForwardAxis`]), which needs no known velocity (a start in motion).
    pub mounting_from_turns: bool,
    /// The forward-axis fit an earlier pass over the same recording ended with (offline: the
    /// speed hints need the mounting from their first, and the end's estimate is the best):
    /// taken as the mounting from the start, its yaw 1-sigmas and speed scale carried as if
    /// just fitted, the IMU-only constraint following it. It overrides `mounting`, and
    /// `mounting_from_turns` must be `false` with it, as with a given mounting.
    pub mounting_fit: Option<ForwardFit>,
    /// Path length of forward driving the mounting estimate gathers before it is used, m.
    pub mounting_min_path_m: f64,
    /// 1-sigma of the non-holonomic constraint (zero lateral and vertical body velocity), m/s;
    /// a large value (say 100) switches it off in effect.
    pub nonholonomic_sigma_mps: f64,
    /// 1-sigma of the speed source's scale error (wheel radius, encoder calibration), fraction:
    /// the prior of the filter's scale state. The hints' own sigma is the per-hint (white)
    /// part only, since a scale error is common to all of them.
    pub speed_scale_sigma: f64,
    /// After hints went stale, the IMU's rest flag gives a zero-velocity update only while
    /// the filter's velocity is within this many standard deviations of zero.
    pub fallback_zupt_gate_sigma: f64,
    /// Whether a speed hint's update may turn the heading (`crate::eskf::Heading`): by default
    /// it does not, since body-frame velocities do not observe it.
    pub speed_heading: Heading,
    /// Added to a speed hint's `sample_ns` before it is compared with the filter's velocity,
    /// s: the speed source's lag behind the IMU (positive: the hint describes motion that much
    /// later than its stamp says).
    pub speed_time_offset_s: f64,
    /// The lever arm from the IMU to the rear axle (the point the speed and the
    /// non-holonomic constraints describe), body frame (x forward, y left, z up), m; also
    /// used by the IMU-only constraint ([`crate::nonholonomic`]).
    pub lever_arm_m: Vector3<f64>,
    /// Hints that can wait for their delivery time at once; when full, the oldest waiting hint
    /// is dropped (and counted in [`HintStats::overflowed`]).
    pub capacity: usize,
}

impl Default for HintConfig {
    /// Stale after 0.25 s (12 periods of a 50 Hz controller), delivery 5 ms, the IMU mounted
    /// aligned with the body (estimated, when `mounting` is set to `None`, from revised
    /// velocities), 3 m of forward driving for an estimated mounting, a
    /// non-holonomic 1-sigma of 0.02 m/s, a speed scale 1-sigma of 2%, a fallback rest gate
    /// of 5 sigma, 256 waiting hints.
    fn default() -> Self {
        Self {
            max_age_s: 0.25,
            delivery_s: 0.005,
            mounting: Some(UnitQuaternion::identity()),
            imu_mounting: None,
            mounting_from_turns: false,
            mounting_fit: None,
            mounting_min_path_m: 3.0,
            nonholonomic_sigma_mps: 0.02,
            speed_scale_sigma: 0.02,
            fallback_zupt_gate_sigma: 5.0,
            speed_heading: Heading::Kept,
            speed_time_offset_s: 0.0,
            lever_arm_m: Vector3::zeros(),
            capacity: 256,
        }
    }
}

/// How many standard deviations (of the prior and the fit, in quadrature) the forward-axis
/// fit's speed scale may lie from the scale state's prior before the prior is taken as refuted
/// for this robot (a prior-data conflict check: M. Evans and H. Moshonov, "Checking for
/// prior-data conflict", Bayesian Analysis 1(4), 2006): 3, a 0.3 % two-sided tail.
pub const SCALE_CONFLICT_SIGMAS: f64 = 3.0;

/// The filter's speed scale checked against the forward-axis fit's once the fit's is
/// observable (its 1-sigma below [`HintConfig::speed_scale_sigma`]; [`ForwardFit`];
/// fractions: the hints read `1 + k` times the speed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScaleTaken {
    /// When, ns (sample clock).
    pub at_ns: u64,
    /// The fit's scale error and its 1-sigma.
    pub fit: (f64, f64),
    /// The filter's 1-sigma then.
    pub prior_sigma: f64,
    /// Whether the fit lay beyond [`SCALE_CONFLICT_SIGMAS`] of the filter's: its variance was
    /// then widened to cover the fit, which it took as a measurement; else nothing changed.
    pub prior_refuted: bool,
    /// The filter's scale error and 1-sigma after the check.
    pub taken: (f64, f64),
}

/// Where an estimated forward axis came from (no `--mount`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AxisSource {
    /// The speed hints' changes and turns against the specific force
    /// (`odometry::cruise::ForwardAxis`).
    SpeedChanges,
    /// The path the filter integrated from a rest against the hints' distance
    /// (`odometry::velocity_axis`).
    Path,
    /// Both, fused by their inverse variances (`odometry::velocity_axis::fuse`).
    Fused,
    /// An earlier pass over the same recording ([`HintConfig::mounting_fit`]).
    FirstPass,
}

impl AxisSource {
    /// The name reports use: `speed_changes`, `path` or `fused`.
    pub fn name(self) -> &'static str {
        match self {
            Self::SpeedChanges => "speed_changes",
            Self::Path => "path",
            Self::Fused => "fused",
            Self::FirstPass => "first_pass",
        }
    }
}

/// A trusted forward-axis fit (`crate::cruise::ForwardAxis`, `crate::velocity_axis`): the
/// mounting it gives, its yaw 1-sigma, and the speed hints' scale error it shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardFit {
    /// The mounting (sensor to body).
    pub mounting: UnitQuaternion<f64>,
    /// 1-sigma of its yaw, rad (from the residual variance's upper confidence bound): the
    /// fit's noise.
    pub sigma_rad: f64,
    /// 1-sigma of its yaw that a horizontal specific-force bias left by the reference (its
    /// tilt, accelerometer bias and the floor's slope) may have aliased into the fit, rad: a
    /// systematic error, common to every later speed hint.
    pub bias_sigma_rad: f64,
    /// The speed hints' scale error `k` (they read `1 + k` times the speed the specific force
    /// shows: `1 / |F| - 1`), fraction; `None` while the hints' own noise is half the
    /// excitation or more.
    pub scale: Option<f64>,
    /// 1-sigma of `scale`, fraction: the fit's noise and the bias's share, in quadrature.
    pub scale_sigma: f64,
}

impl ForwardFit {
    /// The yaw's whole 1-sigma, rad: the fit's noise and the bias's share, in quadrature.
    pub fn systematic_sigma_rad(&self) -> f64 {
        self.sigma_rad.hypot(self.bias_sigma_rad)
    }
}

/// What the forward axis estimated from the speed hints gave (`odometry::cruise::
/// ForwardAxis`, `odometry::velocity_axis`), for reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardAxisReport {
    /// When it was first trusted, ns (sample clock).
    pub trusted_at_ns: u64,
    /// Where the latest mounting came from.
    pub source: AxisSource,
    /// The latest fit: its mounting, its yaw 1-sigmas (the fit's noise, and the whole one the
    /// published position 1-sigma carries, [`ForwardFit::systematic_sigma_rad`]) and its speed
    /// scale error.
    pub fit: ForwardFit,
    /// What the filter took from the fit's scale once observable (`None`: not yet).
    pub scale_taken: Option<ScaleTaken>,
}

/// A configuration the stage cannot run with; the message names the field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("hint configuration `{field}`: {reason}")]
pub struct HintConfigError {
    /// The field, e.g. `max_age_s`.
    pub field: &'static str,
    /// What is wrong with it.
    pub reason: String,
}

impl HintConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), HintConfigError> {
        let positive = |field: &'static str, x: f64| {
            if x.is_finite() && x > 0.0 {
                Ok(())
            } else {
                Err(HintConfigError {
                    field,
                    reason: format!("must be finite and > 0, got {x}"),
                })
            }
        };
        positive("max_age_s", self.max_age_s)?;
        if !(self.delivery_s.is_finite() && self.delivery_s >= 0.0) {
            return Err(HintConfigError {
                field: "delivery_s",
                reason: format!("must be finite and >= 0, got {}", self.delivery_s),
            });
        }
        positive("mounting_min_path_m", self.mounting_min_path_m)?;
        if self.mounting_fit.is_some() && self.mounting_from_turns {
            return Err(HintConfigError {
                field: "mounting_from_turns",
                reason: "must be false with an earlier pass's mounting_fit".into(),
            });
        }
        positive("nonholonomic_sigma_mps", self.nonholonomic_sigma_mps)?;
        positive("speed_scale_sigma", self.speed_scale_sigma)?;
        positive("fallback_zupt_gate_sigma", self.fallback_zupt_gate_sigma)?;
        if !(self.lever_arm_m.iter().all(|x| x.is_finite()) && self.lever_arm_m.norm() <= 10.0) {
            return Err(HintConfigError {
                field: "lever_arm_m",
                reason: format!(
                    "must be finite and within 10 m, got {:?}",
                    self.lever_arm_m.as_slice()
                ),
            });
        }
        if !(self.speed_time_offset_s.is_finite()
            && self.speed_time_offset_s.abs() < self.max_age_s)
        {
            return Err(HintConfigError {
                field: "speed_time_offset_s",
                reason: format!(
                    "must be finite and within the maximum age ({} s), got {}",
                    self.max_age_s, self.speed_time_offset_s
                ),
            });
        }
        if self.capacity == 0 {
            return Err(HintConfigError {
                field: "capacity",
                reason: "must be >= 1".into(),
            });
        }
        Ok(())
    }
}

/// A hint the stage refuses; the message names the hint and the field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HintError {
    /// A field the flags declare valid is NaN or infinite.
    #[error("robot hint seq {seq}: {field} is not finite ({value})")]
    NotFinite {
        /// The hint's sequence number.
        seq: u64,
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A 1-sigma that is not > 0.
    #[error("robot hint seq {seq}: {field} must be > 0, got {value}")]
    BadSigma {
        /// The hint's sequence number.
        seq: u64,
        /// The field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The hint carries no time.
    #[error("robot hint seq {seq}: stamps.sample_ns is 0 (the time the hint describes)")]
    NoTime {
        /// The hint's sequence number.
        seq: u64,
    },
}

/// Checks the fields a hint's flags declare valid.
pub fn check_hint(h: &RobotHint) -> Result<(), HintError> {
    if h.stamps.sample_ns == 0 {
        return Err(HintError::NoTime { seq: h.seq });
    }
    let pairs = [
        (
            hint_flags::SPEED_VALID,
            ("forward_speed_mps", h.forward_speed_mps),
            ("forward_speed_sigma_mps", h.forward_speed_sigma_mps),
        ),
        (
            hint_flags::YAW_RATE_VALID,
            ("yaw_rate_rps", h.yaw_rate_rps),
            ("yaw_rate_sigma_rps", h.yaw_rate_sigma_rps),
        ),
    ];
    for (flag, (field, value), (sigma_field, sigma)) in pairs {
        if h.flags & flag == 0 {
            continue;
        }
        for (field, value) in [(field, value), (sigma_field, sigma)] {
            if !value.is_finite() {
                return Err(HintError::NotFinite {
                    seq: h.seq,
                    field,
                    value,
                });
            }
        }
        if sigma <= 0.0 {
            return Err(HintError::BadSigma {
                seq: h.seq,
                field: sigma_field,
                value: sigma,
            });
        }
    }
    Ok(())
}

/// The time from which samples may use a hint, ns: its publication (or its own time when it
/// carries none) plus the delivery allowance.
pub fn usable_from_ns(h: &RobotHint, delivery_ns: u64) -> u64 {
    let published = if h.stamps.acquired_ns == 0 {
        h.stamps.sample_ns
    } else {
        h.stamps.acquired_ns
    };
    published.saturating_add(delivery_ns)
}

/// Whether the hint says anything about rest (a stationary source bit is set).
pub fn has_rest_source(h: &RobotHint) -> bool {
    h.flags & (hint_flags::SOURCE_COMMANDED | hint_flags::SOURCE_ENCODERS) != 0
}

/// Yaw-rate sigmas beyond which a hint's own yaw rate says the robot turns.
pub const TURNING_SIGMAS: f64 = 3.0;

/// Whether the hint contradicts itself: its stationary bit is set while its own yaw rate,
/// where it carries one, lies beyond [`TURNING_SIGMAS`] of its 1-sigma from zero. A source
/// that calls a turn on the spot stationary (no forward speed: a controller's linear command,
/// or encoders counted as one forward wheel) would otherwise stop the heading: the zero-rate
/// update at that rest takes the turn for gyro bias (a simulated robot with such encoders lost
/// 109 deg of a 142 deg turn on the spot and ended 23.6 m off a 14.6 m drive). Such a hint
/// decides nothing about rest; the IMU's detector does.
pub fn turns_while_stationary(h: &RobotHint) -> bool {
    h.flags & hint_flags::STATIONARY != 0
        && h.flags & hint_flags::YAW_RATE_VALID != 0
        && h.yaw_rate_rps.abs() > TURNING_SIGMAS * h.yaw_rate_sigma_rps
}

/// Counters of the hints a stage has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HintStats {
    /// Hints accepted by `OdometryStage::hint`.
    pub received: u64,
    /// Hints that reached their delivery time and became the newest hint.
    pub consumed: u64,
    /// Hints skipped because a hint describing a later time had already been consumed.
    pub out_of_order: u64,
    /// Waiting hints dropped because the buffer was full.
    pub overflowed: u64,
    /// Speed updates applied.
    pub speed_updates: u64,
    /// Speed hints not applied: stale or older than the velocity history when their sample
    /// came, the mounting not yet known, or more than eight delivered at one sample.
    pub speed_skipped: u64,
    /// Rests the stationary hints decided whose gyro reading refuted the filter's gyro bias
    /// (`Navigator`'s zero-rate conflict: the bias widened and the reading taken).
    pub gyro_bias_refuted: u64,
}

impl std::fmt::Display for HintStats {
    /// One line for a person: `received 12, consumed 12, out of order 0, ...`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "received {}, consumed {}, out of order {}, overflowed {}, speed updates {}, \
             speed skipped {}, gyro bias refuted {}",
            self.received,
            self.consumed,
            self.out_of_order,
            self.overflowed,
            self.speed_updates,
            self.speed_skipped,
            self.gyro_bias_refuted
        )
    }
}

/// A first-in first-out ring of `Copy` values with its storage allocated once.
///
/// Hand-written rather than `VecDeque` so that a full ring overwrites its oldest entry
/// instead of growing (`VecDeque::push_back` reallocates).
#[derive(Debug)]
pub struct Ring<T> {
    buf: Vec<T>,
    head: usize,
    len: usize,
}

impl<T: Copy> Clone for Ring<T> {
    fn clone(&self) -> Self {
        Self {
            buf: self.buf.clone(),
            head: self.head,
            len: self.len,
        }
    }

    /// Copies `other` into this ring's storage: no allocation when the capacities are equal,
    /// and then only the values held are copied (the rest of the storage is never read).
    fn clone_from(&mut self, other: &Self) {
        let cap = other.buf.len();
        if self.buf.len() == cap {
            let (head, end) = (other.head, other.head + other.len);
            let wrapped = end.saturating_sub(cap);
            self.buf[head..end.min(cap)].copy_from_slice(&other.buf[head..end.min(cap)]);
            self.buf[..wrapped].copy_from_slice(&other.buf[..wrapped]);
        } else {
            self.buf.clone_from(&other.buf);
        }
        self.head = other.head;
        self.len = other.len;
    }
}

impl<T: Copy + Default> Ring<T> {
    /// A ring holding at most `capacity` values (at least 1).
    pub fn new(capacity: usize) -> Self {
        Self {
            buf: vec![T::default(); capacity.max(1)],
            head: 0,
            len: 0,
        }
    }

    /// Number of values held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the ring is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Appends `v`; when full, the oldest value is overwritten and returned.
    pub fn push(&mut self, v: T) -> Option<T> {
        let cap = self.buf.len();
        if self.len == cap {
            let old = self.buf[self.head];
            self.buf[self.head] = v;
            self.head = (self.head + 1) % cap;
            return Some(old);
        }
        self.buf[(self.head + self.len) % cap] = v;
        self.len += 1;
        None
    }

    /// The oldest value.
    pub fn front(&self) -> Option<&T> {
        (self.len > 0).then(|| &self.buf[self.head])
    }

    /// Removes and returns the oldest value.
    pub fn pop(&mut self) -> Option<T> {
        let v = *self.front()?;
        self.head = (self.head + 1) % self.buf.len();
        self.len -= 1;
        Some(v)
    }

    /// The `i`-th newest value (0 is the newest).
    pub fn newest(&self, i: usize) -> Option<&T> {
        (i < self.len).then(|| &self.buf[(self.head + self.len - 1 - i) % self.buf.len()])
    }

    /// Removes every value.
    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
    }

    /// The `i`-th oldest value (0 is the oldest).
    pub fn oldest(&self, i: usize) -> Option<&T> {
        (i < self.len).then(|| &self.buf[(self.head + i) % self.buf.len()])
    }

    /// The `i`-th oldest value, to change it in place (0 is the oldest).
    pub fn oldest_mut(&mut self, i: usize) -> Option<&mut T> {
        let cap = self.buf.len();
        (i < self.len).then(|| &mut self.buf[(self.head + i) % cap])
    }

    /// Whether the ring holds as many values as it can.
    pub fn is_full(&self) -> bool {
        self.len == self.buf.len()
    }
}

/// The mounting `R_bs` (sensor to body) from the body's forward and up directions expressed
/// in the sensor frame: body z is `up_s`, body x is `forward_s` with its component along
/// `up_s` removed, body y completes a right-handed frame. `None` when `forward_s` is (nearly)
/// parallel to `up_s` or either is zero.
pub fn mounting_from(forward_s: &Vector3<f64>, up_s: &Vector3<f64>) -> Option<UnitQuaternion<f64>> {
    let z = up_s.try_normalize(1e-12)?;
    let x = (forward_s - z * z.dot(forward_s)).try_normalize(1e-9 * forward_s.norm())?;
    let y = z.cross(&x);
    // Rows of R_bs are the body axes in the sensor frame.
    let r = Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]);
    Some(UnitQuaternion::from_rotation_matrix(
        &Rotation3::from_matrix_unchecked(r),
    ))
}

/// Estimates the IMU-to-body mounting from the first drive.
///
/// Method: a wheeled robot that does not slip moves along its body x axis, so its velocity in
/// the sensor frame is always along the body's forward axis expressed in the sensor frame,
/// whatever it turns: `v_s = R_bs^T (v, 0, 0)`. The sum of `q^-1 v_n dt` over forward driving
/// (the sensor-frame displacement) therefore points along body x in the sensor frame; body z
/// is the gravity-up direction at rest (the floor is level). The stage feeds it each motion's
/// velocities after their revision at the following rest (the zero-velocity updates have then
/// removed most of the velocity drift), and uses the result once [`HintConfig::
/// mounting_min_path_m`] of path has been gathered. It assumes the robot drives forward until
/// then; a reversing leg would point the estimate backwards.
///
/// The direction's 1-sigma ([`Self::yaw_sigma_rad`]) is the displacement's across the path
/// over its horizontal length (small angles), the displacement's taken as the sum of the
/// velocities' 1-sigmas given with them times their intervals: a velocity's error drifts, one
/// error over the path, so the 1-sigmas add rather than add in quadrature.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MountingEstimator {
    /// Sensor-frame displacement gathered, m.
    sum_s: Vector3<f64>,
    /// Path length gathered, m.
    path_m: f64,
    /// 1-sigma of the displacement across the path, m.
    across_m: f64,
}

impl MountingEstimator {
    /// Adds a velocity `v_s` (m/s, sensor frame) held for `dt_s` seconds, with its 1-sigma
    /// across the path `sigma_mps` (m/s; 0 where no 1-sigma is asked of the estimate).
    pub fn add(&mut self, v_s: &Vector3<f64>, sigma_mps: f64, dt_s: f64) {
        self.sum_s += v_s * dt_s;
        self.path_m += v_s.norm() * dt_s;
        self.across_m += sigma_mps * dt_s;
    }

    /// Path length gathered so far, m.
    pub fn path_m(&self) -> f64 {
        self.path_m
    }

    /// The mounting, from the displacement so far and the up direction `up_s` (sensor frame).
    pub fn mounting(&self, up_s: &Vector3<f64>) -> Option<UnitQuaternion<f64>> {
        mounting_from(&self.sum_s, up_s)
    }

    /// 1-sigma of the mounting's yaw, rad, `up_s` the up direction (sensor frame): the
    /// displacement's 1-sigma across the path over its horizontal length (the type's
    /// documentation); infinite before any horizontal displacement.
    pub fn yaw_sigma_rad(&self, up_s: &Vector3<f64>) -> f64 {
        let horizontal = (self.sum_s - up_s * up_s.dot(&self.sum_s)).norm();
        if horizontal > 0.0 {
            self.across_m / horizontal
        } else {
            f64::INFINITY
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn mounting_from_axes_recovers_a_rotation() {
        let r_bs = UnitQuaternion::from_euler_angles(0.05, -0.03, 1.2);
        let r_sb = r_bs.inverse();
        let forward_s = r_sb * Vector3::x() * 7.0 + r_sb * Vector3::z() * 0.3;
        let up_s = r_sb * Vector3::z();
        let got = mounting_from(&forward_s, &up_s).unwrap();
        assert_relative_eq!(got.angle_to(&r_bs), 0.0, epsilon = 1e-12);
        assert!(mounting_from(&up_s, &up_s).is_none());
        assert!(mounting_from(&Vector3::zeros(), &up_s).is_none());
    }

    /// 0.5 m/s along the sensor's -y for 4 s, each second's velocity known to 0.01 m/s across
    /// the path: 2 m with 0.04 m of drift across it, 0.02 rad; the first second alone, 0.02 rad
    /// as well (0.01 m over 0.5 m); a vertical component counts in neither.
    #[test]
    fn the_estimated_yaw_carries_the_drift_across_the_path() {
        let up = Vector3::z();
        let mut e = MountingEstimator::default();
        assert_eq!(e.yaw_sigma_rad(&up), f64::INFINITY);
        e.add(&Vector3::new(0.0, -0.5, 0.3), 0.01, 1.0);
        assert_relative_eq!(e.yaw_sigma_rad(&up), 0.02, epsilon = 1e-12);
        for _ in 0..3 {
            e.add(&Vector3::new(0.0, -0.5, 0.0), 0.01, 1.0);
        }
        assert_relative_eq!(e.yaw_sigma_rad(&up), 0.02, epsilon = 1e-12);
        let forward = e
            .mounting(&up)
            .unwrap()
            .inverse_transform_vector(&Vector3::x());
        assert_relative_eq!(forward, Vector3::new(0.0, -1.0, 0.0), epsilon = 1e-12);
    }

    #[test]
    fn ring_overwrites_its_oldest_value_when_full() {
        let mut r = Ring::<u32>::new(3);
        assert!(r.is_empty() && r.front().is_none());
        for v in 1..=3 {
            assert_eq!(r.push(v), None);
        }
        assert_eq!(r.push(4), Some(1));
        assert_eq!(
            (r.len(), r.front(), r.newest(0), r.newest(2)),
            (3, Some(&2), Some(&4), Some(&2))
        );
        assert_eq!(r.newest(3), None);
        assert_eq!(r.pop(), Some(2));
        assert_eq!(r.pop(), Some(3));
        r.push(5);
        assert_eq!((r.pop(), r.pop(), r.pop()), (Some(4), Some(5), None));
    }

    #[test]
    fn a_copy_holds_the_same_values_wrapped_or_not() {
        let mut a = Ring::<u32>::new(4);
        let mut b = Ring::<u32>::new(4);
        for v in 1..=6 {
            a.push(v);
            // Held values 2..=v (at most 4), wrapped around the storage's end from v = 5.
            b.clone_from(&a);
            let held = |r: &Ring<u32>| (0..r.len()).map(|i| *r.oldest(i).unwrap()).collect();
            let (x, y): (Vec<u32>, Vec<u32>) = (held(&a), held(&b));
            assert_eq!(x, y);
            assert_eq!(x.last(), Some(&v));
        }
        a.pop();
        b.clone_from(&a);
        assert_eq!((b.len(), b.front(), b.newest(0)), (3, Some(&4), Some(&6)));
        // A ring of another capacity takes the other's storage.
        let mut c = Ring::<u32>::new(2);
        c.clone_from(&a);
        assert_eq!((c.len(), c.front(), c.newest(0)), (3, Some(&4), Some(&6)));
    }

    #[test]
    fn an_earlier_pass_fit_with_a_fit_of_its_own_is_refused() {
        let fit = ForwardFit {
            mounting: UnitQuaternion::identity(),
            sigma_rad: 0.1,
            bias_sigma_rad: 0.0,
            scale: None,
            scale_sigma: f64::INFINITY,
        };
        let mut cfg = HintConfig {
            mounting_fit: Some(fit),
            ..HintConfig::default()
        };
        assert_eq!(cfg.validate(), Ok(()));
        cfg.mounting_from_turns = true;
        assert_eq!(cfg.validate().unwrap_err().field, "mounting_from_turns");
    }

    #[test]
    fn bad_hints_are_refused_naming_the_field() {
        let ok = RobotHint {
            stamps: ipc_types::Stamps {
                sample_ns: 1,
                ..Default::default()
            },
            seq: 4,
            flags: hint_flags::SPEED_VALID,
            forward_speed_mps: 0.5,
            forward_speed_sigma_mps: 0.01,
            ..Default::default()
        };
        assert_eq!(check_hint(&ok), Ok(()));
        let nan = RobotHint {
            forward_speed_mps: f64::NAN,
            ..ok
        };
        assert!(
            check_hint(&nan)
                .unwrap_err()
                .to_string()
                .contains("seq 4: forward_speed_mps")
        );
        let zero_sigma = RobotHint {
            forward_speed_sigma_mps: 0.0,
            ..ok
        };
        assert!(matches!(
            check_hint(&zero_sigma),
            Err(HintError::BadSigma {
                field: "forward_speed_sigma_mps",
                ..
            })
        ));
        // Fields the flags do not declare valid are not checked.
        let unflagged = RobotHint {
            flags: 0,
            forward_speed_mps: f64::NAN,
            ..ok
        };
        assert_eq!(check_hint(&unflagged), Ok(()));
        let timeless = RobotHint {
            stamps: ipc_types::Stamps::default(),
            ..ok
        };
        assert_eq!(check_hint(&timeless), Err(HintError::NoTime { seq: 4 }));
    }

    #[test]
    fn delivery_counts_from_publication() {
        let mut h = RobotHint::default();
        h.stamps.sample_ns = 1_000;
        assert_eq!(usable_from_ns(&h, 5), 1_005);
        h.stamps.acquired_ns = 3_000;
        assert_eq!(usable_from_ns(&h, 5), 3_005);
    }
}
