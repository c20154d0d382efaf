//! `mems-odometry offline`: the calibration stage and the odometry stage over a raw recording,
//! in one process, exactly as `mems-calibrate serve` and `mems-odometry serve` run them live.
//! An MCAP recording's robot hints (topic `mems/robot/hint`) go to the odometry stage in
//! publication order, each before the first raw sample taken after its publication (the
//! stage's own delivery rule decides which samples use it), unless `--no-hints`.
//!
//! An MCAP run (with its successor segments) is streamed: raw samples flow from the reader (a
//! thread of its own, decoding beside the stages) through both stages as they are read, each held back only [`HINT_WINDOW_NS`] for the hints
//! recorded after it, so memory is bounded by that window and the stages' own, not by the
//! file. Text recordings, and MCAP with `--repair-torn-reads` (a pass over the whole
//! recording), are read into memory first.
//!
//! Truth comparison (recordings from `mems-sim`): our navigation frame has its origin at the
//! alignment point and its heading fixed there; the truth's frame is the scenario's. At the first
//! aligned state the rotation between the two frames' headings is taken from the two attitudes
//! (its yaw part only: a roll or pitch difference is our own tilt error and stays in the error),
//! and the truth positions are expressed in our frame relative to the truth position there.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use anyhow::{Result, bail};
use calibrate::stage::{CalibrationStage, RefineConfig};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint, odometry_flags};
use nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};
use odometry::stage::OdometryStage;
use recording::Truth;
use recording::mcap::SegmentRead;
use recording::mcap::run::{Item, RawRun};
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
    /// Also write the run as a live run's recording to this MCAP file: raw samples and hints
    /// as read, corrected samples, odometry states (revisions included) and poses, each logged
    /// at its own time (`crate::out`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Overwrite the recording at `--out`.
    #[arg(long, requires = "out")]
    force: bool,
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

/// How long a raw sample is held back for the robot hints recorded after it, ns: a hint
/// recorded later than this after its publication reaches the stage late (counted).
const HINT_WINDOW_NS: u64 = 2_000_000_000;

/// Items a reader thread sends at a time, and blocks in flight: what the streamed path holds
/// between the reader and the stages.
const BLOCK: usize = 4096;
const BLOCKS_IN_FLIGHT: usize = 4;

/// The recording's raw samples, truth and hints, in file order: an MCAP run streamed
/// ([`recording::mcap::run::RawRun`]) by a reader thread, so that decoding runs beside the
/// stages on a second core, or a text recording (or a repaired one) in memory.
enum Source {
    Stream {
        blocks: Receiver<recording::Result<Vec<Item>>>,
        block: std::vec::IntoIter<Item>,
        reader: Option<JoinHandle<Vec<SegmentRead>>>,
    },
    Memory(std::vec::IntoIter<Item>),
}

/// Reads the run at `path` in blocks of [`BLOCK`] items into `tx` until the end, an error
/// (sent as the last block) or the receiver's end; returns the files read.
fn read_run(
    path: &Path,
    hints: bool,
    tx: SyncSender<recording::Result<Vec<Item>>>,
) -> Vec<SegmentRead> {
    let mut run = match RawRun::open(path, hints) {
        Ok(run) => run,
        Err(e) => {
            let _ = tx.send(Err(e));
            return Vec::new();
        }
    };
    let mut block = Vec::with_capacity(BLOCK);
    for item in run.by_ref() {
        match item {
            Ok(item) => block.push(item),
            Err(e) => {
                let _ = tx.send(Err(e));
                return run.segments().to_vec();
            }
        }
        if block.len() == BLOCK {
            let full = std::mem::replace(&mut block, Vec::with_capacity(BLOCK));
            if tx.send(Ok(full)).is_err() {
                return run.segments().to_vec();
            }
        }
    }
    let _ = tx.send(Ok(block));
    run.segments().to_vec()
}

impl Source {
    /// Opens the input; also returns the log repairs of a text recording.
    fn open(args: &OfflineArgs) -> Result<(Self, recording::LogRepairs)> {
        let is_mcap = recording::mcap::has_magic(&args.input)?;
        if is_mcap && !args.repair_torn_reads {
            let (tx, blocks) = sync_channel(BLOCKS_IN_FLIGHT);
            let (path, hints) = (args.input.clone(), !args.no_hints);
            let reader = std::thread::Builder::new()
                .name("mcap-reader".into())
                .spawn(move || read_run(&path, hints, tx))?;
            let source = Self::Stream {
                blocks,
                block: Vec::new().into_iter(),
                reader: Some(reader),
            };
            return Ok((source, recording::LogRepairs::default()));
        }
        let policy = if args.strict_time {
            recording::LogPolicy::Strict
        } else {
            recording::LogPolicy::Repair
        };
        let mut recording = crate::load_recording(&args.input, policy)?;
        if args.repair_torn_reads {
            let report = calibrate::repair::repair_torn_reads(
                &mut recording.samples,
                &calibrate::repair::RepairConfig::default(),
            );
            tracing::info!(
                "{}: repaired torn reads in {} of {} samples (accelerometer x, y, \
                 z: {:?}; gyro: {:?})",
                args.input.display(),
                report.samples_repaired,
                recording.samples.len(),
                report.accel.map(|a| a.repaired),
                report.gyro.map(|g| g.map(|a| a.repaired))
            );
        }
        // Hints first (the merge orders them by publication), then truth and samples by time.
        let mut items: Vec<Item> = if is_mcap && !args.no_hints {
            let hints = recording::mcap::read_all(&args.input)?.hints;
            hints.into_iter().map(Item::Hint).collect()
        } else {
            Vec::new()
        };
        let mut truth = recording.truth.take().unwrap_or_default();
        truth.sort_by_key(|t| t.t_ns);
        let mut truth = truth.into_iter().peekable();
        for raw in recording.samples {
            while let Some(t) = truth.next_if(|t| t.t_ns <= raw.stamps.sample_ns) {
                items.push(Item::Truth(t));
            }
            items.push(Item::Raw(raw));
        }
        items.extend(truth.map(Item::Truth));
        Ok((Self::Memory(items.into_iter()), recording.repairs))
    }

    fn next(&mut self) -> Option<recording::Result<Item>> {
        match self {
            Self::Stream { blocks, block, .. } => loop {
                if let Some(item) = block.next() {
                    return Some(Ok(item));
                }
                match blocks.recv() {
                    Ok(Ok(next)) => *block = next.into_iter(),
                    Ok(Err(e)) => return Some(Err(e)),
                    Err(_) => return None,
                }
            },
            Self::Memory(items) => items.next().map(Ok),
        }
    }

    /// The files a streamed run was read from (after its end), each with its truncation.
    fn segments(&mut self) -> Vec<SegmentRead> {
        match self {
            Self::Stream { reader, .. } => reader
                .take()
                .and_then(|r| r.join().ok())
                .unwrap_or_default(),
            Self::Memory(_) => Vec::new(),
        }
    }
}

/// Truth records not yet passed by the states, in time order.
#[derive(Default)]
struct TruthQueue(VecDeque<Truth>);

impl TruthQueue {
    /// The truth at `t_ns`, dropping every earlier one (states come in time order).
    fn at(&mut self, t_ns: u64) -> Option<&Truth> {
        while self.0.front().is_some_and(|t| t.t_ns < t_ns) {
            self.0.pop_front();
        }
        self.0.front().filter(|t| t.t_ns == t_ns)
    }
}

/// Raw samples held back by [`HINT_WINDOW_NS`], and the hints waiting for them in publication
/// order (the order a live subscriber receives them in): each hint goes to the odometry stage
/// before the first raw sample taken at or after its publication (the stage's own delivery
/// rule decides which samples use it).
#[derive(Default)]
struct Merge {
    raw: VecDeque<RawImuSample>,
    hints: VecDeque<RobotHint>,
    /// Time of the last sample released, ns.
    released_ns: Option<u64>,
    /// Hints seen, and those recorded too late for their place (see [`HINT_WINDOW_NS`]).
    hints_seen: u64,
    hints_late: u64,
}

impl Merge {
    fn hint(&mut self, h: RobotHint) {
        self.hints_seen += 1;
        let t = h.stamps.acquired_ns;
        if self.released_ns.is_some_and(|r| t <= r) {
            self.hints_late += 1;
        }
        let at = self.hints.partition_point(|q| q.stamps.acquired_ns <= t);
        self.hints.insert(at, h);
    }

    /// The next sample due once `newest_ns` has been read (`None`: the end of the input), with
    /// the hints to give the stage before it.
    fn release(
        &mut self,
        newest_ns: Option<u64>,
        mut hint: impl FnMut(&RobotHint),
    ) -> Option<RawImuSample> {
        let due = self
            .raw
            .front()
            .is_some_and(|r| newest_ns.is_none_or(|n| r.stamps.sample_ns + HINT_WINDOW_NS <= n));
        if !due {
            return None;
        }
        let raw = self.raw.pop_front()?;
        while let Some(h) = self.hints.front()
            && h.stamps.acquired_ns <= raw.stamps.sample_ns
        {
            hint(h);
            self.hints.pop_front();
        }
        self.released_ns = Some(raw.stamps.sample_ns);
        Some(raw)
    }
}

/// What the run's report gathers from the odometry states.
#[derive(Default)]
struct Summary {
    truth: TruthQueue,
    last: Option<OdometryState>,
    aligned_ns: Option<u64>,
    rests: Vec<serde_json::Value>,
    frame: Option<TruthFrame>,
    rest_errors: Vec<serde_json::Value>,
    truth_distance: f64,
    prev_truth: Option<Vector3<f64>>,
}

impl Summary {
    /// Takes the (non-revision) state of one sample.
    fn state(&mut self, state: OdometryState) {
        if self.aligned_ns.is_none() && state.flags & odometry_flags::ALIGNED != 0 {
            self.aligned_ns = Some(state.stamps.sample_ns);
        }
        let new_rest = self.last.is_some_and(|l| state.rest_count > l.rest_count);
        if new_rest {
            self.rests.push(json!({
                "t_s": state.stamps.sample_ns as f64 * 1e-9,
                "position_m": state.position_m,
                "sigma_m": state.position_sigma_m,
            }));
        }
        if let Some(t) = self.truth.at(state.stamps.sample_ns) {
            let p = Vector3::from(t.position_m);
            if let Some(q) = self.prev_truth {
                self.truth_distance += (p - q).xy().norm();
            }
            self.prev_truth = Some(p);
            if self.frame.is_none() && state.flags & odometry_flags::ALIGNED != 0 {
                self.frame = Some(TruthFrame::new(&state, t));
            }
            if let (Some(f), true) = (&self.frame, new_rest) {
                let e = Vector3::from(state.position_m) - f.position(t);
                self.rest_errors.push(json!({
                    "t_s": state.stamps.sample_ns as f64 * 1e-9,
                    "error_m": [e.x, e.y, e.z],
                    "truth_distance_m": self.truth_distance,
                }));
            }
        }
        self.last = Some(state);
    }
}

/// Runs the pipeline and prints the result.
pub fn run(args: OfflineArgs) -> Result<()> {
    let (file, detector) = args.stage.load()?;
    let (mut source, repairs) = Source::open(&args)?;
    let calibration = CalibrationStage::new(&file, detector, RefineConfig::default())
        .map_err(|e| anyhow::anyhow!("{}: {e}", args.stage.calib_name()))?;
    let mut config = args.stage.profile.odometry(crate::odometry_config(&file));
    config.rest_updates = !args.no_zupt;
    let odometry = OdometryStage::with_hints(config, args.hints.config()?)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let input = args.input.display();
    let mut stages = Stages {
        calibration,
        odometry,
        out: output(&args)?,
        summary: Summary::default(),
        error: None,
    };
    let (merge, first_ns) = stages.stream(&args, &mut source)?;
    report_input(&args, &mut source, &merge);
    let Stages {
        mut calibration,
        mut odometry,
        mut out,
        mut summary,
        error,
    } = stages;
    calibration.finish();
    // As `mems-odometry serve` at its end: revisions only, which this report does not use (the
    // recording keeps them).
    odometry.finish(&mut |s| {
        if let Some(out) = out.as_mut() {
            out.state(s);
        }
    });
    if let Some(out) = out {
        out.finish()?;
    }
    if let Some(e) = error {
        return Err(e.context(format!("{input}")));
    }
    let Some(end) = summary.last else {
        bail!("{input}: no samples");
    };
    if end.flags & odometry_flags::ALIGNED == 0 {
        bail!(
            "{input}: never aligned: {}",
            why_never_aligned(&calibration, detector.learn.duration_s)
        );
    }
    let aligned_at_s = summary
        .aligned_ns
        .map_or(0.0, |t| (t - first_ns.unwrap_or(0)) as f64 * 1e-9);
    tracing::info!(
        "aligned {aligned_at_s:.2} s into the recording (at its first rest of \
         {} s); the position counts from there",
        config.align_s
    );
    let truth_error = match (&summary.frame, summary.truth.at(end.stamps.sample_ns)) {
        (Some(f), Some(t)) => {
            let e = Vector3::from(end.position_m) - f.position(t);
            Some([e.x, e.y, e.z])
        }
        _ => None,
    };
    let truth_distance = summary.truth_distance;
    let result = json!({
        "end_displacement_m": end.position_m,
        "sigma_m": end.position_sigma_m,
        "distance_m": end.distance_m,
        "truth_error_m": truth_error,
        "truth_distance_m": truth_error.map(|_| truth_distance),
        "rest_intervals": summary.rest_errors,
        "aligned_at_s": aligned_at_s,
        "rests": summary.rests,
        "log_repairs": {
            "repeats_dropped": repairs.repeats_dropped,
            "times_rebuilt": repairs.times_rebuilt,
        },
        "seq": end.seq,
        "hints": {
            "in_recording": merge.hints_seen,
            "late": merge.hints_late,
            "applied": end.hints_applied,
            "disagreements": end.hint_disagreements,
            "speed_updates": odometry.hint_stats().speed_updates,
        },
    });
    if args.json {
        println!("{result}");
    } else {
        print_result(&end, truth_error, truth_distance);
    }
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

/// The two stages of an offline run, what they write and what is learned from their output.
struct Stages {
    calibration: CalibrationStage,
    odometry: OdometryStage,
    out: Option<crate::out::Out>,
    summary: Summary,
    /// The odometry stage's first error: the run stops feeding it and reports it.
    error: Option<anyhow::Error>,
}

impl Stages {
    /// Streams `source` through both stages, with robot hints merged into sample order and the
    /// raw samples and hints written to the output. Returns the merge's counts and the first
    /// sample's time, ns.
    fn stream(&mut self, args: &OfflineArgs, source: &mut Source) -> Result<(Merge, Option<u64>)> {
        let input = args.input.display();
        let mut merge = Merge::default();
        let mut first_ns = None;
        let mut warned_no_gyro = false;
        let mut newest_ns = Some(0);
        while newest_ns.is_some() {
            match source.next().transpose()? {
                Some(Item::Raw(raw)) => {
                    newest_ns = Some(raw.stamps.sample_ns);
                    first_ns.get_or_insert(raw.stamps.sample_ns);
                    if !warned_no_gyro && raw.flags & ipc_types::raw_flags::GYRO_VALID == 0 {
                        warned_no_gyro = true;
                        warn_no_gyro(args, raw.seq);
                    }
                    merge.raw.push_back(raw);
                }
                Some(Item::Hint(h)) => {
                    if let Some(out) = self.out.as_mut() {
                        out.hint(&h);
                    }
                    merge.hint(h);
                }
                Some(Item::Truth(t)) => self.summary.truth.0.push_back(t),
                None => newest_ns = None,
            }
            let mut hint_error = None;
            while let Some(raw) = merge.release(newest_ns, |h| {
                if let Err(e) = self.odometry.hint(h) {
                    hint_error.get_or_insert(e);
                }
            }) {
                if let Some(e) = hint_error.take() {
                    bail!("{input}: {e}");
                }
                if let Some(out) = self.out.as_mut() {
                    out.raw(&raw);
                }
                let (odometry, summary, out, error) = (
                    &mut self.odometry,
                    &mut self.summary,
                    &mut self.out,
                    &mut self.error,
                );
                self.calibration
                    .push(&raw, &mut |c: &CorrectedImuSample| {
                        feed(c, odometry, summary, out, error)
                    })
                    .map_err(|e| anyhow::anyhow!("{input}: {e}"))?;
            }
        }
        Ok((merge, first_ns))
    }
}

/// Says on stderr what the input held that the result does not show: truncated segments and
/// robot hints recorded too late to be merged in order.
fn report_input(args: &OfflineArgs, source: &mut Source, merge: &Merge) {
    for segment in source.segments() {
        if let Some(t) = &segment.truncation {
            tracing::warn!("{}: {t}", segment.path.display());
        }
    }
    if merge.hints_late > 0 {
        tracing::warn!(
            "{}: {} robot hints were recorded more than {} s after their \
             publication and reached the odometry stage after samples they would have preceded",
            args.input.display(),
            merge.hints_late,
            HINT_WINDOW_NS as f64 * 1e-9
        );
    }
}

/// The human-readable result: the end displacement with its 1-sigma, and the error against
/// truth where the recording has one.
fn print_result(end: &OdometryState, truth_error: Option<[f64; 3]>, truth_distance: f64) {
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

fn feed(
    c: &CorrectedImuSample,
    odometry: &mut OdometryStage,
    summary: &mut Summary,
    out: &mut Option<crate::out::Out>,
    error: &mut Option<anyhow::Error>,
) {
    if error.is_some() {
        return;
    }
    if let Some(out) = out.as_mut() {
        out.corrected(c);
    }
    let mut state = None;
    let result = odometry.process(c, &mut |s: &OdometryState| {
        if let Some(out) = out.as_mut() {
            out.state(s);
        }
        if s.flags & odometry_flags::REVISION == 0 {
            state = Some(*s);
        }
    });
    match (result, state) {
        (Err(e), _) => *error = Some(anyhow::anyhow!("{e}")),
        (Ok(()), Some(state)) => summary.state(state),
        (Ok(()), None) => {}
    }
}

/// Without a gyroscope nothing tracks the attitude. Offline keeps navigating (static
/// recordings such as the thesis's, accelerometer-only, are dead-reckoned at a fixed
/// attitude), but says what that position is worth.
fn warn_no_gyro(args: &OfflineArgs, seq: u64) {
    tracing::warn!(
        "{}: sample seq {seq} has no gyroscope (GYRO_VALID clear); the attitude \
         is held at its alignment, so the position is meaningful only if the sensor never \
         rotated (a static recording). mems-odometry serve publishes no position for such \
         samples (NO_GYRO)",
        args.input.display(),
    );
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
