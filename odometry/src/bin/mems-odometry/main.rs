//! `mems-odometry`: odometry from calibrated samples, live (`serve`: `mems/imu/corrected` and
//! `mems/robot/hint` in, `mems/odometry/state` out) or offline over a raw recording (`offline`:
//! the calibration stage and the odometry stage in one process, the same code the live
//! processes run, with the recording's robot hints). `gyrocal` fits the gyro's scale and
//! misalignment correction from a recorded pose session into the calibration file.

mod gyrocal;
mod hint_args;
mod offline;
mod serve;

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Once;

use anyhow::{Context, Result, bail};
use calibrate::calibfile::CalibrationFile;
use calibrate::zero_state::{DetectorConfig, DetectorKind};
use clap::{Parser, Subcommand};
use odometry::stage::OdometryConfig;

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Subscribe to corrected samples and publish odometry states.
    Serve(serve::ServeArgs),
    /// Run calibration and odometry over a raw recording (CSV or MCAP).
    Offline(offline::OfflineArgs),
    /// Fit the gyro's scale and misalignment correction from a recorded pose session and
    /// optionally store it in the calibration file's [gyro] table.
    Gyrocal(gyrocal::GyroCalArgs),
}

/// The odometry configuration a calibration file implies ([`odometry::config::from_calibration`]:
/// its local gravity, `[gyro]` correction and `[noise]` table, the identity correction and the
/// MPU-9250 defaults for what it lacks; an uncalibrated gyro and the defaulted figures are named
/// once on stderr). `serve` and `offline` both use this, so that a
/// replayed recording reproduces the live states exactly.
pub fn odometry_config(file: &CalibrationFile) -> OdometryConfig {
    static NOTE: Once = Once::new();
    let calibrated = odometry::config::from_calibration(file);
    if let Some(note) = calibrated.defaults_note() {
        NOTE.call_once(|| eprintln!("mems-odometry: {note}"));
    }
    calibrated.config
}

/// Options of the calibration stage shared by `offline` with `mems-calibrate serve`'s defaults.
#[derive(clap::Args, Clone)]
pub struct StageArgs {
    /// Calibration file (TOML) written by `mems-calibrate fit`.
    #[arg(long)]
    pub calib: PathBuf,
    /// Zero-state detector (offline; live, it is `mems-calibrate serve`'s).
    #[arg(long, value_enum, default_value_t = DetectorKind::Glrt)]
    pub detector: DetectorKind,
    /// Start-up rest the detector learns from, s (offline; as `mems-calibrate serve --learn-s`).
    #[arg(long, default_value_t = 5.0)]
    pub learn_s: f64,
}

impl StageArgs {
    /// The calibration file and the detector settings these options give (the detector's
    /// defaults for the file's gravity, learning for `learn_s`); refuses a `learn_s` that is
    /// not positive and finite.
    pub fn load(&self) -> Result<(CalibrationFile, DetectorConfig)> {
        let file = CalibrationFile::load(&self.calib)
            .with_context(|| format!("cannot load calibration {}", self.calib.display()))?;
        if !(self.learn_s > 0.0 && self.learn_s.is_finite()) {
            bail!("--learn-s must be > 0, got {}", self.learn_s);
        }
        let mut detector = DetectorConfig::new(self.detector, file.gravity_mps2);
        detector.learn.duration_s = self.learn_s;
        Ok((file, detector))
    }
}

/// Reads a raw recording (CSV or MCAP); a truncated one is read up to the cut, which is
/// reported on stderr.
pub fn load_recording(path: &Path) -> Result<recording::Recording> {
    let recording = recording::load_raw(path)?;
    if let Some(t) = &recording.truncation {
        eprintln!("mems-odometry: {}: {t}", path.display());
    }
    Ok(recording)
}

fn main() -> ExitCode {
    let result: Result<()> = match Cli::parse().command {
        Command::Serve(args) => serve::run(args),
        Command::Offline(args) => offline::run(args),
        Command::Gyrocal(args) => gyrocal::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("mems-odometry: {e:#}");
            ExitCode::FAILURE
        }
    }
}
