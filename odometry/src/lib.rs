//! Odometry from calibrated IMU samples: gravity alignment, gyro-aided attitude, integration to
//! velocity and displacement with zero-velocity updates, and drift removal over motion
//! intervals. The stage is a plain state machine (sample in, states out) with no I/O, shared
//! by the live process and the offline runner. The gyro's scale and misalignment, which the
//! calibration stage does not correct, are fitted from a pose session by
//! `calibrate_science::gyrocal`. Robot
//! hints (the controller's rest and speed knowledge, [`hints`]) feed the same stage; over a
//! recording they reach it in the order a live pipeline receives them ([`arrival`]).
//! Measured accuracy on simulated drives: docs/odometry.md.

pub mod arrival;
pub mod attitudes;
pub mod axes;
pub mod clip;
pub mod config;
pub mod consistency;
pub mod cruise;
pub mod diagnose;
pub mod eskf;
pub mod hand_bound;
pub mod handover;
mod hindsight;
pub mod hints;
mod navigator;
pub mod nonholonomic;
pub mod platform;
pub mod profile;
pub mod rest_noise;
pub mod rest_scatter;
pub mod sampled_noise;
pub mod session;
pub mod speed_lag;
pub mod stage;
pub mod steps;
pub mod stops;
pub mod uncalibrated;
mod untrusted;
pub mod velocity_axis;
pub mod walking;
