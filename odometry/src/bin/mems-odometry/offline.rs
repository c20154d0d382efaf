//! `mems-odometry offline`: the calibration stage and the odometry stage over a raw recording,
//! in one process, exactly as `mems-calibrate serve` and `mems-odometry serve` run them live.
//! An MCAP recording's robot hints (topic `mems/robot/hint`) go to the odometry stage in
//! publication order, each before the first raw sample taken after its publication (the
//! stage's own delivery rule decides which samples use it), unless `--no-hints`.
//!
//! Truth comparison (recordings from `mems-sim`): our navigation frame has its origin at the
//! alignment point and its heading fixed there; the truth's frame is the scenario's. At the first
//! aligned state the rotation between the two frames' headings is taken from the two attitudes
//! (its yaw part only: a roll or pitch difference is our own tilt error and stays in the error),
//! and the truth positions are expressed in our frame relative to the truth position there.

use std::path::PathBuf;

use anyhow::{Result, bail};
use calibrate::stage::{CalibrationStage, RefineConfig};
use ipc_types::{CorrectedImuSample, OdometryState, RobotHint, odometry_flags};
use nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};
use odometry::stage::OdometryStage;
use recording::Truth;
use serde_json::json;

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
}

fn quat(wxyz: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]))
}

/// Maps truth positions into our navigation frame once the first aligned state is known.
struct TruthFrame {
    origin: Vector3<f64>,
    to_ours: Rotation3<f64>,
}

impl TruthFrame {
    fn new(ours: &OdometryState, truth: &Truth) -> Self {
        // Rotation taking truth-frame vectors to ours: ours = q_o q_t^-1 truth; its yaw part.
        let m =
            (quat(ours.attitude_wxyz) * quat(truth.attitude_wxyz).inverse()).to_rotation_matrix();
        let yaw = m[(1, 0)].atan2(m[(0, 0)]);
        Self {
            origin: Vector3::from(truth.position_m),
            to_ours: Rotation3::from_axis_angle(&Vector3::z_axis(), yaw),
        }
    }

    fn position(&self, truth: &Truth) -> Vector3<f64> {
        self.to_ours * (Vector3::from(truth.position_m) - self.origin)
    }
}

/// Runs the pipeline and prints the result.
pub fn run(args: OfflineArgs) -> Result<()> {
    let (file, detector) = args.stage.load()?;
    let policy = if args.strict_time {
        recording::LogPolicy::Strict
    } else {
        recording::LogPolicy::Repair
    };
    let mut recording = crate::load_recording(&args.input, policy)?;
    if args.repair_torn_reads {
        let report = calibrate::repair::repair_torn_reads(
            &mut recording.samples,
            &calibrate::repair::TornReadConfig::default(),
        );
        eprintln!(
            "mems-odometry: {}: repaired {} torn reads (x, y, z: {:?}) in {} samples",
            args.input.display(),
            report.total(),
            report.repaired,
            report.samples
        );
    }
    // Without a gyroscope nothing tracks the attitude. Offline keeps navigating (static
    // recordings such as the thesis's, accelerometer-only, are dead-reckoned at a fixed
    // attitude), but says what that position is worth.
    if let Some(r) = recording
        .samples
        .iter()
        .find(|r| r.flags & ipc_types::raw_flags::GYRO_VALID == 0)
    {
        eprintln!(
            "mems-odometry: {}: sample seq {} has no gyroscope (GYRO_VALID clear); the attitude \
             is held at its alignment, so the position is meaningful only if the sensor never \
             rotated (a static recording). mems-odometry serve publishes no position for such \
             samples (NO_GYRO)",
            args.input.display(),
            r.seq
        );
    }
    let mut calibration = CalibrationStage::new(&file, detector, RefineConfig::default())
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.stage.calib_name()))?;
    let mut config = args.stage.profile.odometry(crate::odometry_config(&file));
    config.rest_updates = !args.no_zupt;
    let mut odometry = OdometryStage::with_hints(config, args.hints.config()?)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let is_mcap = args
        .input
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
    let mut hints: Vec<RobotHint> = if is_mcap && !args.no_hints {
        recording::mcap::read_all(&args.input)?.hints
    } else {
        Vec::new()
    };
    // Publication order (the order a live subscriber receives them in).
    hints.sort_by_key(|h| h.stamps.acquired_ns);
    let mut next_hint = 0;

    // Truth by sample time (the canonical CSV has one per sample; MCAP a channel).
    let mut truth: Vec<Truth> = recording.truth.clone().unwrap_or_default();
    truth.sort_by_key(|t| t.t_ns);
    let truth_at = |t_ns: u64| -> Option<&Truth> {
        truth
            .binary_search_by_key(&t_ns, |t| t.t_ns)
            .ok()
            .map(|i| &truth[i])
    };

    let mut last: Option<OdometryState> = None;
    let mut aligned_ns: Option<u64> = None;
    let mut rests = Vec::new();
    let mut frame: Option<TruthFrame> = None;
    let mut rest_errors = Vec::new();
    let mut truth_distance = 0.0;
    let mut prev_truth: Option<Vector3<f64>> = None;
    let mut error: Option<anyhow::Error> = None;
    let mut feed = |c: &CorrectedImuSample, odometry: &mut OdometryStage| {
        if error.is_some() {
            return;
        }
        let c = *c;
        let mut states: [Option<OdometryState>; 1] = [None];
        let result = odometry.process(&c, &mut |s: &OdometryState| {
            if s.flags & odometry_flags::REVISION == 0 {
                states[0] = Some(*s);
            }
        });
        if let Err(e) = result {
            error = Some(anyhow::anyhow!("{}: {e}", args.input.display()));
            return;
        }
        let Some(state) = states[0] else { return };
        if aligned_ns.is_none() && state.flags & odometry_flags::ALIGNED != 0 {
            aligned_ns = Some(state.stamps.sample_ns);
        }
        let new_rest = last.is_some_and(|l| state.rest_count > l.rest_count);
        if new_rest {
            rests.push(json!({
                "t_s": state.stamps.sample_ns as f64 * 1e-9,
                "position_m": state.position_m,
                "sigma_m": state.position_sigma_m,
            }));
        }
        if let Some(t) = truth_at(state.stamps.sample_ns) {
            let p = Vector3::from(t.position_m);
            if let Some(q) = prev_truth {
                truth_distance += (p - q).xy().norm();
            }
            prev_truth = Some(p);
            if frame.is_none() && state.flags & odometry_flags::ALIGNED != 0 {
                frame = Some(TruthFrame::new(&state, t));
            }
            if let (Some(f), true) = (&frame, new_rest) {
                let e = Vector3::from(state.position_m) - f.position(t);
                rest_errors.push(json!({
                    "t_s": state.stamps.sample_ns as f64 * 1e-9,
                    "error_m": [e.x, e.y, e.z],
                    "truth_distance_m": truth_distance,
                }));
            }
        }
        last = Some(state);
    };
    for raw in &recording.samples {
        while let Some(h) = hints.get(next_hint)
            && h.stamps.acquired_ns <= raw.stamps.sample_ns
        {
            odometry
                .hint(h)
                .map_err(|e| anyhow::anyhow!("{}: {e}", args.input.display()))?;
            next_hint += 1;
        }
        calibration
            .push(raw, &mut |c: &CorrectedImuSample| feed(c, &mut odometry))
            .map_err(|e| anyhow::anyhow!("{}: {e}", args.input.display()))?;
    }
    calibration.finish();
    // As `mems-odometry serve` at its end: revisions only, which this report does not use.
    odometry.finish(&mut |_| {});
    if let Some(e) = error {
        return Err(e);
    }
    let Some(end) = last else {
        bail!("{}: no samples", args.input.display());
    };
    if end.flags & odometry_flags::ALIGNED == 0 {
        bail!(
            "{}: never aligned: {}",
            args.input.display(),
            why_never_aligned(&calibration, detector.learn.duration_s)
        );
    }
    let first_ns = recording.samples.first().map_or(0, |s| s.stamps.sample_ns);
    let aligned_at_s = aligned_ns.map_or(0.0, |t| (t - first_ns) as f64 * 1e-9);
    eprintln!(
        "mems-odometry: aligned {aligned_at_s:.2} s into the recording (at its first rest of \
         {} s); the position counts from there",
        config.align_s
    );
    let truth_error = match (&frame, truth_at(end.stamps.sample_ns)) {
        (Some(f), Some(t)) => {
            let e = Vector3::from(end.position_m) - f.position(t);
            Some([e.x, e.y, e.z])
        }
        _ => None,
    };
    let result = json!({
        "end_displacement_m": end.position_m,
        "sigma_m": end.position_sigma_m,
        "distance_m": end.distance_m,
        "truth_error_m": truth_error,
        "truth_distance_m": truth_error.map(|_| truth_distance),
        "rest_intervals": rest_errors,
        "aligned_at_s": aligned_at_s,
        "rests": rests,
        "log_repairs": {
            "repeats_dropped": recording.repairs.repeats_dropped,
            "times_rebuilt": recording.repairs.times_rebuilt,
        },
        "seq": end.seq,
        "hints": {
            "in_recording": hints.len(),
            "applied": end.hints_applied,
            "disagreements": end.hint_disagreements,
            "speed_updates": odometry.hint_stats().speed_updates,
        },
    });
    if args.json {
        println!("{result}");
    } else {
        let p = end.position_m;
        let s = end.position_sigma_m;
        println!(
            "end displacement ({:+.4}, {:+.4}, {:+.4}) m +- ({:.4}, {:.4}, {:.4}) m, distance {:.2} m",
            p[0], p[1], p[2], s[0], s[1], s[2], end.distance_m
        );
        if let Some(e) = truth_error {
            let horizontal = (e[0] * e[0] + e[1] * e[1]).sqrt();
            println!(
                "error against truth ({:+.3}, {:+.3}, {:+.3}) m: {:.2} % of {:.1} m travelled",
                e[0],
                e[1],
                e[2],
                100.0 * horizontal / truth_distance.max(f64::EPSILON),
                truth_distance
            );
        }
    }
    Ok(())
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
