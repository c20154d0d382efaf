//! What a recording holds, for a person (`mems-info RUN.mcap`) or a script (`--json`), in the
//! manner of `mcap info` and `ros2 bag info`: the run's files (a run recorded across
//! recorder restarts spans several, read as one, see `recording::segment`), its time span,
//! each topic's count, rate and sequence gaps, the raw stream's losses, the recorder's events
//! and the calibration the run used.
//!
//! Counts are of messages as stored (what the official MCAP readers count), streamed with
//! `recording::mcap::run::RunReader` up to the cut of a truncated file. Sequence gaps are found from
//! the messages' own `seq` fields (odometry revisions, which repeat earlier numbers, are
//! counted apart); a number that goes back is a restarted publisher, not a gap. Times are the
//! recording's MCAP log times: Unix ns (UTC) in a recording anchored to the wall clock (its
//! `mems.clock` metadata record, `recording::clock`), printed as UTC dates; ns of the recording
//! machine's `CLOCK_MONOTONIC` in an older one, which has no wall-clock reference.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use ipc_types::stream::range::Clipping;
use ipc_types::stream::{Freezes, Holes, Step, TimeLine};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};
use ipc_types::{corrected_flags, odometry_flags, raw_flags, service};
use recording::mcap::run::{Message, RunReader};
use recording::mcap::{EventKind, MessageEncoding, RecorderEvent};
use serde::{Deserialize, Serialize};

/// One file of the run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FileInfo {
    /// The file.
    pub path: PathBuf,
    /// Its size, bytes.
    pub bytes: u64,
    /// Messages read from it (all topics).
    pub messages: u64,
    /// Why reading stopped early (a killed recorder's file ends without its summary), if it
    /// did; the messages before the cut are counted.
    pub truncated: Option<String>,
    /// Damaged records skipped (the read went on after each), with the messages each held.
    pub damaged: Vec<recording::mcap::scan::Damage>,
    /// Messages lost in the damaged records, all topics (as their message indexes count them).
    pub messages_lost: u64,
}

/// One topic of the run.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct TopicInfo {
    /// Messages stored.
    pub count: u64,
    /// The channel's schema name.
    pub schema: String,
    /// The channel's message encoding.
    pub encoding: String,
    /// First and last MCAP log time, ns.
    pub first_log_ns: u64,
    /// See `first_log_ns`.
    pub last_log_ns: u64,
    /// Messages per second of log time, (count - 1) over the span, when the span is at least
    /// [`MIN_RATE_SPAN_S`]; `None` (`-` in the table) otherwise: two messages a few
    /// microseconds apart (a burst of revised poses, the recorder's closing events) have no
    /// rate worth printing.
    pub rate_hz: Option<f64>,
    /// Whether the messages carry a sequence number (the pose and truth topics do not); the
    /// three counts below are 0 without one.
    pub sequenced: bool,
    /// Places where the sequence number skipped ahead.
    pub seq_gaps: u64,
    /// Sequence numbers skipped over all gaps.
    pub seq_missing: u64,
    /// Places where the sequence number went back: a restarted publisher.
    pub seq_restarts: u64,
    /// Odometry states flagged `REVISION` (republished history; not part of the sequence).
    pub revisions: u64,
    /// Messages that say their input was not taken at its word: corrected samples flagged
    /// `CLIPPED` or `IMPLAUSIBLE`, odometry states flagged `UNTRUSTED_INPUT`.
    pub untrusted: u64,
    /// Messages of a JSON channel that did not decode as JSON with the expected fields.
    pub undecodable: u64,
}

/// The shortest span of log time over which a topic's rate is given, s.
pub const MIN_RATE_SPAN_S: f64 = 1.0;

impl TopicInfo {
    /// The topic's rate, Hz, if its messages span at least [`MIN_RATE_SPAN_S`].
    fn rate(&self) -> Option<f64> {
        let span_s = self.last_log_ns.saturating_sub(self.first_log_ns) as f64 * 1e-9;
        (self.count > 1 && span_s >= MIN_RATE_SPAN_S).then(|| (self.count - 1) as f64 / span_s)
    }
}

/// The raw sample stream's own account of its losses.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RawInfo {
    /// Acquisition sessions (the sequence number restarts at each).
    pub sessions: u64,
    /// Sample rate from the sample times of the longest session, Hz.
    pub sample_rate_hz: f64,
    /// Whether any sample holds a gyroscope measurement.
    pub gyro: bool,
    /// Samples the sensor lost (sum of `lost_before`).
    pub lost_at_sensor: u64,
    /// Samples the publisher gave up for stalled subscribers (the last `undelivered` of each
    /// session, summed).
    pub undelivered: u64,
    /// Samples flagged `SATURATED`.
    pub saturated: u64,
    /// The same per axis (`SATURATED_AXES`; a sample whose source did not say which axes
    /// counts in `samples` only).
    pub clipped: Clipping,
    /// Holes in the sample times that nothing marked, measured against the stream's nominal
    /// period (`ipc_types::stream`): count, total and the longest, with the seq and sample time
    /// of the sample after it.
    pub holes: Holes,
    /// Runs of samples repeating one reading on every axis for longer than a hole
    /// (`ipc_types::stream::Freezes`: a sensor that stopped updating while it was read), with
    /// the seq and sample time of each run's last repeat.
    pub frozen: Holes,
}

/// The recorder's events, by kind.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct EventCounts {
    /// `gap` events: sequence ranges the recording misses.
    pub gap: u64,
    /// Sequence numbers the `gap` events name.
    pub gap_missing: u64,
    /// `seq_reset` events.
    pub seq_reset: u64,
    /// `publisher_lost` events.
    pub publisher_lost: u64,
    /// `publisher_back` events.
    pub publisher_back: u64,
    /// `segment` events (recorder restarts).
    pub segment: u64,
}

/// A recording's wall-clock anchor and its start and end as UTC dates.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct WallClockInfo {
    /// `CLOCK_REALTIME` at the recorder's start, Unix ns.
    pub realtime_ns: u64,
    /// `CLOCK_MONOTONIC` at the same moment, ns.
    pub monotonic_ns: u64,
    /// `realtime_ns - monotonic_ns`: what turns the messages' monotonic stamps into Unix ns.
    pub offset_ns: i128,
    /// The first log time, RFC 3339 UTC.
    pub start_utc: String,
    /// The last log time, RFC 3339 UTC.
    pub end_utc: String,
}

/// Everything `mems-info` reports about a run.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RunInfo {
    /// The run's files in order.
    pub files: Vec<FileInfo>,
    /// Messages over all files and topics.
    pub messages: u64,
    /// Earliest and latest MCAP log time, ns (none without messages): Unix ns when
    /// `wall_clock` is set, `CLOCK_MONOTONIC` ns otherwise.
    pub start_ns: Option<u64>,
    /// See `start_ns`.
    pub end_ns: Option<u64>,
    /// The wall clock the log times are anchored to, when the recording states one.
    pub wall_clock: Option<WallClockInfo>,
    /// `end_ns - start_ns`, s.
    pub duration_s: f64,
    /// Per topic.
    pub topics: BTreeMap<String, TopicInfo>,
    /// The raw stream, when the run has one.
    pub raw: Option<RawInfo>,
    /// The recorder's events.
    pub events: EventCounts,
    /// The calibrations the corrected samples name (`calib_id`, hex).
    pub calib_ids: BTreeSet<String>,
}

/// The fields `mems-info` reads from a message; the topics' own types have more, which are
/// skipped, so every topic decodes with this one type.
#[derive(Deserialize, Default)]
struct Fields {
    seq: Option<u64>,
    flags: Option<u16>,
    lost_before: Option<u32>,
    #[serde(alias = "reserved")]
    undelivered: Option<u32>,
    calib_id: Option<u64>,
    stamps: Option<SampleTime>,
    accel_g: Option<[f64; 3]>,
    gyro_dps: Option<[f64; 3]>,
}

#[derive(Deserialize)]
struct SampleTime {
    sample_ns: u64,
}

impl Fields {
    /// The fields of a message: from its JSON whatever the topic; from protobuf by decoding
    /// it as its topic's type (`None` if it does not decode; all fields absent on a topic
    /// without them, as the pose and truth).
    fn of(message: &Message<'_>) -> Option<Self> {
        if message.encoding == Some(MessageEncoding::Json) {
            return serde_json::from_slice(message.data).ok();
        }
        let stamps = |s: ipc_types::Stamps| {
            Some(SampleTime {
                sample_ns: s.sample_ns,
            })
        };
        let fields = if let Some(m) = message.decode::<RawImuSample>() {
            let m = m.ok()?;
            Self {
                seq: Some(m.seq),
                flags: Some(m.flags),
                lost_before: Some(m.lost_before),
                undelivered: Some(m.undelivered),
                stamps: stamps(m.stamps),
                accel_g: Some(m.accel_g),
                gyro_dps: Some(m.gyro_dps),
                ..Self::default()
            }
        } else if let Some(m) = message.decode::<CorrectedImuSample>() {
            let m = m.ok()?;
            Self {
                seq: Some(m.seq),
                flags: Some(m.flags),
                calib_id: Some(m.calib_id),
                stamps: stamps(m.stamps),
                ..Self::default()
            }
        } else if let Some(m) = message.decode::<OdometryState>() {
            let m = m.ok()?;
            Self {
                seq: Some(m.seq),
                flags: Some(m.flags),
                stamps: stamps(m.stamps),
                ..Self::default()
            }
        } else if let Some(m) = message.decode::<RobotHint>() {
            let m = m.ok()?;
            Self {
                seq: Some(m.seq),
                flags: Some(m.flags),
                stamps: stamps(m.stamps),
                ..Self::default()
            }
        } else {
            Self::default()
        };
        Some(fields)
    }
}

/// Per-topic sequence tracking.
#[derive(Default)]
struct Sequence {
    last: Option<u64>,
}

impl Sequence {
    /// Updates `topic` with sequence number `seq`; returns whether it restarted.
    fn next(&mut self, seq: u64, topic: &mut TopicInfo) -> bool {
        let restart = match self.last {
            Some(last) if seq > last + 1 => {
                topic.seq_gaps += 1;
                topic.seq_missing += seq - last - 1;
                false
            }
            Some(last) if seq <= last => {
                topic.seq_restarts += 1;
                true
            }
            _ => false,
        };
        self.last = Some(seq);
        restart
    }
}

/// The raw stream's running state.
#[derive(Default)]
struct RawTrack {
    info: RawInfo,
    /// The current session's latest `undelivered` (a running total per publisher).
    session_undelivered: u64,
    /// The current session's first and latest sample time, ns, and its sample count.
    session: Option<(u64, u64, u64)>,
    /// The longest session's sample count and rate, Hz.
    longest: (u64, f64),
    /// The current session's time line.
    time: TimeLine,
    /// The current session's runs of repeated readings ([`RawInfo::frozen`]).
    freezes: Freezes,
}

impl RawTrack {
    /// Counts one raw sample; `new_session` when its sequence number restarted.
    fn sample(&mut self, f: &Fields, new_session: bool) {
        if new_session || self.session.is_none() {
            self.close_session();
            self.info.sessions += 1;
            self.time.restart();
        }
        let flags = f.flags.unwrap_or(0);
        self.info.gyro |= flags & raw_flags::GYRO_VALID != 0;
        self.info.saturated += u64::from(flags & raw_flags::SATURATED != 0);
        self.info.clipped.count(flags);
        self.info.lost_at_sensor += u64::from(f.lost_before.unwrap_or(0));
        self.session_undelivered = u64::from(f.undelivered.unwrap_or(0));
        let t = f.stamps.as_ref().map_or(0, |s| s.sample_ns);
        let marked = flags & raw_flags::GAP_BEFORE != 0 || f.lost_before.unwrap_or(0) > 0;
        if let Step::Hole { dt_ns } = self.time.step(t)
            && !marked
        {
            self.info.holes.record(f.seq.unwrap_or(0), t, dt_ns);
        }
        if marked {
            self.freezes.end(&self.time);
        }
        if let Some(a) = f.accel_g {
            let gyro = f.gyro_dps.filter(|_| flags & raw_flags::GYRO_VALID != 0);
            self.freezes
                .push(&self.time, f.seq.unwrap_or(0), t, a, gyro);
        }
        self.time.accept(t);
        self.session = Some(match self.session {
            Some((first, _, n)) => (first, t, n + 1),
            None => (t, t, 1),
        });
    }

    /// Ends the current session: its undelivered count, and its rate if it is the longest.
    fn close_session(&mut self) {
        self.freezes.end(&self.time);
        self.info.frozen = self.freezes.frozen;
        self.info.undelivered += std::mem::take(&mut self.session_undelivered);
        if let Some((first, last, n)) = self.session.take()
            && n > self.longest.0
            && last > first
        {
            self.longest = (n, (n - 1) as f64 / ((last - first) as f64 * 1e-9));
        }
    }

    fn finish(mut self) -> RawInfo {
        self.close_session();
        self.info.sample_rate_hz = self.longest.1;
        self.info
    }
}

/// The counts of a run as its messages go by.
#[derive(Default)]
struct Tally {
    info: RunInfo,
    sequences: BTreeMap<String, Sequence>,
    raw: Option<RawTrack>,
}

impl Tally {
    /// Counts one message: its topic, time, and what its fields say.
    fn message(&mut self, message: &Message<'_>) {
        let (info, channel, t) = (&mut self.info, message.channel, message.log_time_ns);
        info.start_ns = Some(info.start_ns.map_or(t, |s| s.min(t)));
        info.end_ns = Some(info.end_ns.map_or(t, |e| e.max(t)));
        let topic = info.topics.entry(channel.topic.clone()).or_default();
        if topic.count == 0 {
            topic.schema = channel.schema_name.clone();
            topic.encoding = channel.encoding.clone();
            topic.first_log_ns = t;
        }
        topic.count += 1;
        topic.last_log_ns = t;
        if message.encoding.is_none() {
            return;
        }
        if channel.topic == recording::mcap::EVENTS_TOPIC {
            match message.decode::<RecorderEvent>() {
                Some(Ok(event)) => info.events.count(&event),
                _ => topic.undecodable += 1,
            }
            return;
        }
        let Some(fields) = Fields::of(message) else {
            topic.undecodable += 1;
            return;
        };
        if channel.topic == service::ODOMETRY
            && fields.flags.unwrap_or(0) & odometry_flags::REVISION != 0
        {
            topic.revisions += 1;
            return;
        }
        let flags = fields.flags.unwrap_or(0);
        topic.untrusted += u64::from(match channel.topic.as_str() {
            service::CORRECTED => {
                flags & (corrected_flags::CLIPPED | corrected_flags::IMPLAUSIBLE) != 0
            }
            service::ODOMETRY => flags & odometry_flags::UNTRUSTED_INPUT != 0,
            _ => false,
        });
        topic.sequenced |= fields.seq.is_some();
        let restart = fields.seq.is_some_and(|seq| {
            self.sequences
                .entry(channel.topic.clone())
                .or_default()
                .next(seq, topic)
        });
        if channel.topic == service::RAW {
            self.raw
                .get_or_insert_with(RawTrack::default)
                .sample(&fields, restart);
        }
        if let Some(id) = fields
            .calib_id
            .filter(|_| channel.topic == service::CORRECTED)
        {
            info.calib_ids.insert(format!("{id:016x}"));
        }
    }
}

impl RunInfo {
    /// Reads the run whose first file is `path` (and its successor segments), message by
    /// message (memory is bounded by a chunk, not the run). Errors if a file cannot be read
    /// or is not MCAP; a truncated file is reported, not an error.
    pub fn read(path: &Path) -> anyhow::Result<Self> {
        let mut tally = Tally::default();
        let mut run = RunReader::open(path)?;
        let mut per_file: Vec<(PathBuf, u64)> = Vec::new();
        while let Some(message) = run.next() {
            let message = message?;
            if per_file.last().is_none_or(|(p, _)| p != message.path) {
                per_file.push((message.path.to_path_buf(), 0));
            }
            if let Some((_, n)) = per_file.last_mut() {
                *n += 1;
            }
            tally.message(&message);
        }
        let mut info = tally.info;
        for segment in run.segments() {
            let bytes = std::fs::metadata(&segment.path)
                .with_context(|| format!("{}", segment.path.display()))?
                .len();
            let messages = per_file
                .iter()
                .find(|(p, _)| *p == segment.path)
                .map_or(0, |(_, n)| *n);
            info.messages += messages;
            info.files.push(FileInfo {
                path: segment.path.clone(),
                bytes,
                messages,
                truncated: segment.truncation.as_ref().map(ToString::to_string),
                damaged: segment.damaged.clone(),
                messages_lost: segment.damaged.iter().map(|d| d.messages_lost()).sum(),
            });
        }
        for topic in info.topics.values_mut() {
            topic.rate_hz = topic.rate();
        }
        if let (Some(s), Some(e)) = (info.start_ns, info.end_ns) {
            info.duration_s = (e - s) as f64 * 1e-9;
            info.wall_clock = run.clock().map(|c| WallClockInfo {
                realtime_ns: c.realtime_ns,
                monotonic_ns: c.monotonic_ns,
                offset_ns: c.offset_ns(),
                start_utc: recording::clock::utc(s),
                end_utc: recording::clock::utc(e),
            });
        }
        info.raw = tally.raw.map(RawTrack::finish);
        Ok(info)
    }

    /// The files, sizes and message counts, and the time the recording spans.
    fn write_files(&self, s: &mut String) {
        let total: u64 = self.files.iter().map(|f| f.bytes).sum();
        let _ = writeln!(
            s,
            "files:     {} ({:.1} MB, {} messages)",
            self.files.len(),
            total as f64 / 1e6,
            self.messages
        );
        for f in &self.files {
            let cut = f
                .truncated
                .as_deref()
                .map_or(String::new(), |why| format!("; truncated: {why}"));
            let _ = writeln!(
                s,
                "  {}: {:.1} MB, {} messages{cut}",
                f.path.display(),
                f.bytes as f64 / 1e6,
                f.messages
            );
            for damage in &f.damaged {
                let _ = writeln!(s, "    {damage}");
            }
        }
        match &self.wall_clock {
            Some(c) => {
                let _ = writeln!(
                    s,
                    "duration:  {:.3} s, {} to {} (log times UTC; message stamps CLOCK_MONOTONIC \
                     + {} ns)",
                    self.duration_s, c.start_utc, c.end_utc, c.offset_ns
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "duration:  {:.3} s (log times {} to {} ns CLOCK_MONOTONIC; no wall-clock \
                     reference)",
                    self.duration_s,
                    self.start_ns.unwrap_or(0),
                    self.end_ns.unwrap_or(0)
                );
            }
        }
    }

    /// A line per topic: count, rate, schema and sequence.
    fn write_topics(&self, s: &mut String) {
        let _ = writeln!(s, "topics:");
        let width = self.topics.keys().map(String::len).max().unwrap_or(0);
        for (name, t) in &self.topics {
            let mut revisions = if t.revisions > 0 {
                format!(", {} revisions", t.revisions)
            } else {
                String::new()
            };
            if t.untrusted > 0 {
                let _ = write!(
                    revisions,
                    ", {} untrusted (clipped or implausible input)",
                    t.untrusted
                );
            }
            let undecodable = if t.undecodable > 0 {
                format!(", {} undecodable", t.undecodable)
            } else {
                String::new()
            };
            let sequence = if t.sequenced {
                format!(
                    "gaps {} ({} missing), restarts {}",
                    t.seq_gaps, t.seq_missing, t.seq_restarts
                )
            } else {
                "no sequence numbers".to_string()
            };
            let rate = t.rate_hz.map_or("-".to_string(), |r| format!("{r:.1}"));
            let _ = writeln!(
                s,
                "  {name:width$}  {:>9} msgs {rate:>9} Hz  {} ({})  {sequence}{revisions}{undecodable}",
                t.count, t.schema, t.encoding
            );
        }
    }

    /// The report as a table for a person.
    pub fn table(&self) -> String {
        let mut s = String::new();
        self.write_files(&mut s);
        self.write_topics(&mut s);
        if let Some(r) = &self.raw {
            let _ = writeln!(
                s,
                "raw:       {} session(s), {:.1} Hz, gyro {}; lost at the sensor {}, \
                 undelivered {}, saturated {}",
                r.sessions,
                r.sample_rate_hz,
                if r.gyro { "yes" } else { "no" },
                r.lost_at_sensor,
                r.undelivered,
                r.saturated
            );
            if r.clipped.samples > 0 {
                let _ = writeln!(
                    s,
                    "clipped:   {} samples at the end of their range ({})",
                    r.clipped.samples,
                    r.clipped.per_axis_text()
                );
            }
            let holes = r.holes.describe(self.start_ns.unwrap_or(0));
            let _ = writeln!(
                s,
                "holes:     {}",
                holes.unwrap_or_else(|| "0 (no unmarked hole in the sample times)".into())
            );
            if let Some(frozen) = Freezes::describe(&r.frozen, self.start_ns.unwrap_or(0)) {
                let _ = writeln!(s, "frozen:    {frozen}: the sensor stopped updating");
            }
        }
        let e = &self.events;
        let _ = writeln!(
            s,
            "recorder:  gap {} ({} missing), seq reset {}, publisher lost {}, back {}, \
             segments {}",
            e.gap, e.gap_missing, e.seq_reset, e.publisher_lost, e.publisher_back, e.segment
        );
        let ids: Vec<&str> = self.calib_ids.iter().map(String::as_str).collect();
        let _ = writeln!(
            s,
            "calib_id:  {}",
            if ids.is_empty() {
                "none (no corrected samples)".to_string()
            } else {
                ids.join(", ")
            }
        );
        s
    }
}

impl EventCounts {
    fn count(&mut self, event: &RecorderEvent) {
        match event.kind {
            EventKind::Gap => {
                self.gap += 1;
                if let (Some(from), Some(to)) = (event.from_seq, event.to_seq) {
                    self.gap_missing += to.saturating_sub(from) + 1;
                }
            }
            EventKind::SeqReset => self.seq_reset += 1,
            EventKind::PublisherLost => self.publisher_lost += 1,
            EventKind::PublisherBack => self.publisher_back += 1,
            EventKind::Segment => self.segment += 1,
        }
    }
}
