//! The files and directories mems-odometry creates, made one way: private to the user (files
//! 0600, directories 0700), never written through a symbolic link, never over an existing
//! file unless `--force` says so, and replaced atomically.
//!
//! - [`Output`]: a command's output (`--out`, `--into`, `--state`). It is written to a private
//!   temporary file beside its path and renamed there by [`Output::commit`]; a run that fails
//!   (or a process killed) before that leaves no file at the path, and the temporary file is
//!   removed when the [`Output`] is dropped. Without `--force` an existing path (a file, a
//!   directory, a symbolic link, even a dangling one) is refused, before the run and again at
//!   the rename (`renameat2(RENAME_NOREPLACE)`); with it, the rename replaces what is there (a
//!   symbolic link is replaced, never followed).
//! - [`OutputPath`]: the same for a file that a library writes by path (a plot): a path in a
//!   private temporary directory beside the output, renamed there (0600) when committed.
//! - [`refuse_existing`]: the check of an output path before a long run, so that it fails
//!   early.
//! - [`create_new`]: a file written in place as it grows (the recorder's, which a killed
//!   recorder must leave at its path): created exclusively (`O_CREAT | O_EXCL`, which never
//!   follows a symbolic link), 0600.
//! - [`private_dir`]: a temporary directory (`mkdtemp`: a new random name, 0700).
//! - [`create_dir`]: an output directory, 0700 when created; an existing symbolic link is
//!   refused.

use std::fs::{DirBuilder, File, OpenOptions};
use std::io::{self, Write};
use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

use tempfile::{NamedTempFile, TempDir};

/// Permissions of every file created: read and write for the user only.
pub const FILE_MODE: u32 = 0o600;
/// Permissions of every directory created: the user only.
pub const DIR_MODE: u32 = 0o700;

/// A file or directory that could not be created or written; names its path (and the option
/// that gave it, if any).
#[derive(Debug, thiserror::Error)]
#[error("{}{}: {io}", .flag.map(|f| format!("{f} ")).unwrap_or_default(), .path.display())]
pub struct Error {
    /// The path.
    pub path: PathBuf,
    /// The command-line option that named it (`--out`), if any.
    pub flag: Option<&'static str>,
    /// What went wrong, without the path.
    pub io: io::Error,
}

impl Error {
    fn new(path: &Path, flag: Option<&'static str>, io: io::Error) -> Self {
        Self {
            path: path.to_path_buf(),
            flag,
            io,
        }
    }

    /// The error for an existing path that `--force` would replace.
    fn exists(path: &Path, flag: Option<&'static str>) -> Self {
        let io = io::Error::new(
            io::ErrorKind::AlreadyExists,
            "already exists; pass --force to replace it",
        );
        Self::new(path, flag, io)
    }
}

/// What an output does to a file already at its path.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Existing {
    /// Refuse to write (no `--force`).
    Refuse,
    /// Replace it, atomically (`--force`, or an `--into` that updates it).
    Replace,
}

impl Existing {
    /// [`Existing::Replace`] when `force` (the `--force` flag), else [`Existing::Refuse`].
    pub fn force(force: bool) -> Self {
        if force { Self::Replace } else { Self::Refuse }
    }
}

/// A command's output file being written: a private temporary file beside its path until
/// [`Output::commit`] renames it there (see the crate documentation).
#[derive(Debug)]
pub struct Output {
    path: PathBuf,
    flag: Option<&'static str>,
    existing: Existing,
    temp: NamedTempFile,
}

impl Output {
    /// Starts the output at `path`, given by option `flag` (for errors), or refuses it (an
    /// existing path without [`Existing::Replace`], or a directory that cannot be written).
    pub fn create(
        path: impl AsRef<Path>,
        flag: Option<&'static str>,
        existing: Existing,
    ) -> Result<Self, Error> {
        let path = path.as_ref();
        let (dir, prefix) = staging(path, flag, existing)?;
        let temp = tempfile::Builder::new()
            .prefix(&prefix)
            .suffix(".partial")
            .tempfile_in(dir)
            .map_err(|e| Error::new(path, flag, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            flag,
            existing,
            temp,
        })
    }

    /// The path the output will have.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The temporary file to write to.
    pub fn file(&mut self) -> &mut File {
        self.temp.as_file_mut()
    }

    /// Syncs the file and renames it to its path (over what is there only with
    /// [`Existing::Replace`]).
    pub fn commit(self) -> Result<(), Error> {
        let (path, flag) = (self.path, self.flag);
        self.temp
            .as_file()
            .sync_all()
            .map_err(|e| Error::new(&path, flag, e))?;
        let persisted = match self.existing {
            Existing::Replace => self.temp.persist(&path),
            Existing::Refuse => self.temp.persist_noclobber(&path),
        };
        persisted
            .map(drop)
            .map_err(|e| renamed_error(&path, flag, e.error))
    }
}

/// A command's output file that a library writes by path: [`OutputPath::temp_path`] is in a
/// private temporary directory beside the output, and [`OutputPath::commit`] makes the file
/// 0600 and renames it to the output's path (over what is there only with
/// [`Existing::Replace`]). Dropped uncommitted, it leaves nothing.
#[derive(Debug)]
pub struct OutputPath {
    path: PathBuf,
    flag: Option<&'static str>,
    existing: Existing,
    dir: TempDir,
    temp: PathBuf,
}

impl OutputPath {
    /// Starts the output at `path`, given by option `flag`, or refuses it (as
    /// [`Output::create`]).
    pub fn create(
        path: impl AsRef<Path>,
        flag: Option<&'static str>,
        existing: Existing,
    ) -> Result<Self, Error> {
        let path = path.as_ref();
        let (parent, prefix) = staging(path, flag, existing)?;
        let dir = tempfile::Builder::new()
            .prefix(&prefix)
            .suffix(".partial")
            .permissions(std::fs::Permissions::from_mode(DIR_MODE))
            .tempdir_in(parent)
            .map_err(|e| Error::new(path, flag, e))?;
        let temp = dir
            .path()
            .join(path.file_name().expect("checked by beside"));
        Ok(Self {
            path: path.to_path_buf(),
            flag,
            existing,
            dir,
            temp,
        })
    }

    /// Where to write the file.
    pub fn temp_path(&self) -> &Path {
        &self.temp
    }

    /// Makes the written file 0600 and renames it to its path.
    pub fn commit(self) -> Result<(), Error> {
        let (path, flag) = (&self.path, self.flag);
        let private = std::fs::Permissions::from_mode(FILE_MODE);
        std::fs::set_permissions(&self.temp, private).map_err(|e| Error::new(path, flag, e))?;
        let renamed = match self.existing {
            Existing::Replace => std::fs::rename(&self.temp, path),
            Existing::Refuse => {
                // A hard link fails on an existing path; the temporary name goes with the dir.
                std::fs::hard_link(&self.temp, path)
            }
        };
        renamed.map_err(|e| renamed_error(path, flag, e))?;
        drop(self.dir);
        Ok(())
    }
}

/// The error of renaming an output to `path`.
fn renamed_error(path: &Path, flag: Option<&'static str>, io: io::Error) -> Error {
    match io.kind() {
        io::ErrorKind::AlreadyExists => Error::exists(path, flag),
        _ => Error::new(path, flag, io),
    }
}

/// Refuses an existing `path` unless `existing` replaces it; then where its temporary file
/// goes and the prefix of its name (as [`beside`]).
fn staging<'a>(
    path: &'a Path,
    flag: Option<&'static str>,
    existing: Existing,
) -> Result<(&'a Path, std::ffi::OsString), Error> {
    if existing == Existing::Refuse {
        refuse_existing(path, flag)?;
    }
    beside(path, flag)
}

/// The directory of output `path` and the prefix of a temporary name beside it
/// (`.NAME.`); errors if `path` has no file name.
fn beside<'a>(
    path: &'a Path,
    flag: Option<&'static str>,
) -> Result<(&'a Path, std::ffi::OsString), Error> {
    let name = path.file_name().ok_or_else(|| {
        let io = io::Error::new(io::ErrorKind::InvalidInput, "is not a file name");
        Error::new(path, flag, io)
    })?;
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(name);
    prefix.push(".");
    Ok((dir, prefix))
}

/// Refuses an existing `path` (a file, a directory or a symbolic link, dangling or not), with
/// an error that names it, `flag` and `--force`: the check before a run whose output would be
/// refused at its end.
pub fn refuse_existing(path: impl AsRef<Path>, flag: Option<&'static str>) -> Result<(), Error> {
    let path = path.as_ref();
    match path.symlink_metadata() {
        Ok(_) => Err(Error::exists(path, flag)),
        Err(_) => Ok(()),
    }
}

/// Writes `bytes` as the output at `path` ([`Output::create`], then [`Output::commit`]).
pub fn write(
    path: impl AsRef<Path>,
    flag: Option<&'static str>,
    existing: Existing,
    bytes: &[u8],
) -> Result<(), Error> {
    let mut out = Output::create(path, flag, existing)?;
    let path = out.path().to_path_buf();
    out.file()
        .write_all(bytes)
        .map_err(|e| Error::new(&path, flag, e))?;
    out.commit()
}

/// Creates a new file at `path` to be written in place, 0600; an existing path (a symbolic
/// link included, dangling or not) is refused.
pub fn create_new(path: impl AsRef<Path>, flag: Option<&'static str>) -> Result<File, Error> {
    let path = path.as_ref();
    OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(FILE_MODE)
        .open(path)
        .map_err(|e| match e.kind() {
            io::ErrorKind::AlreadyExists => Error::exists(path, flag),
            _ => Error::new(path, flag, e),
        })
}

/// A new private temporary directory under `$TMPDIR`, named `prefix` and random characters
/// (0700, set explicitly: `tempfile` leaves a directory's mode to the umask; removed with
/// everything in it when dropped, unless kept with [`TempDir::keep`]).
pub fn private_dir(prefix: &str) -> Result<TempDir, Error> {
    tempfile::Builder::new()
        .prefix(prefix)
        .permissions(std::fs::Permissions::from_mode(DIR_MODE))
        .tempdir()
        .map_err(|e| Error::new(&std::env::temp_dir().join(prefix), None, e))
}

/// Makes sure the output directory `path` exists: creates it (and its missing parents) 0700;
/// an existing directory is kept, a symbolic link refused.
pub fn create_dir(path: impl AsRef<Path>, flag: Option<&'static str>) -> Result<(), Error> {
    let path = path.as_ref();
    if let Ok(meta) = path.symlink_metadata() {
        let io = if meta.file_type().is_symlink() {
            io::Error::other("is a symbolic link; give the directory itself")
        } else if !meta.is_dir() {
            io::Error::other("is not a directory")
        } else {
            return Ok(());
        };
        return Err(Error::new(path, flag, io));
    }
    DirBuilder::new()
        .recursive(true)
        .mode(DIR_MODE)
        .create(path)
        .map_err(|e| Error::new(path, flag, e))
}
