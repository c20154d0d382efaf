//! `mems-odometry serve`: the odometry stage between `mems/imu/corrected` and
//! `mems/odometry/state`, with the robot's hints from `mems/robot/hint` when a controller
//! publishes them.
//!
//! - Before each sample, the hints published (`stamps.acquired_ns`) by its time are handed to
//!   the stage in arrival order; the stage uses a hint for the samples taken at least
//!   `--hint-delivery-ms` after its publication, so the states do not depend on how hints and
//!   samples interleave in transport, and a replay gives the same states. A hint published
//!   after the sample waits in the subscriber's queue. A refused hint (NaN, no time) is
//!   reported on stderr and skipped.
//! - Every corrected sample gives one state, in order; the end of a motion interval also
//!   republishes that interval's states with the `REVISION` flag. `stamps.odometry_ns` is
//!   `CLOCK_MONOTONIC` at publication.
//! - A refused sample (NaN, a value beyond any calibrated sensor's range, time not increasing)
//!   is reported on stderr, counted (`refused` in the summary) and skipped: it never reaches
//!   the filter's state.
//! - Samples without a gyroscope (`raw_flags::GYRO_VALID` clear: an accelerometer-only sensor
//!   mode, the MPU-9250 at 4 kHz) cannot be navigated, since nothing tracks the attitude: each
//!   gets a state flagged `NO_GYRO`, never `ALIGNED`, with no position or velocity (zero), and
//!   does not reach the stage; the first one is reported once on stderr.
//! - Sequence numbers that go back mean a new sensor session (a restarted acquire), and so does
//!   a time step longer than `ipc_types::limits::MAX_STEP_S` (no dead reckoning bridges it):
//!   the stage starts over (new alignment).
//! - The process sleeps on the corrected service's event (its publisher notifies it after each
//!   send) and notifies `mems/odometry/state`'s: the live state at once, a sample's revisions
//!   together after them. `--spin` polls instead.
//! - The loop allocates nothing per sample from the system allocator: iceoryx2's one small
//!   block per published state comes from the process's pool (`alloc_count::pool`). The
//!   summary gives the steady-state counts (`alloc_count::steady`).
//! - SIGINT/SIGTERM: a summary, exit status 0.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Duration;

use alloc_count::steady::SteadyState;
use anyhow::{Context, Result};
use calibrate::calibfile::CalibrationFile;
use ipc_types::clock::monotonic_ns;
use ipc_types::limits::MAX_STEP_NS;
use ipc_types::wake::{self, Output, WaitMode};
use ipc_types::{
    CorrectedImuSample, OdometryState, RobotHint, corrected_flags, odometry_flags, raw_flags,
    service,
};
use odometry::hints::{HintConfigError, usable_from_ns};
use odometry::stage::OdometryStage;

/// Options of `mems-odometry serve`.
#[derive(clap::Args)]
pub struct ServeArgs {
    /// Calibration file (TOML): its gravity and noise parameters configure the filter.
    #[arg(long)]
    calib: PathBuf,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// Poll for corrected samples without sleeping (for a core of its own) instead of sleeping
    /// until the calibration stage's event wakes the process.
    #[arg(long)]
    spin: bool,
    /// Motion profile (its rest handling; the detector is `mems-calibrate serve`'s).
    #[arg(long, value_enum, default_value_t)]
    profile: odometry::profile::Profile,
    #[command(flatten)]
    hints: crate::hint_args::HintArgs,
}

/// Longest sleep without a notification: a publisher that does not notify (an older tool) is
/// still served, with this latency.
const TICK: Duration = Duration::from_millis(100);

/// Runs until SIGINT/SIGTERM.
pub fn run(args: ServeArgs) -> Result<()> {
    let file = CalibrationFile::load(&args.calib).context("cannot load calibration")?;
    let config = args.profile.odometry(crate::odometry_config(&file));
    let hint_config = args.hints.config()?;
    let namespace = service::namespace(args.namespace.as_deref());
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let corrected_name = service::full_name(&namespace, service::CORRECTED);
    let odometry_name = service::full_name(&namespace, service::ODOMETRY);
    let corrected = service::open::<CorrectedImuSample>(&node, &corrected_name)?;
    let odometry = service::open::<OdometryState>(&node, &odometry_name)?;
    let hint_service =
        service::open::<RobotHint>(&node, &service::full_name(&namespace, service::HINT))?;
    let subscriber = service::subscriber(&corrected)?;
    let hint_subscriber = service::subscriber(&hint_service)?;
    let mode = if args.spin {
        WaitMode::Spin
    } else {
        WaitMode::Event
    };
    // Hints are taken before the samples they precede: only samples wake the process.
    let listener = wake::listener(&node, &corrected_name, mode)?;
    let mut out = Output::new(&node, &odometry, &odometry_name)?;
    let mut server = Server::new(move || OdometryStage::with_hints(config, hint_config))?;
    let mut steady =
        SteadyState::from_env(|| crate::ALLOCATOR.counts()).map_err(anyhow::Error::msg)?;
    // Start-up is over: from here on small blocks come from the pool.
    crate::ALLOCATOR.arm();
    wake::serve_loop(&[listener], TICK, || -> Result<ControlFlow<(), bool>> {
        let mut any = false;
        while let Some(sample) = subscriber.receive()? {
            any = true;
            steady.inputs(1);
            let s = *sample.payload();
            drop(sample);
            server.take_hints(s.stamps.sample_ns, || {
                Ok(hint_subscriber.receive()?.map(|h| *h.payload()))
            })?;
            server.process(&s, &mut out)?;
        }
        Ok(ControlFlow::Continue(any))
    })?;
    // A replay of the hindsight still under way is completed (as offline at the end of a
    // recording).
    server.stage.finish(&mut |state| send(&mut out, state));
    out.end_of_input()?;
    server.report(out.sent(), &steady);
    Ok(())
}

/// The odometry stage as the live process drives it: hints before the samples they precede,
/// a new stage for each sensor session, NO_GYRO samples answered without it, and the counts
/// of the summary.
struct Server<F> {
    new_stage: F,
    stage: OdometryStage,
    /// A hint received before the samples it precedes.
    held: Option<RobotHint>,
    hints_received: u64,
    hints_refused: u64,
    last_seq: Option<u64>,
    last_ns: Option<u64>,
    received: u64,
    refused: u64,
    sessions: u64,
    warned_no_gyro: bool,
}

impl<F: Fn() -> Result<OdometryStage, HintConfigError>> Server<F> {
    fn new(new_stage: F) -> Result<Self> {
        Ok(Self {
            stage: new_stage()?,
            new_stage,
            held: None,
            hints_received: 0,
            hints_refused: 0,
            last_seq: None,
            last_ns: None,
            received: 0,
            refused: 0,
            sessions: 1,
            warned_no_gyro: false,
        })
    }

    /// Hands the stage the hints published by `sample_ns`, in publication order; a later one
    /// waits (held) for the samples to catch up, so that hints running ahead of the samples (a
    /// replay at full speed) do not pile up in the stage. `next` receives one hint.
    fn take_hints(
        &mut self,
        sample_ns: u64,
        mut next: impl FnMut() -> Result<Option<RobotHint>>,
    ) -> Result<()> {
        loop {
            if self.held.is_none() {
                self.held = next()?;
            }
            match self.held {
                Some(h) if usable_from_ns(&h, 0) <= sample_ns => {
                    self.held = None;
                    self.hints_received += 1;
                    if let Err(e) = self.stage.hint(&h) {
                        self.hints_refused += 1;
                        tracing::warn!("refused: {e}");
                    }
                }
                _ => return Ok(()),
            }
        }
    }

    /// One corrected sample: its live state (and revisions) published to `out`.
    fn process(&mut self, s: &CorrectedImuSample, out: &mut Output<OdometryState>) -> Result<()> {
        self.received += 1;
        let no_gyro = s.raw_flags & raw_flags::GYRO_VALID == 0;
        if no_gyro && !self.warned_no_gyro {
            self.warned_no_gyro = true;
            tracing::warn!(
                "sample seq {} has no gyroscope (GYRO_VALID clear: an \
                 accelerometer-only sensor mode, such as the MPU-9250 at 4 kHz); without it \
                 the attitude cannot be tracked, so no position is estimated: states carry \
                 NO_GYRO and never ALIGNED. Run the sensor at 1000 Hz or below for odometry",
                s.seq
            );
        }
        // A time step no dead reckoning bridges (the stage refuses it) is a new time base, as
        // a new session is.
        let jump = self
            .last_ns
            .is_some_and(|l| s.stamps.sample_ns > l.saturating_add(MAX_STEP_NS));
        if self.last_seq.is_some_and(|l| s.seq <= l) || jump {
            // A new sensor session: the old one's revisions are completed, then align again.
            self.stage.finish(&mut |state| send(out, state));
            out.end_of_input()?;
            self.stage = (self.new_stage)()?;
            self.sessions += 1;
        }
        self.last_seq = Some(s.seq);
        self.last_ns = Some(s.stamps.sample_ns);
        // The live state is published (and its subscribers woken) before any revision work
        // the stage does after it. A sample that settles a zero-state batch is followed by
        // that batch's settling and revisions (a few hundred us): the process yields its core
        // first, so that a subscriber woken onto it runs before that work rather than after it
        // (docs/latency.md). Only then: a yield hands the core to any runnable task, which may
        // keep it for a whole time slice.
        let settles = s.flags & corrected_flags::PROVISIONAL == 0;
        let mut emit = |state: &OdometryState| {
            send(out, state);
            if settles && state.flags & odometry_flags::REVISION == 0 {
                std::thread::yield_now();
            }
        };
        if no_gyro {
            emit(&OdometryState {
                stamps: s.stamps,
                seq: s.seq,
                attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
                flags: odometry_flags::NO_GYRO,
                ..OdometryState::default()
            });
        } else if let Err(e) = self.stage.process(s, &mut emit) {
            self.refused += 1;
            tracing::warn!("refused: {e}");
        }
        out.end_of_input()?;
        Ok(())
    }

    /// The summary on stderr, with the `published` count and the steady-state allocations.
    fn report(&self, published: u64, steady: &SteadyState) {
        tracing::info!(
            "received {}, published {published} (revisions included), refused \
             {}, sessions {}, discarded for stalled subscribers {}; hints received {}, refused \
             {}, this session: {}",
            self.received,
            self.refused,
            self.sessions,
            service::stalled_discards(),
            self.hints_received,
            self.hints_refused,
            self.stage.hint_stats()
        );
        tracing::info!(
            "{}; small-block pool: peak {} of 1024 blocks, {} requests found it \
             empty",
            steady.summary(),
            crate::ALLOCATOR.peak_blocks(),
            crate::ALLOCATOR.fallbacks()
        );
    }
}

/// Publishes `state`, stamped with the time it leaves the process.
fn send(out: &mut Output<OdometryState>, state: &OdometryState) {
    let mut state = *state;
    state.stamps.odometry_ns = monotonic_ns();
    out.send(state);
}
