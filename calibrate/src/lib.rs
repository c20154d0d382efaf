//! The live calibration path of mems-odometry: what a process needs to turn raw samples into
//! calibrated ones. The accelerometer error model ([`model`]) and the calibration file that
//! holds it ([`calibfile`], with its optional terms in [`terms`] and noise table in
//! [`noise_params`]), the zero-state detectors ([`zero_state`]) and the calibration stage
//! ([`stage`]) behind `mems-calibrate serve` with the file its learned state is kept in
//! ([`warm_file`]), and the torn-read repair ([`repair`]) that
//! `mems-odometry offline` and the offline science apply to recordings. Fitting, diagnosis,
//! evaluations and plots are in `calibrate-science` (calibrate/science), whose binary runs the
//! offline subcommands ([`offline`]).
//!
//! Units: models work in g (see [`model`] for why "g" means local gravity); sample times are
//! nanoseconds, durations seconds (names ending in `_s`); corrected output is in SI (m/s^2).

pub mod calibfile;
pub mod gravity;
pub mod model;
pub mod noise_level;
pub mod noise_params;
pub mod offline;
pub mod repair;
pub mod stage;
pub mod terms;
pub mod warm_file;
pub mod window;
pub mod zero_state;
