//! The replay loop behind `mems-replay`: publishes recorded raw samples on the raw service as
//! the acquisition process would, for the pipeline, the latency benchmark and tests.
//!
//! Each sample is published with the recorded payload except `stamps.acquired_ns`, which is set
//! to the publish time (ns `CLOCK_MONOTONIC`, as acquisition stamps it); `seq` and
//! `stamps.sample_ns` stay as recorded, so that downstream results are reproducible bit for bit.
//! Pacing follows the recorded sample times against the monotonic clock, scaled by a speed
//! factor, or is as fast as the subscribers take the samples ([`Pace::Max`]): the lossless
//! publisher of `ipc_types::service` retries until every subscriber has room, so nothing is lost
//! either way. Where the sample times start over (a recording of several acquisition sessions),
//! pacing starts over with them.
//!
//! Recorded robot hints are published on the hint service as the robot's controller would:
//! with `ipc_types::service::hint_publisher` (never blocking), exactly as recorded (both
//! stamps kept, since the odometry judges a hint's age and delivery by them), each at its
//! place in time among the raw samples: before the first raw sample whose `sample_ns` is not
//! earlier than the hint's publication time `stamps.acquired_ns` (hints published after the
//! last raw sample are not replayed: no sample would use them).

#![warn(missing_docs)]

use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use ipc_types::clock::monotonic_ns;
use ipc_types::service::{self, ServiceError};
use ipc_types::stop;
use ipc_types::{RawImuSample, RobotHint};

/// How fast to publish.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// The recorded sample spacing divided by `speed` (1 = real time, 2 = twice as fast).
    RealTime {
        /// Speed factor, positive and finite.
        speed: f64,
    },
    /// As fast as the slowest subscriber takes the samples.
    Max,
}

/// How to replay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplayOptions {
    /// Pacing.
    pub pace: Pace,
    /// Subscribers that must be connected before the first sample is sent (0: start at once).
    pub wait_subscribers: usize,
    /// How long to wait for them before giving up with [`ReplayError::NoSubscribers`].
    pub wait_timeout: Duration,
}

/// What a replay did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplaySummary {
    /// Samples published.
    pub sent: u64,
    /// Robot hints published.
    pub hints_sent: u64,
    /// Time from the first publication to the last.
    pub elapsed: Duration,
    /// Whether SIGINT or SIGTERM stopped the replay before the last sample.
    pub interrupted: bool,
    /// Samples that reached fewer subscribers than [`ReplayOptions::wait_subscribers`] while
    /// that many were registered: lost for a subscriber that had not connected yet (iceoryx2
    /// queues up to one buffer for it, then drops). 0 in a lossless replay; an error for
    /// `mems-replay`.
    pub short_deliveries: u64,
    /// Samples sent while fewer than [`ReplayOptions::wait_subscribers`] subscribers were
    /// registered, because one left: it ended, or it died and an iceoryx2 process removed its
    /// dead node (any node creation does). A departure, not a replay fault: counted and
    /// reported, and the remaining subscribers get every sample. A dead subscriber counts as
    /// registered until its node is removed, and what is sent to it until then as delivered.
    pub after_subscriber_left: u64,
}

impl ReplaySummary {
    /// Publication rate, samples per second: (sent - 1) / elapsed; 0 with fewer than 2 samples.
    pub fn rate_hz(&self) -> f64 {
        let s = self.elapsed.as_secs_f64();
        if self.sent < 2 || s <= 0.0 {
            0.0
        } else {
            (self.sent - 1) as f64 / s
        }
    }
}

/// Why a replay failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The speed factor is not a positive finite number.
    #[error("the speed factor must be a positive finite number, got {0}")]
    BadSpeed(f64),
    /// The service or publisher could not be opened.
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
    /// iceoryx2 refused to send a sample.
    #[error("{service}: cannot send the sample with seq {seq}: {message}")]
    Send {
        /// The full service name.
        service: String,
        /// The sample's sequence number.
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

/// Waits until `options.wait_subscribers` subscribers are connected to `raw` (named `name`),
/// then lets them settle. `Ok(false)`: termination was requested meanwhile.
fn wait_for_subscribers(
    raw: &iceoryx2::service::port_factory::publish_subscribe::PortFactory<
        ipc::Service,
        RawImuSample,
        (),
    >,
    name: &str,
    options: &ReplayOptions,
) -> Result<bool, ReplayError> {
    let wait_start = Instant::now();
    loop {
        let connected = raw.dynamic_config().number_of_subscribers();
        if connected >= options.wait_subscribers {
            break;
        }
        if wait_start.elapsed() >= options.wait_timeout {
            return Err(ReplayError::NoSubscribers {
                service: name.to_string(),
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

/// Publishes `samples` (in order, `stamps.sample_ns` increasing within each session) on the raw
/// service under `namespace`, from `node`, and `hints` (in order of publication,
/// `stamps.acquired_ns`) on the hint service among them (see the module documentation), paced
/// as `options` say; with `wait_subscribers` > 0 it starts
/// [`SETTLE`] after they are registered and counts samples that reached fewer of them, apart
/// from those sent after one of them left ([`ReplaySummary`]). SIGINT or SIGTERM ([`ipc_types::stop`], installed here)
/// stops the replay early with [`ReplaySummary::interrupted`] set. Returns
/// [`LINGER`] after the last sample, so that every subscriber has connected to it.
pub fn replay(
    node: &Node<ipc::Service>,
    namespace: &str,
    samples: &[RawImuSample],
    hints: &[RobotHint],
    options: &ReplayOptions,
) -> Result<ReplaySummary, ReplayError> {
    if let Pace::RealTime { speed } = options.pace
        && !(speed.is_finite() && speed > 0.0)
    {
        return Err(ReplayError::BadSpeed(speed));
    }
    stop::install()?;
    let name = service::full_name(namespace, service::RAW);
    let raw = service::open::<RawImuSample>(node, &name)?;
    let publisher = service::publisher(&raw)?;
    // Wakes the subscribers after each send (they sleep on the event service).
    let waker = ipc_types::wake::Waker::new(node, &name)?;
    // The hint service is only opened when there are hints to publish.
    let hint_port = if hints.is_empty() {
        None
    } else {
        let hint_name = service::full_name(namespace, service::HINT);
        let hint_service = service::open::<RobotHint>(node, &hint_name)?;
        let hint_publisher = service::hint_publisher(&hint_service)?;
        Some((hint_name, hint_service, hint_publisher))
    };
    let interrupted = |summary: ReplaySummary| ReplaySummary {
        interrupted: true,
        ..summary
    };
    let mut summary = ReplaySummary {
        sent: 0,
        hints_sent: 0,
        elapsed: Duration::ZERO,
        interrupted: false,
        short_deliveries: 0,
        after_subscriber_left: 0,
    };

    if !wait_for_subscribers(&raw, &name, options)? {
        return Ok(interrupted(summary));
    }

    let Some(first) = samples.first() else {
        return Ok(summary);
    };
    // Pacing anchor: a sample time and when it was due; moved where sample times start over.
    let (mut anchor_ns, mut anchor) = (first.stamps.sample_ns, Instant::now());
    let mut previous_ns = anchor_ns;
    let start = anchor;
    let mut next_hint = 0;
    for recorded in samples {
        let t_ns = recorded.stamps.sample_ns;
        if t_ns < previous_ns {
            (anchor_ns, anchor) = (t_ns, Instant::now());
        }
        previous_ns = t_ns;
        if let Pace::RealTime { speed } = options.pace {
            let offset_ns = t_ns.saturating_sub(anchor_ns) as f64 / speed;
            let due = anchor + Duration::from_nanos(offset_ns.round() as u64);
            stop::sleep(due.saturating_duration_since(Instant::now()));
        }
        if stop::requested() {
            return Ok(interrupted(summary));
        }
        if let Some((hint_name, _, hint_publisher)) = &hint_port {
            while let Some(hint) = hints.get(next_hint)
                && hint.stamps.acquired_ns <= t_ns
            {
                hint_publisher
                    .send_copy(*hint)
                    .map_err(|e| ReplayError::Send {
                        service: hint_name.clone(),
                        seq: hint.seq,
                        message: format!("{e:?}"),
                    })?;
                next_hint += 1;
                summary.hints_sent += 1;
            }
        }
        let mut sample = *recorded;
        sample.stamps.acquired_ns = monotonic_ns();
        let recipients = publisher.send_copy(sample).map_err(|e| ReplayError::Send {
            service: name.clone(),
            seq: sample.seq,
            message: format!("{e:?}"),
        })?;
        waker.notify().map_err(|e| ReplayError::Send {
            service: name.clone(),
            seq: sample.seq,
            message: e.to_string(),
        })?;
        if recipients < options.wait_subscribers {
            if raw.dynamic_config().number_of_subscribers() < options.wait_subscribers {
                summary.after_subscriber_left += 1;
            } else {
                summary.short_deliveries += 1;
            }
        }
        summary.sent += 1;
        summary.elapsed = start.elapsed();
    }
    if stop::sleep(LINGER) {
        return Ok(interrupted(summary));
    }
    Ok(summary)
}
