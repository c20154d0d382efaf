//! `mems-calibrate serve`: the calibration stage between `mems/imu/raw` and
//! `mems/imu/corrected`.
//!
//! - Every accepted raw sample gives one corrected sample, in order, published as soon as it is
//!   received (its batch's zero-state verdict may come with a later sample: see
//!   `calibrate::stage`); `stamps.calibrated_ns` is `CLOCK_MONOTONIC` at publication. The
//!   process sleeps on the raw service's event (the publisher notifies it after each send) and
//!   notifies `mems/imu/corrected`'s after each of its own; `--spin` polls instead.
//! - A refused raw sample (NaN, time not increasing, missing gyroscope) is reported on stderr
//!   and not published; the service goes on.
//! - A restarted publisher (sequence numbers starting again) is a new sensor session: the stage
//!   starts over (time check, detector learning, refinement).
//! - `--state FILE`: the stage's [`calibrate::stage::WarmState`] (references, bias refinement, stream) is written
//!   to FILE when the detector has learned and then at most once a second while it changes
//!   (atomically: a temporary file renamed over it), and read back at start-up when FILE
//!   exists, so that a restarted process goes on where the killed one stopped instead of
//!   learning again, possibly from a robot in motion. A malformed FILE or one made with another
//!   calibration is a start-up error naming it.
//! - The loop allocates nothing per sample from the system allocator: iceoryx2's one small
//!   block per published sample comes from the process's pool (`alloc_count::pool`). The
//!   summary gives the steady-state counts (`alloc_count::steady`).
//! - SIGINT/SIGTERM: a summary, exit status 0.

mod hooks;
mod start;

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Result;
use calibrate::calibfile::CalibrationFile;
use calibrate::zero_state::args::DetectorArgs;
use ipc_types::wake::{self, Output, WaitMode};
use ipc_types::{CorrectedImuSample, RawImuSample, service};
use mems_stage::live;

use hooks::Watch;

/// Options of `mems-calibrate serve`.
#[derive(clap::Args)]
pub struct ServeArgs {
    /// Calibration file (TOML) written by `mems-calibrate fit`. Without it, the identity at
    /// standard gravity: a part taken as it reads, whose error along gravity the bias
    /// refinement removes at rest (an uncalibrated part's rest may read gravity up to 39 % off,
    /// `calibrate::zero_state::learn::UNCALIBRATED_GRAVITY_ERROR`).
    #[arg(long)]
    calib: Option<PathBuf>,
    /// The zero-state detector (default: glrt, learning from the first half second of rest with
    /// the confidence of 5 s, as `mems-odometry`'s vehicle profile).
    #[command(flatten)]
    detector: DetectorArgs,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// Poll for raw samples without sleeping (for a core of its own) instead of sleeping until
    /// the publisher's event wakes the process.
    #[arg(long)]
    spin: bool,
    /// Keep the stage's learned state in this file (JSON) and go on from it at start-up when
    /// it exists: a restarted process neither relearns nor changes the output's bias.
    #[arg(long, value_name = "FILE")]
    state: Option<PathBuf>,
}

impl ServeArgs {
    /// What `--calib` names, for messages.
    fn calib_name(&self) -> String {
        self.calib.as_ref().map_or_else(
            || "no calibration file (the identity)".into(),
            |p| p.display().to_string(),
        )
    }
}

/// Runs the service until SIGINT/SIGTERM.
pub fn serve(args: &ServeArgs) -> Result<()> {
    let file = match &args.calib {
        Some(path) => CalibrationFile::load(path)?,
        None => CalibrationFile::identity(ipc_types::units::STANDARD_GRAVITY_MPS2),
    };
    let mut stage = start::stage(args, &file)?;
    let ns = service::namespace(args.namespace.as_deref());
    let raw_name = service::full_name(&ns, service::RAW);
    let corrected_name = service::full_name(&ns, service::CORRECTED);
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let mut subscriber = service::subscriber(&service::open::<RawImuSample>(&node, &raw_name)?)?;
    let mode = if args.spin {
        WaitMode::Spin
    } else {
        WaitMode::Event
    };
    let listener = wake::listener(&node, &raw_name, mode)?;
    let corrected = service::open::<CorrectedImuSample>(&node, &corrected_name)?;
    let mut out = Output::new(&node, &corrected, &corrected_name)?;
    tracing::info!(
        "{} ({} model, calib_id {:016x}), {} detector, {raw_name} -> {corrected_name}{}",
        args.calib_name(),
        file.model,
        stage.calib_id(),
        stage.detector().config().kind.name(),
        if args.spin { ", spinning" } else { "" }
    );
    // Subscribers killed without closing their ports would otherwise stay connected.
    let _cleanup = service::DeadNodeCleanup::start(Duration::from_secs(1))?;
    let mut watch = Watch::new(args.state.as_deref())?;
    // Start-up is over: from here on small blocks come from the pool.
    crate::ALLOCATOR.arm();
    let counts = live::serve(&mut stage, &mut subscriber, &mut out, listener, &mut watch)?;
    hooks::report(&stage, counts.refused, &watch.steady);
    Ok(())
}
