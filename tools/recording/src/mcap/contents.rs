//! Whole-run reading into memory: [`read_all`] and what it returns, and the last sequence
//! numbers of a file.

use std::path::{Path, PathBuf};

use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};

use super::checks::RawChecks;
use super::codec::Topic;
use super::codec::events::RecorderEvent;
use super::codec::pose::PoseInFrame;
use super::reader::{Reader, SegmentRead};
use super::run::continues_run;
use super::scan;
use crate::error::{Error, ErrorKind, Result, Truncation};
use crate::{Format, Recording, Truth};

/// Everything [`read_all`] found in a file.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Contents {
    /// Raw samples in file order, exactly as recorded.
    pub raw: Vec<RawImuSample>,
    /// The acquisition sessions in `raw`, as index ranges in file order (none when `raw` is
    /// empty). A session ends where the sequence number does not increase: the publisher was
    /// restarted and counts from 0 again (an acquire restarted inside one recording, or two
    /// replays recorded into one file); its sample times may start over. Within a session,
    /// sample times strictly increase.
    pub raw_sessions: Vec<std::ops::Range<usize>>,
    /// Ground-truth records in file order.
    pub truth: Vec<Truth>,
    /// Corrected samples in file order.
    pub corrected: Vec<CorrectedImuSample>,
    /// Odometry states in file order (revisions included, where the odometry stage sent them).
    pub odometry: Vec<OdometryState>,
    /// Robot hints in file order.
    pub hints: Vec<RobotHint>,
    /// Poses derived from the odometry states, in file order.
    pub poses: Vec<PoseInFrame>,
    /// The recorder's events in file order.
    pub events: Vec<RecorderEvent>,
    /// Number of messages on other topics (not decoded).
    pub other_messages: u64,
    /// Set when the run's last segment ends early or is damaged (a killed recorder);
    /// everything before the cut is above.
    pub truncation: Option<Truncation>,
    /// The files read, in order: the run's first file and its successors
    /// ([`crate::segment`]), each with its own truncation (a segment whose recorder was killed
    /// ends early; the next one continues the run).
    pub segments: Vec<SegmentRead>,
}

impl Contents {
    /// The raw samples of session `index` of [`Contents::raw_sessions`].
    ///
    /// Panics if there is no such session.
    pub fn raw_session(&self, index: usize) -> &[RawImuSample] {
        &self.raw[self.raw_sessions[index].clone()]
    }

    /// The raw samples and truth as a [`Recording`] of `path`. Errors with
    /// [`ErrorKind::SeveralSessions`] if the raw stream restarts: a [`Recording`] is one
    /// session, in time order.
    pub(crate) fn into_recording(self, path: &Path) -> Result<Recording> {
        if let Some(second) = self.raw_sessions.get(1) {
            let kind = ErrorKind::SeveralSessions {
                sessions: self.raw_sessions.len(),
                index: second.start,
                previous_seq: self.raw[second.start - 1].seq,
                seq: self.raw[second.start].seq,
            };
            return Err(Error::file(path, kind));
        }
        Ok(Recording {
            source: path.to_path_buf(),
            format: Format::Mcap,
            samples: self.raw,
            truth: (!self.truth.is_empty()).then_some(self.truth),
            truncation: self.truncation,
            repairs: crate::LogRepairs::default(),
        })
    }
}

/// Reads every message of the known topics of an MCAP recording (raw, truth, corrected,
/// odometry, robot hints, pose, events), from the file at `path` and then from each of its
/// successor segments ([`crate::segment`]: files named as successors that begin with their
/// [`EventKind::Segment`](super::EventKind::Segment) event) as one run, each up to its cut if it was truncated
/// (reported in [`Contents::segments`], and for the last in [`Contents::truncation`], never
/// silently).
///
/// Raw samples are split into acquisition sessions where their sequence number restarts
/// ([`Contents::raw_sessions`]). Errors if the file is not MCAP, a message does not decode, a
/// raw sample holds a value the sensor cannot produce ([`limits::check_raw`](ipc_types::limits::check_raw)), or raw sample
/// times (`stamps.sample_ns`) do not strictly increase within a session or step further than
/// [`limits::MAX_STEP_S`](ipc_types::limits::MAX_STEP_S).
pub fn read_all(path: impl AsRef<Path>) -> Result<Contents> {
    let path = path.as_ref();
    let mut contents = Contents::default();
    // The first file is read even if missing, for its error.
    let segments = crate::segment::existing(path);
    for (n, segment) in segments
        .iter()
        .map(PathBuf::as_path)
        .chain(segments.is_empty().then_some(path))
        .enumerate()
    {
        if n > 0 && !continues_run(segment, n)? {
            break;
        }
        let (truncation, damaged) = read_segment(segment, &mut contents)?;
        contents.segments.push(SegmentRead {
            path: segment.to_path_buf(),
            truncation: truncation.clone(),
            damaged,
        });
        contents.truncation = truncation;
    }
    Ok(contents)
}

/// Appends the messages of one file to `contents`; returns its truncation, if any, and the
/// damaged records skipped.
fn read_segment(
    path: &Path,
    contents: &mut Contents,
) -> Result<(Option<Truncation>, Vec<scan::Damage>)> {
    let reader = Reader::open(path)?;
    let mut messages = reader.messages()?;
    while let Some(message) = messages.next() {
        let message = match message {
            Ok(message) => message,
            Err(Error {
                kind: ErrorKind::Truncated(truncation),
                ..
            }) => return Ok((Some(truncation), messages.damaged().to_vec())),
            Err(e) => return Err(e),
        };
        if let Some(sample) = message.decode::<RawImuSample>() {
            let sample = sample?;
            let mut checks = RawChecks {
                previous: contents.raw.last().map(|p| (p.seq, p.stamps.sample_ns)),
            };
            if checks.check(&reader.path, message.index, &message.topic, &sample)? {
                let start = contents.raw.len();
                contents.raw_sessions.push(start..start);
            }
            contents.raw.push(sample);
            if let Some(session) = contents.raw_sessions.last_mut() {
                session.end = contents.raw.len();
            }
        } else if let Some(truth) = message.decode::<Truth>() {
            contents.truth.push(truth?);
        } else if let Some(sample) = message.decode::<CorrectedImuSample>() {
            contents.corrected.push(sample?);
        } else if let Some(state) = message.decode::<OdometryState>() {
            contents.odometry.push(state?);
        } else if let Some(hint) = message.decode::<RobotHint>() {
            contents.hints.push(hint?);
        } else if let Some(pose) = message.decode::<PoseInFrame>() {
            contents.poses.push(pose?);
        } else if let Some(event) = message.decode::<RecorderEvent>() {
            contents.events.push(event?);
        } else {
            contents.other_messages += 1;
        }
    }
    Ok((None, messages.damaged().to_vec()))
}

/// The last sequence number of each service in one MCAP file (odometry revisions excluded),
/// as (topic, seq), for a restarted recorder to name what was lost across the split. Reads up
/// to the cut of a truncated file.
pub fn last_seqs(path: impl AsRef<Path>) -> Result<Vec<(&'static str, u64)>> {
    let reader = Reader::open(path)?;
    let mut last: Vec<(&'static str, u64)> = Vec::new();
    let mut note = |topic: &'static str, seq: u64| match last.iter_mut().find(|(t, _)| *t == topic)
    {
        Some(entry) => entry.1 = seq,
        None => last.push((topic, seq)),
    };
    for message in reader.messages()? {
        let Ok(message) = message else { break };
        if let Some(s) = message.decode::<RawImuSample>() {
            note(RawImuSample::TOPIC, s?.seq);
        } else if let Some(s) = message.decode::<CorrectedImuSample>() {
            note(CorrectedImuSample::TOPIC, s?.seq);
        } else if let Some(s) = message.decode::<OdometryState>() {
            let s = s?;
            if s.flags & ipc_types::odometry_flags::REVISION == 0 {
                note(OdometryState::TOPIC, s.seq);
            }
        } else if let Some(s) = message.decode::<RobotHint>() {
            note(RobotHint::TOPIC, s?.seq);
        }
    }
    Ok(last)
}
