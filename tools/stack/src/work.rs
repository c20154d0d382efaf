//! The stack's work directory (private, under the temporary directory, named by the stack's
//! process id and random characters), and the cleaning up of what stacks killed with SIGKILL
//! left behind.

use anyhow::Result;
use ipc_types::service;
use tempfile::TempDir;

/// Name of a stack's work directory under the temporary directory, before its process id.
const WORK_DIR_PREFIX: &str = "mems-stack-";

/// Creates this stack's work directory, `mems-stack-PID-` and random characters: a new
/// directory, 0700, never an existing path (a planted directory or symbolic link is not
/// used); removed when dropped.
pub fn create() -> Result<TempDir> {
    let prefix = format!("{WORK_DIR_PREFIX}{}-", std::process::id());
    Ok(mems_files::private_dir(&prefix)?)
}

/// Removes what a previous stack killed with SIGKILL left behind: the iceoryx2 resources of
/// dead nodes (its own and, if they died with it, its children's) and the work directories
/// of stacks whose process is gone.
pub fn clean_stale() {
    match service::remove_dead_nodes() {
        Ok(0) => {}
        Ok(n) => tracing::info!("removed the shared memory of {n} dead iceoryx2 nodes"),
        Err(e) => tracing::warn!("{e}"),
    }
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix(WORK_DIR_PREFIX))
            .and_then(|rest| rest.split_once('-'))
            .and_then(|(pid, _)| pid.parse::<i32>().ok())
        else {
            continue;
        };
        // SAFETY: kill(2) with signal 0 only checks whether the process exists.
        let gone = unsafe { libc::kill(pid, 0) } != 0
            && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH);
        if gone && std::fs::remove_dir_all(entry.path()).is_ok() {
            tracing::info!(
                "removed {}, left by a stack that died",
                entry.path().display()
            );
        }
    }
}
