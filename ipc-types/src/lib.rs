//! The wire format of mems-odometry: every payload that crosses a process boundary, the
//! service names, the iceoryx2 settings every process must agree on, and the MPU-9250 unit
//! conversions.
//!
//! Conventions, stated once for the whole project:
//! - Times are nanoseconds of `CLOCK_MONOTONIC` (`u64`), unless a name ends in `_s` (seconds).
//! - The sensor frame is the MPU-9250's accelerometer axes (x, y, z as printed on the part).
//! - Acceleration is *specific force*: at rest with z up the accelerometer reads +1 g on z.
//! - The navigation frame is z-up (x, y horizontal, fixed at the start of odometry); gravity in
//!   it is (0, 0, -g).
//! - Raw samples carry the sensor's own units (g, deg/s, degC); corrected samples and odometry
//!   carry SI units (m/s^2, rad/s, m, m/s).
//!
//! The C header `include/mems_ipc.h` mirrors these types byte for byte; tests pin sizes,
//! alignments and offsets on both sides.

pub mod clock;
pub mod limits;
pub mod service;
pub mod stop;
pub mod stream;
pub mod units;
pub mod wake;
mod wire;

pub use wire::*;
