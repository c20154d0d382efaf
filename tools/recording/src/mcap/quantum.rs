//! The resolution at which the corrected samples and the odometry states are recorded: each
//! value is the nearest multiple of its quantum (a power of two), written as a `float`
//! (docs/recording.md, "Precision"). Each is far below the sensor's one count or the
//! estimate's 1-sigma.

/// Specific force, m/s^2: 2^-15 (31 um/s^2), 1/20 of one count at +-2 g (599 um/s^2).
pub const ACCEL_MPS2: f64 = 1.0 / (1u64 << 15) as f64;
/// Angular rate, rad/s: 2^-17 (7.6 urad/s), 1/17 of one count at +-250 deg/s
/// (133 urad/s).
pub const GYRO_RPS: f64 = 1.0 / (1u64 << 17) as f64;
/// Die temperature, degC: 2^-12 (0.24 mK), 1/12 of one count (3.0 mK).
pub const TEMP_C: f64 = 1.0 / (1u64 << 12) as f64;
/// Position, its 1-sigma and the distance travelled, m: 2^-16 (15 um).
pub const POSITION_M: f64 = 1.0 / (1u64 << 16) as f64;
/// Velocity and its 1-sigma, m/s: 2^-16 (15 um/s).
pub const VELOCITY_MPS: f64 = 1.0 / (1u64 << 16) as f64;
/// Attitude quaternion components: 2^-20 (about 2 urad of rotation).
pub const ATTITUDE: f64 = 1.0 / (1u64 << 20) as f64;

/// `value` as a recording gives it back at resolution `quantum`.
pub fn recorded(value: f64, quantum: f64) -> f64 {
    f64::from(super::proto::quantize(value, quantum))
}
