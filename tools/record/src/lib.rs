//! The recorder behind `mems-record`: subscribes to every mems service and writes an MCAP file
//! through the `recording` crate, with the pose derived from each odometry state for Foxglove
//! and explicit events for lost sequence numbers and vanished publishers.
//!
//! A publisher that stops cleanly announces it (`ipc_types::wake::LEAVING`, sent when its
//! `wake::Output` is dropped), so a clean stop of the stack (source first, the recorder last)
//! records no lost publisher; one that dies (kill -9, a crash) announces nothing and is
//! recorded as `publisher_lost`. The hint publishers wake nobody and cannot announce it.
//!
//! Times: each message's MCAP `log_time` is its receive time, its `publish_time` the message's
//! own sample time, both taken as ns `CLOCK_MONOTONIC` and written as Unix ns (UTC) through the
//! wall clock read at start (`recording::clock::WallClock`, stored in the file's `mems.clock`
//! metadata record); the stamps inside the messages stay `CLOCK_MONOTONIC`. The writer's chunk is flushed to the operating
//! system whenever its oldest message is [`FLUSH_PERIOD`] old, so a killed recorder loses at
//! most that much; SIGINT and SIGTERM ([`ipc_types::stop`]) end the recording cleanly with its
//! summary and footer. Beside the flushed file the writer keeps a compact copy (whole chunks at
//! a higher zstd level, `recording::mcap::Writer::create_new_compacting`) which replaces the
//! file when the recording ends cleanly: a finished recording is 0.88 of the flushed file's
//! size (docs/recording.md), a killed one is the flushed file.
//!
//! An existing recording is never overwritten unless asked ([`Target::Overwrite`]). A recorder
//! restarted by a supervisor continues the run ([`Target::Continue`]) in the next segment file
//! ([`recording::segment`]), which starts with a `segment` event; once the previous segments
//! have been scanned for their last sequence numbers, the numbers lost across the split are
//! written as `gap` events.

#![warn(missing_docs)]

use std::cell::Cell;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use alloc_count::pool::Counts;
use alloc_count::steady::SteadyState;
use anyhow::{Context, Result};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory as _;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use ipc_types::clock::monotonic_ns;
use ipc_types::wake::{self, Exit, WaitMode};
use ipc_types::{CorrectedImuSample, Message, OdometryState, RawImuSample, RobotHint, service};
use recording::clock::WallClock;
use recording::mcap::derived::DerivedChannels;
use recording::mcap::{Channel, EventKind, RecorderEvent, Topic, Writer};
use recording::segment;

/// Age of the oldest unflushed message at which the recorder closes the current chunk and
/// hands it to the operating system: the most a killed recorder can lose. Half the 100 ms the
/// project allows, leaving room for one slow loop iteration.
pub const FLUSH_PERIOD: Duration = Duration::from_millis(50);
/// Longest sleep without a notification (the flush and the publisher check run on it). Each
/// subscriber buffers one second at 4 kHz ([`service::SUBSCRIBER_BUFFER`]).
pub const POLL_PERIOD: Duration = Duration::from_millis(25);
/// Most messages taken from one subscriber per poll, so that flushing and the publisher check
/// keep their periods while a fast publisher (replay `--max`) keeps the queue full.
pub const MAX_BATCH: usize = service::SUBSCRIBER_BUFFER;
/// Period of the publisher check (each service's publisher count compared with the last one)
/// and of the dead-node cleanup beside it, which removes a kill -9'd stage's publisher
/// ([`service::DeadNodeCleanup`], on its own thread: it allocates).
pub const PUBLISHER_CHECK_PERIOD: Duration = Duration::from_millis(100);

/// What to do with a recording already at the output path.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// Refuse to start if a recording (any segment of a run) is there.
    New,
    /// Remove the run that is there (every segment) and record a new one.
    Overwrite,
    /// Continue the run that is there in its next segment file (a restarted recorder); start
    /// it if there is none.
    Continue,
}

/// What to record and for how long.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// The MCAP file of the run (its first segment).
    pub out: PathBuf,
    /// What to do with a recording already there.
    pub target: Target,
    /// Namespace prefix of the service names ("" for none); topics in the file are the base names.
    pub namespace: String,
    /// Stop after this long; `None` records until SIGINT or SIGTERM.
    pub duration: Option<Duration>,
    /// Reads the process allocator's counts (`mems-record`'s pool); with it the summary has
    /// the steady-state allocation calls per message received.
    pub allocations: Option<fn() -> Counts>,
}

/// What was recorded.
#[derive(Debug, Clone)]
pub struct RecordSummary {
    /// The file written (the run's first file, or the segment that continues it).
    pub path: PathBuf,
    /// Its segment number (0: the run's first file).
    pub segment: u32,
    /// Messages per service (base name) received and written, in subscription order.
    pub received: Vec<(&'static str, u64)>,
    /// Events written on [`recording::mcap::EVENTS_TOPIC`].
    pub events: Vec<RecorderEvent>,
    /// Wall time from the first poll to the finished file.
    pub elapsed: Duration,
    /// Whether SIGINT or SIGTERM ended the recording (rather than `duration`).
    pub interrupted: bool,
    /// Allocation calls after a warm-up of messages (inputs: messages received), when
    /// [`RecordOptions::allocations`] was given.
    pub steady: Option<SteadyState>,
    /// Chunks flushed after that warm-up.
    pub steady_flushes: u64,
}

impl RecordSummary {
    /// Keeps `events` and prints a line on standard output for each gap, as
    /// `mems-record: lost N of SERVICE (seq A..=B)`: the loss count a supervisor (`mems-stack`)
    /// reads while the recording goes on.
    fn note(&mut self, events: Vec<RecorderEvent>) {
        for e in &events {
            if let (EventKind::Gap, Some(from), Some(to)) = (e.kind, e.from_seq, e.to_seq) {
                println!(
                    "{LOST_PREFIX}{} of {} (seq {from}..={to})",
                    to - from + 1,
                    e.service
                );
            }
        }
        self.events.extend(events);
    }
}

/// Start of the line [`RecordSummary`] prints for each gap, before the count.
pub const LOST_PREFIX: &str = "mems-record: lost ";

/// Detects lost sequence numbers and vanished publishers on one service. No I/O: feed it what
/// was received and how many publishers the service has, and write the events it returns.
#[derive(Debug, Clone, PartialEq)]
pub struct SeqTracker {
    service: &'static str,
    last_seq: Option<u64>,
    first_seq: Option<u64>,
    had_publisher: bool,
    lost: bool,
    /// A publisher announced that it leaves cleanly ([`wake::LEAVING`]).
    leaving: bool,
}

impl SeqTracker {
    /// A tracker for `service` (its base name), which has seen nothing yet.
    pub fn new(service: &'static str) -> Self {
        Self {
            service,
            last_seq: None,
            first_seq: None,
            had_publisher: false,
            lost: false,
            leaving: false,
        }
    }

    fn event(
        &self,
        kind: EventKind,
        from_seq: Option<u64>,
        to_seq: Option<u64>,
        t_ns: u64,
    ) -> RecorderEvent {
        RecorderEvent {
            kind,
            service: self.service.to_owned(),
            from_seq,
            to_seq,
            t_ns,
        }
    }

    /// Accounts for a message with sequence number `seq` received at `t_ns`. Returns
    /// [`EventKind::PublisherBack`] if the publisher was lost (a message proves it is back,
    /// whether or not the publisher count has been checked since, provided the lost
    /// publisher's messages were all taken before [`SeqTracker::publishers`] reported the
    /// loss), then [`EventKind::Gap`] when
    /// numbers were skipped or [`EventKind::SeqReset`] when the sequence went back. Revisions
    /// (which re-publish earlier numbers on purpose) are not checked for gaps. The first message
    /// only sets the starting point: the recorder may join a running stream.
    pub fn observe(&mut self, seq: u64, revision: bool, t_ns: u64) -> Vec<RecorderEvent> {
        let mut events = Vec::new();
        self.had_publisher = true;
        if self.lost {
            self.lost = false;
            let last = self.last_seq;
            events.push(self.event(EventKind::PublisherBack, last, last, t_ns));
        }
        if revision {
            return events;
        }
        let jump = self.last_seq.and_then(|last| {
            let expected = last.wrapping_add(1);
            if seq > expected {
                Some(self.event(EventKind::Gap, Some(expected), Some(seq - 1), t_ns))
            } else if seq < expected {
                Some(self.event(EventKind::SeqReset, Some(expected), Some(seq), t_ns))
            } else {
                None
            }
        });
        events.extend(jump);
        self.last_seq = Some(seq);
        self.first_seq.get_or_insert(seq);
        events
    }

    /// Accounts for the previous segment of the run having ended at sequence number `previous`
    /// (a restarted recorder learns it after it has started): the numbers between it and the
    /// first one received here are a [`EventKind::Gap`] (or a [`EventKind::SeqReset`] if the
    /// sequence went back). Before any message here, the first one will report it instead.
    pub fn continues_from(&mut self, previous: u64, t_ns: u64) -> Option<RecorderEvent> {
        let Some(first) = self.first_seq else {
            self.last_seq = Some(previous);
            return None;
        };
        let expected = previous.wrapping_add(1);
        if first > expected {
            Some(self.event(EventKind::Gap, Some(expected), Some(first - 1), t_ns))
        } else if first < expected {
            Some(self.event(EventKind::SeqReset, Some(expected), Some(first), t_ns))
        } else {
            None
        }
    }

    /// Accounts for a publisher's announcement that it leaves cleanly, having sent everything
    /// ([`wake::LEAVING`]): the next publisher count of 0 is a stop, not a loss.
    pub fn leaving(&mut self) {
        self.leaving = true;
    }

    /// Accounts for the service's publisher count at `t_ns`: [`EventKind::PublisherLost`] when
    /// it is 0 after a publisher was seen (counted, or proven by a message) unless the
    /// publisher announced that it leaves ([`SeqTracker::leaving`]: nothing is recorded, and a
    /// new publisher is a start, not a return), [`EventKind::PublisherBack`] when one appears
    /// again after a loss.
    pub fn publishers(&mut self, count: usize, t_ns: u64) -> Option<RecorderEvent> {
        if count == 0 && std::mem::take(&mut self.leaving) {
            self.had_publisher = false;
            return None;
        }
        let kind = if count == 0 && self.had_publisher && !self.lost {
            self.lost = true;
            EventKind::PublisherLost
        } else if count > 0 && self.lost {
            self.lost = false;
            EventKind::PublisherBack
        } else {
            self.had_publisher |= count > 0;
            return None;
        };
        Some(self.event(kind, self.last_seq, self.last_seq, t_ns))
    }
}

/// A service being recorded, whatever its message type.
trait Stream {
    /// Receives and writes what is queued, at most `limit` messages; returns the events
    /// written.
    fn drain(&mut self, writer: &mut Writer, limit: usize) -> Result<Vec<RecorderEvent>>;
    /// Compares the publisher count with the last one; returns the events written (with those
    /// of the messages drained on the way).
    fn check_publishers(&mut self, writer: &mut Writer) -> Result<Vec<RecorderEvent>>;
    /// The service's publisher count.
    fn publishers(&self) -> usize;
    /// Accounts for a publisher's announcement that it leaves ([`SeqTracker::leaving`]).
    fn leaving(&mut self);
    /// Writes what was lost since the previous segment ended, given the last sequence number
    /// of each service there (see [`SeqTracker::continues_from`]); returns the events written.
    fn continues_from(
        &mut self,
        writer: &mut Writer,
        previous: &[(&'static str, u64)],
    ) -> Result<Vec<RecorderEvent>>;
    /// The service's base name and the messages received so far.
    fn received(&self) -> (&'static str, u64);
    /// The full service name.
    fn name(&self) -> &str;
}

/// Extra messages written for each message of a stream (the pose for odometry states).
type Derive<T> = Box<dyn FnMut(&mut Writer, &T, u64) -> recording::Result<()>>;

/// One subscribed service and its MCAP channel.
struct Subscription<T: Topic + Message> {
    name: String,
    service: PortFactory<ipc::Service, T, ()>,
    subscriber: Subscriber<ipc::Service, T, ()>,
    channel: Channel<T>,
    events: Channel<RecorderEvent>,
    tracker: SeqTracker,
    received: u64,
    derive: Option<Derive<T>>,
}

impl<T: Topic + Message> Subscription<T> {
    /// Subscribes to `T`'s service under `namespace` and adds its channel to `writer`.
    fn open(
        node: &Node<ipc::Service>,
        namespace: &str,
        writer: &mut Writer,
        events: Channel<RecorderEvent>,
    ) -> Result<Self> {
        let name = service::full_name(namespace, T::TOPIC);
        let service = service::open::<T>(node, &name)?;
        let subscriber = service::subscriber(&service)?;
        Ok(Self {
            name,
            service,
            subscriber,
            channel: writer.add_channel::<T>()?,
            events,
            tracker: SeqTracker::new(T::TOPIC),
            received: 0,
            derive: None,
        })
    }

    /// Also writes `derive`'s messages for every message received.
    fn deriving(
        mut self,
        derive: impl FnMut(&mut Writer, &T, u64) -> recording::Result<()> + 'static,
    ) -> Self {
        self.derive = Some(Box::new(derive));
        self
    }
}

impl<T: Topic + Message> Stream for Subscription<T> {
    fn drain(&mut self, writer: &mut Writer, limit: usize) -> Result<Vec<RecorderEvent>> {
        let mut events = Vec::new();
        for _ in 0..limit {
            let Some(sample) = self
                .subscriber
                .receive()
                .map_err(|e| anyhow::anyhow!("receive on {}: {e:?}", self.name))?
            else {
                break;
            };
            let received_ns = monotonic_ns();
            let message: &T = sample.payload();
            self.received += 1;
            for event in self
                .tracker
                .observe(message.seq(), message.is_revision(), received_ns)
            {
                writer.write(self.events, &event, received_ns)?;
                events.push(event);
            }
            writer.write(self.channel, message, received_ns)?;
            if let Some(derive) = self.derive.as_mut() {
                derive(writer, message, received_ns)?;
            }
        }
        Ok(events)
    }

    fn publishers(&self) -> usize {
        self.service.dynamic_config().number_of_publishers()
    }

    fn leaving(&mut self) {
        self.tracker.leaving();
    }

    fn check_publishers(&mut self, writer: &mut Writer) -> Result<Vec<RecorderEvent>> {
        let count = self.publishers();
        let mut events = Vec::new();
        if count == 0 {
            // Whatever the departed publishers sent is queued before they left: take it all
            // first, so that the loss is recorded after their last message, with its number,
            // and any later message proves a new publisher.
            events = self.drain(writer, usize::MAX)?;
        }
        let now = monotonic_ns();
        if let Some(event) = self.tracker.publishers(count, now) {
            writer.write(self.events, &event, now)?;
            events.push(event);
        }
        Ok(events)
    }

    fn continues_from(
        &mut self,
        writer: &mut Writer,
        previous: &[(&'static str, u64)],
    ) -> Result<Vec<RecorderEvent>> {
        let Some(&(_, last)) = previous.iter().find(|(topic, _)| *topic == T::TOPIC) else {
            return Ok(Vec::new());
        };
        let now = monotonic_ns();
        let event = self.tracker.continues_from(last, now);
        if let Some(event) = &event {
            writer.write(self.events, event, now)?;
        }
        Ok(event.into_iter().collect())
    }

    fn name(&self) -> &str {
        &self.name
    }

    fn received(&self) -> (&'static str, u64) {
        (T::TOPIC, self.received)
    }
}

/// Records every service until `options.duration` has passed or SIGINT/SIGTERM arrives, then
/// finishes the file (summary and footer).
pub fn record(options: &RecordOptions) -> Result<RecordSummary> {
    // Before any port exists: a SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node_name = NodeName::new("mems-record").context("node name")?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("cannot create iceoryx2 node: {e:?}"))?;
    let (number, path) = open_target(&options.out, options.target)?;
    let mut writer = Writer::create_new_compacting(&path)?;
    writer.anchor(WallClock::now())?;
    let events = writer.add_channel::<RecorderEvent>()?;
    let mut split = Vec::new();
    if number > 0 {
        let event = RecorderEvent {
            kind: EventKind::Segment,
            service: String::new(),
            from_seq: Some(u64::from(number)),
            to_seq: Some(u64::from(number)),
            t_ns: monotonic_ns(),
        };
        writer.write(events, &event, event.t_ns)?;
        // On disk at once: it makes this file part of the run for the readers.
        writer.flush()?;
        split.push(event);
    }
    let mut derived = DerivedChannels::add(&mut writer)?;
    let ns = options.namespace.as_str();
    // One line per service; a new service is one more line here.
    let mut streams: Vec<Box<dyn Stream>> = vec![
        Box::new(Subscription::<RawImuSample>::open(
            &node,
            ns,
            &mut writer,
            events,
        )?),
        Box::new(Subscription::<CorrectedImuSample>::open(
            &node,
            ns,
            &mut writer,
            events,
        )?),
        Box::new(
            Subscription::<OdometryState>::open(&node, ns, &mut writer, events)?
                .deriving(move |w, state, log_ns| derived.write(w, state, log_ns)),
        ),
        // Hints from the robot's controller (published without back-pressure: a hint the
        // recorder could not take shows as a gap event).
        Box::new(Subscription::<RobotHint>::open(
            &node,
            ns,
            &mut writer,
            events,
        )?),
    ];

    let start = Instant::now();
    let previous = (number > 0).then(|| scan_previous(&options.out, number));
    let mut summary = RecordSummary {
        path,
        segment: number,
        received: Vec::new(),
        events: split,
        elapsed: Duration::ZERO,
        interrupted: false,
        steady: options
            .allocations
            .map(SteadyState::from_env)
            .transpose()
            .map_err(anyhow::Error::msg)?,
        steady_flushes: 0,
    };
    let looped = record_loop(
        &node,
        &mut writer,
        &mut streams,
        options,
        previous,
        &mut summary,
    );
    // Finish the file even after an error, so that it keeps its summary and footer.
    let finished = writer.finish();
    looped?;
    finished?;
    summary.received = streams.iter().map(|s| s.received()).collect();
    summary.elapsed = start.elapsed();
    Ok(summary)
}

/// The segment number and file to write for `out` and `target`, having removed the run there
/// for [`Target::Overwrite`]; errors (naming the file) for [`Target::New`] when a recording is
/// there.
fn open_target(out: &Path, target: Target) -> Result<(u32, PathBuf)> {
    // The compact copies a killed recorder left beside the run's files (its flushed files
    // are the recording).
    let mut files = segment::existing(out);
    if files.is_empty() {
        files.push(out.to_path_buf());
    }
    for file in &files {
        if recording::mcap::remove_stale_copy(file)? {
            tracing::info!("removed the unfinished compact copy of {}", file.display());
        }
    }
    match target {
        Target::New => {
            segment::check_target(out, false)?;
            Ok((0, out.to_path_buf()))
        }
        Target::Overwrite => {
            for old in segment::check_target(out, true)? {
                std::fs::remove_file(&old)
                    .with_context(|| format!("cannot remove {}", old.display()))?;
            }
            Ok((0, out.to_path_buf()))
        }
        Target::Continue => Ok(segment::next_free(out)),
    }
}

/// What [`scan_previous`] finds: the last sequence number of each service (base name) before
/// the split.
type PreviousScan = recording::Result<Vec<(&'static str, u64)>>;

/// Last sequence numbers of the run before segment `number`, per service, from a thread (the
/// recorder subscribes and records meanwhile): the newest segment that holds each service.
fn scan_previous(out: &Path, number: u32) -> mpsc::Receiver<PreviousScan> {
    let (tx, rx) = mpsc::channel();
    let out = out.to_path_buf();
    std::thread::spawn(move || {
        let scan = || {
            let mut found: Vec<(&'static str, u64)> = Vec::new();
            for n in (0..number).rev() {
                for (topic, seq) in recording::mcap::last_seqs(segment::path(&out, n))? {
                    if !found.iter().any(|(t, _)| *t == topic) {
                        found.push((topic, seq));
                    }
                }
                if found.len() >= 4 {
                    break;
                }
            }
            Ok(found)
        };
        let _ = tx.send(scan());
    });
    rx
}

/// Drains, writes, checks publishers and flushes until the duration has passed or a signal
/// arrived; records events and `interrupted` in `summary`. Sleeps on the services' events
/// (their publishers notify after each send), waking at least every [`POLL_PERIOD`] for the
/// flush and the publisher check. Once `previous` delivers the previous segments' last
/// sequence numbers, writes what was lost across the split.
fn record_loop(
    node: &Node<ipc::Service>,
    writer: &mut Writer,
    streams: &mut [Box<dyn Stream>],
    options: &RecordOptions,
    mut previous: Option<mpsc::Receiver<PreviousScan>>,
    summary: &mut RecordSummary,
) -> Result<()> {
    let start = Instant::now();
    let mut oldest_unflushed: Option<Instant> = None;
    let mut last_check: Option<Instant> = None;
    let listeners = streams
        .iter()
        .map(|s| wake::listener(node, s.name(), WaitMode::Event))
        .collect::<Result<Vec<_>, _>>()?;
    // Removes the resources of kill -9'd nodes, so that their publishers stop counting.
    let _cleanup = service::DeadNodeCleanup::start(PUBLISHER_CHECK_PERIOD)?;
    // Per stream: whether its publisher announced that it leaves (wake::LEAVING).
    let leaving: Vec<Cell<bool>> = streams.iter().map(|_| Cell::new(false)).collect();
    let on_event = |i: usize, id: EventId| {
        if id == wake::LEAVING {
            leaving[i].set(true);
        }
    };
    let exit = wake::serve_loop_with_events(&listeners, POLL_PERIOD, on_event, || -> Result<_> {
        if drain(writer, streams, summary)? {
            oldest_unflushed.get_or_insert_with(Instant::now);
        }
        if let Some(scanned) = previous.as_ref().and_then(|rx| rx.try_recv().ok()) {
            previous = None;
            match scanned {
                Ok(last) => {
                    for stream in streams.iter_mut() {
                        summary.note(stream.continues_from(writer, &last)?);
                    }
                    oldest_unflushed.get_or_insert_with(Instant::now);
                }
                Err(e) => tracing::warn!(
                    "cannot read the previous segment ({e}): the split is \
                     recorded, the numbers lost across it are not"
                ),
            }
        }
        if options.duration.is_some_and(|d| start.elapsed() >= d) {
            return Ok(ControlFlow::Break(()));
        }
        if last_check.is_none_or(|t| t.elapsed() >= PUBLISHER_CHECK_PERIOD) {
            last_check = Some(Instant::now());
            for (i, stream) in streams.iter_mut().enumerate() {
                let (_, before) = stream.received();
                if stream.publishers() == 0 {
                    // A publisher announces its departure before it releases its port: the
                    // announcement is queued by now, if not taken at the last wake-up.
                    take_leaving(listeners[i].as_ref(), &leaving[i])?;
                }
                if leaving[i].take() {
                    stream.leaving();
                }
                let events = stream.check_publishers(writer)?;
                if !events.is_empty() || stream.received().1 > before {
                    oldest_unflushed.get_or_insert_with(Instant::now);
                }
                summary.note(events);
            }
        }
        if oldest_unflushed.is_some_and(|t| t.elapsed() >= FLUSH_PERIOD) {
            writer.flush()?;
            oldest_unflushed = None;
            if summary.steady.as_ref().is_some_and(SteadyState::is_steady) {
                summary.steady_flushes += 1;
            }
        }
        Ok(ControlFlow::Continue(false))
    })?;
    if exit == Exit::Signal {
        summary.interrupted = true;
        // After a signal this last drain takes everything queued: a queue holds at most
        // SUBSCRIBER_BUFFER = MAX_BATCH messages.
        drain(writer, streams, summary)?;
    }
    Ok(())
}

/// Sets `leaving` if `listener` has a [`wake::LEAVING`] notification pending (and consumes
/// its pending notifications: the caller checks the stream's publishers, which drains it).
fn take_leaving(listener: Option<&Listener<ipc::Service>>, leaving: &Cell<bool>) -> Result<()> {
    if let Some(listener) = listener {
        listener
            .try_wait(|a| {
                if a.id == wake::LEAVING {
                    leaving.set(true);
                }
            })
            .map_err(|e| anyhow::anyhow!("cannot read a listener: {e:?}"))?;
    }
    Ok(())
}

/// Takes up to [`MAX_BATCH`] messages from each stream; whether any came.
fn drain(
    writer: &mut Writer,
    streams: &mut [Box<dyn Stream>],
    summary: &mut RecordSummary,
) -> Result<bool> {
    let mut any = false;
    for stream in streams.iter_mut() {
        let (_, before) = stream.received();
        summary.note(stream.drain(writer, MAX_BATCH)?);
        let received = stream.received().1 - before;
        if let Some(steady) = summary.steady.as_mut() {
            steady.inputs(received);
        }
        any |= received > 0;
    }
    Ok(any)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kinds(events: &[RecorderEvent]) -> Vec<EventKind> {
        events.iter().map(|e| e.kind).collect()
    }

    #[test]
    fn consecutive_numbers_give_no_event() {
        let mut t = SeqTracker::new(service::RAW);
        for seq in 5..100 {
            assert_eq!(t.observe(seq, false, seq), vec![]);
        }
    }

    #[test]
    fn a_jump_is_a_gap_of_the_missing_numbers() {
        let mut t = SeqTracker::new(service::CORRECTED);
        assert_eq!(t.observe(10, false, 1), vec![]);
        let e = t.observe(14, false, 2);
        assert_eq!(kinds(&e), [EventKind::Gap]);
        assert_eq!((e[0].from_seq, e[0].to_seq), (Some(11), Some(13)));
        assert_eq!((e[0].service.as_str(), e[0].t_ns), (service::CORRECTED, 2));
        assert_eq!(t.observe(15, false, 3), vec![]);
    }

    #[test]
    fn going_back_is_a_reset_and_revisions_are_not_gaps() {
        let mut t = SeqTracker::new(service::ODOMETRY);
        t.observe(100, false, 0);
        assert_eq!(t.observe(40, true, 0), vec![], "a revision of seq 40");
        assert_eq!(t.observe(101, false, 0), vec![]);
        let e = t.observe(0, false, 7);
        assert_eq!(kinds(&e), [EventKind::SeqReset]);
        assert_eq!((e[0].from_seq, e[0].to_seq), (Some(102), Some(0)));
        assert_eq!(t.observe(1, false, 8), vec![]);
    }

    #[test]
    fn publisher_lost_and_back_are_reported_once_each() {
        let mut t = SeqTracker::new(service::RAW);
        assert_eq!(t.publishers(0, 1), None, "no publisher yet: nothing lost");
        assert_eq!(t.publishers(1, 2), None, "first publisher: not a return");
        t.observe(7, false, 3);
        let lost = t.publishers(0, 4).unwrap();
        assert_eq!(lost.kind, EventKind::PublisherLost);
        assert_eq!(
            (lost.from_seq, lost.to_seq, lost.t_ns),
            (Some(7), Some(7), 4)
        );
        assert_eq!(t.publishers(0, 5), None, "still lost: reported once");
        let back = t.publishers(2, 6).unwrap();
        assert_eq!(back.kind, EventKind::PublisherBack);
        assert_eq!((back.from_seq, back.to_seq), (Some(7), Some(7)));
        assert_eq!(t.publishers(1, 7), None);
        assert_eq!(t.observe(8, false, 8), vec![], "already reported back");
    }

    /// A publisher that announced its departure is stopped, not lost; the next one is a start,
    /// and a later departure without an announcement is a loss again.
    #[test]
    fn an_announced_departure_is_no_loss() {
        let mut t = SeqTracker::new(service::RAW);
        assert_eq!(t.publishers(1, 1), None);
        t.observe(7, false, 2);
        t.leaving();
        assert_eq!(t.publishers(1, 3), None, "announced, port not yet released");
        assert_eq!(t.publishers(0, 4), None, "a clean stop");
        assert_eq!(t.publishers(1, 5), None, "a start, not a return");
        assert_eq!(t.publishers(0, 6).unwrap().kind, EventKind::PublisherLost);
    }

    /// A restarted stage's first message arrives before the publisher check notices it: the
    /// return is reported first, then the numbers it skipped.
    #[test]
    fn a_message_after_a_loss_reports_the_return_then_the_gap() {
        let mut t = SeqTracker::new(service::CORRECTED);
        t.observe(41, false, 1);
        t.publishers(0, 2).unwrap();
        let e = t.observe(60, false, 3);
        assert_eq!(kinds(&e), [EventKind::PublisherBack, EventKind::Gap]);
        assert_eq!((e[0].from_seq, e[0].to_seq), (Some(41), Some(41)));
        assert_eq!((e[1].from_seq, e[1].to_seq), (Some(42), Some(59)));
        assert_eq!(t.publishers(1, 4), None, "not reported twice");
    }

    #[test]
    fn a_message_proves_a_publisher_that_no_count_saw() {
        let mut t = SeqTracker::new(service::RAW);
        t.observe(0, false, 1);
        t.observe(1, false, 2);
        let lost = t.publishers(0, 3).unwrap();
        assert_eq!(lost.kind, EventKind::PublisherLost);
        assert_eq!((lost.from_seq, lost.to_seq), (Some(1), Some(1)));
    }

    /// A restarted recorder learns where the previous segment ended after it has started:
    /// the numbers in between are a gap, whether or not a message came first.
    #[test]
    fn the_split_between_segments_is_a_gap() {
        let mut t = SeqTracker::new(service::RAW);
        t.observe(120, false, 1);
        t.observe(121, false, 2);
        let gap = t.continues_from(99, 3).unwrap();
        assert_eq!(gap.kind, EventKind::Gap);
        assert_eq!(
            (gap.from_seq, gap.to_seq, gap.t_ns),
            (Some(100), Some(119), 3)
        );
        let mut early = SeqTracker::new(service::RAW);
        assert_eq!(early.continues_from(99, 1), None, "no message yet");
        let e = early.observe(105, false, 2);
        assert_eq!(kinds(&e), [EventKind::Gap]);
        assert_eq!((e[0].from_seq, e[0].to_seq), (Some(100), Some(104)));
        let mut none_lost = SeqTracker::new(service::RAW);
        none_lost.observe(100, false, 1);
        assert_eq!(none_lost.continues_from(99, 2), None);
        let mut reset = SeqTracker::new(service::RAW);
        reset.observe(0, false, 1);
        let e = reset.continues_from(99, 2).unwrap();
        assert_eq!(e.kind, EventKind::SeqReset);
        assert_eq!((e.from_seq, e.to_seq), (Some(100), Some(0)));
    }

    #[test]
    fn a_publisher_lost_before_any_message_has_no_sequence_number() {
        let mut t = SeqTracker::new(service::RAW);
        t.publishers(1, 0);
        let lost = t.publishers(0, 1).unwrap();
        assert_eq!((lost.from_seq, lost.to_seq), (None, None));
    }
}
