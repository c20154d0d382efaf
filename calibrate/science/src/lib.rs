//! The offline calibration science of mems-odometry: fitting error models with their
//! uncertainty (labelled in [`fit`], label-free in [`labelfree`], both from `calibrate-fit`), static-segment detection
//! ([`segments`]) and calibration inputs ([`session`]), the gyro's scale and misalignment from a
//! pose session ([`gyrocal`]), the residual diagnosis ([`diagnose`]),
//! the evaluations of `mems-eval` ([`thesis_eval`], [`static_eval`], with [`integrate`] and
//! [`drerror`]) and their plots ([`plots`]). The binaries `mems-calibrate-offline` (the `fit`,
//! `diagnose`, `allan` and `gyrocal` subcommands of `mems-calibrate`) and `mems-eval` live here. The live
//! path these fits feed (model, calibration file, zero-state detectors, stage) is the
//! `calibrate` crate.
//!
//! Units: models and fits work in g (see `calibrate::model` for why "g" means local gravity);
//! sample times are nanoseconds, durations seconds (names ending in `_s`); displacement
//! evaluation is in SI (m/s^2, m).

pub use calibrate_fit::{fit, labelfree};

pub mod coverage;
pub mod diagnose;
pub mod drerror;
pub mod gyrocal;
pub mod integrate;
pub mod plots;
pub mod segments;
pub mod session;
pub mod static_eval;
pub mod thesis_eval;
