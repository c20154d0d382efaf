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
