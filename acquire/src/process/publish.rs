//! The publishing of `mems-acquire`: its service and publisher opened, the sensor session
//! placed, then FIFO reads on an absolute schedule run by the source driver
//! (`mems_stage::source::produce`, see `super::reads`), every sample published on
//! `mems/imu/raw`, until the duration is over or SIGINT/SIGTERM arrives.

use std::path::PathBuf;
use std::time::Duration;

use alloc_count::pool::BlockPool;
use anyhow::Result;
use embedded_hal::i2c::I2c;
use ipc_types::wake::Output;
use ipc_types::{RawImuSample, service};

use super::reads::{RawOut, Reads};
use super::{SimPart, Summary};
use crate::acquisition::{Acquisition, SourceSpec, fifo_fill_ns};
use crate::clock::Clock;
use crate::driver::{self, Mpu9250};
use crate::session::Session;

/// How the samples are published: where, for how long, at what configuration and read
/// interval, and the process's small-block pool (armed once the loop starts).
pub struct Publish<'a, const N: usize> {
    /// Namespace prefix for service names (`None`: `$MEMS_NAMESPACE`).
    pub namespace: Option<String>,
    /// Stop after this many seconds (`None`: until SIGINT/SIGTERM).
    pub duration_s: Option<f64>,
    /// The sensor's configuration.
    pub config: driver::Config,
    /// Time between FIFO reads, ns.
    pub read_interval_ns: u64,
    /// The process's global allocator: small blocks come from it once the loop starts.
    pub pool: &'a BlockPool<N>,
    /// The sensor session's state file, which a restarted process continues (see
    /// [`crate::session`]; `None`: every start is a new session).
    pub session_file: Option<PathBuf>,
}

impl<const N: usize> Publish<'_, N> {
    /// The sensor session of `source` (`sim` describing a simulated part) at this
    /// configuration: the one the session file holds for that part, continued, or a new one.
    pub fn session(&self, source: &SourceSpec, sim: &SimPart) -> Result<Session> {
        let now_ns = ipc_types::clock::monotonic_ns();
        let Some(path) = &self.session_file else {
            return Ok(Session::transient(now_ns));
        };
        let part = format!("{source:?}, {:?}, {sim:?}", self.config);
        let session = Session::open(path, &part, now_ns)?;
        if let Some(resume) = session.resume() {
            tracing::info!(
                "continuing the sensor session of {}: next sample seq {}, {:.3} s after its \
                 newest sample",
                path.display(),
                resume.next_seq,
                now_ns.saturating_sub(resume.last_sample_ns) as f64 * 1e-9
            );
        }
        Ok(session)
    }

    /// Publishes what `driver` reads, on `clock`, in `session`, until the duration is over or
    /// SIGINT/SIGTERM arrives; then logs the run's [`Summary`].
    pub fn run<I2C: I2c, C: Clock>(
        &self,
        driver: Mpu9250<I2C>,
        clock: C,
        session: Session,
    ) -> Result<()> {
        let namespace = service::namespace(self.namespace.as_deref());
        let name = service::full_name(&namespace, service::RAW);
        // Before any port exists: a SIGINT/SIGTERM is kept from then on.
        ipc_types::stop::install()?;
        let node = service::node()?;
        let raw = service::open::<RawImuSample>(&node, &name)?;
        // A subscriber whose buffer is full (stopped, hung) is waited for at most an eighth of
        // the FIFO's fill time, then its samples are given up and counted for it: the loop never
        // waits on a subscriber for as long as the FIFO lasts, so the sensor loses nothing for it.
        let stall_wait = Duration::from_nanos(fifo_fill_ns(&self.config) / 8);
        let (publisher, undelivered) = service::publisher_waiting_at_most(&raw, stall_wait)?;
        // Wakes the subscribers after a read's first sample and after its last.
        let out = Output::with_publisher(&node, publisher, &name)?;

        let acq = Acquisition::start(driver, clock, self.config, self.read_interval_ns)
            .map_err(|e| anyhow::anyhow!("{e}"))?
            .in_session(session);
        tracing::info!(
            "{} ({}) at {} Hz on {name}, reading every {:.2} ms",
            acq.driver().bus_label(),
            acq.driver().part().unwrap_or("?"),
            self.config.output_rate_hz(),
            self.read_interval_ns as f64 * 1e-6
        );
        let mut reads = Reads::new(acq, self.duration_s.map(Duration::from_secs_f64));
        let mut sink = RawOut { out, undelivered };
        // Start-up is over: from here on small blocks come from the pool.
        self.pool.arm();
        mems_stage::source::produce::<_, _, anyhow::Error>(&mut reads, &mut sink)?;
        let elapsed = reads.start.elapsed();
        Summary::of(&reads.acq, &sink.undelivered, elapsed).log(self.pool);
        Ok(())
    }
}
