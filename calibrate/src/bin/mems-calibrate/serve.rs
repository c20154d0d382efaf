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
//! - The loop allocates nothing per sample from the system allocator: iceoryx2's one small
//!   block per published sample comes from the process's pool (`alloc_count::pool`). The
//!   summary gives the steady-state counts (`alloc_count::steady`).
//! - SIGINT/SIGTERM: a summary, exit status 0.

use std::path::PathBuf;
use std::time::Duration;

use alloc_count::steady::SteadyState;
use anyhow::{Context, Result, anyhow};
use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig};
use calibrate::zero_state::{DetectorConfig, DetectorKind};
use ipc_types::clock::monotonic_ns;
use ipc_types::wake::{self, Output, WaitMode};
use ipc_types::{CorrectedImuSample, RawImuSample, service};
use std::ops::ControlFlow;

/// Refused samples reported one by one before the rest are only counted.
const REPORTED_REFUSALS: u64 = 10;

/// Longest sleep without a notification: a publisher that does not notify (an older tool) is
/// still served, with this latency.
const TICK: Duration = Duration::from_millis(100);

/// Options of `mems-calibrate serve`.
#[derive(clap::Args)]
pub struct ServeArgs {
    /// Calibration file (TOML) written by `mems-calibrate fit`.
    #[arg(long)]
    calib: PathBuf,
    /// Zero-state detector: glrt (accelerometer and gyroscope; needs the gyroscope),
    /// glrt-accel (the same on the accelerometer alone, for a sensor run without its gyroscope)
    /// or yu (accelerometer batches of 20, as in the thesis).
    #[arg(long, value_enum, default_value_t = DetectorKind::Glrt)]
    detector: DetectorKind,
    /// The GLRT's window, in batches of 20 samples (default 25: 0.5 s at 1 kHz; 100 is 0.5 s
    /// at 4 kHz).
    #[arg(long, value_name = "BATCHES", value_parser = clap::value_parser!(u32).range(1..))]
    glrt_window: Option<u32>,
    /// Length of the start-up rest the detector learns its thresholds from, s.
    #[arg(long, default_value_t = 5.0)]
    learn_s: f64,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// Poll for raw samples without sleeping (for a core of its own) instead of sleeping until
    /// the publisher's event wakes the process.
    #[arg(long)]
    spin: bool,
}

/// Runs the service until SIGINT/SIGTERM.
pub fn serve(args: &ServeArgs) -> Result<()> {
    let file = CalibrationFile::load(&args.calib)?;
    if !(args.learn_s > 0.0 && args.learn_s.is_finite()) {
        anyhow::bail!("--learn-s must be > 0, got {}", args.learn_s);
    }
    let mut config = DetectorConfig::new(args.detector, file.gravity_mps2);
    config.learn.duration_s = args.learn_s;
    if let Some(k) = args.glrt_window {
        config.glrt.window_batches = k as usize;
    }
    let mut stage = CalibrationStage::new(&file, config, RefineConfig::default())
        .with_context(|| args.calib.display().to_string())?;

    let ns = service::namespace(args.namespace.as_deref());
    let raw_name = service::full_name(&ns, service::RAW);
    let corrected_name = service::full_name(&ns, service::CORRECTED);
    let node = service::node()?;
    let raw = service::open::<RawImuSample>(&node, &raw_name)?;
    let subscriber = service::subscriber(&raw)?;
    let mode = if args.spin {
        WaitMode::Spin
    } else {
        WaitMode::Event
    };
    let listener = wake::listener(&node, &raw_name, mode)?;
    let corrected = service::open::<CorrectedImuSample>(&node, &corrected_name)?;
    let mut out = Output::new(&node, &corrected, &corrected_name)?;
    eprintln!(
        "mems-calibrate serve: {} ({} model, calib_id {:016x}), {} detector, {raw_name} -> {corrected_name}{}",
        args.calib.display(),
        file.model,
        stage.calib_id(),
        args.detector.name(),
        if args.spin { ", spinning" } else { "" }
    );

    let mut refused = 0u64;
    // Subscribers killed without closing their ports would otherwise stay connected.
    let _cleanup = service::DeadNodeCleanup::start(Duration::from_secs(1))?;
    let mut steady =
        SteadyState::from_env(|| crate::ALLOCATOR.counts()).map_err(anyhow::Error::msg)?;
    // Start-up is over: from here on small blocks come from the pool.
    crate::ALLOCATOR.arm();
    let step = || -> Result<ControlFlow<(), bool>> {
        let mut received = false;
        while let Some(sample) = subscriber
            .receive()
            .map_err(|e| anyhow!("receive on {raw_name}: {e:?}"))?
        {
            received = true;
            steady.inputs(1);
            let pushed = stage.push(sample.payload(), &mut |s| {
                let mut s = *s;
                s.stamps.calibrated_ns = monotonic_ns();
                out.send(s);
            });
            drop(sample);
            if let Err(e) = pushed {
                refused += 1;
                if refused <= REPORTED_REFUSALS {
                    eprintln!("mems-calibrate serve: refused: {e}");
                }
            }
            out.end_of_input()?;
        }
        Ok(ControlFlow::Continue(received))
    };
    wake::serve_loop(&node, &[listener], TICK, step)?;
    stage.finish();
    let s = stage.stats();
    let (learn_restarts, _) = stage.detector().learn_rejections();
    let (accel, gyro, refined) = stage.refinement();
    eprintln!(
        "mems-calibrate serve: accepted {}, published {}, at rest {}, refused {refused}, gaps {}, \
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
    eprintln!(
        "mems-calibrate serve: {}; small-block pool: peak {} of 1024 blocks, {} requests found it empty",
        steady.summary(),
        crate::ALLOCATOR.peak_blocks(),
        crate::ALLOCATOR.fallbacks()
    );
    Ok(())
}
