//! Ground truth of simulated sessions.

use serde::{Deserialize, Serialize};

/// Ground truth of a simulated session at one sample time.
///
/// Frames: navigation frame z-up (gravity (0, 0, -g) in it), sensor frame as in `ipc-types`.
/// `specific_force_mps2` is what an ideal accelerometer would read (rigid-body motion only; the
/// vibration disturbance of a drive is not part of it) and `angular_rate_rps` what an ideal gyro
/// would read, both in the sensor frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Sample time, ns (the same clock as the samples' `stamps.sample_ns`).
    pub t_ns: u64,
    /// Position in the navigation frame, m.
    pub position_m: [f64; 3],
    /// Velocity in the navigation frame, m/s.
    pub velocity_mps: [f64; 3],
    /// Attitude: unit quaternion (w, x, y, z) rotating sensor-frame vectors into the
    /// navigation frame.
    pub attitude_wxyz: [f64; 4],
    /// Ideal specific force in the sensor frame, m/s^2.
    pub specific_force_mps2: [f64; 3],
    /// Ideal angular rate in the sensor frame, rad/s.
    pub angular_rate_rps: [f64; 3],
    /// Whether the body is at rest (zero velocity, zero angular rate).
    pub at_rest: bool,
}
