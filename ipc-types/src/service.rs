//! Service names and the iceoryx2 settings every process opens them with.
//!
//! iceoryx2's defaults lose data silently (subscriber buffer 2, safe overflow on). Every
//! service here is opened lossless: safe overflow off, a subscriber buffer of
//! [`SUBSCRIBER_BUFFER`] samples, and publishers that retry until delivered. A subscriber that
//! falls behind therefore applies back-pressure to its publisher instead of losing samples.
//! An opener may not ask for more than the creator configured, so all processes must use
//! these functions rather than their own builders.

use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;

/// Raw samples from the acquisition (or replay) process: [`crate::RawImuSample`].
pub const RAW: &str = "mems/imu/raw";
/// Calibrated samples with the zero-state flag: [`crate::CorrectedImuSample`].
pub const CORRECTED: &str = "mems/imu/corrected";
/// Odometry state: [`crate::OdometryState`].
pub const ODOMETRY: &str = "mems/odometry/state";

/// Environment variable holding a namespace prefix for every service name (tests, and two
/// stacks on one machine). Every binary also takes `--namespace`, which wins over it.
pub const NAMESPACE_ENV: &str = "MEMS_NAMESPACE";

/// Samples each subscriber can queue: one second at the highest output rate (4 kHz).
pub const SUBSCRIBER_BUFFER: usize = 4096;
/// Samples a publisher may hold loaned at once.
pub const MAX_LOANED: usize = 4;
/// Publishers per service (a restarted process may briefly overlap its predecessor).
pub const MAX_PUBLISHERS: usize = 2;
/// Subscribers per service (pipeline stage, recorder, clients, `mems-topic`).
pub const MAX_SUBSCRIBERS: usize = 16;
/// Nodes per service.
pub const MAX_NODES: usize = 32;

/// An iceoryx2 service or port could not be opened; the message names the service and the
/// iceoryx2 error.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceError(pub String);

impl core::fmt::Display for ServiceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ServiceError {}

/// The full service name for `base` (one of [`RAW`], [`CORRECTED`], [`ODOMETRY`]) under a
/// namespace; an empty namespace gives `base` itself.
pub fn full_name(namespace: &str, base: &str) -> String {
    let ns = namespace.trim_matches('/');
    if ns.is_empty() {
        base.to_string()
    } else {
        format!("{ns}/{base}")
    }
}

/// The namespace to use: `cli` when given, else the [`NAMESPACE_ENV`] variable, else none.
pub fn namespace(cli: Option<&str>) -> String {
    cli.map(str::to_string)
        .or_else(|| std::env::var(NAMESPACE_ENV).ok())
        .unwrap_or_default()
}

/// Creates the iceoryx2 node of a process. iceoryx2's own log is limited to errors unless the
/// `IOX2_LOG_LEVEL` environment variable says otherwise (its warning that no config file was
/// loaded is expected: every setting that matters is made explicitly in this module).
pub fn node() -> Result<Node<ipc::Service>, ServiceError> {
    set_log_level_from_env_or(LogLevel::Error);
    NodeBuilder::new()
        .create::<ipc::Service>()
        .map_err(|e| ServiceError(format!("cannot create iceoryx2 node: {e:?}")))
}

/// Removes the shared-memory resources of every node whose process died without cleaning up
/// (a SIGKILLed stage) and returns how many such dead nodes were found. iceoryx2 also does this
/// when a node is created; supervisors call it right after a child dies.
pub fn remove_dead_nodes() -> Result<usize, ServiceError> {
    let mut dead = Vec::new();
    Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    })
    .map_err(|e| ServiceError(format!("cannot list iceoryx2 nodes: {e:?}")))?;
    let found = dead.len();
    for view in dead {
        view.try_remove_stale_resources()
            .map_err(|e| ServiceError(format!("cannot remove a dead node's resources: {e:?}")))?;
    }
    Ok(found)
}

/// Opens (or creates) the publish-subscribe service `name` carrying `T`, with the lossless
/// settings of this module.
pub fn open<T: core::fmt::Debug + ZeroCopySend>(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<PortFactory<ipc::Service, T, ()>, ServiceError> {
    let service_name: ServiceName = name
        .try_into()
        .map_err(|e| ServiceError(format!("invalid service name {name:?}: {e:?}")))?;
    let service = node
        .service_builder(&service_name)
        .publish_subscribe::<T>()
        .enable_safe_overflow(false)
        .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
        .history_size(0)
        .max_publishers(MAX_PUBLISHERS)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(|e| ServiceError(format!("cannot open service {name:?}: {e:?}")))?;
    Ok(service)
}

/// A lossless publisher on `service`: it retries until every subscriber has room.
pub fn publisher<T: core::fmt::Debug + ZeroCopySend>(
    service: &PortFactory<ipc::Service, T, ()>,
) -> Result<Publisher<ipc::Service, T, ()>, ServiceError> {
    service
        .publisher_builder()
        .max_loaned_samples(MAX_LOANED)
        .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
        .create()
        .map_err(|e| ServiceError(format!("cannot create publisher: {e:?}")))
}

/// A subscriber on `service` with the full [`SUBSCRIBER_BUFFER`].
pub fn subscriber<T: core::fmt::Debug + ZeroCopySend>(
    service: &PortFactory<ipc::Service, T, ()>,
) -> Result<Subscriber<ipc::Service, T, ()>, ServiceError> {
    service
        .subscriber_builder()
        .buffer_size(SUBSCRIBER_BUFFER)
        .create()
        .map_err(|e| ServiceError(format!("cannot create subscriber: {e:?}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RawImuSample;

    #[test]
    fn names_take_a_namespace() {
        assert_eq!(full_name("", RAW), "mems/imu/raw");
        assert_eq!(full_name("t1/", ODOMETRY), "t1/mems/odometry/state");
        assert_eq!(namespace(Some("x")), "x");
    }

    /// A real service in one process: a burst larger than iceoryx2's default buffer (2) is
    /// delivered whole, in order, because the service is lossless.
    #[test]
    fn burst_is_delivered_losslessly() {
        let node = node().unwrap();
        let name = full_name(&format!("unit-{}", std::process::id()), RAW);
        let service = open::<RawImuSample>(&node, &name).unwrap();
        let subscriber = subscriber(&service).unwrap();
        let publisher = publisher(&service).unwrap();
        for seq in 0..1000u64 {
            let sample = RawImuSample {
                seq,
                ..Default::default()
            };
            publisher.send_copy(sample).unwrap();
        }
        let mut got = Vec::new();
        while let Some(s) = subscriber.receive().unwrap() {
            got.push(s.seq);
        }
        assert_eq!(got, (0..1000).collect::<Vec<_>>());
    }
}
