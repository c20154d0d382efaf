//! Recordings that outlive their recorder: one run may span several files, its *segments*.
//!
//! A recorder that is restarted (a supervisor restarts a killed `mems-record`) never overwrites
//! the run it joins: it continues in the next segment, `run.1.mcap`, `run.2.mcap`, ... beside
//! `run.mcap` (the number goes before the extension; a name without extension gets `.1`, ...).
//! The new segment starts with an [`crate::mcap::EventKind::Segment`] event and records the
//! sequence numbers lost across the split as [`crate::mcap::EventKind::Gap`] events;
//! [`crate::mcap::read_all`] reads all segments of a run as one.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use crate::error::{Error, ErrorKind, Result};

/// The path of segment `n` of the run whose first segment is `base` (`n` = 0 is `base`).
pub fn path(base: &Path, n: u32) -> PathBuf {
    if n == 0 {
        return base.to_path_buf();
    }
    let mut name = OsString::from(base.file_stem().unwrap_or_default());
    name.push(format!(".{n}"));
    if let Some(ext) = base.extension() {
        name.push(".");
        name.push(ext);
    }
    base.with_file_name(name)
}

/// The files named as segments of the run at `base` that exist, in order: `base`, then its
/// successors up to the first number that does not exist (none when `base` does not exist).
/// A successor is part of the run only if it begins with its segment event (see
/// [`crate::mcap::read_all`]).
pub fn existing(base: &Path) -> Vec<PathBuf> {
    (0..)
        .map(|n| path(base, n))
        .take_while(|p| p.exists())
        .collect()
}

/// The first segment of the run at `base` that does not exist yet: where a recorder that
/// continues the run writes.
pub fn next_free(base: &Path) -> (u32, PathBuf) {
    (0..)
        .map(|n| (n, path(base, n)))
        .find(|(_, p)| !p.exists())
        .expect("some segment number is free")
}

/// Checks that a new run can be recorded at `base`, before anything is started: its directory
/// exists and is writable, and no segment of a run is there unless `force` (then the existing
/// segments are returned, for the caller to remove when it starts recording). Errors name the
/// path and what is wrong.
pub fn check_target(base: &Path, force: bool) -> Result<Vec<PathBuf>> {
    let fail = |what: String| Error::file(base, ErrorKind::Invalid(what));
    let dir = match base.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !dir.is_dir() {
        return Err(fail(format!("directory {} does not exist", dir.display())));
    }
    if base.is_dir() {
        return Err(fail("is a directory".into()));
    }
    // Successors count even without `base`: a new run would skip their numbers.
    let existing: Vec<PathBuf> = base
        .exists()
        .then(|| base.to_path_buf())
        .into_iter()
        .chain((1..).map(|n| path(base, n)).take_while(|p| p.exists()))
        .collect();
    if !existing.is_empty() && !force {
        let names: Vec<String> = existing.iter().map(|p| p.display().to_string()).collect();
        return Err(fail(format!(
            "a recording is already there ({}); choose another name or pass --force to \
             overwrite it",
            names.join(", ")
        )));
    }
    // Writable: create (and remove) a probe file in the directory.
    let probe = dir.join(format!(".mems-record-probe-{}", std::process::id()));
    mems_files::create_new(&probe, None)
        .map_err(|e| fail(format!("cannot write in {}: {}", dir.display(), e.io)))?;
    let _ = std::fs::remove_file(&probe);
    Ok(existing)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_dir(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("segment-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn successors_number_before_the_extension() {
        let base = Path::new("/data/run.mcap");
        assert_eq!(path(base, 0), base);
        assert_eq!(path(base, 1), Path::new("/data/run.1.mcap"));
        assert_eq!(path(base, 12), Path::new("/data/run.12.mcap"));
        assert_eq!(path(Path::new("a.b.mcap"), 2), Path::new("a.b.2.mcap"));
        assert_eq!(path(Path::new("run"), 3), Path::new("run.3"));
    }

    #[test]
    fn an_existing_run_is_refused_unless_forced_and_the_next_segment_is_free() {
        let dir = temp_dir("check");
        let base = dir.join("run.mcap");
        assert_eq!(check_target(&base, false).unwrap(), Vec::<PathBuf>::new());
        assert_eq!(next_free(&base), (0, base.clone()));
        std::fs::write(&base, b"x").unwrap();
        std::fs::write(path(&base, 1), b"x").unwrap();
        // Not consecutive: not part of the run.
        std::fs::write(path(&base, 3), b"x").unwrap();
        let err = check_target(&base, false).unwrap_err().to_string();
        assert!(
            err.contains("already there") && err.contains("--force"),
            "{err}"
        );
        assert!(err.contains("run.1.mcap"), "{err}");
        assert_eq!(
            check_target(&base, true).unwrap(),
            vec![base.clone(), path(&base, 1)]
        );
        assert_eq!(next_free(&base), (2, path(&base, 2)));
        // A successor alone is refused too.
        std::fs::remove_file(&base).unwrap();
        let err = check_target(&base, false).unwrap_err().to_string();
        assert!(err.contains("run.1.mcap"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_missing_directory_is_named() {
        let err = check_target(Path::new("/nonexistent-dir/x/run.mcap"), true)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("/nonexistent-dir/x/run.mcap") && err.contains("does not exist"),
            "{err}"
        );
    }
}
