//! The recorded topics `mems-replay` can publish, one per iceoryx2 service of
//! `ipc_types::service`, their payloads, and the time at which each message is replayed.
//!
//! A message's replay time is its own time on the recording's `CLOCK_MONOTONIC` stamps: the
//! sample time (`stamps.sample_ns`) of a raw or corrected sample or an odometry state, the
//! publication time (`stamps.acquired_ns`) of a robot hint. An odometry state flagged
//! `REVISION` revises an earlier sample, so its sample time is in the past: it is replayed at
//! the time of the state before it on its topic (the odometry sends a revision right after the
//! live state that made it possible). Where a topic's time goes back otherwise, its times start
//! over (two runs recorded into one file): a new epoch, and pacing starts over with it.

use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint, odometry_flags};
use recording::mcap::Topic;
use recording::mcap::run::Message;

/// A recorded topic that maps to one of our iceoryx2 services (topic name = service base name).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Replayable {
    /// `mems/robot/hint`, published as the robot's controller would (never blocking).
    Hint,
    /// `mems/imu/raw`, published as `mems-acquire` would.
    Raw,
    /// `mems/imu/corrected`, published as `mems-calibrate serve` would.
    Corrected,
    /// `mems/odometry/state`, published as `mems-odometry serve` would.
    Odometry,
}

impl Replayable {
    /// Every replayable topic, in the order messages of the same time are published (a hint
    /// before the sample it precedes, a sample before what the pipeline made of it).
    pub const ALL: [Self; 4] = [Self::Hint, Self::Raw, Self::Corrected, Self::Odometry];

    /// The recorded topic, which is also the service's base name.
    pub fn topic(self) -> &'static str {
        match self {
            Self::Hint => RobotHint::TOPIC,
            Self::Raw => RawImuSample::TOPIC,
            Self::Corrected => CorrectedImuSample::TOPIC,
            Self::Odometry => OdometryState::TOPIC,
        }
    }

    /// The replayable topic recorded as `topic`, if it is one.
    pub fn of_topic(topic: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|r| r.topic() == topic)
    }

    /// Its index in [`Self::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }
}

/// One recorded message of a replayable topic.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Payload {
    /// A robot hint.
    Hint(RobotHint),
    /// A raw sample.
    Raw(RawImuSample),
    /// A corrected sample.
    Corrected(CorrectedImuSample),
    /// An odometry state.
    Odometry(OdometryState),
}

impl Payload {
    /// Its topic.
    pub fn topic(&self) -> Replayable {
        match self {
            Self::Hint(_) => Replayable::Hint,
            Self::Raw(_) => Replayable::Raw,
            Self::Corrected(_) => Replayable::Corrected,
            Self::Odometry(_) => Replayable::Odometry,
        }
    }

    /// Its own time, ns `CLOCK_MONOTONIC` (see the module documentation).
    pub fn time_ns(&self) -> u64 {
        match self {
            Self::Hint(h) => h.stamps.acquired_ns,
            Self::Raw(s) => s.stamps.sample_ns,
            Self::Corrected(s) => s.stamps.sample_ns,
            Self::Odometry(s) => s.stamps.sample_ns,
        }
    }

    /// Its sequence number.
    pub fn seq(&self) -> u64 {
        match self {
            Self::Hint(h) => h.seq,
            Self::Raw(s) => s.seq,
            Self::Corrected(s) => s.seq,
            Self::Odometry(s) => s.seq,
        }
    }

    /// Whether it is an odometry state revising an earlier one.
    pub fn is_revision(&self) -> bool {
        matches!(self, Self::Odometry(s) if s.flags & odometry_flags::REVISION != 0)
    }

    /// The message decoded, if it is on `topic`.
    pub fn decode(message: &Message<'_>, topic: Replayable) -> Option<recording::Result<Self>> {
        match topic {
            Replayable::Hint => message.decode().map(|r| r.map(Self::Hint)),
            Replayable::Raw => message.decode().map(|r| r.map(Self::Raw)),
            Replayable::Corrected => message.decode().map(|r| r.map(Self::Corrected)),
            Replayable::Odometry => message.decode().map(|r| r.map(Self::Odometry)),
        }
    }
}

/// Where a message is replayed: its epoch (times started over that many times before it on
/// its topic) and its replay time in that epoch, ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Place {
    /// Epoch: 0 until the topic's times first start over.
    pub epoch: u32,
    /// Replay time, ns `CLOCK_MONOTONIC` as recorded.
    pub time_ns: u64,
}

/// The places of one topic's messages, in file order (see the module documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct Timeline {
    epoch: u32,
    last_ns: Option<u64>,
}

impl Timeline {
    /// The place of the next message of the topic.
    pub fn place(&mut self, payload: &Payload) -> Place {
        let t_ns = payload.time_ns();
        let time_ns = match self.last_ns {
            Some(last) if payload.is_revision() => last,
            Some(last) if t_ns < last => {
                self.epoch += 1;
                t_ns
            }
            _ => t_ns,
        };
        if !payload.is_revision() || self.last_ns.is_none() {
            self.last_ns = Some(time_ns);
        }
        Place {
            epoch: self.epoch,
            time_ns,
        }
    }

    /// How many times the topic's times started over so far.
    pub fn epochs_started_over(&self) -> u32 {
        self.epoch
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::Stamps;

    fn state(sample_ns: u64, revision: bool) -> Payload {
        Payload::Odometry(OdometryState {
            stamps: Stamps {
                sample_ns,
                ..Stamps::default()
            },
            flags: if revision {
                odometry_flags::REVISION
            } else {
                0
            },
            ..OdometryState::default()
        })
    }

    #[test]
    fn a_revision_takes_the_place_of_the_state_before_it_and_times_going_back_start_an_epoch() {
        let mut timeline = Timeline::default();
        let places: Vec<(u32, u64)> = [
            state(10, false),
            state(20, false),
            state(12, true),
            state(30, false),
            state(5, false),
            state(3, true),
            state(6, false),
        ]
        .iter()
        .map(|p| {
            let place = timeline.place(p);
            (place.epoch, place.time_ns)
        })
        .collect();
        assert_eq!(
            places,
            [(0, 10), (0, 20), (0, 20), (0, 30), (1, 5), (1, 5), (1, 6)]
        );
        assert_eq!(timeline.epochs_started_over(), 1);
    }

    #[test]
    fn every_topic_maps_to_its_service() {
        assert_eq!(Replayable::Raw.topic(), ipc_types::service::RAW);
        assert_eq!(Replayable::Corrected.topic(), ipc_types::service::CORRECTED);
        assert_eq!(Replayable::Odometry.topic(), ipc_types::service::ODOMETRY);
        assert_eq!(Replayable::Hint.topic(), ipc_types::service::HINT);
        for r in Replayable::ALL {
            assert_eq!(Replayable::of_topic(r.topic()), Some(r));
            assert_eq!(Replayable::ALL[r.index()], r);
        }
        assert_eq!(Replayable::of_topic("mems/odometry/pose"), None);
    }
}
