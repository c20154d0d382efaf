//! The calibration file the stack runs with: `--calib`, or for a simulated source one made
//! now by the recipe of `mems_sim::calibration`.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};
use calibrate::calibfile::CalibrationFile;

use crate::cli::Cli;

/// The calibration file the stack runs with: `--calib`, or for a simulated source one
/// calibrated now in `work`; loaded and checked here ([`CalibrationFile::load`]), so that a
/// file the stages would refuse stops the stack before anything starts.
pub fn calibration(cli: &Cli, bins: &Path, work: &Path) -> Result<PathBuf> {
    let path = match (&cli.calib, cli.source.as_str()) {
        (Some(c), _) => c.clone(),
        (None, "sim" | "sim-spi") => calibrate_sim(bins, work, cli.seed)?,
        (None, other) => bail!("--calib is required for source {other}"),
    };
    CalibrationFile::load(&path)?;
    Ok(path)
}

/// Calibrates the simulated part in `work` with the binaries in `bins`
/// ([`mems_sim::calibration`]): the same simulated MPU-9250 as the live run (datasheet-level
/// errors) at another power-on (`seed` + 1000), so the turn-on bias is not known exactly.
fn calibrate_sim(bins: &Path, work: &Path, seed: u64) -> Result<PathBuf> {
    let recipe = mems_sim::calibration::recipe(work, seed + 1000);
    for step in &recipe.steps {
        run_step(&bins.join(step.program), &step.args)?;
    }
    Ok(recipe.calib)
}

/// Runs a preparatory command to completion, failing with its command line if it fails.
fn run_step(program: &Path, args: &[OsString]) -> Result<()> {
    let status = Command::new(program)
        .args(args)
        .status()
        .with_context(|| format!("cannot run {}", program.display()))?;
    if !status.success() {
        let args: Vec<_> = args.iter().map(|a| a.to_string_lossy()).collect();
        bail!("{} {} failed: {status}", program.display(), args.join(" "));
    }
    Ok(())
}
