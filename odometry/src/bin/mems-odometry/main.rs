//! `mems-odometry`: odometry from calibrated samples, live (`serve`: `mems/imu/corrected` and
//! `mems/robot/hint` in, `mems/odometry/state` out) or offline over a raw recording (`offline`:
//! the calibration stage and the odometry stage in one process, the same code the live
//! processes run, with the recording's robot hints). `gyrocal` fits the gyro's scale and
//! misalignment correction from a recorded pose session into the calibration file.

mod gyrocal;
mod hint_args;
mod offline;
mod serve;

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Once;

use anyhow::Result;
use calibrate::calibfile::CalibrationFile;
use calibrate::zero_state::DetectorKind;
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
