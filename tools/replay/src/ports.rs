//! The iceoryx2 ports of a replay: one publisher per replayed topic on its service, opened as
//! the process that publishes it live opens it (lossless for samples and states, never
//! blocking for robot hints), and the event that wakes the subscribers of each data service.
//! Every message goes out through `ipc_types::wake::Output`, the live processes' send path,
//! as one input of its own (sent, then notified).

use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use ipc_types::clock::monotonic_ns;
use ipc_types::service::{self, ServiceError, Undelivered};
use ipc_types::wake::Output;
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};

use crate::ReplayError;
use crate::topics::{Payload, Replayable};

/// What one send did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Delivery {
    /// Subscribers the message reached.
    pub recipients: usize,
    /// Whether the publisher gave the message up for a subscriber whose buffer had stayed full
    /// for [`service::STALL_TIMEOUT`] (see [`service::publisher_waiting_at_most`]).
    pub given_up: bool,
}

/// A subscriber registered on a service: its port and the node (process) it belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SubscriberPort {
    /// The subscriber port's id.
    pub id: u128,
    /// Its node's id.
    pub node: UniqueNodeId,
}

/// One topic's service and publisher.
struct Port<T: core::fmt::Debug + ZeroCopySend + 'static> {
    name: String,
    service: PubSubFactory<ipc::Service, T, ()>,
    /// Woken for samples and states; unwoken for robot hints: only samples wake the odometry,
    /// which takes the hints first.
    output: Output<T>,
    /// What the lossless publisher gave up for stalled subscribers (`None` for the hints,
    /// whose publisher never waits).
    undelivered: Option<Undelivered>,
}

impl<T: core::fmt::Debug + ZeroCopySend + Copy + 'static> Port<T> {
    fn open(
        node: &Node<ipc::Service>,
        namespace: &str,
        topic: Replayable,
    ) -> Result<Self, ServiceError> {
        let name = service::full_name(namespace, topic.topic());
        let service = service::open::<T>(node, &name)?;
        let (output, undelivered) = if topic == Replayable::Hint {
            (Output::unwoken(service::hint_publisher(&service)?), None)
        } else {
            // `service::publisher`'s settings, with the count of what it gives up.
            let (publisher, undelivered) =
                service::publisher_waiting_at_most(&service, service::STALL_TIMEOUT)?;
            (
                Output::with_publisher(node, publisher, &name)?,
                Some(undelivered),
            )
        };
        Ok(Self {
            name,
            service,
            output,
            undelivered,
        })
    }

    /// Sends `payload` (sequence number `seq`) and wakes the subscribers.
    fn send(&mut self, payload: T, seq: u64) -> Result<Delivery, ReplayError> {
        let given_up_before = self.undelivered.as_ref().map_or(0, Undelivered::total);
        let recipients = self.output.send(payload);
        self.output.end_of_input().map_err(|e| ReplayError::Send {
            service: self.name.clone(),
            seq,
            message: e.to_string(),
        })?;
        let given_up = self.undelivered.as_ref().map_or(0, Undelivered::total) > given_up_before;
        Ok(Delivery {
            recipients,
            given_up,
        })
    }

    fn subscribers(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
    }

    fn subscriber_ports(&self) -> Vec<SubscriberPort> {
        let mut ports = Vec::new();
        self.service.dynamic_config().list_subscribers(|s| {
            ports.push(SubscriberPort {
                id: s.subscriber_id.value(),
                node: s.node_id,
            });
            CallbackProgression::Continue
        });
        ports
    }
}

/// The ports of the replayed topics.
pub struct Ports {
    hint: Option<Port<RobotHint>>,
    raw: Option<Port<RawImuSample>>,
    corrected: Option<Port<CorrectedImuSample>>,
    odometry: Option<Port<OdometryState>>,
    /// The topics whose subscribers are waited for and counted: all but the hints, unless
    /// they are replayed alone.
    waited: Vec<Replayable>,
}

impl Ports {
    /// Opens the services of `topics` under `namespace`.
    pub fn open(
        node: &Node<ipc::Service>,
        namespace: &str,
        topics: &[Replayable],
    ) -> Result<Self, ServiceError> {
        let has = |t: Replayable| topics.contains(&t);
        let mut waited: Vec<Replayable> = topics
            .iter()
            .copied()
            .filter(|&t| t != Replayable::Hint)
            .collect();
        if waited.is_empty() {
            waited = topics.to_vec();
        }
        Ok(Self {
            hint: has(Replayable::Hint)
                .then(|| Port::open(node, namespace, Replayable::Hint))
                .transpose()?,
            raw: has(Replayable::Raw)
                .then(|| Port::open(node, namespace, Replayable::Raw))
                .transpose()?,
            corrected: has(Replayable::Corrected)
                .then(|| Port::open(node, namespace, Replayable::Corrected))
                .transpose()?,
            odometry: has(Replayable::Odometry)
                .then(|| Port::open(node, namespace, Replayable::Odometry))
                .transpose()?,
            waited,
        })
    }

    /// Publishes `payload` as its live publisher would: recorded, except that a sample or a
    /// state carries its publication time in its publisher's own stamp (`acquired_ns` of a
    /// raw sample, `calibrated_ns` of a corrected one, `odometry_ns` of a state); a robot
    /// hint is sent exactly as recorded (the odometry judges its age by both its stamps).
    /// Returns what the send did, or `None` if its topic is not waited for.
    pub fn send(&mut self, payload: &Payload) -> Result<Option<Delivery>, ReplayError> {
        let seq = payload.seq();
        let unopened = || ReplayError::Send {
            service: payload.topic().topic().to_string(),
            seq,
            message: "its topic is not replayed".into(),
        };
        let delivery = match *payload {
            Payload::Hint(h) => self.hint.as_mut().ok_or_else(unopened)?.send(h, seq)?,
            Payload::Raw(mut s) => {
                s.stamps.acquired_ns = monotonic_ns();
                self.raw.as_mut().ok_or_else(unopened)?.send(s, seq)?
            }
            Payload::Corrected(mut s) => {
                s.stamps.calibrated_ns = monotonic_ns();
                self.corrected.as_mut().ok_or_else(unopened)?.send(s, seq)?
            }
            Payload::Odometry(mut s) => {
                s.stamps.odometry_ns = monotonic_ns();
                self.odometry.as_mut().ok_or_else(unopened)?.send(s, seq)?
            }
        };
        Ok(self.waited.contains(&payload.topic()).then_some(delivery))
    }

    /// Subscribers registered on `topic`'s service (0 if it is not replayed).
    pub fn subscribers(&self, topic: Replayable) -> usize {
        match topic {
            Replayable::Hint => self.hint.as_ref().map_or(0, Port::subscribers),
            Replayable::Raw => self.raw.as_ref().map_or(0, Port::subscribers),
            Replayable::Corrected => self.corrected.as_ref().map_or(0, Port::subscribers),
            Replayable::Odometry => self.odometry.as_ref().map_or(0, Port::subscribers),
        }
    }

    /// The subscribers registered on `topic`'s service (none if it is not replayed).
    pub fn subscriber_ports(&self, topic: Replayable) -> Vec<SubscriberPort> {
        match topic {
            Replayable::Hint => self.hint.as_ref().map(Port::subscriber_ports),
            Replayable::Raw => self.raw.as_ref().map(Port::subscriber_ports),
            Replayable::Corrected => self.corrected.as_ref().map(Port::subscriber_ports),
            Replayable::Odometry => self.odometry.as_ref().map(Port::subscriber_ports),
        }
        .unwrap_or_default()
    }

    /// The waited-for service with the fewest subscribers: its full name and their number.
    pub fn fewest_subscribers(&self, namespace: &str) -> (String, usize) {
        self.waited
            .iter()
            .map(|&t| {
                (
                    service::full_name(namespace, t.topic()),
                    self.subscribers(t),
                )
            })
            .min_by_key(|(_, n)| *n)
            .unwrap_or_default()
    }
}
