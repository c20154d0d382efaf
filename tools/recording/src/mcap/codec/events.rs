//! The recorder's own events: their codec and schema.

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use super::Topic;
use super::schema::{object, uint};
use crate::mcap::proto;

/// Topic of the recorder's own events ([`RecorderEvent`]).
pub const EVENTS_TOPIC: &str = "mems/recorder/events";

/// What a [`RecorderEvent`] reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// Sequence numbers `from_seq..=to_seq` never arrived: they are missing from the recording.
    Gap,
    /// The sequence went back: `to_seq` arrived when `from_seq` was expected (a restarted
    /// publisher that counts from 0 again).
    SeqReset,
    /// The service's last publisher went away (`from_seq` = `to_seq` = the last sequence
    /// number received, `None` if none was).
    PublisherLost,
    /// A publisher appeared again after [`EventKind::PublisherLost`] (sequence numbers as there).
    PublisherBack,
    /// The recorder was restarted and this file continues the run of the previous segment
    /// (see [`crate::segment`]): `from_seq` = `to_seq` = this segment's number (1 for the first
    /// successor), `service` empty. What was lost across the split follows as
    /// [`EventKind::Gap`] events.
    Segment,
}

impl EventKind {
    /// Every kind.
    pub const ALL: [Self; 5] = [
        Self::Gap,
        Self::SeqReset,
        Self::PublisherLost,
        Self::PublisherBack,
        Self::Segment,
    ];

    /// The kind's name, as JSON and protobuf spell it (`gap`, `seq_reset`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::Gap => "gap",
            Self::SeqReset => "seq_reset",
            Self::PublisherLost => "publisher_lost",
            Self::PublisherBack => "publisher_back",
            Self::Segment => "segment",
        }
    }
}

/// An event the recorder noticed on a service, so that a crashed or restarted stage shows in
/// the recording explicitly.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecorderEvent {
    /// What happened.
    pub kind: EventKind,
    /// The service's base name (without namespace), e.g. `mems/imu/corrected`.
    pub service: String,
    /// First sequence number concerned (see [`EventKind`]).
    pub from_seq: Option<u64>,
    /// Last sequence number concerned (see [`EventKind`]).
    pub to_seq: Option<u64>,
    /// When the recorder noticed, ns `CLOCK_MONOTONIC`.
    pub t_ns: u64,
}

impl Topic for RecorderEvent {
    const TOPIC: &'static str = EVENTS_TOPIC;
    const SCHEMA_NAME: &'static str = "mems.RecorderEvent";

    type Proto = proto::RecorderEvent;

    fn proto_schema() -> Vec<u8> {
        proto::file_descriptor_set()
    }

    fn fill_proto(&self, p: &mut Self::Proto) {
        p.kind.clear();
        p.kind.push_str(self.kind.name());
        p.service.clear();
        p.service.push_str(&self.service);
        p.from_seq = self.from_seq;
        p.to_seq = self.to_seq;
        p.t_ns = self.t_ns;
    }

    fn from_proto(p: Self::Proto) -> std::result::Result<Self, String> {
        let kind = EventKind::ALL
            .into_iter()
            .find(|k| k.name() == p.kind)
            .ok_or_else(|| format!("field kind: unknown event kind {:?}", p.kind))?;
        Ok(Self {
            kind,
            service: p.service,
            from_seq: p.from_seq,
            to_seq: p.to_seq,
            t_ns: p.t_ns,
        })
    }

    fn json_schema() -> Value {
        let seq = |what: &str| {
            json!({
                "type": ["integer", "null"],
                "minimum": 0,
                "maximum": u64::MAX,
                "description": what,
            })
        };
        object(
            Self::SCHEMA_NAME,
            "Something the recorder noticed on a service: lost sequence numbers, a publisher gone or back.",
            &[
                (
                    "kind",
                    json!({
                        "type": "string",
                        "enum": ["gap", "seq_reset", "publisher_lost", "publisher_back", "segment"],
                        "description": "gap: from_seq..=to_seq missing; seq_reset: to_seq arrived when from_seq was expected; publisher_lost/back: from_seq = to_seq = last sequence number received (null if none); segment: a restarted recorder continues the run in this file, from_seq = to_seq = its segment number.",
                    }),
                ),
                (
                    "service",
                    json!({"type": "string", "description": "Service base name, e.g. mems/imu/raw."}),
                ),
                ("from_seq", seq("First sequence number concerned.")),
                ("to_seq", seq("Last sequence number concerned.")),
                (
                    "t_ns",
                    uint("When the recorder noticed, ns CLOCK_MONOTONIC.", u64::MAX),
                ),
            ],
        )
    }

    fn publish_time_ns(&self) -> u64 {
        self.t_ns
    }

    fn is_finite(&self) -> bool {
        true
    }
}
