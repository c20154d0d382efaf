//! Accelerometer calibration for mems-odometry: the thesis's error models with their
//! uncertainty, labelled and label-free fitting, static-segment detection, torn-read repair,
//! calibration files, the evaluation used by `mems-calibrate` and `mems-eval`, and the live
//! side: zero-state detectors ([`zero_state`]) and the calibration stage ([`stage`]) behind
//! `mems-calibrate serve`.
//!
//! Units: models and fits work in g (see [`model`] for why "g" means local gravity); sample
//! times are nanoseconds, durations seconds (names ending in `_s`); corrected output and
//! displacement evaluation are in SI (m/s^2, m).

pub mod calibfile;
pub mod diagnose;
pub mod drerror;
pub mod fit;
pub mod integrate;
pub mod labelfree;
pub mod model;
pub mod noise_level;
pub mod plots;
pub mod repair;
pub mod segments;
pub mod session;
pub mod stage;
pub mod static_eval;
pub mod terms;
pub mod thesis_eval;
pub mod window;
pub mod zero_state;

/// The noise crate (Allan deviation, [`noise::NoiseParams`]), re-exported for the crates that
/// read a calibration file's `[noise]` table.
pub use noise;
