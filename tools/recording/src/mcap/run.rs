//! A recorded run streamed: its first file and its successor segments ([`crate::segment`]) read
//! message by message, each file as it goes ([`super::scan::Scanner::stream`]), so that what is
//! held at a time is one chunk of one file, however long the run. Messages are decoded by their
//! channel's [`MessageEncoding`].
//!
//! [`RunReader`] yields every message; [`RawRun`] the raw samples, truth and robot hints of a
//! run with the checks of [`super::read_all`] (a restart of the raw stream is refused: one
//! acquisition session is replayed at a time).

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use ipc_types::{RawImuSample, RobotHint};

use super::checks::RawChecks;
use super::codec::events::{EventKind, RecorderEvent};
use super::codec::{MessageEncoding, Topic};
use super::reader::{SegmentRead, decode_as};
use super::scan::{ChannelInfo, Scanner};
use crate::Truth;
use crate::clock::WallClock;
use crate::error::{Error, ErrorKind, Result, Truncation};

/// One message of a run, borrowed from the reader until its next message.
#[derive(Debug)]
pub struct Message<'a> {
    /// The file it is in.
    pub path: &'a Path,
    /// 1-based index in its file, all topics counted.
    pub index: u64,
    /// Its channel.
    pub channel: &'a ChannelInfo,
    /// Its channel's encoding (`None`: no decoder reads it).
    pub encoding: Option<MessageEncoding>,
    /// MCAP log time, ns.
    pub log_time_ns: u64,
    /// MCAP publish time, ns.
    pub publish_time_ns: u64,
    /// The encoded message.
    pub data: &'a [u8],
}

impl Message<'_> {
    /// Decodes the message as a `T`, or `None` if it is on another topic. Errors if the
    /// channel's schema is not `T`'s, no decoder reads its encoding, or the message does not
    /// decode.
    pub fn decode<T: Topic>(&self) -> Option<Result<T>> {
        if self.channel.topic != T::TOPIC {
            return None;
        }
        let encoding = self
            .encoding
            .ok_or((&self.channel.encoding, &self.channel.schema_encoding));
        Some(decode_as(
            self.path,
            self.index,
            &self.channel.topic,
            &self.channel.schema_name,
            encoding,
            self.data,
        ))
    }
}

/// The file being read.
struct Current {
    path: PathBuf,
    scanner: Scanner<BufReader<File>>,
    /// Messages read from it.
    read: u64,
}

/// The messages of a run in file order, file after file (see the module documentation).
pub struct RunReader {
    /// The run's files not opened yet, with their segment number.
    pending: std::vec::IntoIter<(usize, PathBuf)>,
    current: Option<Current>,
    /// The last message's channel, encoding and data.
    channel: Option<(Rc<ChannelInfo>, Option<MessageEncoding>)>,
    data: Vec<u8>,
    segments: Vec<SegmentRead>,
    /// The wall clock of the newest file that had one.
    clock: Option<WallClock>,
}

impl RunReader {
    /// The run whose first file is `path`: `path`, then each successor segment that exists and
    /// begins with its segment event (as [`super::read_all`] reads them). Errors if `path`
    /// cannot be opened or is not MCAP.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let mut files: Vec<(usize, PathBuf)> = crate::segment::existing(path)
            .into_iter()
            .enumerate()
            .collect();
        if files.is_empty() {
            files.push((0, path.to_path_buf()));
        }
        let mut run = Self::of(files);
        run.advance()?;
        Ok(run)
    }

    /// The one file at `path`, without its successors.
    pub fn one(path: impl AsRef<Path>) -> Result<Self> {
        let mut run = Self::of(vec![(0, path.as_ref().to_path_buf())]);
        run.advance()?;
        Ok(run)
    }

    fn of(files: Vec<(usize, PathBuf)>) -> Self {
        Self {
            pending: files.into_iter(),
            current: None,
            channel: None,
            data: Vec::new(),
            segments: Vec::new(),
            clock: None,
        }
    }

    /// The wall clock the run's log and publish times are anchored to (the metadata record
    /// [`crate::clock::METADATA_NAME`] of the files read so far; a recorder writes it before
    /// its first message), `None` for a recording whose times are `CLOCK_MONOTONIC`.
    pub fn clock(&self) -> Option<WallClock> {
        self.clock
    }

    /// Opens the next file of the run, if any (a successor only if it continues the run).
    fn advance(&mut self) -> Result<()> {
        self.current = None;
        let Some((n, path)) = self.pending.next() else {
            return Ok(());
        };
        if n > 0 && !continues_run(&path, n)? {
            self.pending = Vec::new().into_iter();
            return Ok(());
        }
        let file = File::open(&path).map_err(|e| Error::io(&path, e))?;
        let len = file.metadata().map_err(|e| Error::io(&path, e))?.len();
        if !super::has_magic(&path)? {
            let kind = ErrorKind::UnknownFormat("does not start with the MCAP magic bytes".into());
            return Err(Error::file(&path, kind));
        }
        let scanner = Scanner::stream(file, len).map_err(|e| Error::io(&path, e))?;
        self.current = Some(Current {
            path,
            scanner,
            read: 0,
        });
        Ok(())
    }

    /// The files read so far, each with its truncation (a file that ends early or whose
    /// framing is damaged is read up to the cut, and the run goes on with its successor) and
    /// the damaged records skipped in it.
    pub fn segments(&self) -> &[SegmentRead] {
        &self.segments
    }

    /// The next message, `None` at the end of the run. An error ends the run (a truncation is
    /// no error: it is in [`Self::segments`]).
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Option<Result<Message<'_>>> {
        loop {
            let current = self.current.as_mut()?;
            let next = current.scanner.next_into(&mut self.data);
            if let Some((_, fields)) = current
                .scanner
                .metadata()
                .iter()
                .rev()
                .find(|(name, _)| name == crate::clock::METADATA_NAME)
            {
                self.clock = WallClock::from_metadata(fields).or(self.clock);
            }
            match next {
                Some(Ok((channel, log_time_ns, publish_time_ns))) => {
                    current.read += 1;
                    if self
                        .channel
                        .as_ref()
                        .is_none_or(|(c, _)| !Rc::ptr_eq(c, &channel))
                    {
                        let encoding =
                            MessageEncoding::of(&channel.encoding, &channel.schema_encoding);
                        self.channel = Some((channel, encoding));
                    }
                    let (channel, encoding) = self.channel.as_ref().expect("set above");
                    let current = self.current.as_ref().expect("read above");
                    return Some(Ok(Message {
                        path: &current.path,
                        index: current.read,
                        channel,
                        encoding: *encoding,
                        log_time_ns,
                        publish_time_ns,
                        data: &self.data,
                    }));
                }
                end => {
                    let truncation = end.and_then(|e| e.err()).map(|reason| Truncation {
                        messages_read: current.read,
                        reason,
                    });
                    self.segments.push(SegmentRead {
                        path: current.path.clone(),
                        truncation,
                        damaged: current.scanner.damaged().to_vec(),
                    });
                    if let Err(e) = self.advance() {
                        self.pending = Vec::new().into_iter();
                        return Some(Err(e));
                    }
                }
            }
        }
    }
}

/// The wall clock a recording's times are anchored to ([`RunReader::clock`] after its first
/// message: a recorder writes the metadata record before it), `None` for a CSV or an MCAP
/// file without the record.
pub fn clock_of(path: impl AsRef<Path>) -> Result<Option<WallClock>> {
    let path = path.as_ref();
    if !super::has_magic(path)? {
        return Ok(None);
    }
    let mut run = RunReader::one(path)?;
    if let Some(Err(e)) = run.next() {
        return Err(e);
    }
    Ok(run.clock())
}

/// One item of a [`RawRun`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Item {
    /// A raw sample.
    Raw(RawImuSample),
    /// Ground truth (simulated recordings).
    Truth(Truth),
    /// A robot hint.
    Hint(RobotHint),
}

/// The raw samples, truth and robot hints of a run in file order, streamed; other topics are
/// skipped undecoded. Raw samples are checked as [`super::read_all`] checks them; a restart of
/// the raw stream (a second acquisition session) is an error ([`ErrorKind::SessionRestart`]).
pub struct RawRun {
    reader: RunReader,
    checks: RawChecks,
    raw_read: u64,
    hints: bool,
}

impl RawRun {
    /// The run at `path` ([`RunReader::open`]); robot hints only if `hints`.
    pub fn open(path: impl AsRef<Path>, hints: bool) -> Result<Self> {
        Ok(Self {
            reader: RunReader::open(path)?,
            checks: RawChecks::default(),
            raw_read: 0,
            hints,
        })
    }

    /// The files read so far ([`RunReader::segments`]).
    pub fn segments(&self) -> &[SegmentRead] {
        self.reader.segments()
    }

    fn item(&mut self) -> Option<Result<Item>> {
        loop {
            let message = match self.reader.next()? {
                Ok(m) => m,
                Err(e) => return Some(Err(e)),
            };
            if let Some(sample) = message.decode::<RawImuSample>() {
                let result = sample.and_then(|sample| {
                    let previous = self.checks;
                    let restart = self.checks.check(
                        message.path,
                        message.index,
                        &message.channel.topic,
                        &sample,
                    )?;
                    if restart && self.raw_read > 0 {
                        let previous_seq = previous.previous_seq().unwrap_or_default();
                        let kind = ErrorKind::SessionRestart {
                            index: self.raw_read,
                            previous_seq,
                            seq: sample.seq,
                        };
                        let field = format!("{}: seq", message.channel.topic);
                        return Err(Error::message(
                            message.path,
                            message.index,
                            Some(&field),
                            kind,
                        ));
                    }
                    self.raw_read += 1;
                    Ok(Item::Raw(sample))
                });
                return Some(result);
            }
            if let Some(truth) = message.decode::<Truth>() {
                return Some(truth.map(Item::Truth));
            }
            if self.hints
                && let Some(hint) = message.decode::<RobotHint>()
            {
                return Some(hint.map(Item::Hint));
            }
        }
    }
}

impl Iterator for RawRun {
    type Item = Result<Item>;

    /// The next item; after an error, `None`.
    fn next(&mut self) -> Option<Self::Item> {
        let item = self.item();
        if matches!(item, Some(Err(_))) {
            self.reader.pending = Vec::new().into_iter();
            self.reader.current = None;
        }
        item
    }
}

/// Whether the file at `path` is segment `n` of a run: its first message is the recorder's
/// [`EventKind::Segment`] event numbered `n` (a file that merely has a successor's name is
/// not read with the run).
pub(crate) fn continues_run(path: &Path, n: usize) -> Result<bool> {
    let mut run = RunReader::one(path)?;
    Ok(match run.next() {
        Some(Ok(message)) => match message.decode::<RecorderEvent>() {
            Some(event) => {
                let event = event?;
                event.kind == EventKind::Segment && event.from_seq == Some(n as u64)
            }
            None => false,
        },
        _ => false,
    })
}
