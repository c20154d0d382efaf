//! Service names and the iceoryx2 settings every process opens them with.
//!
//! iceoryx2's defaults lose data silently (subscriber buffer 2, safe overflow on). Every
//! service here is opened lossless: safe overflow off, a subscriber buffer of
//! [`SUBSCRIBER_BUFFER`] samples, and publishers that retry until delivered. A subscriber that
//! falls behind therefore applies back-pressure to its publisher instead of losing samples.
//! An opener may not ask for more than the creator configured, so all processes must use
//! these functions rather than their own builders.

use iceoryx2::identifiers::UniqueNodeId;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Raw samples from the acquisition (or replay) process: [`crate::RawImuSample`].
pub const RAW: &str = "mems/imu/raw";
/// Calibrated samples with the zero-state flag: [`crate::CorrectedImuSample`].
pub const CORRECTED: &str = "mems/imu/corrected";
/// Odometry state: [`crate::OdometryState`].
pub const ODOMETRY: &str = "mems/odometry/state";
/// Rest and speed hints from the robot's own controller: [`crate::RobotHint`]. Controllers
/// should publish them without blocking (their control loop must not wait for the odometry):
/// see [`hint_publisher`].
pub const HINT: &str = "mems/robot/hint";

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
/// loaded is expected: every setting that matters is made explicitly in this module). A
/// process installs [`crate::stop`] itself (a test harness keeps its own Ctrl-C).
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

/// The ids of the iceoryx2 nodes whose process died and whose resources are not removed yet
/// (their ports still registered on their services). iceoryx2 tells a dead node by its
/// process's monitor lock, so a node is listed here from its process's death until its
/// cleanup (by any process) has removed its ports; never one of a live process.
pub fn dead_nodes() -> Result<Vec<UniqueNodeId>, ServiceError> {
    let mut dead = Vec::new();
    Node::<ipc::Service>::list(Config::global_config(), |state| {
        if matches!(state, NodeState::Dead(_)) {
            dead.push(*state.node_id());
        }
        CallbackProgression::Continue
    })
    .map_err(|e| ServiceError(format!("cannot list iceoryx2 nodes: {e:?}")))?;
    Ok(dead)
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
    patiently(&format!("service {name:?}"), pubsub_in_flux, || {
        node.service_builder(&service_name)
            .publish_subscribe::<T>()
            .enable_safe_overflow(false)
            .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
            .history_size(0)
            .max_publishers(MAX_PUBLISHERS)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create()
    })
}

/// How long opening a service keeps trying while iceoryx2 finds it half made or half removed
/// by another process. iceoryx2 itself gives up after its `creation_timeout` (1 s by default,
/// `service/builder/mod.rs`, `open_or_create`): on a loaded machine a creator that is not
/// scheduled for a second would otherwise stop every process started beside it.
pub const OPEN_PATIENCE: Duration = Duration::from_secs(30);

/// Calls `attempt` until it succeeds, fails with an error `in_flux` does not call transient,
/// or [`OPEN_PATIENCE`] has passed; the error names `what`.
pub(crate) fn patiently<T, E: core::fmt::Debug>(
    what: &str,
    in_flux: impl Fn(&E) -> bool,
    mut attempt: impl FnMut() -> Result<T, E>,
) -> Result<T, ServiceError> {
    let start = Instant::now();
    loop {
        match attempt() {
            Ok(value) => return Ok(value),
            Err(e) if in_flux(&e) && start.elapsed() < OPEN_PATIENCE => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Err(e) => return Err(ServiceError(format!("cannot open {what}: {e:?}"))),
        }
    }
}

/// Whether a publish-subscribe open-or-create failed only because another process was
/// creating or removing the service at that moment (or a signal interrupted the wait).
fn pubsub_in_flux(e: &PublishSubscribeOpenOrCreateError) -> bool {
    use PublishSubscribeOpenError as Open;
    matches!(
        e,
        PublishSubscribeOpenOrCreateError::SystemInFlux
            | PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                Open::HangsInCreation | Open::IsMarkedForDestruction | Open::Interrupt
            )
    )
}

/// How long a publisher waits for one subscriber's full buffer before it gives that sample
/// up for that subscriber (and counts it, see [`stalled_discards`]).
pub const STALL_TIMEOUT: Duration = Duration::from_secs(2);

static STALLED_DISCARDS: AtomicU64 = AtomicU64::new(0);

/// Samples this process's publishers gave up delivering to a subscriber that stayed full for
/// [`STALL_TIMEOUT`] (a SIGKILLed or hung subscriber). Processes report it in their summary.
pub fn stalled_discards() -> u64 {
    STALLED_DISCARDS.load(Ordering::Relaxed)
}

/// A publisher on `service` that retries until every subscriber has room: a slow subscriber
/// applies back-pressure, nothing is overwritten. A subscriber whose buffer stays full for
/// [`STALL_TIMEOUT`] (killed with SIGKILL before iceoryx2 noticed, or hung) would block the
/// pipeline for ever; for it, the sample is discarded, counted and reported on stderr, and
/// while it stays stalled later samples for it are discarded at once, so the live subscribers
/// keep their rate. Dead-node cleanup (`remove_dead_nodes`, or any node creation) then removes
/// its connection.
pub fn publisher<T: core::fmt::Debug + ZeroCopySend>(
    service: &PortFactory<ipc::Service, T, ()>,
) -> Result<Publisher<ipc::Service, T, ()>, ServiceError> {
    Ok(publisher_waiting_at_most(service, STALL_TIMEOUT)?.0)
}

/// Samples a publisher gave up delivering, per subscriber port (see
/// [`publisher_waiting_at_most`]). Cloning shares the counts.
#[derive(Debug, Clone, Default)]
pub struct Undelivered(Arc<Mutex<Vec<(u128, u64)>>>);

impl Undelivered {
    /// (subscriber port id, samples given up for it), in the order the subscribers stalled.
    pub fn per_subscriber(&self) -> Vec<(u128, u64)> {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Samples given up, summed over subscribers.
    pub fn total(&self) -> u64 {
        let counts = self.0.lock().unwrap_or_else(|e| e.into_inner());
        counts.iter().map(|(_, n)| n).sum()
    }

    fn count(&self, port: u128) {
        let mut counts = self.0.lock().unwrap_or_else(|e| e.into_inner());
        match counts.iter_mut().find(|(id, _)| *id == port) {
            Some((_, n)) => *n += 1,
            None => counts.push((port, 1)),
        }
    }
}

/// [`publisher`], but waiting at most `wait` for a subscriber whose buffer is full before
/// giving the sample up for it (the source, whose sensor FIFO overflows if it waits longer,
/// passes a fraction of the FIFO's fill time), and counting what it gave up per subscriber in
/// the returned [`Undelivered`] (and in [`stalled_discards`]). `wait` is per stalled
/// subscriber; while one stays stalled (it took no sample within [`STALL_TIMEOUT`] of the last
/// sample given up for it), later samples for it are given up at once.
pub fn publisher_waiting_at_most<T: core::fmt::Debug + ZeroCopySend>(
    service: &PortFactory<ipc::Service, T, ()>,
    wait: Duration,
) -> Result<(Publisher<ipc::Service, T, ()>, Undelivered), ServiceError> {
    let undelivered = Undelivered::default();
    let counts = undelivered.clone();
    // Receiver port id -> when it was last given up on. Room for every subscriber up front,
    // so that the hot path does not allocate.
    let stalled: Mutex<Vec<(u128, Instant)>> = Mutex::new(Vec::with_capacity(MAX_SUBSCRIBERS));
    counts
        .0
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .reserve(MAX_SUBSCRIBERS);
    let handler = move |info: &BackpressureInfo| -> BackpressureAction {
        let mut stalled = stalled.lock().unwrap_or_else(|e| e.into_inner());
        let recently = stalled
            .iter()
            .any(|(id, at)| *id == info.receiver_port_id && at.elapsed() < STALL_TIMEOUT);
        if !recently && info.elapsed_time < wait {
            return BackpressureAction::Retry;
        }
        if !recently {
            tracing::warn!(
                "subscriber port {:#x} has not taken a sample for {wait:?}: discarding \
                 for it",
                info.receiver_port_id
            );
        }
        stalled.retain(|(id, _)| *id != info.receiver_port_id);
        stalled.push((info.receiver_port_id, Instant::now()));
        STALLED_DISCARDS.fetch_add(1, Ordering::Relaxed);
        counts.count(info.receiver_port_id);
        BackpressureAction::DiscardData
    };
    let publisher = service
        .publisher_builder()
        .max_loaned_samples(MAX_LOANED)
        .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
        .set_backpressure_handler(handler)
        .create()
        .map_err(|e| ServiceError(format!("cannot create publisher: {e:?}")))?;
    Ok((publisher, undelivered))
}

/// Dead-node cleanup on a thread of its own: every `period` it removes the resources of
/// iceoryx2 nodes whose process died (a SIGKILLed subscriber's connection, which would
/// otherwise stall a lossless publisher for [`STALL_TIMEOUT`], or count as a live publisher).
/// Listing the nodes makes thousands of heap allocations per call in iceoryx2 0.10 (every path
/// is formatted) and reads a directory, which a serving loop must not do per sample; this
/// thread does it beside the loop, with its own node and as `SCHED_OTHER` (a SCHED_FIFO
/// process's threads inherit its policy). Dropping it stops and joins the thread, which
/// releases its node.
pub struct DeadNodeCleanup {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl DeadNodeCleanup {
    /// Starts the thread; returns once its node exists (or with the error creating it).
    pub fn start(period: Duration) -> Result<Self, ServiceError> {
        let stop = Arc::new(AtomicBool::new(false));
        let (ready, started) = std::sync::mpsc::sync_channel(1);
        let stopped = stop.clone();
        let thread = std::thread::Builder::new()
            .name("dead-node-cleanup".into())
            .spawn(move || {
                // SAFETY: sets this thread's own scheduling policy; `param` outlives the call.
                unsafe {
                    let param = libc::sched_param { sched_priority: 0 };
                    libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_OTHER, &param);
                }
                let node = match node() {
                    Ok(n) => n,
                    Err(e) => {
                        let _ = ready.send(Err(e));
                        return;
                    }
                };
                let _ = ready.send(Ok(()));
                while !stopped.load(Ordering::Relaxed) {
                    node.try_cleanup_dead_nodes();
                    std::thread::park_timeout(period);
                }
            })
            .map_err(|e| ServiceError(format!("cannot start the dead-node cleanup thread: {e}")))?;
        started
            .recv()
            .map_err(|_| ServiceError("the dead-node cleanup thread ended at start".into()))??;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }
}

impl Drop for DeadNodeCleanup {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            thread.thread().unpark();
            let _ = thread.join();
        }
    }
}

/// A publisher for a robot controller's hints ([`HINT`]): it never blocks. A subscriber whose
/// buffer is full (an odometry process that hangs) misses the hint; the odometry treats a
/// missing hint as a stale one and falls back to the IMU alone, which is safe, whereas a
/// control loop that waited on the odometry would not be.
pub fn hint_publisher<T: core::fmt::Debug + ZeroCopySend>(
    service: &PortFactory<ipc::Service, T, ()>,
) -> Result<Publisher<ipc::Service, T, ()>, ServiceError> {
    service
        .publisher_builder()
        .max_loaned_samples(MAX_LOANED)
        .backpressure_strategy(BackpressureStrategy::DiscardData)
        .create()
        .map_err(|e| ServiceError(format!("cannot create hint publisher: {e:?}")))
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

    /// Opening retries iceoryx2's transient failures (a service another process is creating or
    /// removing) and returns at once on any other, naming the service.
    #[test]
    fn opening_waits_out_a_service_in_flux_only() {
        let mut attempts = 0;
        let opened = patiently("service \"s\"", pubsub_in_flux, || {
            attempts += 1;
            match attempts {
                1 => Err(PublishSubscribeOpenOrCreateError::SystemInFlux),
                2 => Err(
                    PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                        PublishSubscribeOpenError::HangsInCreation,
                    ),
                ),
                _ => Ok(attempts),
            }
        });
        assert_eq!(opened, Ok(3));
        let mut attempts = 0;
        let refused: Result<(), _> = patiently("service \"s\"", pubsub_in_flux, || {
            attempts += 1;
            Err(
                PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
                    PublishSubscribeOpenError::IncompatibleTypes,
                ),
            )
        });
        assert_eq!(attempts, 1);
        let message = refused.unwrap_err().0;
        assert!(
            message.starts_with("cannot open service \"s\": ")
                && message.contains("IncompatibleTypes"),
            "{message}"
        );
    }

    /// A service whose creator stopped half way for longer than iceoryx2's 1 s
    /// `creation_timeout` (its static config still at the permissions it is written with:
    /// owner read-write, iceoryx2-cal's `static_storage/file.rs`, `INIT_PERMISSIONS`) is
    /// opened once that creator is gone, not refused as hanging in creation.
    #[test]
    fn a_service_hanging_in_creation_is_waited_for() {
        use std::os::unix::fs::PermissionsExt;
        let name = full_name(&format!("unit-hang-{}", std::process::id()), RAW);
        let node = node().unwrap();
        let dir =
            std::path::PathBuf::from(Config::global_config().global.service_dir().to_string());
        // Created once to find its static config (the file that names it), then dropped,
        // which removes it.
        let file = {
            let _service = open::<RawImuSample>(&node, &name).unwrap();
            std::fs::read_dir(&dir)
                .unwrap()
                .filter_map(|e| Some(e.ok()?.path()))
                .find(|p| {
                    p.extension().is_some_and(|x| x == "service")
                        && std::fs::read_to_string(p).is_ok_and(|s| s.contains(&name))
                })
                .expect("the service's static config")
        };
        assert!(!file.exists(), "{} left behind", file.display());
        std::fs::write(&file, b"").unwrap();
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).unwrap();
        let creator_gone = std::thread::spawn({
            let file = file.clone();
            move || {
                std::thread::sleep(Duration::from_millis(2500));
                std::fs::remove_file(file).unwrap();
            }
        });
        let opened = open::<RawImuSample>(&node, &name);
        creator_gone.join().unwrap();
        assert!(opened.is_ok(), "{:?}", opened.err());
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

    /// Sends `n` samples with sequence numbers 0.. on `publisher`, draining `live` after each
    /// (checking their order); returns how many `live` received.
    fn send_and_drain(
        publisher: &Publisher<ipc::Service, RawImuSample, ()>,
        live: &iceoryx2::port::subscriber::Subscriber<ipc::Service, RawImuSample, ()>,
        n: u64,
    ) -> u64 {
        let mut got = 0u64;
        for seq in 0..n {
            publisher
                .send_copy(RawImuSample {
                    seq,
                    ..Default::default()
                })
                .unwrap();
            while let Some(s) = live.receive().unwrap() {
                assert_eq!(s.seq, got);
                got += 1;
            }
        }
        got
    }

    /// A subscriber that never takes its samples (as a SIGKILLed one) stalls the publisher for
    /// STALL_TIMEOUT once; after that its samples are discarded and counted, and a live
    /// subscriber receives every sample.
    #[test]
    fn a_stalled_subscriber_is_given_up_and_counted() {
        let node = node().unwrap();
        let name = full_name(&format!("stall-{}", std::process::id()), RAW);
        let service = open::<RawImuSample>(&node, &name).unwrap();
        let stuck = subscriber(&service).unwrap();
        let live = subscriber(&service).unwrap();
        let (publisher, undelivered) = publisher_waiting_at_most(&service, STALL_TIMEOUT).unwrap();
        // A subscriber's side of the connection is established by its first receive: the
        // stuck one has been receiving, then stops (as one that is killed).
        assert!(stuck.receive().unwrap().is_none());
        let extra = 10;
        let start = Instant::now();
        let got = send_and_drain(&publisher, &live, SUBSCRIBER_BUFFER as u64 + extra);
        let waited = start.elapsed();
        assert_eq!(got, SUBSCRIBER_BUFFER as u64 + extra);
        assert_eq!(undelivered.total(), extra);
        assert!(waited >= STALL_TIMEOUT, "waited {waited:?}");
        assert!(
            waited < 2 * STALL_TIMEOUT,
            "stalled more than once: {waited:?}"
        );
    }

    /// With a bounded wait, a stalled subscriber's samples are given up and counted for that
    /// subscriber alone: the live one receives all of them and has nothing counted.
    #[test]
    fn samples_given_up_are_counted_per_subscriber() {
        let node = node().unwrap();
        let name = full_name(&format!("bounded-{}", std::process::id()), RAW);
        let service = open::<RawImuSample>(&node, &name).unwrap();
        let stuck = subscriber(&service).unwrap();
        let live = subscriber(&service).unwrap();
        let (publisher, undelivered) =
            publisher_waiting_at_most(&service, Duration::from_millis(5)).unwrap();
        assert!(stuck.receive().unwrap().is_none());
        let extra = 25;
        let got = send_and_drain(&publisher, &live, SUBSCRIBER_BUFFER as u64 + extra);
        assert_eq!(got, SUBSCRIBER_BUFFER as u64 + extra);
        let counts = undelivered.per_subscriber();
        assert_eq!(counts.len(), 1, "{counts:?}");
        assert_eq!(counts[0].1, extra);
        assert_eq!(undelivered.total(), extra);
        // The stalled subscriber still holds the samples that fitted, in order.
        let mut held = 0u64;
        while let Some(s) = stuck.receive().unwrap() {
            assert_eq!(s.seq, held);
            held += 1;
        }
        assert_eq!(held, SUBSCRIBER_BUFFER as u64);
    }
}
