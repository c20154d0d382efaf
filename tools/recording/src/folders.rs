//! The recordings a command line names: files as given, folders as the recordings in them.
//! `mems-calibrate diagnose` and `allan` and `mems-eval`'s earlier recordings take their
//! inputs this way.

use std::path::{Path, PathBuf};

/// Why [`expand`] failed.
#[derive(Debug, thiserror::Error)]
pub enum FolderError {
    /// A folder could not be listed.
    #[error("{}: {source}", path.display())]
    Unreadable {
        /// The folder.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A folder holds no recording.
    #[error("{}: no .csv or .mcap recordings in this folder", path.display())]
    Empty {
        /// The folder.
        path: PathBuf,
    },
}

/// The files `paths` name: files as given, and each folder as the `.csv` and `.mcap` files in
/// it (extensions in any case: `RUN.CSV` too) in natural order, digit runs compared as numbers
/// (`data_2.csv` before `data_10.csv`, as the thesis numbers its sessions). A folder that
/// cannot be listed or holds no recording is an error.
pub fn expand(paths: &[PathBuf]) -> Result<Vec<PathBuf>, FolderError> {
    let mut out = Vec::new();
    for p in paths {
        if !p.is_dir() {
            out.push(p.clone());
            continue;
        }
        let entries = std::fs::read_dir(p).map_err(|source| FolderError::Unreadable {
            path: p.clone(),
            source,
        })?;
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|f| f.is_file() && is_recording(f))
            .collect();
        if files.is_empty() {
            return Err(FolderError::Empty { path: p.clone() });
        }
        files.sort_by_key(|f| natural_key(&f.file_name().unwrap_or_default().to_string_lossy()));
        out.extend(files);
    }
    Ok(out)
}

/// Whether `path` has a recording's extension, `.csv` or `.mcap` in any case.
fn is_recording(path: &Path) -> bool {
    path.extension()
        .is_some_and(|x| x.eq_ignore_ascii_case("csv") || x.eq_ignore_ascii_case("mcap"))
}

/// Sort key comparing digit runs as numbers.
fn natural_key(name: &str) -> Vec<(u8, u64, String)> {
    let mut key = Vec::new();
    let mut chars = name.chars().peekable();
    while let Some(&c) = chars.peek() {
        let mut run = String::new();
        let digits = c.is_ascii_digit();
        while let Some(&d) = chars.peek() {
            if d.is_ascii_digit() != digits {
                break;
            }
            run.push(d);
            chars.next();
        }
        if digits {
            key.push((0, run.parse().unwrap_or(u64::MAX), String::new()));
        } else {
            key.push((1, 0, run));
        }
    }
    key
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_compares_numbers() {
        let mut names = [
            "start_up_data_10.csv",
            "start_up_data_2.csv",
            "start_up_data_1.csv",
        ];
        names.sort_by_key(|n| natural_key(n));
        assert_eq!(
            names,
            [
                "start_up_data_1.csv",
                "start_up_data_2.csv",
                "start_up_data_10.csv"
            ]
        );
    }

    #[test]
    fn folders_expand_to_their_recordings_in_natural_order() {
        let dir = std::env::temp_dir().join(format!("folders-expand-{}", std::process::id()));
        let (full, empty) = (dir.join("full"), dir.join("empty"));
        for d in [&full, &empty] {
            std::fs::create_dir_all(d).unwrap();
        }
        for name in ["run_10.csv", "run_2.MCAP", "run_1.csv", "notes.txt"] {
            std::fs::write(full.join(name), "").unwrap();
        }
        let given = dir.join("given.txt");
        let files = expand(&[full.clone(), given.clone()]).unwrap();
        let expected = ["run_1.csv", "run_2.MCAP", "run_10.csv"].map(|n| full.join(n));
        assert_eq!(files[..3], expected);
        assert_eq!(files[3], given, "a file is taken as given");
        let err = expand(&[empty]).unwrap_err().to_string();
        assert!(err.contains("no .csv or .mcap recordings"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
