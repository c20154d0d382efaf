//! Odometry from calibrated IMU samples: gravity alignment, gyro-aided attitude, integration to
//! velocity and displacement with zero-velocity updates, and drift removal over motion
//! intervals. The stage is a plain state machine (sample in, states out) with no I/O, shared
//! by the live process and the offline runner.

pub mod eskf;
pub mod gyrocal;
pub mod stage;
