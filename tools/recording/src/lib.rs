//! Recordings of IMU sessions: the canonical CSV, MCAP, and readers for the capstone thesis's
//! files. Every reader reports malformed input with the file, line and field.
//!
//! - [`load_raw`] opens any raw time series (canonical CSV, a thesis time-series CSV, or MCAP)
//!   by sniffing its first bytes and header; [`load_raw_with`] can repair the defects of real
//!   logs in the text formats ([`LogPolicy`]).
//! - [`csv`]: the canonical CSV ([`csv::read_raw`], [`csv::write_raw`]).
//! - [`folders`]: the recordings a command line names, folders expanded ([`folders::expand`]).
//! - [`mcap`]: MCAP recordings ([`mcap::Writer`], [`mcap::Reader`], [`mcap::read_all`]).
//! - [`segment`]: a run recorded across recorder restarts, in several files read as one.
//! - [`thesis`]: the thesis's six-position means ([`load_six_position`]) and fitted parameters.
//!
//! Units follow `ipc-types`: raw samples in g, deg/s and degC in the sensor frame, times in
//! integer nanoseconds.

#![warn(missing_docs)]

pub mod clock;
pub mod csv;
mod error;
pub mod folders;
pub mod mcap;
pub mod segment;
mod text;
pub mod thesis;
mod truth;

use std::path::{Path, PathBuf};

use ipc_types::RawImuSample;

pub use error::{Error, ErrorKind, Position, Result};
pub use thesis::load_six_position;
pub use truth::Truth;

/// The file format a [`Recording`] was read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// The canonical CSV ([`csv`]).
    CanonicalCsv,
    /// A thesis time-series CSV ([`thesis`]); accelerometer only.
    ThesisCsv,
    /// An MCAP file ([`mcap`]).
    Mcap,
}

/// A raw recording in memory.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The file it was read from.
    pub source: PathBuf,
    /// The file's format.
    pub format: Format,
    /// The samples in time order, `stamps.sample_ns` strictly increasing. From CSV files, `seq`
    /// is the row index and the counts are derived from the values (see [`csv`]); from MCAP,
    /// samples are exactly as recorded.
    pub samples: Vec<RawImuSample>,
    /// Ground truth when the file holds it: one per sample in the canonical CSV, as recorded
    /// on the truth channel in MCAP.
    pub truth: Option<Vec<Truth>>,
    /// Set when an MCAP file ends early (a killed recorder): what was read up to the cut.
    pub truncation: Option<mcap::Truncation>,
    /// What [`LogPolicy::Repair`] changed (all zero when reading strictly).
    pub repairs: LogRepairs,
}

/// How the text readers treat the defects of real logs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LogPolicy {
    /// Refuse a row whose time does not increase, naming its line.
    #[default]
    Strict,
    /// Repair what a logger commonly does to a sensor's stream:
    /// - a row whose values (accelerometer, gyroscope, temperature) equal the previous row's
    ///   exactly is a repeat (a logger that polls faster than the sensor) and is dropped: real
    ///   noise of a few counts makes two genuine successive samples equal on every channel
    ///   very unlikely (an accelerometer-only log of a quiet, coarsely quantised sensor is the
    ///   exception, and loses such samples);
    /// - a new sample whose time is equal to or before the previous one's (host timestamps
    ///   quantised or jittered) gets the previous time plus the nominal period: the median,
    ///   over consecutive distinct times, of their step divided by the rows between them (a
    ///   clock quantised to twice the period steps two periods every two rows);
    /// - a step back of more than [`MAX_TIME_REPAIR_S`] is not jitter and is refused, naming its
    ///   line.
    Repair,
}

/// Largest step back in time [`LogPolicy::Repair`] rebuilds, s.
pub const MAX_TIME_REPAIR_S: f64 = 1.0;

/// What [`LogPolicy::Repair`] changed in a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LogRepairs {
    /// Rows dropped as exact repeats of the previous one.
    pub repeats_dropped: u64,
    /// Samples whose time was rebuilt from the nominal period.
    pub times_rebuilt: u64,
    /// The nominal period used, ns (0 when nothing was rebuilt).
    pub period_ns: u64,
    /// Holes in the rows' times that nothing marked (`lost_before`, `GAP_BEFORE`), measured
    /// against the file's nominal period ([`ipc_types::stream`]), with the line after each;
    /// found under every policy and not repaired: the stages bridge them as gaps.
    pub holes: ipc_types::stream::Holes,
}

impl LogRepairs {
    /// Whether anything was changed.
    pub fn any(&self) -> bool {
        self.repeats_dropped > 0 || self.times_rebuilt > 0
    }
}

impl std::fmt::Display for LogRepairs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "dropped {} rows repeating the previous row's values; rebuilt {} sample times that \
             did not increase",
            self.repeats_dropped, self.times_rebuilt
        )?;
        if self.times_rebuilt > 0 {
            write!(
                f,
                ", from the nominal period {:.3} ms",
                self.period_ns as f64 * 1e-6
            )?;
        }
        Ok(())
    }
}

/// Opens a raw time-series recording of any supported kind: MCAP (by its magic bytes), the
/// canonical CSV (a header naming `t_s`), or a thesis time-series CSV (its header on the first
/// line, or a title line and then its header). An MCAP file whose raw stream restarts (several
/// acquisition sessions) is refused naming the restart; [`mcap::read_all`] reads every session.
pub fn load_raw(path: impl AsRef<Path>) -> Result<Recording> {
    load_raw_with(path, LogPolicy::Strict)
}

/// [`load_raw`] with `policy` for the text formats (MCAP recordings are our own recorder's,
/// strictly ordered, and always read strictly).
pub fn load_raw_with(path: impl AsRef<Path>, policy: LogPolicy) -> Result<Recording> {
    let path = path.as_ref();
    if mcap::has_magic(path)? {
        return mcap::read_all(path)?.into_recording(path);
    }
    let mut rows = text::Rows::open(path)?;
    let Some((line, first)) = rows.next_row()? else {
        let kind = ErrorKind::UnknownFormat("the file is empty".into());
        return Err(Error::file(path, kind));
    };
    if csv::is_canonical_header(first) {
        let header = first.clone();
        return csv::read_body(&mut rows, line, &header, policy);
    }
    if thesis::is_series_header(first) {
        return thesis::read_series_body(&mut rows, policy);
    }
    let first: Vec<String> = first.iter().map(str::to_owned).collect();
    match rows.next_row()? {
        Some((_, second)) if thesis::is_series_header(second) => {
            thesis::read_series_body(&mut rows, policy)
        }
        _ => {
            let kind = ErrorKind::UnknownFormat(format!(
                "{:?} is neither a canonical CSV header (naming t_s), a thesis time-series \
                 header (time,x (g),y (g),z (g)), nor a title line followed by one",
                first.join(",")
            ));
            Err(Error::line(path, line, None, kind))
        }
    }
}
