//! `mems-odometry serve`: the odometry session (`odometry::session`: hint order, sensor
//! sessions, samples without a gyroscope) between `mems/imu/corrected` and
//! `mems/odometry/state`, with the robot's hints from `mems/robot/hint` when a controller
//! publishes them, run by the live driver (`mems_stage::live`).
//!
//! - Every corrected sample gives one state, in order; the end of a motion interval also
//!   republishes that interval's states with the `REVISION` flag. `stamps.odometry_ns` is
//!   `CLOCK_MONOTONIC` at publication. The live state is published (and its subscribers woken)
//!   before any revision work the stage does after it; a sample that settles a zero-state batch
//!   is followed by that work (a few hundred us), so the process yields its core first, and a
//!   subscriber woken onto it runs before that work rather than after it (docs/latency.md).
//! - Hints are taken as they arrive, ahead of the samples (the session orders them); a refused
//!   hint or sample (NaN, a value beyond any calibrated sensor's range, time not increasing) is
//!   reported on stderr, counted (`refused` in the summary) and skipped.
//! - Samples without a gyroscope (`raw_flags::GYRO_VALID` clear: the MPU-9250 at 4 kHz) get a
//!   state flagged `NO_GYRO` with no position ([`NoGyro::Unnavigated`]); the first is
//!   reported once on stderr.
//! - The process sleeps on the corrected service's event and notifies `mems/odometry/state`'s;
//!   `--spin` polls instead. The loop allocates nothing per sample from the system allocator:
//!   iceoryx2's one small block per published state comes from the process's pool
//!   (`alloc_count::pool`). SIGINT/SIGTERM: a summary with the steady-state counts, exit 0.

mod hooks;

use std::path::PathBuf;

use anyhow::{Context, Result};
use calibrate::calibfile::CalibrationFile;
use ipc_types::service;
use ipc_types::wake::{self, Output, WaitMode};
use ipc_types::{OdometryState, RobotHint};
use odometry::profile::Profile;
use odometry::session::{NoGyro, OdometrySession};

use hooks::{Inputs, Watch};

/// Options of `mems-odometry serve`.
#[derive(clap::Args)]
pub struct ServeArgs {
    /// Calibration file (TOML): its gravity and noise parameters configure the filter.
    /// Without it, standard gravity and the MPU-9250's datasheet noise.
    #[arg(long)]
    calib: Option<PathBuf>,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// Poll for corrected samples without sleeping (for a core of its own) instead of sleeping
    /// until the calibration stage's event wakes the process.
    #[arg(long)]
    spin: bool,
    /// Motion profile (its rest handling; the detector is `mems-calibrate serve`'s). `auto`
    /// runs `other` until it has seen 10 s of motion, then the recognized platform's
    /// (`odometry::session::AUTO_DECIDE_MOVING_S`), said on stderr.
    #[arg(long, value_enum, default_value_t)]
    profile: Profile,
    #[command(flatten)]
    hints: crate::hint_args::HintArgs,
}

/// Runs until SIGINT/SIGTERM.
pub fn run(args: ServeArgs) -> Result<()> {
    let file = match &args.calib {
        Some(path) => CalibrationFile::load(path).context("cannot load calibration")?,
        None => CalibrationFile::identity(ipc_types::units::STANDARD_GRAVITY_MPS2),
    };
    let base = crate::load::odometry_config(&file);
    let hints = args.hints.config()?;
    let mut session = match args.profile {
        Profile::Auto => OdometrySession::auto(base, hints, NoGyro::Unnavigated)?,
        p => OdometrySession::new(p.odometry(base), hints, NoGyro::Unnavigated)?,
    };
    let ns = service::namespace(args.namespace.as_deref());
    let name = |base| service::full_name(&ns, base);
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let mut input = Inputs {
        hints: service::subscriber(&service::open::<RobotHint>(&node, &name(service::HINT))?)?,
        samples: service::subscriber(&service::open(&node, &name(service::CORRECTED))?)?,
    };
    let odometry = service::open::<OdometryState>(&node, &name(service::ODOMETRY))?;
    let mut out = Output::new(&node, &odometry, &name(service::ODOMETRY))?;
    let mode = if args.spin {
        WaitMode::Spin
    } else {
        WaitMode::Event
    };
    // Only samples wake the process: hints wait for them anyway.
    let listener = wake::listener(&node, &name(service::CORRECTED), mode)?;
    let mut watch = Watch::new(args.profile)?;
    // Start-up is over: from here on small blocks come from the pool.
    crate::ALLOCATOR.arm();
    let counts = mems_stage::live::serve(&mut session, &mut input, &mut out, listener, &mut watch)?;
    watch.report(&counts, &session);
    Ok(())
}
