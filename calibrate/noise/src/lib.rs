//! IMU noise characterisation: the overlapping Allan deviation of a static recording, the
//! noise parameters fitted to it with their uncertainty, and their exports.
//!
//! Pipeline ([`analysis::analyze`], or [`run_allan`] for the `mems-calibrate allan` command):
//! 1. [`repair`]: torn reads (+-256-count errors from non-atomic register reads) are repaired
//!    and flagged `REPAIRED`; repeated samples are counted.
//! 2. [`series`]: accelerometer axes in m/s^2 (g times the configured gravity, by default
//!    `ipc_types::units::STANDARD_GRAVITY_MPS2`) and gyro axes in rad/s, sensor frame; gaps are
//!    counted, long ones split the record, and the sample interval is the mean within segments.
//! 3. [`allan`]: overlapping Allan variance at half-octave cluster times (O(n) per cluster time
//!    via cumulative sums), with chi-squared 1-sigma intervals from the equivalent degrees of
//!    freedom.
//! 4. [`fit`]: `AVAR = N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3` by non-negative generalised least
//!    squares with the estimates' covariance; each term resolved with a 1-sigma or reported as
//!    unresolved with an upper limit and the reason.
//! 5. [`params::NoiseParams`] (TOML, for the calibration file), [`kalibr`] (`imu.yaml`),
//!    [`plot`] (PNG), and [`floor`] (the displacement a static record drifts by from noise).
//!
//! [`synth`] generates records with known noise for tests and simulations.

pub mod allan;
pub mod analysis;
pub mod cli;
pub mod covariance;
pub mod fit;
pub mod floor;
pub mod kalibr;
/// The noise parameters as the calibration file stores them (they live in `calibrate`, which
/// the live processes link without this crate's analysis and plots).
pub use calibrate::noise_params as params;
pub mod plot;
/// The torn-read repair and repeat count (in `calibrate`, which `mems-odometry offline` and the
/// calibration fits use too).
pub use calibrate::repair;
pub mod series;
pub mod synth;

pub use analysis::{Options, Report, analyze};
pub use cli::{Args, run_allan};
pub use params::NoiseParams;
