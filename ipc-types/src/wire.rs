//! The `#[repr(C)]` payloads. Every field is a fixed-size integer, an `f64`, or an array of
//! them; there is no implicit padding (reserved fields fill the gaps), so the layout is the same
//! in Rust, C (`include/mems_ipc.h`) and Python `ctypes`.
//!
//! Each type has an explicit iceoryx2 `type_name` carrying a format version: a change of
//! layout must change the version, so that old and new binaries refuse to connect instead of
//! misreading each other.

use iceoryx2::prelude::ZeroCopySend;
use serde::{Deserialize, Serialize};

/// Per-stage timestamps, nanoseconds of `CLOCK_MONOTONIC`, carried on every message so that
/// any subscriber can compute per-hop latency. A stage that has not touched the message leaves
/// its field 0.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ZeroCopySend)]
#[type_name("mems::Stamps.v1")]
#[repr(C)]
pub struct Stamps {
    /// The time the sensor sampled the data (reconstructed from the output rate, see acquire).
    pub sample_ns: u64,
    /// When the acquisition (or replay) process published the raw sample.
    pub acquired_ns: u64,
    /// When the calibration process published the corrected sample.
    pub calibrated_ns: u64,
    /// When the odometry process published the state.
    pub odometry_ns: u64,
}

/// Bits of [`RawImuSample::flags`].
pub mod raw_flags {
    /// Samples were lost immediately before this one (see `lost_before`).
    pub const GAP_BEFORE: u16 = 1 << 0;
    /// The FIFO overflowed before this sample; the driver reset it.
    pub const FIFO_OVERFLOW: u16 = 1 << 1;
    /// At least one axis is at the end of the configured full-scale range.
    pub const SATURATED: u16 = 1 << 2;
    /// The sample was repaired (e.g. a corrupted value replaced) before publication.
    pub const REPAIRED: u16 = 1 << 3;
    /// `gyro_dps` / `gyro_counts` hold a measurement.
    pub const GYRO_VALID: u16 = 1 << 4;
    /// `temp_c` / `temp_counts` hold a measurement.
    pub const TEMP_VALID: u16 = 1 << 5;
    /// The first sample of a restarted acquisition process that continues the sensor session
    /// (same part, same clock): set with `GAP_BEFORE`, and `lost_before` counts the samples
    /// not read while no process ran.
    pub const RESUMED: u16 = 1 << 6;
    /// Which axes are at the end of their full-scale range, one bit each with `SATURATED`:
    /// accelerometer x, y, z then gyroscope x, y, z ([`saturated_axis`]).
    pub const SATURATED_AXES: u16 = 0x3f << 7;

    /// The `SATURATED_AXES` bit of axis `i`: 0-2 accelerometer x, y, z; 3-5 gyroscope x, y, z.
    pub const fn saturated_axis(i: usize) -> u16 {
        1 << (7 + i)
    }
}

/// One raw IMU sample as the sensor produced it, in the sensor frame and the sensor's units.
///
/// Service `mems/imu/raw`. `accel_g` is `accel_counts / LSB-per-g` of the configured range
/// (see [`crate::units`]) for a live sensor; for recordings that only hold values in g (the
/// thesis files), `accel_g` is authoritative and the counts are the nearest integers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, ZeroCopySend)]
#[type_name("mems::RawImuSample.v1")]
#[repr(C)]
pub struct RawImuSample {
    /// Per-stage timestamps; `stamps.sample_ns` is the sample's own time.
    pub stamps: Stamps,
    /// Sequence number in the sensor session: consecutive from 0, one per sample published
    /// (samples the sensor lost are counted by `lost_before`, not numbered). A restarted
    /// acquisition that continues the session continues its numbers (`RESUMED`); a number
    /// that goes back starts a new session.
    pub seq: u64,
    /// Specific force in g, sensor frame.
    pub accel_g: [f64; 3],
    /// Angular rate in deg/s, sensor frame (valid with `raw_flags::GYRO_VALID`).
    pub gyro_dps: [f64; 3],
    /// Die temperature in degC (valid with `raw_flags::TEMP_VALID`).
    pub temp_c: f64,
    /// Accelerometer output in counts.
    pub accel_counts: [i16; 3],
    /// Gyroscope output in counts.
    pub gyro_counts: [i16; 3],
    /// TEMP_OUT in counts.
    pub temp_counts: i16,
    /// Bits from [`raw_flags`].
    pub flags: u16,
    /// Number of sensor samples lost immediately before this one (0 when none).
    pub lost_before: u32,
    /// Samples the publisher has given up delivering so far, before this one, because a
    /// subscriber's buffer stayed full (a stalled subscriber), summed over subscribers and
    /// saturating; 0 from publishers that do not count (a replay). Recordings made before
    /// this field was counted name it `reserved` and hold 0.
    #[serde(alias = "reserved")]
    pub undelivered: u32,
}

/// Bits of [`CorrectedImuSample::flags`].
pub mod corrected_flags {
    /// The zero-state (rest) detector classified the window containing this sample as rest.
    pub const ZERO_STATE: u16 = 1 << 0;
    /// The detector has learned its thresholds (before that, `ZERO_STATE` is never set).
    pub const DETECTOR_READY: u16 = 1 << 1;
    /// The bias was refined at rest since the calibration file was loaded.
    pub const BIAS_REFINED: u16 = 1 << 2;
    /// The sample's batch is not decided yet: `ZERO_STATE`, `DETECTOR_READY` and the
    /// `zs_*` fields are the latest verdict's, carried over. A later sample of the same batch
    /// settles it (see [`super::CorrectedImuSample::settles`]); a sample that no later sample
    /// settles (its batch was cut by a gap, a new stream or the end of the stream) keeps these
    /// flags as final.
    pub const PROVISIONAL: u16 = 1 << 3;
    /// The first sample of a new sensor session (a publisher that started its sequence
    /// numbers again, or a new time base): nothing before it belongs to the same power-on
    /// and clock. Set by the calibration stage on the first sample of every session after the
    /// stream's first (`crate::stream`: the rule); consumers follow it.
    pub const NEW_SESSION: u16 = 1 << 4;
    /// Samples are missing before this one that nothing marked: the time line has a hole
    /// (`crate::stream::TimeLine`). `raw_flags::GAP_BEFORE` is set too.
    pub const HOLE_BEFORE: u16 = 1 << 5;
    /// An axis of the raw sample sat at the end of its full-scale range
    /// (`raw_flags::SATURATED`; which axes: `raw_flags::SATURATED_AXES`): the true value was
    /// at least as large, by an unknown amount.
    pub const CLIPPED: u16 = 1 << 6;
    /// The sample fails the plausibility test of `crate::stream::plausible`: no platform of
    /// the profile makes such a specific force or rate. Set by the odometry stage, which knows
    /// the profile; the filter does not integrate it.
    pub const IMPLAUSIBLE: u16 = 1 << 7;
    /// The rest the detector learned from read gravity's magnitude further off than a
    /// calibrated accelerometer does (`calibrate::zero_state::learn::CALIBRATED_GRAVITY_ERROR`):
    /// the part is uncalibrated; or the part was declared uncalibrated (`--uncalibrated`),
    /// whatever its detector learned. The stage's bias refinement removes the error along gravity
    /// from the samples; the odometry widens its accelerometer prior (`odometry::uncalibrated`).
    pub const GRAVITY_OFF: u16 = 1 << 8;
}

/// One calibrated sample: sensor frame, SI units.
///
/// Service `mems/imu/corrected`. `accel_mps2 = S^-1 (a' - b)` with the calibration `calib_id`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, ZeroCopySend)]
#[type_name("mems::CorrectedImuSample.v3")]
#[repr(C)]
pub struct CorrectedImuSample {
    /// Per-stage timestamps copied from the raw sample, with `calibrated_ns` filled in.
    pub stamps: Stamps,
    /// Sequence number of the raw sample this was computed from.
    pub seq: u64,
    /// Calibrated specific force, m/s^2, sensor frame.
    pub accel_mps2: [f64; 3],
    /// Calibrated angular rate, rad/s, sensor frame.
    pub gyro_rps: [f64; 3],
    /// Die temperature, degC.
    pub temp_c: f64,
    /// Mean specific force over the detector window that decided `ZERO_STATE`, m/s^2.
    pub zs_mean_mps2: [f64; 3],
    /// Standard deviation over the same window, m/s^2.
    pub zs_std_mps2: [f64; 3],
    /// Identifier of the calibration applied (a hash of the calibration file's parameters).
    pub calib_id: u64,
    /// Bits from [`corrected_flags`].
    pub flags: u16,
    /// The raw sample's [`raw_flags`], passed through.
    pub raw_flags: u16,
    /// How many samples immediately before this one (all [`corrected_flags::PROVISIONAL`])
    /// this sample's verdict settles: their final `ZERO_STATE`, `DETECTOR_READY`, `zs_mean_mps2`
    /// and `zs_std_mps2` are this sample's. Zero on a provisional sample. (A recording made
    /// before samples were released provisionally holds zero here and no provisional flags:
    /// every flag final.)
    #[serde(alias = "reserved")]
    pub settles: u32,
    /// The accelerometer offset the calibration stage's bias refinement at rest subtracts
    /// from `accel_mps2` beyond the calibration file's bias, m/s^2, sensor frame (zero before
    /// its first refinement, and in recordings made before the field existed). A consumer
    /// that estimates the stream's residual bias itself (the odometry's filter) moves its
    /// estimate by the change of this offset: the refinement changes the stream's bias by
    /// exactly that much.
    #[serde(default)]
    pub refined_accel_mps2: [f64; 3],
    /// The gyroscope bias the same refinement subtracts from `gyro_rps` beyond the
    /// calibration file's, rad/s, sensor frame (zero before its first refinement, and in
    /// recordings made before the field existed). A consumer that estimates the stream's
    /// residual rate bias itself can tell the refinement's changes from its own.
    #[serde(default)]
    pub refined_gyro_rps: [f64; 3],
}

/// Bits of [`OdometryState::flags`].
pub mod odometry_flags {
    /// The filter considers the sensor at rest and applied a zero-velocity update.
    pub const ZERO_VELOCITY: u16 = 1 << 0;
    /// Gravity alignment is done; before it, position and velocity are held at zero.
    pub const ALIGNED: u16 = 1 << 1;
    /// This message revises an earlier state (drift removed after a motion interval ended);
    /// its `stamps.sample_ns` is the time of the state it replaces.
    pub const REVISION: u16 = 1 << 2;
    /// A fresh robot hint says the robot is stationary at this sample (applied as a
    /// zero-velocity update).
    pub const HINT_STATIONARY: u16 = 1 << 3;
    /// A fresh robot speed hint constrained the velocity at this sample.
    pub const HINT_SPEED: u16 = 1 << 4;
    /// Hints have been received, but the newest is older than the configured maximum age:
    /// the filter runs on the IMU alone.
    pub const HINT_STALE: u16 = 1 << 5;
    /// The fresh hint and the IMU's own zero-state detector disagree at this sample (one says
    /// rest, the other motion).
    pub const HINT_DISAGREE: u16 = 1 << 6;
    /// The sample has no gyroscope measurement (an accelerometer-only mode, such as the
    /// MPU-9250 at 4 kHz): the attitude cannot be tracked, so the filter neither aligns nor
    /// navigates; `ALIGNED` is clear and position and velocity are not estimated (zero).
    pub const NO_GYRO: u16 = 1 << 7;
    /// Samples were missing before this one (the raw stream flagged a gap, or the sequence
    /// skipped): the filter predicted across the gap and widened its 1-sigma for the motion
    /// the platform could have made in it (`manoeuvre_accel_mps2`, `manoeuvre_rate_rps`).
    pub const GAP_BEFORE: u16 = 1 << 8;
    /// Clipped or implausible input reached the filter at or before this sample since the
    /// last one without: the filter bridged what it did not see (an implausible sample as
    /// unobserved, a clipped axis with the unseen excess in its 1-sigma), so the state rests
    /// on less than the sensor's word.
    pub const UNTRUSTED_INPUT: u16 = 1 << 9;
    /// Wheeled platform without hints: the zero-state detector flagged rest, but the window
    /// that decided it vibrated more than the platform did standing at alignment
    /// (`OdometryConfig::rest_vibration_factor` times its standard deviation), or shook below
    /// 2 Hz more than it did standing (`odometry::stops`, without speed hints): the sample is
    /// taken as motion (no zero-velocity update), never silently as rest.
    pub const REST_VIBRATING: u16 = 1 << 11;
    /// Wheeled platform: the non-holonomic constraint (zero lateral and vertical body
    /// velocity) disagreed with the filter's velocity by more than its gate at this sample
    /// (a skid, a wrong mounting, or a drifting velocity): it was not applied.
    pub const NONHOLONOMIC_REJECTED: u16 = 1 << 12;
    /// Wheeled platform without speed hints: the zero-state detector flagged rest, but the
    /// filter's velocity was further from zero than its 1-sigma allows (a car cruising as
    /// smoothly as it stood): the sample is taken as motion, never silently as rest.
    pub const REST_MOVING: u16 = 1 << 13;
    /// Wheeled platform without speed hints: the zero-state detector found motion (its window
    /// vibrated more than its rest), but below 2 Hz the specific force and the angular rate
    /// were as quiet as standing at alignment, with no turn, and the filter's velocity did not
    /// contradict a stop (`odometry::stops`: a car stopped with its engine running): the
    /// sample is taken as rest, with a zero-velocity update.
    pub const VIBRATING_STOP: u16 = 1 << 14;
}

/// The odometry estimate at one sample time.
///
/// Service `mems/odometry/state`. Position and velocity are in the navigation frame (z up,
/// origin and heading fixed at alignment); sigmas are 1-sigma per axis.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, ZeroCopySend)]
#[type_name("mems::OdometryState.v2")]
#[repr(C)]
pub struct OdometryState {
    /// Per-stage timestamps, with `odometry_ns` filled in.
    pub stamps: Stamps,
    /// Sequence number of the raw sample this state was computed from.
    pub seq: u64,
    /// Displacement from the alignment point, m, navigation frame.
    pub position_m: [f64; 3],
    /// 1-sigma of `position_m`, m.
    pub position_sigma_m: [f64; 3],
    /// Velocity, m/s, navigation frame.
    pub velocity_mps: [f64; 3],
    /// 1-sigma of `velocity_mps`, m/s.
    pub velocity_sigma_mps: [f64; 3],
    /// Gravity's specific-force reaction in the sensor frame, m/s^2 (about (0, 0, +g) when
    /// the sensor lies level, z up).
    pub gravity_sensor_mps2: [f64; 3],
    /// Attitude: unit quaternion (w, x, y, z) rotating sensor-frame vectors into the
    /// navigation frame.
    pub attitude_wxyz: [f64; 4],
    /// Path length travelled since alignment, m.
    pub distance_m: f64,
    /// Bits from [`odometry_flags`].
    pub flags: u16,
    /// Zero; keeps the layout free of implicit padding. Not in the serde form (nor in any
    /// recording's schema): it carries nothing.
    #[serde(skip)]
    pub reserved16: u16,
    /// Number of rest intervals seen since alignment.
    pub rest_count: u32,
    /// Robot hints applied since alignment (stationary and speed updates).
    pub hints_applied: u32,
    /// Samples since alignment at which a fresh hint and the IMU detector disagreed (see
    /// [`odometry_flags::HINT_DISAGREE`]).
    pub hint_disagreements: u32,
}

/// Bits of [`RobotHint::flags`].
pub mod hint_flags {
    /// The robot is stationary (its wheels do not turn). Without this bit the hint says it
    /// moves or says nothing about rest (see the source bits).
    pub const STATIONARY: u16 = 1 << 0;
    /// The stationary state comes from the controller's command (zero velocity commanded).
    pub const SOURCE_COMMANDED: u16 = 1 << 1;
    /// The stationary state comes from the wheel encoders (zero measured speed).
    pub const SOURCE_ENCODERS: u16 = 1 << 2;
    /// `forward_speed_mps` and its sigma hold a measurement.
    pub const SPEED_VALID: u16 = 1 << 3;
    /// `yaw_rate_rps` and its sigma hold a measurement.
    pub const YAW_RATE_VALID: u16 = 1 << 4;
}

/// What the robot's own controller knows about its motion, published for the odometry.
///
/// Service `mems/robot/hint`. `stamps.sample_ns` is the time the hint describes, on the IMU
/// samples' clock (`CLOCK_MONOTONIC`, ns); `stamps.acquired_ns` is when the controller
/// published it; the other stamps are 0. The robot body frame is x forward, y left, z up
/// (REP 103); the rotation from the IMU's sensor frame to it is configuration of the odometry
/// process. A hint with neither source bit says nothing about rest.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize, ZeroCopySend)]
#[type_name("mems::RobotHint.v1")]
#[repr(C)]
pub struct RobotHint {
    /// `sample_ns`: the time the hint describes; `acquired_ns`: when it was published.
    pub stamps: Stamps,
    /// The hint publisher's own sequence number: consecutive, starting at 0.
    pub seq: u64,
    /// Forward speed along body x, m/s (valid with [`hint_flags::SPEED_VALID`]).
    pub forward_speed_mps: f64,
    /// 1-sigma of `forward_speed_mps`, m/s.
    pub forward_speed_sigma_mps: f64,
    /// Yaw rate about body z (counter-clockwise positive seen from above), rad/s (valid
    /// with [`hint_flags::YAW_RATE_VALID`]).
    pub yaw_rate_rps: f64,
    /// 1-sigma of `yaw_rate_rps`, rad/s.
    pub yaw_rate_sigma_rps: f64,
    /// Bits from [`hint_flags`].
    pub flags: u16,
    /// Zero; keeps the layout free of implicit padding. Not in the serde form (nor in any
    /// recording's schema): it carries nothing.
    #[serde(skip)]
    pub reserved16: u16,
    /// Zero; keeps the layout free of implicit padding. Not in the serde form.
    #[serde(skip)]
    pub reserved: u32,
}

/// What every message on a service carries, for tools that handle any of them (latency,
/// loss accounting, recording).
pub trait Message: Copy + core::fmt::Debug + ZeroCopySend + Serialize + 'static {
    /// The raw sample sequence number the message derives from.
    fn seq(&self) -> u64;
    /// The per-stage timestamps.
    fn stamps(&self) -> &Stamps;
    /// When the stage that publishes this message type published it, ns `CLOCK_MONOTONIC`.
    fn published_ns(&self) -> u64;
    /// Whether the message re-publishes an earlier sequence number on purpose (a revision);
    /// loss accounting skips these.
    fn is_revision(&self) -> bool {
        false
    }
    /// Samples the source lost immediately before this one and said so (a raw sample's
    /// `lost_before`: a FIFO overflow at the sensor); 0 for the stages' messages.
    fn lost_at_source(&self) -> u64 {
        0
    }
}

impl Message for RawImuSample {
    fn seq(&self) -> u64 {
        self.seq
    }
    fn stamps(&self) -> &Stamps {
        &self.stamps
    }
    fn published_ns(&self) -> u64 {
        self.stamps.acquired_ns
    }
    fn lost_at_source(&self) -> u64 {
        u64::from(self.lost_before)
    }
}

impl Message for CorrectedImuSample {
    fn seq(&self) -> u64 {
        self.seq
    }
    fn stamps(&self) -> &Stamps {
        &self.stamps
    }
    fn published_ns(&self) -> u64 {
        self.stamps.calibrated_ns
    }
}

impl Message for OdometryState {
    fn seq(&self) -> u64 {
        self.seq
    }
    fn stamps(&self) -> &Stamps {
        &self.stamps
    }
    fn published_ns(&self) -> u64 {
        self.stamps.odometry_ns
    }
    fn is_revision(&self) -> bool {
        self.flags & odometry_flags::REVISION != 0
    }
}

impl Message for RobotHint {
    fn seq(&self) -> u64 {
        self.seq
    }
    fn stamps(&self) -> &Stamps {
        &self.stamps
    }
    fn published_ns(&self) -> u64 {
        self.stamps.acquired_ns
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{align_of, offset_of, size_of};

    #[test]
    fn stamps_layout() {
        assert_eq!(size_of::<Stamps>(), 32);
        assert_eq!(align_of::<Stamps>(), 8);
        assert_eq!(offset_of!(Stamps, sample_ns), 0);
        assert_eq!(offset_of!(Stamps, acquired_ns), 8);
        assert_eq!(offset_of!(Stamps, calibrated_ns), 16);
        assert_eq!(offset_of!(Stamps, odometry_ns), 24);
    }

    #[test]
    fn raw_layout() {
        assert_eq!(size_of::<RawImuSample>(), 120);
        assert_eq!(align_of::<RawImuSample>(), 8);
        assert_eq!(offset_of!(RawImuSample, stamps), 0);
        assert_eq!(offset_of!(RawImuSample, seq), 32);
        assert_eq!(offset_of!(RawImuSample, accel_g), 40);
        assert_eq!(offset_of!(RawImuSample, gyro_dps), 64);
        assert_eq!(offset_of!(RawImuSample, temp_c), 88);
        assert_eq!(offset_of!(RawImuSample, accel_counts), 96);
        assert_eq!(offset_of!(RawImuSample, gyro_counts), 102);
        assert_eq!(offset_of!(RawImuSample, temp_counts), 108);
        assert_eq!(offset_of!(RawImuSample, flags), 110);
        assert_eq!(offset_of!(RawImuSample, lost_before), 112);
        assert_eq!(offset_of!(RawImuSample, undelivered), 116);
    }

    #[test]
    fn corrected_layout() {
        assert_eq!(size_of::<CorrectedImuSample>(), 208);
        assert_eq!(align_of::<CorrectedImuSample>(), 8);
        assert_eq!(offset_of!(CorrectedImuSample, stamps), 0);
        assert_eq!(offset_of!(CorrectedImuSample, seq), 32);
        assert_eq!(offset_of!(CorrectedImuSample, accel_mps2), 40);
        assert_eq!(offset_of!(CorrectedImuSample, gyro_rps), 64);
        assert_eq!(offset_of!(CorrectedImuSample, temp_c), 88);
        assert_eq!(offset_of!(CorrectedImuSample, zs_mean_mps2), 96);
        assert_eq!(offset_of!(CorrectedImuSample, zs_std_mps2), 120);
        assert_eq!(offset_of!(CorrectedImuSample, calib_id), 144);
        assert_eq!(offset_of!(CorrectedImuSample, flags), 152);
        assert_eq!(offset_of!(CorrectedImuSample, raw_flags), 154);
        assert_eq!(offset_of!(CorrectedImuSample, settles), 156);
        assert_eq!(offset_of!(CorrectedImuSample, refined_accel_mps2), 160);
        assert_eq!(offset_of!(CorrectedImuSample, refined_gyro_rps), 184);
    }

    #[test]
    fn odometry_layout() {
        assert_eq!(size_of::<OdometryState>(), 216);
        assert_eq!(align_of::<OdometryState>(), 8);
        assert_eq!(offset_of!(OdometryState, stamps), 0);
        assert_eq!(offset_of!(OdometryState, seq), 32);
        assert_eq!(offset_of!(OdometryState, position_m), 40);
        assert_eq!(offset_of!(OdometryState, position_sigma_m), 64);
        assert_eq!(offset_of!(OdometryState, velocity_mps), 88);
        assert_eq!(offset_of!(OdometryState, velocity_sigma_mps), 112);
        assert_eq!(offset_of!(OdometryState, gravity_sensor_mps2), 136);
        assert_eq!(offset_of!(OdometryState, attitude_wxyz), 160);
        assert_eq!(offset_of!(OdometryState, distance_m), 192);
        assert_eq!(offset_of!(OdometryState, flags), 200);
        assert_eq!(offset_of!(OdometryState, reserved16), 202);
        assert_eq!(offset_of!(OdometryState, rest_count), 204);
        assert_eq!(offset_of!(OdometryState, hints_applied), 208);
        assert_eq!(offset_of!(OdometryState, hint_disagreements), 212);
    }

    #[test]
    fn hint_layout() {
        assert_eq!(size_of::<RobotHint>(), 80);
        assert_eq!(align_of::<RobotHint>(), 8);
        assert_eq!(offset_of!(RobotHint, stamps), 0);
        assert_eq!(offset_of!(RobotHint, seq), 32);
        assert_eq!(offset_of!(RobotHint, forward_speed_mps), 40);
        assert_eq!(offset_of!(RobotHint, forward_speed_sigma_mps), 48);
        assert_eq!(offset_of!(RobotHint, yaw_rate_rps), 56);
        assert_eq!(offset_of!(RobotHint, yaw_rate_sigma_rps), 64);
        assert_eq!(offset_of!(RobotHint, flags), 72);
        assert_eq!(offset_of!(RobotHint, reserved16), 74);
        assert_eq!(offset_of!(RobotHint, reserved), 76);
    }
}
