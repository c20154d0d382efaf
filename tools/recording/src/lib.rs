//! Recordings of IMU sessions: the canonical CSV, MCAP, and readers for the capstone thesis's
//! files. Every reader reports malformed input with the file, line and field.
//!
//! - [`load_raw`] opens any raw time series (canonical CSV, a thesis time-series CSV, or MCAP)
//!   by sniffing its first bytes and header.
//! - [`csv`]: the canonical CSV ([`csv::read_raw`], [`csv::write_raw`]).
//! - [`mcap`]: MCAP recordings ([`mcap::Writer`], [`mcap::Reader`], [`mcap::read_all`]).
//! - [`thesis`]: the thesis's six-position means ([`load_six_position`]) and fitted parameters.
//!
//! Units follow `ipc-types`: raw samples in g, deg/s and degC in the sensor frame, times in
//! integer nanoseconds.

#![warn(missing_docs)]

pub mod csv;
mod error;
pub mod mcap;
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
}

/// Opens a raw time-series recording of any supported kind: MCAP (by its magic bytes), the
/// canonical CSV (a header naming `t_s`), or a thesis time-series CSV (its header on the first
/// line, or a title line and then its header). An MCAP file whose raw stream restarts (several
/// acquisition sessions) is refused naming the restart; [`mcap::read_all`] reads every session.
pub fn load_raw(path: impl AsRef<Path>) -> Result<Recording> {
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
        return csv::read_body(&mut rows, line, &header);
    }
    if thesis::is_series_header(first) {
        return thesis::read_series_body(&mut rows);
    }
    let first: Vec<String> = first.iter().map(str::to_owned).collect();
    match rows.next_row()? {
        Some((_, second)) if thesis::is_series_header(second) => {
            thesis::read_series_body(&mut rows)
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
