//! The crate's one error type: every failure names the file and, where it applies, the 1-based
//! line (or MCAP message) and the field (column name) it was found in.

use std::path::{Path, PathBuf};
use std::{fmt, io};

/// Where in a file an error was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Position {
    /// 1-based line of a text file (the line the offending row starts on).
    Line(u64),
    /// 1-based index of a message in an MCAP file, counting all topics in file order.
    Message(u64),
}

/// A failure to read or write a recording, with its location.
///
/// Displays as `file:line: field "name": problem`, e.g.
/// `data.csv:17: field "ay_g": cannot parse "1.2.3" as a number`.
#[derive(Debug, thiserror::Error)]
#[error("{}{}: {kind}", .path.display(), location(.position, .field))]
pub struct Error {
    /// The file being read or written.
    pub path: PathBuf,
    /// Where in the file, when the problem is local to a line or message.
    pub position: Option<Position>,
    /// The column (CSV) or channel/field (MCAP) concerned, when there is one.
    pub field: Option<String>,
    /// What went wrong.
    pub kind: ErrorKind,
}

/// What went wrong, without the location (see [`Error`]).
#[derive(Debug, thiserror::Error)]
pub enum ErrorKind {
    /// The operating system refused to open, read or write the file.
    #[error("{0}")]
    Io(io::Error),
    /// A cell is not a number (or not an integer of the expected range, see `expected`).
    #[error("cannot parse {text:?} as {expected}")]
    Parse {
        /// The cell's text.
        text: String,
        /// What the cell should hold, e.g. "a number".
        expected: &'static str,
    },
    /// A cell holds NaN or an infinity, which no recording may contain.
    #[error("{text:?} is not a finite number")]
    NotFinite {
        /// The cell's text.
        text: String,
    },
    /// A row has fewer fields than the header; `field` names the first missing column.
    #[error("missing (the line has {found} fields, the header {expected})")]
    MissingField {
        /// Number of columns in the header.
        expected: usize,
        /// Number of fields on the line.
        found: usize,
    },
    /// A row has more fields than the header.
    #[error("extra field {text:?} (the line has {found} fields, the header {expected})")]
    ExtraField {
        /// The first field beyond the header's columns.
        text: String,
        /// Number of columns in the header.
        expected: usize,
        /// Number of fields on the line.
        found: usize,
    },
    /// A sample's time is earlier than the previous sample's.
    #[error("time goes backwards: {} s after {} s", seconds(*.t_ns), seconds(*.previous_ns))]
    TimeBackwards {
        /// This sample's time, ns.
        t_ns: u64,
        /// The previous sample's time, ns.
        previous_ns: u64,
    },
    /// A value is not a measurement the sensor can make (beyond its largest range, or not
    /// finite; see [`ipc_types::limits`]).
    #[error("{0}")]
    OutOfRange(ipc_types::limits::OutOfBounds),
    /// A sample's time is further after the previous sample's than any real gap
    /// ([`ipc_types::limits::MAX_STEP_S`]).
    #[error(
        "time jumps {} s ahead of the previous sample's ({} s); steps longer than {} s are not \
         a sampling gap",
        seconds(*.t_ns - *.previous_ns),
        seconds(*.previous_ns),
        ipc_types::limits::MAX_STEP_S
    )]
    TimeStep {
        /// This sample's time, ns.
        t_ns: u64,
        /// The previous sample's time, ns.
        previous_ns: u64,
    },
    /// A sample's time equals the previous sample's (a duplicated sample).
    #[error("duplicate time {} s (equal to the previous sample's)", seconds(*.t_ns))]
    DuplicateTime {
        /// The repeated time, ns.
        t_ns: u64,
    },
    /// An MCAP file holds several raw acquisition sessions where one was expected.
    #[error(
        "the raw stream holds {sessions} acquisition sessions: at raw sample {index} (from 0) \
         the sequence number restarts ({previous_seq} -> {seq}); read the sessions with \
         recording::mcap::read_all (Contents::raw_sessions)"
    )]
    SeveralSessions {
        /// Number of sessions.
        sessions: usize,
        /// Index among the raw samples of the second session's first sample.
        index: usize,
        /// Sequence number of the sample before it.
        previous_seq: u64,
        /// Its sequence number.
        seq: u64,
    },
    /// A streamed raw stream restarts: its sequence number does not increase.
    #[error(
        "the raw stream restarts at raw sample {index} (from 0): the sequence number goes \
         {previous_seq} -> {seq} (a second acquisition session; read the sessions with \
         recording::mcap::read_all, Contents::raw_sessions)"
    )]
    SessionRestart {
        /// Index among the raw samples of the second session's first sample.
        index: u64,
        /// Sequence number of the sample before it.
        previous_seq: u64,
        /// Its sequence number.
        seq: u64,
    },
    /// A header names a column the format does not define.
    #[error("unknown column (known columns: {known})")]
    UnknownColumn {
        /// The columns the format accepts, comma-separated.
        known: String,
    },
    /// A header names the same column twice.
    #[error("column appears twice in the header")]
    DuplicateColumn,
    /// A required column (or one of a group that must be complete) is absent from the header.
    #[error("column missing from the header{context}")]
    MissingColumn {
        /// Why the column is required, e.g. " (truth columns are all or none)"; may be empty.
        context: &'static str,
    },
    /// The file is not in any format this crate reads.
    #[error("not a recognised recording: {0}")]
    UnknownFormat(String),
    /// The content is well-formed but violates a rule of the format (the message says which).
    #[error("{0}")]
    Invalid(String),
    /// An MCAP file ends early (a killed writer) or is damaged; messages before the cut were
    /// readable.
    #[error("{0}")]
    Truncated(Truncation),
    /// The MCAP library rejected the file or a write.
    #[error("MCAP: {0}")]
    Mcap(::mcap::McapError),
    /// A message's JSON does not decode into the expected type.
    #[error("JSON: {0}")]
    Json(serde_json::Error),
    /// A protobuf message does not decode into the expected type.
    #[error("protobuf: {0}")]
    Protobuf(String),
}

impl Error {
    /// An error about the whole file.
    pub(crate) fn file(path: &Path, kind: ErrorKind) -> Self {
        Self {
            path: path.to_path_buf(),
            position: None,
            field: None,
            kind,
        }
    }

    /// An error at a line (and optionally a column) of a text file.
    pub(crate) fn line(path: &Path, line: u64, field: Option<&str>, kind: ErrorKind) -> Self {
        Self {
            path: path.to_path_buf(),
            position: Some(Position::Line(line)),
            field: field.map(str::to_owned),
            kind,
        }
    }

    /// An error at a message of an MCAP file; `field` names the topic or field.
    pub(crate) fn message(path: &Path, index: u64, field: Option<&str>, kind: ErrorKind) -> Self {
        Self {
            path: path.to_path_buf(),
            position: Some(Position::Message(index)),
            field: field.map(str::to_owned),
            kind,
        }
    }

    /// An I/O error on the file.
    pub(crate) fn io(path: &Path, source: io::Error) -> Self {
        Self::file(path, ErrorKind::Io(source))
    }
}

/// Shorthand for results of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Formats the location suffix of an error: `:17` or `: message 17`, then `: field "x"`.
fn location(position: &Option<Position>, field: &Option<String>) -> String {
    let mut out = match position {
        Some(Position::Line(line)) => format!(":{line}"),
        Some(Position::Message(index)) => format!(": message {index}"),
        None => String::new(),
    };
    if let Some(field) = field {
        out.push_str(&format!(": field {field:?}"));
    }
    out
}

/// Formats integer nanoseconds as exact decimal seconds, e.g. `12.000000345`.
pub(crate) fn seconds(ns: u64) -> String {
    format!("{}.{:09}", ns / 1_000_000_000, ns % 1_000_000_000)
}

/// Where a truncated or damaged MCAP file stops being readable.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Truncation {
    /// Complete messages read before the cut (all topics).
    pub messages_read: u64,
    /// What the MCAP reader found at the cut.
    pub reason: String,
}

impl fmt::Display for Truncation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the file ends early or is damaged after {} complete messages ({})",
            self.messages_read, self.reason
        )
    }
}
