//! `mems-odometry offline`: the calibration stage and the odometry session over a raw
//! recording, in one process: the same stages `mems-calibrate serve` and `mems-odometry serve`
//! run live, chained (`mems_stage::Chain`) and run by the offline driver
//! (`mems_stage::offline`). An MCAP recording's robot hints (topic `mems/robot/hint`) go to the
//! odometry session, which orders them as it does live, unless `--no-hints`.
//!
//! An MCAP run (with its successor segments) is streamed: raw samples flow from the reader (a
//! thread of its own, decoding beside the stages) through both stages as they are read, each
//! held back only `source::HINT_WINDOW_NS` for the hints recorded after it, so memory is
//! bounded by that window and the stages' own, not by the file. Text recordings, and MCAP with
//! `--repair-torn-reads` (a pass over the whole recording), are read into memory first.
//! Truth (recordings from `mems-sim`) is compared as `summary` says.

mod source;
mod summary;

use std::cell::RefCell;
use std::path::PathBuf;

use anyhow::{Result, anyhow, bail};
use calibrate::stage::{CalibrationStage, RefineConfig};
use ipc_types::odometry_flags;
use mems_stage::offline::Stop;
use mems_stage::{Chain, Either};
use odometry::session::{NoGyro, OdometrySession};
use serde_json::json;

use source::{HINT_WINDOW_NS, Inputs, Source};
use summary::{Summary, TruthQueue};

/// Options of `mems-odometry offline`.
#[derive(clap::Args)]
pub struct OfflineArgs {
    #[command(flatten)]
    stage: crate::StageArgs,
    /// Raw recording: canonical CSV, thesis CSV or MCAP.
    #[arg(long)]
    input: PathBuf,
    /// Integrate without zero-velocity updates after alignment (the rest flags still align).
    #[arg(long)]
    no_zupt: bool,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
    /// Ignore the recording's robot hints (IMU only).
    #[arg(long)]
    no_hints: bool,
    /// Refuse a text recording whose times do not strictly increase, instead of dropping
    /// exact repeats and rebuilding such times from the nominal rate (`recording::LogPolicy`).
    #[arg(long)]
    strict_time: bool,
    /// Repair torn high/low-byte reads first (`calibrate::repair`): for recordings made by a
    /// logger that read the two bytes of an axis in separate transactions, such as the
    /// thesis's (docs/diagnosis.md). Our driver never tears a read, so live and offline agree
    /// only without it.
    #[arg(long)]
    repair_torn_reads: bool,
    #[command(flatten)]
    hints: crate::hint_args::HintArgs,
    /// Also write the run as a live run's recording to this MCAP file: raw samples and hints
    /// as read, corrected samples, odometry states (revisions included) and poses, each logged
    /// at its own time (`crate::out`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Overwrite the recording at `--out`.
    #[arg(long, requires = "out")]
    force: bool,
}

/// Runs the pipeline and prints the result.
pub fn run(args: OfflineArgs) -> Result<()> {
    let (file, detector) = args.stage.load()?;
    let (mut source, repairs) = Source::open(&args)?;
    let input = args.input.display();
    let calibration = CalibrationStage::new(&file, detector, RefineConfig::default())
        .map_err(|e| anyhow!("{}: {e}", args.stage.calib_name()))?;
    let mut config = args.stage.profile.odometry(crate::odometry_config(&file));
    config.rest_updates = !args.no_zupt;
    let session = OdometrySession::new(config, args.hints.config()?, NoGyro::HoldAttitude)?;
    let mut chain = Chain {
        first: calibration,
        second: session,
    };
    let (truth, out) = (
        RefCell::new(TruthQueue::default()),
        RefCell::new(output(&args)?),
    );
    let mut summary = Summary::default();
    let mut inputs = Inputs::new(&mut source, &truth, &out);
    let ran = mems_stage::offline::run(&mut chain, &mut inputs, &mut |o| {
        source::write(&out, o);
        if let Either::Second(s) = o
            && s.flags & odometry_flags::REVISION == 0
        {
            summary.state(*s, &mut truth.borrow_mut());
        }
    });
    let (first_ns, hints_seen, hints_late) =
        (inputs.first_ns, inputs.hints_seen, inputs.hints_late);
    report_input(
        &args,
        &mut source,
        hints_late,
        chain.second.stats().first_no_gyro_seq,
    );
    if let Some(out) = out.into_inner() {
        out.finish()?;
    }
    match ran {
        Err(Stop::Refused { refusal, .. }) => bail!("{input}: {refusal}"),
        Err(Stop::Input(e)) => return Err(e),
        Ok(_) => {}
    }
    let Some(end) = summary.last else {
        bail!("{input}: no samples");
    };
    if end.flags & odometry_flags::ALIGNED == 0 {
        bail!(
            "{input}: never aligned: {}",
            why_never_aligned(&chain.first, detector.learn.duration_s)
        );
    }
    let aligned_at_s = summary
        .aligned_ns
        .map_or(0.0, |t| (t - first_ns.unwrap_or(0)) as f64 * 1e-9);
    tracing::info!(
        "aligned {aligned_at_s:.2} s into the recording (at its first rest of {} s); the \
         position counts from there",
        config.align_s
    );
    let truth_error = summary.truth_error(&end, &mut truth.borrow_mut());
    if !args.json {
        summary.print(&end, truth_error);
        return Ok(());
    }
    let extra = json!({
        "aligned_at_s": aligned_at_s,
        "log_repairs": {
            "repeats_dropped": repairs.repeats_dropped,
            "times_rebuilt": repairs.times_rebuilt,
        },
        "hints": {
            "in_recording": hints_seen,
            "late": hints_late,
            "applied": end.hints_applied,
            "disagreements": end.hint_disagreements,
            "speed_updates": chain.second.hint_stats().speed_updates,
        },
    });
    println!("{}", summary.json(&end, truth_error, extra));
    Ok(())
}

/// The `--out` recording, anchored to the input's wall clock (none for an unanchored input).
fn output(args: &OfflineArgs) -> Result<Option<crate::out::Out>> {
    let Some(path) = &args.out else {
        return Ok(None);
    };
    let clock = recording::mcap::run::clock_of(&args.input)?;
    Ok(Some(crate::out::Out::create(path, args.force, clock)?))
}
/// Says on stderr what the input held that the result does not show: truncated segments,
/// robot hints recorded too late to be merged in order, and samples without a gyroscope
/// (navigated at a held attitude: `NoGyro::HoldAttitude`).
fn report_input(args: &OfflineArgs, source: &mut Source, hints_late: u64, no_gyro: Option<u64>) {
    let input = args.input.display();
    for segment in source.segments() {
        if let Some(t) = &segment.truncation {
            tracing::warn!("{}: {t}", segment.path.display());
        }
    }
    if hints_late > 0 {
        tracing::warn!(
            "{input}: {hints_late} robot hints were recorded more than {} s after their \
             publication and reached the odometry stage after samples they would have preceded",
            HINT_WINDOW_NS as f64 * 1e-9
        );
    }
    if let Some(seq) = no_gyro {
        tracing::warn!(
            "{input}: sample seq {seq} has no gyroscope (GYRO_VALID clear); the attitude is \
             held at its alignment, so the position is meaningful only if the sensor never \
             rotated (a static recording). mems-odometry serve publishes no position for such \
             samples (NO_GYRO)"
        );
    }
}

/// Why the odometry never aligned: the detector never learned (with the learner's last
/// refusal), or it never flagged rest after it did.
fn why_never_aligned(calibration: &CalibrationStage, learn_s: f64) -> String {
    let detector = calibration.detector();
    let kind = detector.config().kind.name();
    if detector.is_ready() {
        return format!(
            "the {kind} detector flagged no rest long enough to align on after it was ready \
             ({} samples flagged rest in all)",
            calibration.stats().rest
        );
    }
    match detector.learn_rejections() {
        (0, _) => format!(
            "the {kind} detector found no {learn_s} s of data to learn its rest from (a shorter \
             --learn-s, or --profile pedestrian for a foot-mounted sensor)"
        ),
        (n, why) => format!(
            "the {kind} detector refused all {n} windows of {learn_s} s it could learn its rest \
             from; the last because {}",
            why.map_or_else(|| "of a gap".into(), |w| w.to_string())
        ),
    }
}
