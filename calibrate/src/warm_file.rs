//! The file of `mems-calibrate serve --state`: the calibration stage's [`WarmState`] as JSON,
//! written atomically (a private temporary file beside it, renamed over it) so that a process killed
//! while writing leaves the previous state, and read back by its successor.

use std::path::Path;

use anyhow::{Context, Result};

use crate::stage::WarmState;

/// Reads a state written by [`save`]; the error names the file.
pub fn load(path: &Path) -> Result<WarmState> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the state file {}", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: not a calibration stage state", path.display()))
}

/// Writes `state` to `path` atomically (`mems_files`: a private file beside it, 0600, renamed
/// over it; a symbolic link there is replaced, not followed).
pub fn save(path: &Path, state: &WarmState) -> Result<()> {
    let json = serde_json::to_string_pretty(state)?;
    let replace = mems_files::Existing::Replace;
    Ok(mems_files::write(
        path,
        Some("--state"),
        replace,
        json.as_bytes(),
    )?)
}
