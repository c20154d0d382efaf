//! What `serve` and `offline` load before they run: the calibration file (with the stage
//! options `offline` shares with `mems-calibrate serve`), the odometry configuration it implies,
//! and raw recordings.

use std::path::{Path, PathBuf};
use std::sync::Once;

use anyhow::{Context, Result};
use calibrate::calibfile::CalibrationFile;
use calibrate::zero_state::DetectorConfig;
use calibrate::zero_state::args::DetectorArgs;
use odometry::config::OdometryConfig;
use odometry::profile::Profile;
use recording::LogPolicy;

/// The odometry configuration a calibration file implies ([`odometry::config::from_calibration`]:
/// its local gravity, `[gyro]` correction and `[noise]` table, the identity correction and the
/// MPU-9250 defaults for what it lacks; an uncalibrated gyro and the defaulted figures are named
/// once on stderr). `serve` and `offline` both use this, so that a
/// replayed recording reproduces the live states exactly.
pub fn odometry_config(file: &CalibrationFile) -> OdometryConfig {
    static NOTE: Once = Once::new();
    let calibrated = odometry::config::from_calibration(file);
    if let Some(note) = calibrated.defaults_note() {
        NOTE.call_once(|| tracing::info!("{note}"));
    }
    calibrated.config
}

/// Options of the calibration stage shared by `offline` with `mems-calibrate serve`'s defaults.
#[derive(clap::Args, Clone)]
pub struct StageArgs {
    /// Calibration file (TOML) written by `mems-calibrate fit`. Without it (offline), the
    /// identity calibration at standard gravity and the MPU-9250's datasheet noise: for a part
    /// calibrated at the factory or a first look at a recording.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// The zero-state detector (offline; live, it is `mems-calibrate serve`'s). Default: the
    /// profile's.
    #[command(flatten)]
    pub detector: DetectorArgs,
    /// Motion profile: the detector and rest handling for the platform; `auto` recognizes the
    /// platform from the recording (foot, wheeled, a walker's hand or other,
    /// `odometry::platform`).
    #[arg(long, value_enum, default_value_t = Profile::Auto)]
    pub profile: Profile,
}

impl StageArgs {
    /// The calibration file (or the identity when none is given, said once on stderr) and the
    /// detector settings these options give with `profile` (the resolved one); refuses a
    /// `learn_s` that is not positive and finite.
    pub fn load(&self, profile: Profile) -> Result<(CalibrationFile, DetectorConfig)> {
        let file = match &self.calib {
            Some(path) => CalibrationFile::load(path).context("cannot load calibration")?,
            None => {
                tracing::info!(
                    "no --calib: the identity calibration at standard gravity \
                     ({} m/s^2) and the MPU-9250's datasheet noise",
                    ipc_types::units::STANDARD_GRAVITY_MPS2
                );
                CalibrationFile::identity(ipc_types::units::STANDARD_GRAVITY_MPS2)
            }
        };
        let detector = self
            .detector
            .apply(profile.detector(file.gravity_mps2).for_file(&file))
            .map_err(anyhow::Error::msg)?;
        Ok((file, detector))
    }

    /// What `--calib` names, for messages.
    pub fn calib_name(&self) -> String {
        self.calib.as_ref().map_or_else(
            || "the identity calibration".into(),
            |p| p.display().to_string(),
        )
    }
}

/// Reads a raw recording (CSV or MCAP); a truncated one is read up to the cut, and what
/// `policy` repaired is counted, both reported on stderr.
pub fn load_recording(path: &Path, policy: LogPolicy) -> Result<recording::Recording> {
    let recording = recording::load_raw_with(path, policy)?;
    if let Some(t) = &recording.truncation {
        tracing::warn!("{}: {t}", path.display());
    }
    if recording.repairs.any() {
        tracing::warn!(
            "{}: {} (--strict-time refuses such a file)",
            path.display(),
            recording.repairs
        );
    }
    Ok(recording)
}
