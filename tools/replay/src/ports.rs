//! The iceoryx2 ports of a replay: one publisher per replayed topic on its service, opened as
//! the process that publishes it live opens it (lossless for samples and states, never
//! blocking for robot hints), and the event that wakes the subscribers of each data service.

use iceoryx2::port::publisher::Publisher;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory as PubSubFactory;
use ipc_types::clock::monotonic_ns;
use ipc_types::service::{self, ServiceError};
use ipc_types::wake::Waker;
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};

use crate::ReplayError;
use crate::topics::{Payload, Replayable};

/// One topic's service and publisher.
struct Port<T: core::fmt::Debug + ZeroCopySend + 'static> {
    name: String,
    service: PubSubFactory<ipc::Service, T, ()>,
    publisher: Publisher<ipc::Service, T, ()>,
    /// `None` for robot hints: only samples wake the odometry, which takes the hints first.
    waker: Option<Waker>,
}

impl<T: core::fmt::Debug + ZeroCopySend + Copy + 'static> Port<T> {
    fn open(
        node: &Node<ipc::Service>,
        namespace: &str,
        topic: Replayable,
    ) -> Result<Self, ServiceError> {
        let name = service::full_name(namespace, topic.topic());
        let service = service::open::<T>(node, &name)?;
        let (publisher, waker) = if topic == Replayable::Hint {
            (service::hint_publisher(&service)?, None)
        } else {
            (
                service::publisher(&service)?,
                Some(Waker::new(node, &name)?),
            )
        };
        Ok(Self {
            name,
            service,
            publisher,
            waker,
        })
    }

    /// Sends `payload` (sequence number `seq`) and wakes the subscribers; how many it reached.
    fn send(&self, payload: T, seq: u64) -> Result<usize, ReplayError> {
        let fail = |message: String| ReplayError::Send {
            service: self.name.clone(),
            seq,
            message,
        };
        let recipients = self
            .publisher
            .send_copy(payload)
            .map_err(|e| fail(format!("{e:?}")))?;
        if let Some(waker) = &self.waker {
            waker.notify().map_err(|e| fail(e.to_string()))?;
        }
        Ok(recipients)
    }

    fn subscribers(&self) -> usize {
        self.service.dynamic_config().number_of_subscribers()
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
    /// Returns how many subscribers it reached, or `None` if its topic is not waited for.
    pub fn send(&self, payload: &Payload) -> Result<Option<usize>, ReplayError> {
        let seq = payload.seq();
        let unopened = || ReplayError::Send {
            service: payload.topic().topic().to_string(),
            seq,
            message: "its topic is not replayed".into(),
        };
        let recipients = match *payload {
            Payload::Hint(h) => self.hint.as_ref().ok_or_else(unopened)?.send(h, seq)?,
            Payload::Raw(mut s) => {
                s.stamps.acquired_ns = monotonic_ns();
                self.raw.as_ref().ok_or_else(unopened)?.send(s, seq)?
            }
            Payload::Corrected(mut s) => {
                s.stamps.calibrated_ns = monotonic_ns();
                self.corrected.as_ref().ok_or_else(unopened)?.send(s, seq)?
            }
            Payload::Odometry(mut s) => {
                s.stamps.odometry_ns = monotonic_ns();
                self.odometry.as_ref().ok_or_else(unopened)?.send(s, seq)?
            }
        };
        Ok(self.waited.contains(&payload.topic()).then_some(recipients))
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
