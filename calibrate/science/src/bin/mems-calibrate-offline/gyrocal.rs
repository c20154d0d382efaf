//! `mems-calibrate gyrocal` (also run as `mems-odometry gyrocal`): fits the gyro's scale and misalignment correction from a recorded
//! pose session (static orientations with rotations in between, e.g. `mems-sim orientations`)
//! and optionally stores it in the calibration file's `[gyro]` table, where `mems-odometry
//! serve` and `offline` read it (`odometry::config::from_calibration`).
//!
//! The raw session goes through the calibration stage with the file (the code `offline` and
//! `mems-calibrate serve` run): the accelerometer corrected by the file's model, the gyro's
//! bias refined at rest, and the zero-state detector's flags marking the static poses. The
//! corrected samples go to [`calibrate_science::gyrocal::calibrate_gyro`]; its correction `C` gives
//! `omega = C w` (w the bias-free reading, rad/s) in the orthonormal frame closest to the
//! corrected accelerometer's axes, which is why it belongs with the accelerometer calibration
//! it was fitted through (`--into` refuses a file with a different one).
//!
//! The stage's GLRT is set up for a pose session rather than a robot on a floor: its test of
//! the accelerometer's window mean against the gravity vector learned at start-up is left out
//! (each pose holds another attitude), so rest is the gyro's mean at its bias and a small
//! scatter of both sensors, over a window of [`POSE_WINDOW_S`]. A fit whose largest 1-sigma
//! exceeds [`MAX_SIGMA`] is refused (poses that are not static, rotations missed).

use mems_stage::Stage;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig, Settler, calib_id};
use calibrate::zero_state::args::DetectorArgs;
use calibrate::zero_state::{DetectorConfig, DetectorKind};
use calibrate_science::gyrocal::{GyroCalConfig, GyroCalibration, calibrate_gyro};
use ipc_types::{CorrectedImuSample, RawImuSample, corrected_flags, raw_flags};
use nalgebra::Matrix3;
use serde_json::json;

/// Options of `mems-calibrate gyrocal`.
#[derive(clap::Args)]
pub struct GyroCalArgs {
    /// The accelerometer calibration the session is corrected with (TOML).
    #[arg(long)]
    calib: Option<PathBuf>,
    /// The detector marking the static poses (the vehicle profile's GLRT by default; its
    /// window is 1 s unless --glrt-window-s is given); the session starts at rest
    /// for `--learn-s`.
    #[command(flatten)]
    detector: DetectorArgs,
    /// Raw pose session (canonical CSV, thesis CSV or MCAP): at least 9 static poses of 2 s or
    /// more, with rotations about varied axes between them, starting at rest for `--learn-s`.
    #[arg(long)]
    input: PathBuf,
    /// Store the correction and its 1-sigma in this calibration file's `[gyro]` table (the rest
    /// of the file is kept). It must hold the same accelerometer calibration as --calib (the
    /// same file, usually).
    #[arg(long, value_name = "CALIB.toml")]
    into: Option<PathBuf>,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
}

/// The GLRT's tolerance on the accelerometer's mean at rest, m/s^2: each pose holds another
/// attitude, so the mean is left free (this exceeds any change of the specific force between
/// poses, 2 g, many times over) and rest is the gyro's mean at its bias and a small scatter
/// of both sensors over the window.
const POSE_ACCEL_TOLERANCE_MPS2: f64 = 1e3;

/// Length of the GLRT's window, s: long enough that the gyro's window mean resolves a slow
/// start of a rotation, short against a pose's hold.
const POSE_WINDOW_S: f64 = 1.0;

/// Largest 1-sigma of an entry of the correction that is accepted (dimensionless): a fifth of
/// the MPU-9250's 1% scale error, so that a stored correction always improves on none.
const MAX_SIGMA: f64 = 2e-3;

/// A 3x3 matrix as row-major arrays (the calibration file's and the JSON's layout).
fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|k| m[(r, k)]))
}

/// The calibration file `--into` names, checked to hold the same calibration as `file`.
fn load_target(
    args: &GyroCalArgs,
    calib_path: &Path,
    file: &CalibrationFile,
) -> Result<Option<CalibrationFile>> {
    let Some(path) = &args.into else {
        return Ok(None);
    };
    let target = CalibrationFile::load(path).context("cannot load calibration")?;
    if calib_id(&target) != calib_id(file) {
        bail!(
            "{} holds a different calibration than {} (calib_id {:016x} vs {:016x}): the \
             gyro correction is fitted through --calib's accelerometer calibration and \
             belongs in that file",
            path.display(),
            calib_path.display(),
            calib_id(&target),
            calib_id(file)
        );
    }
    Ok(Some(target))
}

/// The session's samples through the calibration stage, each with its final zero-state
/// verdict (the calibration's rest intervals need them).
fn correct_session(
    args: &GyroCalArgs,
    calib_path: &Path,
    file: &CalibrationFile,
    detector: DetectorConfig,
    samples: &[RawImuSample],
) -> Result<Vec<CorrectedImuSample>> {
    let mut stage = CalibrationStage::new(file, detector, RefineConfig::default())
        .map_err(|e| anyhow::anyhow!("{}: {e}", calib_path.display()))?;
    let mut corrected: Vec<CorrectedImuSample> = Vec::with_capacity(samples.len());
    let mut settler = Settler::default();
    for raw in samples {
        stage
            .process(raw, &mut |c: &CorrectedImuSample| {
                settler.push(c, &mut |c| corrected.push(*c))
            })
            .map_err(|e| anyhow::anyhow!("{}: {e}", args.input.display()))?;
    }
    stage.finish(&mut |_| {});
    settler.finish(&mut |c| corrected.push(*c));
    Ok(corrected)
}

/// Prints the correction and its 1-sigma (as JSON with `--json`).
fn print_correction(args: &GyroCalArgs, cal: &GyroCalibration) {
    let (c, sigma) = (rows(&cal.correction), rows(&cal.correction_sigma));
    if args.json {
        let result = json!({
            "correction": c,
            "correction_sigma": sigma,
            "poses": cal.poses,
            "residual_rms": cal.residual_rms,
            "accel_bias_mps2": [cal.accel_bias_mps2.x, cal.accel_bias_mps2.y, cal.accel_bias_mps2.z],
        });
        println!("{result}");
    } else {
        println!(
            "gyro correction C (omega = C w, sensor frame) from {} static poses of {}, residual \
             RMS {:.2e}:",
            cal.poses,
            args.input.display(),
            cal.residual_rms
        );
        for (row, s) in c.iter().zip(&sigma) {
            println!(
                "  [{:+.6} {:+.6} {:+.6}]  +- [{:.1e} {:.1e} {:.1e}]",
                row[0], row[1], row[2], s[0], s[1], s[2]
            );
        }
    }
}

/// Fits the correction, prints it and stores it when asked.
pub fn run(args: GyroCalArgs) -> Result<()> {
    let Some(calib_path) = &args.calib else {
        bail!(
            "gyrocal needs --calib: the correction is fitted through that accelerometer calibration"
        );
    };
    let file = CalibrationFile::load(calib_path).context("cannot load calibration")?;
    let mut detector = args
        .detector
        .apply(DetectorConfig::new(DetectorKind::Glrt, file.gravity_mps2))
        .map_err(anyhow::Error::msg)?;
    // Read the target first, so that a bad one fails before the fit.
    let mut target = load_target(&args, calib_path, &file)?;

    let recording = load_session(&args.input)?;
    if let Some(r) = recording
        .samples
        .iter()
        .find(|r| r.flags & raw_flags::GYRO_VALID == 0)
    {
        bail!(
            "{}: sample seq {} has no gyroscope (GYRO_VALID clear): a gyro calibration needs \
             gyro readings (record the session at a rate with the gyroscope)",
            args.input.display(),
            r.seq
        );
    }
    detector.glrt.accel_tolerance_mps2 = POSE_ACCEL_TOLERANCE_MPS2;
    if args.detector.glrt_window_s.is_none() {
        detector.glrt.window_s = POSE_WINDOW_S;
    }
    let corrected = correct_session(&args, calib_path, &file, detector, &recording.samples)?;
    let rest = corrected
        .iter()
        .filter(|c| c.flags & corrected_flags::ZERO_STATE != 0)
        .count();

    let cal =
        calibrate_gyro(&corrected, &GyroCalConfig::new(file.gravity_mps2)).with_context(|| {
            format!(
                "{}: {} of {} samples flagged at rest by the {} detector",
                args.input.display(),
                rest,
                corrected.len(),
                detector.kind.name()
            )
        })?;
    print_correction(&args, &cal);
    let largest = cal.correction_sigma.max();
    if largest > MAX_SIGMA {
        bail!(
            "{}: the fit is too uncertain to use (largest 1-sigma {largest:.1e} > {MAX_SIGMA:e}): \
             check that the session holds each pose still and that the {} detector's rest flags \
             ({rest} of {} samples) mark the poses",
            args.input.display(),
            detector.kind.name(),
            corrected.len()
        );
    }
    if let (Some(path), Some(target)) = (&args.into, target.as_mut()) {
        target.gyro.correction = Some(rows(&cal.correction));
        target.gyro.correction_sigma = Some(rows(&cal.correction_sigma));
        super::save(target, path, "--into", mems_files::Existing::Replace)?;
        tracing::info!("wrote the gyro correction into {} [gyro]", path.display());
    }
    Ok(())
}

/// The raw session, refusing a file with broken timing (as `mems-odometry offline
/// --strict-time`); a truncated file is reported and its readable part used.
fn load_session(path: &std::path::Path) -> Result<recording::Recording> {
    let recording = recording::load_raw_with(path, recording::LogPolicy::Strict)?;
    if let Some(t) = &recording.truncation {
        tracing::warn!("{}: {t}", path.display());
    }
    Ok(recording)
}
