//! The replay behind `mems-replay`: publishes a recording's replayable topics (raw samples,
//! corrected samples, odometry states, robot hints: [`topics`]) on their iceoryx2 services as
//! the processes that publish them live would ([`ports`]), each message at its place in
//! recorded time, for the pipeline, control processes under test, the latency benchmark and
//! tests.
//!
//! Replaying the raw samples and robot hints lets the live pipeline recompute everything, bit
//! for bit: `seq`, `stamps.sample_ns` and the hints stay as recorded, and a raw sample's
//! `stamps.acquired_ns` is its publication time (as acquisition stamps it). Replaying recorded
//! outputs (corrected samples, states) lets a control process be tested against a run without
//! the pipeline.
//!
//! Messages are taken from the file topic by topic ([`source`]) and merged by their replay time
//! (a sample's or state's sample time, a hint's publication time: a hint goes before the first
//! raw sample taken at or after it). Pacing follows those times against the monotonic clock,
//! scaled by a speed factor and counted from when the first message actually left, or is as fast as the subscribers take the messages
//! ([`Pace::Max`]): the lossless publishers of `ipc_types::service` retry until every
//! subscriber has room, so nothing is lost either way. A subscriber that leaves during the
//! replay (it ends, or its process dies) is a departure, not a replay fault: the others still
//! get every message, and what reached fewer subscribers because of it is counted and reported
//! ([`ReplaySummary`]). A dead subscriber's node is removed by the replay itself
//! ([`DEAD_NODE_CLEANUP_PERIOD`]), so that it neither holds the replay back nor counts as
//! registered for long. Where the recorded times start over (runs recorded into one file),
//! pacing starts over with them. A window ([`source::Window`]) keeps part of the recording;
//! looping ([`ReplayOptions::looping`]) replays it again and again: each pass sends the same
//! sequence numbers and sample times again, which our processes take for a new acquisition
//! session (the calibration starts over, the odometry aligns again); a pass's first corrected
//! sample carries `NEW_SESSION`, as the calibration stage would mark it, so that an odometry
//! fed the corrected topic directly starts over too.

#![warn(missing_docs)]

mod deliveries;
mod paced;
mod pacer;
pub mod ports;
pub mod progress;
pub mod source;
pub mod topics;

use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use ipc_types::service::{DeadNodeCleanup, ServiceError};
use ipc_types::stop;

use crate::deliveries::Deliveries;
use crate::ports::Ports;
use crate::source::{Merge, Recording, Window};
use crate::topics::Replayable;

/// How fast to publish.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// The recorded spacing divided by `speed` (1 = real time, 2 = twice as fast).
    RealTime {
        /// Speed factor, positive and finite.
        speed: f64,
    },
    /// As fast as the slowest subscriber takes the messages.
    Max,
}

/// How to replay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplayOptions {
    /// Pacing.
    pub pace: Pace,
    /// Subscribers that must be connected to each replayed service (the robot hints' only when
    /// they are replayed alone) before the first message is sent (0: start at once).
    pub wait_subscribers: usize,
    /// How long to wait for them before giving up with [`ReplayError::NoSubscribers`].
    pub wait_timeout: Duration,
    /// Replay the recording (or its window) again and again until SIGINT or SIGTERM.
    pub looping: bool,
}

/// What a replay did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ReplaySummary {
    /// Messages published per topic (indexed by [`Replayable::index`]).
    pub sent: [u64; 4],
    /// Passes over the recording started (more than one only when looping).
    pub passes: u64,
    /// Recorded time covered by the current pass so far, ns (over epochs).
    pub pass_recorded_ns: u64,
    /// Time from the first publication to the last.
    pub elapsed: Duration,
    /// Whether SIGINT or SIGTERM stopped the replay before the last message.
    pub interrupted: bool,
    /// Messages that reached fewer subscribers than [`ReplayOptions::wait_subscribers`] while
    /// that many were registered, none of them left and none was given up as stalled: lost for
    /// a subscriber that had not connected yet (iceoryx2 queues up to one buffer for it, then
    /// drops). 0 in a lossless replay; an error for `mems-replay`.
    pub short_deliveries: u64,
    /// Messages that reached fewer than [`ReplayOptions::wait_subscribers`] subscribers
    /// because one left: it ended, or its process died (a SIGKILLed subscriber's node is
    /// removed within [`DEAD_NODE_CLEANUP_PERIOD`], by the replay or by any iceoryx2 process
    /// that creates a node). A departure, not a replay fault: counted and reported, and the
    /// remaining subscribers get every message. Until a dead subscriber's node is removed, what
    /// is sent to it fills its buffer and counts as delivered.
    pub after_subscriber_left: u64,
    /// Messages that reached fewer than [`ReplayOptions::wait_subscribers`] subscribers
    /// because the publisher gave them up for a subscriber whose buffer had stayed full for
    /// `ipc_types::service::STALL_TIMEOUT` (one that died and whose node was not removed yet,
    /// or one that hangs), as every publisher of ours does. Counted and reported, not a
    /// replay fault.
    pub given_up_stalled: u64,
}

impl ReplaySummary {
    /// Messages published, all topics.
    pub fn total_sent(&self) -> u64 {
        self.sent.iter().sum()
    }

    /// Publication rate, messages per second: (sent - 1) / elapsed; 0 with fewer than 2.
    pub fn rate_hz(&self) -> f64 {
        let (s, sent) = (self.elapsed.as_secs_f64(), self.total_sent());
        if sent < 2 || s <= 0.0 {
            0.0
        } else {
            (sent - 1) as f64 / s
        }
    }
}

/// Why a replay failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The speed factor is not a positive finite number.
    #[error("the speed factor must be a positive finite number, got {0}")]
    BadSpeed(f64),
    /// The recording could not be read.
    #[error(transparent)]
    Recording(#[from] recording::Error),
    /// A service or publisher could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// Too few subscribers connected within the timeout.
    #[error(
        "{service}: only {connected} of {wanted} subscribers connected after {:.1} s",
        .waited.as_secs_f64()
    )]
    NoSubscribers {
        /// The full service name.
        service: String,
        /// Subscribers asked for.
        wanted: usize,
        /// Subscribers connected at the timeout.
        connected: usize,
        /// How long the replay waited.
        waited: Duration,
    },
    /// iceoryx2 refused to send a message.
    #[error("{service}: cannot send the message with seq {seq}: {message}")]
    Send {
        /// The full service name.
        service: String,
        /// The message's sequence number.
        seq: u64,
        /// iceoryx2's error.
        message: String,
    },
}
/// How long the publisher stays after the last sample. An iceoryx2 subscriber connects to a
/// publisher's data on its next `receive` after the publisher appeared; if the publisher leaves
/// before that, the subscriber never sees what it sent (measured: a 400-sample replay at
/// `--max` finished in 1 ms and a recorder polling every 1 ms missed all of it). Subscribers
/// that had connected keep receiving what was sent after the publisher leaves.
pub const LINGER: Duration = Duration::from_millis(200);

/// Pause between the subscribers being registered and the first sample. iceoryx2 registers a
/// subscriber at once, but it connects to a publisher's data only on its next `receive` after
/// the publisher appeared; until then the publisher queues one subscriber buffer for it and
/// drops the rest (measured: a release `--max` replay filled the 4096-sample buffer before the
/// recorder, polling every 1 ms, had connected, and 777 samples were lost).
pub const SETTLE: Duration = Duration::from_millis(100);

/// Waits until every waited-for service of `ports` has `options.wait_subscribers`
/// subscribers, then lets them settle. `Ok(false)`: termination was requested meanwhile.
fn wait_for_subscribers(
    ports: &Ports,
    namespace: &str,
    options: &ReplayOptions,
) -> Result<bool, ReplayError> {
    let wait_start = Instant::now();
    loop {
        let (service, connected) = ports.fewest_subscribers(namespace);
        if connected >= options.wait_subscribers {
            break;
        }
        if wait_start.elapsed() >= options.wait_timeout {
            return Err(ReplayError::NoSubscribers {
                service,
                wanted: options.wait_subscribers,
                connected,
                waited: wait_start.elapsed(),
            });
        }
        if stop::sleep(Duration::from_millis(1)) {
            return Ok(false);
        }
    }
    Ok(!(options.wait_subscribers > 0 && stop::sleep(SETTLE)))
}

/// How often the replay removes the nodes of dead processes ([`DeadNodeCleanup`], on a thread
/// of its own, as `mems-record` does). A SIGKILLed subscriber stays registered until some
/// process removes its node; until then what is sent to it fills its buffer, and then the
/// lossless publisher waits for it (up to `ipc_types::service::STALL_TIMEOUT`). Removing it
/// here makes its death a departure within this period, whether or not another iceoryx2
/// process on the machine creates a node meanwhile: a real-time replay of up to 4 kHz at speed
/// 1 sends far less than a buffer in it. Each removal lists every node (docs/acquisition.md:
/// thousands of allocation calls with a few hundred nodes), hence not more often.
pub const DEAD_NODE_CLEANUP_PERIOD: Duration = Duration::from_millis(250);

/// Sends one pass of `messages` through `ports` with the source driver
/// (`mems_stage::source::produce`: [`paced::Pass`] into [`paced::Published`]), counting in
/// `summary` (short deliveries through `deliveries`); `Ok(false)` if SIGINT or SIGTERM stopped
/// it.
fn pass(
    ports: &mut Ports,
    messages: Merge<'_>,
    options: &ReplayOptions,
    deliveries: &mut Deliveries,
    summary: &mut ReplaySummary,
    start: Instant,
    progress: &mut dyn FnMut(&ReplaySummary),
) -> Result<bool, ReplayError> {
    let mut source = paced::Pass::new(messages, options.pace, summary.passes > 1);
    let mut sink = paced::Published {
        ports,
        deliveries,
        summary,
        start,
        progress,
    };
    mems_stage::source::produce::<_, _, ReplayError>(&mut source, &mut sink)?;
    Ok(!stop::requested())
}

/// Publishes `topics` of `recording` (within `window`, if given) on their services under
/// `namespace`, from `node`, paced as `options` say (see the crate documentation); with
/// `wait_subscribers` > 0 it starts [`SETTLE`] after they are registered and counts the
/// messages that reached fewer of them by cause ([`ReplaySummary`]; some only later, at the
/// latest at the end). Removes dead nodes every [`DEAD_NODE_CLEANUP_PERIOD`] meanwhile. `progress` sees
/// the summary after each message. SIGINT or SIGTERM ([`ipc_types::stop`], installed here)
/// stops the replay with [`ReplaySummary::interrupted`] set (the only way a looping replay
/// ends). Returns [`LINGER`] after the last message, so that every subscriber has connected
/// to it.
pub fn replay(
    node: &Node<ipc::Service>,
    namespace: &str,
    recording: &Recording,
    topics: &[Replayable],
    window: Option<Window>,
    options: &ReplayOptions,
    progress: &mut dyn FnMut(&ReplaySummary),
) -> Result<ReplaySummary, ReplayError> {
    if let Pace::RealTime { speed } = options.pace
        && !(speed.is_finite() && speed > 0.0)
    {
        return Err(ReplayError::BadSpeed(speed));
    }
    stop::install()?;
    // Stopped and joined when the replay returns.
    let _cleanup = DeadNodeCleanup::start(DEAD_NODE_CLEANUP_PERIOD)?;
    let mut ports = Ports::open(node, namespace, topics)?;
    let mut summary = ReplaySummary::default();
    if !wait_for_subscribers(&ports, namespace, options)? {
        summary.interrupted = true;
        return Ok(summary);
    }
    let mut deliveries = Deliveries::new(options.wait_subscribers);
    let start = Instant::now();
    loop {
        summary.passes += 1;
        summary.pass_recorded_ns = 0;
        let messages = Merge::new(recording.streams(topics)?, window);
        if !pass(
            &mut ports,
            messages,
            options,
            &mut deliveries,
            &mut summary,
            start,
            progress,
        )? {
            summary.interrupted = true;
            break;
        }
        if !options.looping || summary.total_sent() == 0 {
            break;
        }
    }
    if !summary.interrupted {
        summary.interrupted = stop::sleep(LINGER);
    }
    deliveries.finish(&ports, &mut summary);
    Ok(summary)
}
