//! What is replayed, in which order: a recording's replayable topics, each streamed from the
//! file on its own ([`recording::mcap::run::RunReader`]: one chunk held per topic, however long
//! the run), merged in replay time ([`Merge`]), and surveyed once before the replay
//! ([`Survey`]) for its time span, its topics and every message's validity.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use recording::mcap::RawChecks;
use recording::mcap::run::RunReader;

use crate::topics::{Payload, Place, Replayable, Timeline};

/// One topic's messages in recorded order.
pub type Stream<'a> = Box<dyn Iterator<Item = recording::Result<Payload>> + 'a>;

/// A recording to replay.
#[derive(Debug, Clone)]
pub enum Recording {
    /// An MCAP run (its first file; its successor segments are read with it), streamed.
    Mcap(PathBuf),
    /// Messages in memory, in recorded order: a CSV's raw samples, or a test's messages.
    Memory(Vec<Payload>),
}

impl Recording {
    /// The recording at `path`: MCAP streamed, a CSV (canonical or thesis) read whole (raw
    /// samples only); a truncation of a CSV is returned to be reported.
    pub fn open(path: &Path) -> recording::Result<(Self, Option<String>)> {
        if recording::mcap::has_magic(path)? {
            return Ok((Self::Mcap(path.to_path_buf()), None));
        }
        let csv = recording::load_raw(path)?;
        let truncation = csv.truncation.map(|t| t.to_string());
        let payloads = csv.samples.into_iter().map(Payload::Raw).collect();
        Ok((Self::Memory(payloads), truncation))
    }

    /// Each of `topics`' messages from the start, one stream per topic.
    pub fn streams(&self, topics: &[Replayable]) -> recording::Result<Vec<Stream<'_>>> {
        topics
            .iter()
            .map(|&topic| -> recording::Result<Stream<'_>> {
                Ok(match self {
                    Self::Mcap(path) => Box::new(TopicStream {
                        reader: RunReader::open(path)?,
                        topic,
                        checks: RawChecks::default(),
                    }),
                    Self::Memory(payloads) => Box::new(
                        payloads
                            .iter()
                            .filter(move |p| p.topic() == topic)
                            .map(|p| Ok(*p)),
                    ),
                })
            })
            .collect()
    }
}

/// One topic of an MCAP run; raw samples are checked as `recording::mcap::read_all` checks
/// them.
struct TopicStream {
    reader: RunReader,
    topic: Replayable,
    checks: RawChecks,
}

impl Iterator for TopicStream {
    type Item = recording::Result<Payload>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            let message = match self.reader.next()? {
                Ok(m) => m,
                Err(e) => return Some(Err(e)),
            };
            let Some(payload) = Payload::decode(&message, self.topic) else {
                continue;
            };
            return Some(payload.and_then(|payload| {
                if let Payload::Raw(sample) = &payload {
                    let topic = &message.channel.topic;
                    self.checks
                        .check(message.path, message.index, topic, sample)?;
                }
                Ok(payload)
            }));
        }
    }
}

/// The replay times kept, ns `CLOCK_MONOTONIC` as recorded, both included.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// First replay time kept.
    pub start_ns: u64,
    /// Last replay time kept.
    pub end_ns: u64,
}

/// One topic's stream and its next message.
struct Head<'a> {
    stream: Stream<'a>,
    timeline: Timeline,
    next: Option<(Place, Payload)>,
    ended: bool,
}

/// The messages of several topics merged by their place ([`Place`]: epoch, then replay time;
/// at the same place, in the order of [`Replayable::ALL`]), each topic in recorded order,
/// within a [`Window`] if given. A topic ends at its first message past the window.
pub struct Merge<'a> {
    heads: Vec<Head<'a>>,
    window: Option<Window>,
}

impl<'a> Merge<'a> {
    /// The merge of `streams`.
    pub fn new(streams: Vec<Stream<'a>>, window: Option<Window>) -> Self {
        let heads = streams
            .into_iter()
            .map(|stream| Head {
                stream,
                timeline: Timeline::default(),
                next: None,
                ended: false,
            })
            .collect();
        Self { heads, window }
    }

    /// Fills `head` with its next message in the window, if any.
    fn fill(head: &mut Head<'a>, window: Option<Window>) -> recording::Result<()> {
        while head.next.is_none() && !head.ended {
            let Some(payload) = head.stream.next().transpose()? else {
                head.ended = true;
                break;
            };
            let place = head.timeline.place(&payload);
            match window {
                Some(w) if place.time_ns > w.end_ns => head.ended = true,
                Some(w) if place.time_ns < w.start_ns => {}
                _ => head.next = Some((place, payload)),
            }
        }
        Ok(())
    }
}

impl Iterator for Merge<'_> {
    type Item = recording::Result<(Place, Payload)>;

    fn next(&mut self) -> Option<Self::Item> {
        for head in &mut self.heads {
            if let Err(e) = Self::fill(head, self.window) {
                head.ended = true;
                return Some(Err(e));
            }
        }
        let first = self
            .heads
            .iter_mut()
            .filter(|h| h.next.is_some())
            .min_by_key(|h| h.next.map(|(place, p)| (place, p.topic())))?;
        first.next.take().map(Ok)
    }
}

/// What a recording holds, read once before the replay: every message decoded and checked.
#[derive(Debug, Clone, Default)]
pub struct Survey {
    /// Every recorded topic with its number of messages.
    pub topics: BTreeMap<String, u64>,
    /// Messages of each replayable topic (indexed by [`Replayable::index`]).
    pub counts: [u64; 4],
    /// Each replayable topic's epochs after the first (its times started over).
    pub restarts: [u32; 4],
    /// Per epoch, the first and last replay time of any replayable message, ns.
    pub spans: Vec<(u64, u64)>,
    /// The cuts of files that end early or are damaged (read up to the cut).
    pub truncations: Vec<String>,
}

impl Survey {
    /// Reads the whole recording (all replayable topics, in one pass over an MCAP run).
    pub fn of(recording: &Recording) -> recording::Result<Self> {
        let mut survey = Self::default();
        let mut timelines = [Timeline::default(); 4];
        match recording {
            Recording::Memory(payloads) => {
                for p in payloads {
                    survey.topics.entry(p.topic().topic().into()).or_default();
                    survey.add(p, &mut timelines);
                }
            }
            Recording::Mcap(path) => survey.read_mcap(path, &mut timelines)?,
        }
        Ok(survey)
    }

    fn read_mcap(&mut self, path: &Path, timelines: &mut [Timeline; 4]) -> recording::Result<()> {
        let mut reader = RunReader::open(path)?;
        let mut checks = RawChecks::default();
        while let Some(message) = reader.next() {
            let message = message?;
            *self
                .topics
                .entry(message.channel.topic.clone())
                .or_default() += 1;
            let Some(topic) = Replayable::of_topic(&message.channel.topic) else {
                continue;
            };
            let payload = Payload::decode(&message, topic).expect("on its topic")?;
            if let Payload::Raw(sample) = &payload {
                let topic = &message.channel.topic;
                checks.check(message.path, message.index, topic, sample)?;
            }
            self.add(&payload, timelines);
        }
        self.truncations = reader
            .segments()
            .iter()
            .filter_map(|s| {
                let t = s.truncation.as_ref()?;
                Some(format!("{}: {t}", s.path.display()))
            })
            .collect();
        Ok(())
    }

    fn add(&mut self, payload: &Payload, timelines: &mut [Timeline; 4]) {
        let i = payload.topic().index();
        self.counts[i] += 1;
        let place = timelines[i].place(payload);
        self.restarts[i] = timelines[i].epochs_started_over();
        let epoch = place.epoch as usize;
        if self.spans.len() <= epoch {
            self.spans.resize(epoch + 1, (u64::MAX, 0));
        }
        let span = &mut self.spans[epoch];
        *span = (span.0.min(place.time_ns), span.1.max(place.time_ns));
    }

    /// Recorded time spanned by the replayable messages, ns (summed over epochs).
    pub fn span_ns(&self) -> u64 {
        self.spans.iter().map(|(a, b)| b.saturating_sub(*a)).sum()
    }
}

impl Survey {
    /// The topics to replay: those `asked` (recorded topic names), or by default the raw
    /// samples and robot hints the recording holds. Errors name a topic that is not
    /// replayable or not in the recording, list the replayable ones it holds, and refuse
    /// topics whose times start over a different number of times (no one timeline places
    /// them).
    pub fn select(&self, asked: Option<&[String]>) -> Result<Vec<Replayable>, String> {
        let held: Vec<Replayable> = Replayable::ALL
            .into_iter()
            .filter(|r| self.counts[r.index()] > 0)
            .collect();
        let listed = || {
            let names: Vec<&str> = held.iter().map(|r| r.topic()).collect();
            match names.is_empty() {
                true => "none".to_string(),
                false => names.join(", "),
            }
        };
        let mut topics = match asked {
            None if self.counts[Replayable::Raw.index()] == 0 => {
                return Err(format!(
                    "holds no raw samples (replayable topics it holds: {}; choose with --topics)",
                    listed()
                ));
            }
            None => vec![Replayable::Hint, Replayable::Raw],
            Some(names) => names
                .iter()
                .map(|name| match Replayable::of_topic(name) {
                    Some(r) if held.contains(&r) => Ok(r),
                    Some(_) => Err(format!(
                        "--topics {name}: the recording holds no message on it (replayable \
                         topics it holds: {})",
                        listed()
                    )),
                    None => Err(format!(
                        "--topics {name}: not a replayable topic (replayable: the topics of our \
                         services, {}; this recording holds {})",
                        Replayable::ALL.map(Replayable::topic).join(", "),
                        listed()
                    )),
                })
                .collect::<Result<_, _>>()?,
        };
        topics.retain(|r| held.contains(r));
        topics.sort();
        topics.dedup();
        if let Some(odd) = topics
            .iter()
            .find(|r| self.restarts[r.index()] != self.restarts[topics[0].index()])
        {
            return Err(format!(
                "the times of {} start over {} times but those of {} {} times: no single \
                 timeline places them; replay them apart (--topics)",
                odd.topic(),
                self.restarts[odd.index()],
                topics[0].topic(),
                self.restarts[topics[0].index()]
            ));
        }
        Ok(topics)
    }

    /// The window of `--start`/`--end` (seconds from the recording's first replayable
    /// message, by replay time), `None` without either. Errors name the option.
    pub fn window(
        &self,
        start_s: Option<f64>,
        end_s: Option<f64>,
    ) -> Result<Option<Window>, String> {
        if start_s.is_none() && end_s.is_none() {
            return Ok(None);
        }
        if self.spans.len() > 1 {
            return Err(format!(
                "--start/--end: the recording's times start over {} times (runs recorded into \
                 one file), so a time from its start names no one message",
                self.spans.len() - 1
            ));
        }
        let (first_ns, last_ns) = self.spans.first().copied().unwrap_or((0, 0));
        let length_s = (last_ns - first_ns) as f64 * 1e-9;
        let (start, end) = (start_s.unwrap_or(0.0), end_s.unwrap_or(length_s));
        for (option, value) in [("--start", start), ("--end", end)] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(format!(
                    "{option} {value}: must be a non-negative number of seconds"
                ));
            }
            if value > length_s {
                return Err(format!(
                    "{option} {value}: past the recording's end ({length_s:.9} s after its first \
                     message)"
                ));
            }
        }
        if start >= end {
            return Err(format!("--start {start} must be before --end {end}"));
        }
        let at = |s: f64| first_ns + (s * 1e9).round() as u64;
        Ok(Some(Window {
            start_ns: at(start),
            end_ns: if end_s.is_some() { at(end) } else { last_ns },
        }))
    }

    /// Messages of `topics` within `window`, per topic: the survey's counts without a window,
    /// otherwise counted by merging the recording once more.
    pub fn counts_in(
        &self,
        recording: &Recording,
        topics: &[Replayable],
        window: Option<Window>,
    ) -> recording::Result<[u64; 4]> {
        let mut counts = [0; 4];
        if window.is_none() {
            for t in topics {
                counts[t.index()] = self.counts[t.index()];
            }
            return Ok(counts);
        }
        for message in Merge::new(recording.streams(topics)?, window) {
            counts[message?.1.topic().index()] += 1;
        }
        Ok(counts)
    }
}
