//! The accelerometer error-model fits of mems-odometry, with their uncertainty: labelled poses
//! (a known gravity label per pose, linear least squares, [`fit`]) and label-free poses (only
//! the magnitude of gravity known, Levenberg-Marquardt, [`labelfree`]). A crate of its own so
//! that the odometry can fit an uncalibrated part's rests at several attitudes
//! (`odometry::attitudes`) without linking the offline science's plotting and progress bars;
//! `calibrate-science` re-exports both modules.
//!
//! Units: specific force in g (see `calibrate::model` for why "g" means local gravity).

pub mod fit;
pub mod labelfree;
