//! What the benchmark examples of `mems-replay` share: finding the workspace binaries beside
//! them and running one to completion.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

/// The directory of the workspace binaries: `target/<profile>`, the parent of the
/// `examples` directory the running example lives in.
pub fn bin_dir() -> Result<PathBuf> {
    Ok(std::env::current_exe()?
        .parent()
        .and_then(Path::parent)
        .context("the example lives in target/<profile>/examples")?
        .to_path_buf())
}

/// Runs workspace binary `name` with `args` to completion; its stdout, or an error with its
/// stderr.
pub fn run(bins: &Path, name: &str, args: &[&str]) -> Result<String> {
    let out = Command::new(bins.join(name))
        .args(args)
        .output()
        .with_context(|| format!("cannot run {name}"))?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        bail!("{name} {args:?} failed: {}: {stderr}", out.status);
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Calibrates the simulated part `part` (`mems-sim` options, e.g. `--preset datasheet --seed
/// 1`) as `mems-stack` does: its six-position session at 200 Hz written to `session`, model 3
/// fitted from it into `calib`.
pub fn calibrate_part(bins: &Path, part: &[&str], session: &Path, calib: &Path) -> Result<()> {
    let text = |p: &Path| {
        p.to_str()
            .context("work path is not UTF-8")
            .map(str::to_owned)
    };
    let (session, calib) = (text(session)?, text(calib)?);
    let sim = ["six-position", "--rate", "200", "--out", &session];
    run(bins, "mems-sim", &[&sim[..], part].concat())?;
    let fit = [
        "fit", "--input", &session, "--model", "full", "--out", &calib,
    ];
    run(bins, "mems-calibrate", &fit)?;
    Ok(())
}
