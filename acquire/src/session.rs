//! The sensor session that a restarted acquisition continues.
//!
//! A sensor session is one part sampled on one clock: its samples are numbered consecutively
//! from 0 (`RawImuSample::seq`) and timed on `CLOCK_MONOTONIC` (`stamps.sample_ns`), and a
//! simulated part's motion runs from the session's origin (its power-on). That is what every
//! stage downstream takes for one stream: a sequence number that goes back means a new
//! session. An acquisition process that is killed (SIGKILL, a crash) and restarted by its
//! supervisor has not changed the part nor its clock, so it continues the session: its first
//! sample takes the next sequence number and is flagged `GAP_BEFORE | RESUMED`, with
//! `lost_before` counting the sample periods not read while no process ran (a counted loss, a
//! hole of known length on the same time line, as after a FIFO overflow). The session's state is kept in a small file (the `--session`
//! of `mems-acquire`; `mems-stack` gives one in its private work directory), which survives the
//! process as Copper's `Freezable` task state survives a restart: the part's description, the
//! origin, and before each read's samples are published the next sequence number and the
//! newest sample's time. Written before publication, so a process killed between the write and
//! the publication skips numbers (a loss the subscribers see as missing numbers) and never
//! reuses one.
//!
//! A session is not continued (a new one starts, numbered from 0, and says why) when the file
//! describes another part or configuration, cannot be read back intact, or its newest sample
//! is more than [`limits::MAX_STEP_NS`] old (no stage bridges a longer hole).
//!
//! The state file: 40 bytes of little-endian u64 (a magic number, the origin ns, the next
//! sequence number, the newest sample's time ns, and a check word over those three), then the
//! part's description in UTF-8. Writes of the running fields are one `pwrite` of 24 bytes per
//! read: no allocation.

use std::fs::{File, OpenOptions};
use std::io::{self, Read};
use std::os::unix::fs::{FileExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

use ipc_types::limits;

/// First word of a session file: "MEMSSES1".
const MAGIC: u64 = u64::from_le_bytes(*b"MEMSSES1");
/// Byte offset of the running fields (next sequence number, newest time, check word).
const RUNNING_AT: u64 = 16;
/// Bytes before the part's description.
const HEADER_LEN: usize = 40;

/// Where a continued session stands: what the killed process had published.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Resume {
    /// The sequence number the next sample would have had.
    pub next_seq: u64,
    /// The newest sample's time, ns of `CLOCK_MONOTONIC` (0: none was read).
    pub last_sample_ns: u64,
}

/// An acquisition's sensor session, kept in its state file (or in memory only, without one).
#[derive(Debug)]
pub struct Session {
    file: Option<(File, PathBuf)>,
    origin_ns: u64,
    resume: Option<Resume>,
}

/// A session file that cannot be opened, read or written; the message names it.
#[derive(Debug, thiserror::Error)]
#[error("session file {}: {source}", path.display())]
pub struct SessionError {
    path: PathBuf,
    source: io::Error,
}

impl Session {
    /// A session kept nowhere: it starts at `now_ns` and ends with the process.
    pub fn transient(now_ns: u64) -> Self {
        Self {
            file: None,
            origin_ns: now_ns,
            resume: None,
        }
    }

    /// The session kept in `path` for the part described by `part` (its bus, address or
    /// simulation, and its configuration), at `now_ns`: the one the file holds when it
    /// describes the same part and its newest sample is at most [`limits::MAX_STEP_NS`] old,
    /// else a new one starting at `now_ns`, written to the file (created 0600; a symbolic link
    /// is not followed).
    pub fn open(path: &Path, part: &str, now_ns: u64) -> Result<Self, SessionError> {
        let err = |source| SessionError {
            path: path.to_path_buf(),
            source,
        };
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(path)
            .map_err(err)?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(err)?;
        let kept = match parse(&bytes, part) {
            Ok((origin_ns, resume)) if fresh(&resume, now_ns) => Some((origin_ns, resume)),
            Ok(_) => {
                tracing::info!(
                    "{}: the session's newest sample is over {} s old: a new sensor session",
                    path.display(),
                    limits::MAX_STEP_S
                );
                None
            }
            Err(why) => {
                if !bytes.is_empty() {
                    tracing::info!("{}: {why}: a new sensor session", path.display());
                }
                None
            }
        };
        let mut session = Self {
            file: Some((file, path.to_path_buf())),
            origin_ns: now_ns,
            resume: None,
        };
        match kept {
            Some((origin_ns, resume)) => {
                session.origin_ns = origin_ns;
                session.resume = Some(resume);
            }
            None => session.create(part).map_err(err)?,
        }
        Ok(session)
    }

    /// Writes a new session's file: header, origin, nothing read yet.
    fn create(&mut self, part: &str) -> io::Result<()> {
        let Some((file, _)) = &self.file else {
            return Ok(());
        };
        file.set_len(0)?;
        let mut bytes = Vec::with_capacity(HEADER_LEN + part.len());
        bytes.extend_from_slice(&MAGIC.to_le_bytes());
        bytes.extend_from_slice(&self.origin_ns.to_le_bytes());
        bytes.extend_from_slice(&running(self.origin_ns, 0, 0));
        bytes.extend_from_slice(part.as_bytes());
        file.write_all_at(&bytes, 0)
    }

    /// The session's origin, ns of `CLOCK_MONOTONIC`: when it started (a simulated part's
    /// power-on, from which its motion runs).
    pub fn origin_ns(&self) -> u64 {
        self.origin_ns
    }

    /// What the killed process had published, when this process continues its session
    /// (`None`: a new session, numbered from 0).
    pub fn resume(&self) -> Option<Resume> {
        self.resume
    }

    /// Notes that samples up to `next_seq` (excluded), the newest at `last_sample_ns`, are
    /// about to be published. No allocation.
    pub fn note(&mut self, next_seq: u64, last_sample_ns: u64) -> Result<(), SessionError> {
        let Some((file, path)) = &self.file else {
            return Ok(());
        };
        let bytes = running(self.origin_ns, next_seq, last_sample_ns);
        file.write_all_at(&bytes, RUNNING_AT)
            .map_err(|source| SessionError {
                path: path.clone(),
                source,
            })
    }
}

/// The running fields and their check word.
fn running(origin_ns: u64, next_seq: u64, last_sample_ns: u64) -> [u8; 24] {
    let mut out = [0u8; 24];
    out[..8].copy_from_slice(&next_seq.to_le_bytes());
    out[8..16].copy_from_slice(&last_sample_ns.to_le_bytes());
    out[16..].copy_from_slice(&check(origin_ns, next_seq, last_sample_ns).to_le_bytes());
    out
}

/// A check word over the fields that change (FNV-1a over their bytes): a torn or foreign
/// write does not pass for a session.
fn check(origin_ns: u64, next_seq: u64, last_sample_ns: u64) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for word in [origin_ns, next_seq, last_sample_ns] {
        for b in word.to_le_bytes() {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// The origin and the resume point a session file holds for `part`, or why it holds none.
fn parse(bytes: &[u8], part: &str) -> Result<(u64, Resume), &'static str> {
    if bytes.len() < HEADER_LEN {
        return Err("no session in it");
    }
    let word = |i: usize| u64::from_le_bytes(bytes[i * 8..i * 8 + 8].try_into().expect("8"));
    if word(0) != MAGIC {
        return Err("not a session file");
    }
    if &bytes[HEADER_LEN..] != part.as_bytes() {
        return Err("another part or configuration");
    }
    let (origin_ns, next_seq, last_sample_ns) = (word(1), word(2), word(3));
    if word(4) != check(origin_ns, next_seq, last_sample_ns) {
        return Err("its running fields are damaged");
    }
    Ok((
        origin_ns,
        Resume {
            next_seq,
            last_sample_ns,
        },
    ))
}

/// Whether a session whose newest sample is `resume`'s can be continued at `now_ns` (one that
/// published nothing has nothing to continue).
fn fresh(resume: &Resume, now_ns: u64) -> bool {
    resume.next_seq > 0
        && now_ns >= resume.last_sample_ns
        && now_ns - resume.last_sample_ns <= limits::MAX_STEP_NS
}

#[cfg(test)]
mod tests {
    use super::*;

    const PART: &str = "sim seed 1, 1000 Hz";

    #[test]
    fn a_session_file_is_continued_by_the_same_part_only() {
        let dir = tempfile_dir();
        let path = dir.join("acquire.session");
        let t0 = 5_000_000_000;
        let mut s = Session::open(&path, PART, t0).unwrap();
        assert_eq!((s.origin_ns(), s.resume()), (t0, None));
        s.note(1234, t0 + 1_233_000_000).unwrap();
        drop(s);
        // Reopened 0.3 s later: the same origin, where the first left off.
        let later = t0 + 1_533_000_000;
        let s = Session::open(&path, PART, later).unwrap();
        assert_eq!(s.origin_ns(), t0);
        assert_eq!(
            s.resume(),
            Some(Resume {
                next_seq: 1234,
                last_sample_ns: t0 + 1_233_000_000
            })
        );
        // Another part, or a hole no stage bridges: a new session, and the file says so.
        let mut other = Session::open(&path, "sim seed 2, 1000 Hz", later).unwrap();
        assert_eq!((other.origin_ns(), other.resume()), (later, None));
        other.note(1, later).unwrap();
        let s = Session::open(&path, "sim seed 2, 1000 Hz", later + 1).unwrap();
        assert_eq!(s.origin_ns(), later);
        let far = later + limits::MAX_STEP_NS + 1;
        let s = Session::open(&path, "sim seed 2, 1000 Hz", far).unwrap();
        assert_eq!((s.origin_ns(), s.resume()), (far, None));
        std::fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn a_damaged_or_foreign_file_starts_a_new_session() {
        let dir = tempfile_dir();
        let path = dir.join("acquire.session");
        let mut s = Session::open(&path, PART, 10).unwrap();
        s.note(7, 9).unwrap();
        drop(s);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[RUNNING_AT as usize] ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(parse(&bytes, PART), Err("its running fields are damaged"));
        let s = Session::open(&path, PART, 20).unwrap();
        assert_eq!((s.origin_ns(), s.resume()), (20, None));
        std::fs::write(&path, b"hello, world: not a session file at all").unwrap();
        let s = Session::open(&path, PART, 30).unwrap();
        assert_eq!((s.origin_ns(), s.resume()), (30, None));
        // A symbolic link is not followed.
        let link = dir.join("link.session");
        std::os::unix::fs::symlink(&path, &link).unwrap();
        assert!(Session::open(&link, PART, 40).is_err());
        std::fs::remove_dir_all(dir).unwrap();
    }

    fn tempfile_dir() -> PathBuf {
        tempfile::tempdir().unwrap().keep()
    }
}
