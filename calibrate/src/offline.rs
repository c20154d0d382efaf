//! Where the offline subcommands run: `mems-calibrate fit|diagnose|allan|gyrocal` and
//! `mems-odometry gyrocal` replace their process with `mems-calibrate-offline` (package
//! `calibrate-science`), so that the live processes link none of the fitting, plotting and
//! reporting code.

use std::ffi::OsStr;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::Command;

/// The binary that runs the offline subcommands.
pub const OFFLINE_BINARY: &str = "mems-calibrate-offline";

/// Replaces this process with `mems-calibrate-offline ARGS` (the subcommand first), found
/// beside the running executable (where cargo and `cargo install` put it), else on `PATH`.
/// Returns only when that cannot be started, with an error that names the binary and how to
/// build it.
pub fn exec_offline<I, S>(args: I) -> anyhow::Error
where
    I: IntoIterator<Item = S>,
    S: AsRef<OsStr>,
{
    let beside = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(|dir| dir.join(OFFLINE_BINARY)))
        .filter(|path| path.is_file());
    let program = beside.unwrap_or_else(|| PathBuf::from(OFFLINE_BINARY));
    let error = Command::new(&program).args(args).exec();
    anyhow::anyhow!(
        "the offline subcommands run in {OFFLINE_BINARY} (package calibrate-science), which \
         could not be started ({}: {error}); build it with `cargo build --release -p \
         calibrate-science`",
        program.display()
    )
}
