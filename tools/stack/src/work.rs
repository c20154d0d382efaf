//! The stack's work directory (under the temporary directory, named by the stack's process id),
//! and the cleaning up of what stacks killed with SIGKILL left behind.

use std::path::PathBuf;

use anyhow::{Context, Result};
use ipc_types::service;

/// Name of a stack's work directory under the temporary directory, before its process id.
const WORK_DIR_PREFIX: &str = "mems-stack-";

/// Creates this stack's work directory.
pub fn create() -> Result<PathBuf> {
    let work = std::env::temp_dir().join(format!("{WORK_DIR_PREFIX}{}", std::process::id()));
    std::fs::create_dir_all(&work).with_context(|| format!("cannot create {}", work.display()))?;
    Ok(work)
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
            .and_then(|p| p.parse::<i32>().ok())
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
