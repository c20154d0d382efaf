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
//! - `--state FILE`: the stage's [`WarmState`] (references, bias refinement, stream) is written
//!   to FILE when the detector has learned and then at most once a second while it changes
//!   (atomically: a temporary file renamed over it), and read back at start-up when FILE
//!   exists, so that a restarted process goes on where the killed one stopped instead of
//!   learning again, possibly from a robot in motion. A malformed FILE or one made with another
//!   calibration is a start-up error naming it.
//! - The loop allocates nothing per sample from the system allocator: iceoryx2's one small
//!   block per published sample comes from the process's pool (`alloc_count::pool`). The
//!   summary gives the steady-state counts (`alloc_count::steady`).
//! - SIGINT/SIGTERM: a summary, exit status 0.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use alloc_count::steady::SteadyState;
use anyhow::{Context, Result};
use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig, WarmState};
use calibrate::zero_state::args::DetectorArgs;
use calibrate::zero_state::{DetectorConfig, DetectorKind};
use ipc_types::wake::{self, Output, WaitMode};
use ipc_types::{CorrectedImuSample, RawImuSample, service};
use mems_stage::live::{self, Hooks};

/// Options of `mems-calibrate serve`.
#[derive(clap::Args)]
pub struct ServeArgs {
    /// Calibration file (TOML) written by `mems-calibrate fit`.
    #[arg(long)]
    calib: PathBuf,
    /// The zero-state detector (default: glrt, learning from the first 5 s of rest).
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

/// Reads a warm state written by `--state`.
fn load_state(path: &Path) -> Result<WarmState> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read the state file {}", path.display()))?;
    serde_json::from_str(&text)
        .with_context(|| format!("{}: not a calibration stage state", path.display()))
}

/// Whether two states hold the same learning (references and refinement): the stream
/// position alone changing is no reason to write.
fn same_learning(a: &WarmState, b: &WarmState) -> bool {
    a.reference == b.reference
        && a.refine_accel_mps2 == b.refine_accel_mps2
        && a.refine_gyro_rps == b.refine_gyro_rps
}

/// Writes `state` to `path` atomically (a temporary file beside it, renamed over it).
fn save_state(path: &Path, state: &WarmState) -> Result<()> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, serde_json::to_string_pretty(state)?)
        .with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot replace {}", path.display()))
}

/// The calibration stage `args` ask for: the file's model and gravity, the detector and its
/// learning time, and, with `--state`, what a predecessor had learned.
fn stage(args: &ServeArgs, file: &CalibrationFile) -> Result<CalibrationStage> {
    let config = args
        .detector
        .apply(DetectorConfig::new(DetectorKind::Glrt, file.gravity_mps2))
        .map_err(anyhow::Error::msg)?;
    let mut stage = CalibrationStage::new(file, config, RefineConfig::default())
        .with_context(|| args.calib.display().to_string())?;
    if let Some(path) = args.state.as_deref().filter(|p| p.exists()) {
        let state = load_state(path)?;
        stage
            .resume(&state)
            .with_context(|| format!("{}: cannot go on from it", path.display()))?;
        tracing::info!(
            "going on from {} (last sample seq {}, detector {}, refined {})",
            path.display(),
            state.last_seq,
            if state.reference.is_some() {
                "learned"
            } else {
                "not learned"
            },
            state.refined
        );
    }
    Ok(stage)
}

/// The summary on stderr: the stage's counts, what it learned and refined, and the
/// steady-state allocations.
fn report(stage: &CalibrationStage, refused: u64, steady: &SteadyState) {
    let s = stage.stats();
    let (learn_restarts, _) = stage.detector().learn_rejections();
    let (accel, gyro, refined) = stage.refinement();
    tracing::info!(
        "accepted {}, published {}, at rest {}, refused {refused}, gaps {}, \
         stream restarts {}, learning restarts {learn_restarts}, detector ready {}, refined {refined} \
         (accel {:.4?} m/s^2, gyro {:.5?} rad/s)",
        s.accepted,
        s.released,
        s.rest,
        s.gaps,
        s.restarts,
        stage.detector().is_ready(),
        accel,
        gyro
    );
    tracing::info!(
        "{}; small-block pool: peak {} of 1024 blocks, {} requests found it empty",
        steady.summary(),
        crate::ALLOCATOR.peak_blocks(),
        crate::ALLOCATOR.fallbacks()
    );
}

/// Runs the service until SIGINT/SIGTERM.
pub fn serve(args: &ServeArgs) -> Result<()> {
    let file = CalibrationFile::load(&args.calib)?;
    let mut stage = stage(args, &file)?;
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
        args.calib.display(),
        file.model,
        stage.calib_id(),
        stage.detector().config().kind.name(),
        if args.spin { ", spinning" } else { "" }
    );
    // Subscribers killed without closing their ports would otherwise stay connected.
    let _cleanup = service::DeadNodeCleanup::start(Duration::from_secs(1))?;
    let mut watch = Watch {
        steady: SteadyState::from_env(|| crate::ALLOCATOR.counts()).map_err(anyhow::Error::msg)?,
        state_file: args.state.as_deref(),
        saved: None,
    };
    // Start-up is over: from here on small blocks come from the pool.
    crate::ALLOCATOR.arm();
    let counts = live::serve(&mut stage, &mut subscriber, &mut out, listener, &mut watch)?;
    report(&stage, counts.refused, &watch.steady);
    Ok(())
}

/// The steady-state allocation count, and the `--state` file kept up to date.
struct Watch<'a> {
    steady: SteadyState,
    state_file: Option<&'a Path>,
    /// The state as last written, and when (not per sample: at most once a second).
    saved: Option<(WarmState, Instant)>,
}

impl Hooks<CalibrationStage> for Watch<'_> {
    fn input(&mut self) {
        self.steady.inputs(1);
    }

    fn drained(&mut self, stage: &CalibrationStage) -> Result<()> {
        if let Some(path) = self.state_file
            && let Some(state) = stage.warm_state()
            && state.reference.is_some()
            && self.saved.as_ref().is_none_or(|(s, at)| {
                at.elapsed() >= Duration::from_secs(1) && !same_learning(s, &state)
            })
        {
            save_state(path, &state)?;
            self.saved = Some((state, Instant::now()));
        }
        Ok(())
    }
}
