//! The calibration stage a `mems-calibrate serve` run starts with.

use anyhow::{Context, Result};
use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig};
use calibrate::zero_state::DetectorConfig;

use super::ServeArgs;

/// The calibration stage `args` ask for: the file's model and gravity, the detector and its
/// learning time, and, with `--state`, what a predecessor had learned.
pub fn stage(args: &ServeArgs, file: &CalibrationFile) -> Result<CalibrationStage> {
    let config = args
        .detector
        .apply(DetectorConfig::robot(file.gravity_mps2).for_file(file))
        .map_err(anyhow::Error::msg)?;
    let mut stage = CalibrationStage::new(file, config, RefineConfig::default())
        .with_context(|| args.calib_name())?;
    if let Some(path) = args.state.as_deref().filter(|p| p.exists()) {
        let state = calibrate::warm_file::load(path)?;
        stage
            .resume(&state)
            .with_context(|| format!("{}: cannot go on from it", path.display()))?;
        tracing::info!(
            "going on from {} (last sample seq {}, detector {}, refined {})",
            path.display(),
            state.last_seq,
            if state.reference.is_some() {
                "learned"
            } else {
                "not learned"
            },
            state.refined
        );
    }
    Ok(stage)
}
