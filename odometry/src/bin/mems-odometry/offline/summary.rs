//! What an offline run reports: the states it gathers (alignment, rests, the end), the error
//! against the truth a simulated recording carries, what the input held that the result does
//! not show, and why a run that never aligned did not.
//!
//! Truth comparison: our navigation frame has its origin at the alignment point and its
//! heading fixed there; the truth's frame is the scenario's. At the first aligned state the
//! rotation between the two frames' headings is taken from the two attitudes (its yaw part
//! only: a roll or pitch difference is our own tilt error and stays in the error), and the
//! truth positions are expressed in our frame relative to the truth position there.
//! A simulated drive's truth is its rear axle's (`mems-sim --lever-arm-m`): with a lever arm
//! declared (`--lever-arm`, `r_b` from the IMU to the axle, body frame), the position compared
//! is the axle's, `p + q R_bs^-1 r_b` at the end less the same at the first aligned state
//! (the mounting `R_bs` as used at the end); without one, the IMU's.

use std::path::Path;

use anyhow::{Result, bail};
use calibrate::stage::CalibrationStage;
use calibrate::zero_state::{DetectorKind, StaticReference};
use ipc_types::stream::{Freezes, Holes};
use ipc_types::{OdometryState, odometry_flags};
use mems_stage::Chain;
use mems_stage::offline::Stop;
use nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};
use odometry::arrival::HINT_WINDOW_NS;
use odometry::axes::AxesReport;
use odometry::hints::ForwardAxisReport;
use odometry::session::OdometrySession;
use recording::mcap::SegmentRead;
use recording::{LogRepairs, Truth};
use serde_json::json;

use super::platform::Choice;
use super::source::{Feed, Source};
use super::truth::TruthQueue;

/// The offline chain: the calibration stage, then the odometry session.
pub type OfflineChain = Chain<CalibrationStage, OdometrySession>;

fn quat(wxyz: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]))
}

/// Maps truth positions into our navigation frame once the first aligned state is known.
struct TruthFrame {
    origin: Vector3<f64>,
    to_ours: Rotation3<f64>,
    /// Our attitude there (sensor to navigation).
    attitude: UnitQuaternion<f64>,
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
            attitude: quat(ours.attitude_wxyz),
        }
    }

    fn position(&self, truth: &Truth) -> Vector3<f64> {
        self.to_ours * (Vector3::from(truth.position_m) - self.origin)
    }
}

/// Sample time between two points of the reported track, ns (10 Hz: a car at 30 m/s moves
/// 3 m between them, fine enough to turn a reference track onto ours over its first metres).
const TRACK_PERIOD_NS: u64 = 100_000_000;

/// What the run's report gathers from the odometry states.
#[derive(Default)]
pub struct Summary {
    /// The last state.
    pub last: Option<OdometryState>,
    /// The time, ns, of the alignment the latest state stands on (the first aligned state
    /// since the last unaligned one).
    pub aligned_ns: Option<u64>,
    /// Alignments the filter gave up (aligned, withdrawn), ns: the detector's settled verdict
    /// took away the rest the filter had aligned on (the hindsight navigates again without
    /// it), or a new sensor session started; it waits for another rest.
    withdrawn: Vec<(u64, u64)>,
    rests: Vec<serde_json::Value>,
    /// Our position every [`TRACK_PERIOD_NS`] of sample time from the alignment on: (sample
    /// time ns, position m), as last published ([`Self::revise`]).
    track: Vec<(u64, [f64; 3])>,
    /// The previous revised state's sample time (ns) and position (m).
    last_revision: Option<(u64, [f64; 3])>,
    frame: Option<TruthFrame>,
    rest_errors: Vec<serde_json::Value>,
    truth_distance: f64,
    prev_truth: Option<Vector3<f64>>,
    /// States flagged `REST_VIBRATING`, `REST_MOVING`, `VIBRATING_STOP` and
    /// `NONHOLONOMIC_REJECTED`.
    rest_vibrating: u64,
    rest_moving: u64,
    vibrating_stop: u64,
    nonholonomic_rejected: u64,
}

impl Summary {
    /// Whether the last state was aligned.
    pub fn aligned(&self) -> bool {
        self.last
            .is_some_and(|s| s.flags & odometry_flags::ALIGNED != 0)
    }

    /// Takes the (non-revision) state of one sample, with the truth read so far.
    pub fn state(&mut self, state: OdometryState, truth: &mut TruthQueue) {
        if state.flags & odometry_flags::ALIGNED == 0 {
            self.withdraw(state.stamps.sample_ns);
        } else if self.aligned_ns.is_none() {
            self.aligned_ns = Some(state.stamps.sample_ns);
        }
        self.rest_vibrating += u64::from(state.flags & odometry_flags::REST_VIBRATING != 0);
        self.rest_moving += u64::from(state.flags & odometry_flags::REST_MOVING != 0);
        self.vibrating_stop += u64::from(state.flags & odometry_flags::VIBRATING_STOP != 0);
        self.nonholonomic_rejected +=
            u64::from(state.flags & odometry_flags::NONHOLONOMIC_REJECTED != 0);
        let t_ns = state.stamps.sample_ns;
        if state.flags & odometry_flags::ALIGNED != 0
            && self
                .track
                .last()
                .is_none_or(|&(last, _)| t_ns >= last + TRACK_PERIOD_NS)
        {
            self.track.push((t_ns, state.position_m));
        }
        let new_rest = self.last.is_some_and(|l| state.rest_count > l.rest_count);
        if new_rest {
            self.rests.push(json!({
                "t_s": state.stamps.sample_ns as f64 * 1e-9,
                "position_m": state.position_m,
                "sigma_m": state.position_sigma_m,
            }));
        }
        if let Some(t) = truth.at(state.stamps.sample_ns) {
            if self.frame.is_none() && state.flags & odometry_flags::ALIGNED != 0 {
                self.frame = Some(TruthFrame::new(&state, t));
            }
            // The truth's distance counts from the alignment, as the position does.
            let p = Vector3::from(t.position_m);
            if let (Some(q), Some(_)) = (self.prev_truth, &self.frame) {
                self.truth_distance += (p - q).xy().norm();
            }
            self.prev_truth = Some(p);
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

    /// Takes a revised state (`REVISION`): the track's points after the previous revised
    /// state and up to this one take the position the two give at their time (linear in
    /// time), when the two are at most [`TRACK_PERIOD_NS`] apart (revisions come in time
    /// order over a stretch, at least as often as the track's points); so the track is the
    /// final history, the last state published for each time.
    pub fn revise(&mut self, state: &OdometryState) {
        let (t, p) = (state.stamps.sample_ns, state.position_m);
        if state.flags & odometry_flags::ALIGNED == 0 {
            self.last_revision = None;
            return;
        }
        let (t0, p0) = match self.last_revision.replace((t, p)) {
            Some((t0, p0)) if t0 < t && t - t0 <= TRACK_PERIOD_NS => (t0, p0),
            _ => (t.saturating_sub(1), p),
        };
        let from = self.track.partition_point(|&(tk, _)| tk <= t0);
        for (tk, pk) in self.track[from..].iter_mut().take_while(|(tk, _)| *tk <= t) {
            let f = (*tk - t0) as f64 / (t - t0) as f64;
            *pk = std::array::from_fn(|i| p0[i] + (p[i] - p0[i]) * f);
        }
    }

    /// An unaligned state at `t_ns`: an alignment before it was withdrawn, and what was
    /// measured from it (the truth's frame, the rests' positions) goes with it.
    fn withdraw(&mut self, t_ns: u64) {
        if let Some(aligned) = self.aligned_ns.take() {
            self.withdrawn.push((aligned, t_ns));
            self.frame = None;
            self.truth_distance = 0.0;
            self.rests.clear();
            self.track.clear();
            self.rest_errors.clear();
        }
    }

    /// The end state's error against the truth, m, in our frame (a recording with truth);
    /// `lever` the mounting (sensor to body) and the declared lever arm to the axle (module
    /// documentation).
    pub fn truth_error(
        &self,
        end: &OdometryState,
        truth: &mut TruthQueue,
        lever: Option<(UnitQuaternion<f64>, Vector3<f64>)>,
    ) -> Option<[f64; 3]> {
        let (f, t) = (self.frame.as_ref()?, truth.at(end.stamps.sample_ns)?);
        let mut p = Vector3::from(end.position_m);
        if let Some((r_bs, r_b)) = lever {
            let axle = |q: UnitQuaternion<f64>| q * (r_bs.inverse() * r_b);
            p += axle(quat(end.attitude_wxyz)) - axle(f.attitude);
        }
        let e = p - f.position(t);
        Some([e.x, e.y, e.z])
    }

    /// The result once the chain has run (`ran`): refuses a run that was stopped, gave no
    /// state or never aligned (saying why); says when it aligned, then prints the result
    /// (`json`: as JSON).
    pub fn finish<R: std::fmt::Display>(
        &self,
        ran: Result<u64, Stop<R, anyhow::Error>>,
        read: &Read,
        chain: &OfflineChain,
        truth: &mut TruthQueue,
        json: bool,
    ) -> Result<()> {
        let input = read.input.display();
        stopped(ran, read)?;
        let Some(end) = self.last else {
            bail!("{input}: no samples");
        };
        if end.flags & odometry_flags::ALIGNED == 0 {
            bail!(
                "{input}: never aligned: {}",
                why_never_aligned(&chain.first, read.align_s)
            );
        }
        let aligned_at_s = self
            .aligned_ns
            .map_or(0.0, |t| (t - read.first_ns.unwrap_or(0)) as f64 * 1e-9);
        let in_motion = chain.second.stage().aligned_in_motion();
        say_aligned(aligned_at_s, read.align_s, in_motion, chain);
        let withdrawn = self.say_withdrawn(read, aligned_at_s);
        let accel = chain.second.stage().accel_estimate();
        if let Some(a) = &accel {
            tracing::info!("{a}");
        }
        let vibrating_s = self.say_stops(chain);
        let axes = chain.second.stage().axes();
        if axes.disagree() {
            tracing::warn!(
                "{input}: {}",
                describe_axes(&axes, read.first_ns.unwrap_or(0))
            );
        }
        let reanchored = chain.first.detector().gravity_reanchored();
        if reanchored > 0 {
            tracing::warn!(
                "{input}: the rest detector lost its gravity reference (carried by the \
                 gyroscope through the motion) {reanchored} times and measured it anew at a \
                 rest of {} s still by every other test",
                calibrate::zero_state::glrt::REANCHOR_S
            );
        }
        let relearned = say_learned_again(chain, read);
        let held = chain.first.detector().gravity_held();
        if held > 0 {
            tracing::info!(
                "{input}: the rest detector held {held} rests whose gravity magnitude its \
                 reference does not hold, within an accelerometer bias's reach, after {} s \
                 still by the scatter and the gyroscope",
                calibrate::zero_state::glrt::REANCHOR_S
            );
        }
        let consistency = chain.second.stage().consistency();
        tracing::info!("{consistency}");
        let walking = chain.second.walking_stats();
        if let Some(w) = walking {
            tracing::info!("{w}");
        }
        let truth_error = self.truth_error(&end, truth, declared_lever(chain));
        if json {
            let mut result = self.json(&end, truth_error, aligned_at_s, read, chain);
            result["profile"] = read.choice.json(chain.second.auto_choice());
            result["wheeled"] = self.wheeled_json(&chain.second);
            result["walking"] = json!(walking.map(|w| json!({
                "mode": "pedestrian dead reckoning",
                "steps": w.steps,
                "step_updates": w.step_updates,
                "mean_step_m": w.mean_step_m(),
                "weinberg_k": w.weinberg_k,
                "aligned_on_steps": w.aligned_on_steps,
                "step_nis_per_dof": w.step_nis_per_dof,
            })));
            result["aligned_in_motion"] = json!(in_motion.map(|s| json!({ "speed_mps": s })));
            result["alignments_withdrawn"] = json!(
                withdrawn
                    .iter()
                    .map(|(a, w)| json!({ "aligned_at_s": a, "withdrawn_at_s": w }))
                    .collect::<Vec<_>>()
            );
            result["accel_error"] = json!(accel);
            result["gyro_bias"] = gyro_bias_json(chain);
            result["gravity_reanchored"] = json!(reanchored);
            result["gravity_held"] = json!(held);
            result["detector_learned_again"] = json!(relearned);
            result["steady_vibrating_s"] = json!(vibrating_s);
            result["consistency"] = json!(consistency);
            println!("{result}");
        } else {
            self.print(&end, truth_error);
        }
        Ok(())
    }

    /// Says on stderr how long the detector found the platform steady but vibrating, how many
    /// of those samples the odometry took as stops, and how often a certain stop reset the
    /// velocity; returns the vibrating time, s.
    fn say_stops(&self, chain: &OfflineChain) -> f64 {
        let vibrating_s = chain.first.detector().vibrating_s();
        if vibrating_s > 0.0 {
            tracing::info!(
                "the detector found {vibrating_s:.1} s steady but vibrating above its rest's noise \
                 (no acceleration or turn it could see): taken for motion, not rest, but for \
                 {} samples the odometry took as stops (quiet below 2 Hz, flagged VIBRATING_STOP)",
                self.vibrating_stop
            );
        }
        let resets = chain
            .second
            .imu_constraint()
            .map_or(0, |n| n.velocity_resets);
        if resets > 0 {
            tracing::info!(
                "velocity reset to zero {resets} time(s) at a stop quiet below 2 Hz for 2 s: the \
                 filter held it beyond the rest gate (the velocity, not the stop, was wrong)"
            );
        }
        vibrating_s
    }

    /// The alignments withdrawn, (aligned, withdrawn) in s from the first sample, each said on
    /// stderr against the alignment `aligned_at_s` the position counts from.
    fn say_withdrawn(&self, read: &Read, aligned_at_s: f64) -> Vec<(f64, f64)> {
        let t0 = read.first_ns.unwrap_or(0);
        let s = |t: u64| t.saturating_sub(t0) as f64 * 1e-9;
        let withdrawn: Vec<_> = self.withdrawn.iter().map(|&(a, w)| (s(a), s(w))).collect();
        for (a, w) in &withdrawn {
            tracing::warn!(
                "{}: the alignment at {a:.2} s was withdrawn at {w:.2} s (the detector's \
                 settled verdict took away the rest it stood on, or a new sensor session \
                 started); the position counts from the alignment at {aligned_at_s:.2} s",
                read.input.display()
            );
        }
        withdrawn
    }

    /// The JSON result from the end state `end` (with `truth_error`), when it aligned, what
    /// the run read and what the chain counted.
    fn json(
        &self,
        end: &OdometryState,
        truth_error: Option<[f64; 3]>,
        aligned_at_s: f64,
        read: &Read,
        chain: &OfflineChain,
    ) -> serde_json::Value {
        let stats = chain.second.hint_stats();
        let chain_axes = chain.second.stage().axes();
        let first_ns = read.first_ns.unwrap_or(0);
        let track: Vec<[f64; 4]> = self
            .track
            .iter()
            .map(|&(t, [x, y, z])| [t.saturating_sub(first_ns) as f64 * 1e-9, x, y, z])
            .collect();
        let mut result = json!({
            "end_displacement_m": end.position_m,
            "sigma_m": end.position_sigma_m,
            "distance_m": end.distance_m,
            "truth_error_m": truth_error,
            "truth_distance_m": truth_error.map(|_| self.truth_distance),
            "rest_intervals": self.rest_errors,
            "rests": self.rests,
            "track": track,
            "seq": end.seq,
            "aligned_at_s": aligned_at_s,
            "log_repairs": {
                "repeats_dropped": read.repairs.repeats_dropped,
                "times_rebuilt": read.repairs.times_rebuilt,
            },
            "input_damage": damage_json(&read.segments),
            "input_holes": holes_json(&read.holes, read.first_ns.unwrap_or(0)),
            "input_frozen": holes_json(&read.frozen, read.first_ns.unwrap_or(0)),
            "axes_check": axes_json(&chain_axes, read.first_ns.unwrap_or(0)),
            "hints": {
                "in_recording": read.hints_seen,
                "late": read.hints_late,
                "applied": end.hints_applied,
                "disagreements": end.hint_disagreements,
                "speed_updates": stats.speed_updates,
                "gyro_bias_refuted": stats.gyro_bias_refuted,
                "mounting_rpy_deg": hint_mounting(chain),
                "forward_axis": forward_axis_json(chain, read),
                "speed_scale": speed_scale_json(chain),
            },
        });
        if let (Some(r), Some(t)) = (result.as_object_mut(), read.trust.as_object()) {
            r.extend(t.clone());
        }
        result
    }

    /// What the wheeled profile's IMU-only handling did: the non-holonomic constraint's
    /// updates and mounting, and the rests it refused (`null` for other profiles).
    fn wheeled_json(&self, session: &OdometrySession) -> serde_json::Value {
        let Some(nhc) = session.imu_constraint() else {
            return serde_json::Value::Null;
        };
        let mounting = nhc.mounting().map(|q| rpy_deg(&q));
        json!({
            "nonholonomic_updates": nhc.applied,
            "nonholonomic_rejected": nhc.rejected,
            "nonholonomic_nis_sum": nhc.nis_sum[0],
            "nonholonomic_dof_sum": nhc.nis_sum[1],
            "mounting_rpy_deg": mounting,
            "rest_vibrating_states": self.rest_vibrating,
            "rest_moving_states": self.rest_moving,
            "vibrating_stop_states": self.vibrating_stop,
            "certain_stop_velocity_resets": nhc.velocity_resets,
            "nonholonomic_rejected_states": self.nonholonomic_rejected,
        })
    }

    /// The human-readable result: the end displacement with its 1-sigma, and the error
    /// against truth where the recording has one.
    pub fn print(&self, end: &OdometryState, truth_error: Option<[f64; 3]>) {
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
                100.0 * horizontal / self.truth_distance.max(f64::EPSILON),
                self.truth_distance
            );
        }
    }
}

/// What an offline run read besides the states, and what its report names.
pub struct Read<'a> {
    /// The input, for messages.
    pub input: &'a Path,
    /// The first raw sample's time, ns.
    pub first_ns: Option<u64>,
    /// Robot hints read.
    pub hints_seen: u64,
    /// Hints recorded too late for their place (see [`HINT_WINDOW_NS`]).
    pub hints_late: u64,
    /// What reading a text recording repaired.
    pub repairs: LogRepairs,
    /// The rest the odometry aligns on, s (for the message).
    pub align_s: f64,
    /// Holes in the time line that nothing marked: the text reader's (with lines), else the
    /// calibration stage's (after the run: [`report_input`]).
    pub holes: Holes,
    /// Runs of samples repeating one reading for longer than a hole: the calibration stage's
    /// (`StageStats::frozen`, after the run).
    pub frozen: Holes,
    /// The files of a streamed run, with their truncations and damaged records (after the
    /// run: [`report_input`]).
    pub segments: Vec<SegmentRead>,
    /// The profile the run used and how it was chosen.
    pub choice: Choice,
    /// The ranges, clipped and implausible samples (after the run: `super::trust::json`), an
    /// object whose fields go into the JSON result.
    pub trust: serde_json::Value,
    /// The first pass's forward axis, where this run took its fit from the start.
    pub first_pass_axis: Option<ForwardAxisReport>,
}

impl<'a> Read<'a> {
    /// What `feed` read of `input` (with the text reader's `repairs`), and the rest the
    /// odometry aligns on, `align_s`.
    pub fn new(
        input: &'a Path,
        feed: &Feed,
        repairs: LogRepairs,
        align_s: f64,
        choice: Choice,
    ) -> Self {
        Self {
            input,
            first_ns: feed.first_ns,
            hints_seen: feed.arrival.hints(),
            hints_late: feed.arrival.late_hints(),
            holes: repairs.holes,
            frozen: Holes::default(),
            repairs,
            align_s,
            segments: Vec::new(),
            choice,
            trust: serde_json::Value::Null,
            first_pass_axis: None,
        }
    }
}

/// What the axes check found ([`odometry::axes`]): turns between still moments checked and those that
/// disagreed, the worst (degrees, and its time in seconds from the first sample).
fn axes_json(axes: &AxesReport, t0_ns: u64) -> serde_json::Value {
    json!({
        "checked": axes.checked,
        "disagreed": axes.disagreed,
        "disagree": axes.disagree(),
        "worst": axes.worst.map(|(off, turned, t_ns)| json!({
            "off_deg": off.to_degrees(),
            "turned_deg": turned.to_degrees(),
            "t_s": t_ns.saturating_sub(t0_ns) as f64 * 1e-9,
        })),
    })
}

/// The warning for axes that disagree.
fn describe_axes(axes: &AxesReport, t0_ns: u64) -> String {
    let (off, turned, t_ns) = axes.worst.unwrap_or_default();
    format!(
        "the accelerometer's and the gyroscope's axes disagree: at {} of {} turns between \
         still moments, gravity's direction in the sensor frame turned other than the integrated \
         gyroscope says (worst {:.0} deg off after a {:.0} deg turn, at t {:.1} s); are two \
         columns swapped, or an axis's sign or the axis mapping wrong?",
        axes.disagreed,
        axes.checked,
        off.to_degrees(),
        turned.to_degrees(),
        t_ns.saturating_sub(t0_ns) as f64 * 1e-9
    )
}

/// The holes in the input's time line: count, total and longest (seconds; the longest's
/// seq, line when a text file's, and time from the first sample).
fn holes_json(holes: &Holes, t0_ns: u64) -> serde_json::Value {
    let s = |ns: u64| ns as f64 * 1e-9;
    json!({
        "count": holes.count,
        "total_s": s(holes.total_ns),
        "longest": holes.longest.map(|h| json!({
            "seq": h.seq,
            "line": h.line,
            "t_s": s(h.t_ns.saturating_sub(t0_ns)),
            "length_s": s(h.dt_ns),
        })),
    })
}

/// The damaged records skipped in the input's files: each with its file, offset, length,
/// reason and the messages it held per topic, and the messages lost in all.
fn damage_json(segments: &[SegmentRead]) -> serde_json::Value {
    let records: Vec<serde_json::Value> = segments
        .iter()
        .flat_map(|s| s.damaged.iter().map(move |d| (s, d)))
        .map(|(s, d)| {
            json!({
                "file": s.path,
                "offset": d.offset,
                "bytes": d.bytes,
                "reason": d.reason,
                "lost": d.lost,
                "log_time_ns": d.log_time_ns,
            })
        })
        .collect();
    let lost: u64 = segments
        .iter()
        .flat_map(|s| &s.damaged)
        .map(|d| d.messages_lost())
        .sum();
    json!({ "records": records, "messages_lost": lost })
}

/// Says on stderr what the input held that the result does not show: truncated segments,
/// damaged records skipped, robot hints recorded too late to be merged in order, and samples
/// without a gyroscope (`no_gyro`: the first one's seq; navigated at a held attitude:
/// `NoGyro::HoldAttitude`). Returns the files read, for the JSON result.
pub fn report_input(read: &Read, source: &mut Source, no_gyro: Option<u64>) -> Vec<SegmentRead> {
    let input = read.input.display();
    let segments = source.segments();
    for segment in &segments {
        if let Some(t) = &segment.truncation {
            tracing::warn!("{}: {t}", segment.path.display());
        }
        for damage in &segment.damaged {
            tracing::warn!("{}: {damage}", segment.path.display());
        }
    }
    if let Some(holes) = read.holes.describe(read.first_ns.unwrap_or(0)) {
        tracing::warn!(
            "{input}: {holes}; each bridged as a gap: the 1-sigma grows across it as over an \
             unobserved interval (docs/input-checks.md)"
        );
    }
    if let Some(frozen) = Freezes::describe(&read.frozen, read.first_ns.unwrap_or(0)) {
        tracing::warn!(
            "{input}: {frozen}: the sensor stopped updating while it was read; integrated as \
             measured, so what it did meanwhile is missing from the position \
             (docs/input-checks.md)"
        );
    }
    if read.hints_late > 0 {
        tracing::warn!(
            "{input}: {} robot hints were recorded more than {} s after their publication and \
             reached the odometry stage after samples they would have preceded",
            read.hints_late,
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
    segments
}

/// The mounting (the IMU-only constraint's, else the hints') and the declared lever arm to
/// the axle, when one is declared and the mounting known.
fn declared_lever(chain: &OfflineChain) -> Option<(UnitQuaternion<f64>, Vector3<f64>)> {
    let stage = chain.second.stage();
    let r_b = stage.lever_arm_m();
    let mounting = stage
        .imu_constraint()
        .and_then(|n| n.mounting())
        .or_else(|| stage.mounting());
    mounting
        .filter(|_| r_b != Vector3::zeros())
        .map(|q| (q, r_b))
}

/// The mounting the speed hints use (sensor to body, roll, pitch, yaw in degrees), given or
/// estimated; `None` while unknown.
fn hint_mounting(chain: &OfflineChain) -> Option<[f64; 3]> {
    chain.second.stage().mounting().map(|q| rpy_deg(&q))
}

/// Roll, pitch and yaw of a mounting, degrees.
fn rpy_deg(q: &UnitQuaternion<f64>) -> [f64; 3] {
    let (r, p, y) = q.euler_angles();
    [r.to_degrees(), p.to_degrees(), y.to_degrees()]
}

/// A forward-axis fit in words: its mounting's roll, pitch and yaw and its yaw 1-sigmas.
pub fn describe_fit(fit: &odometry::hints::ForwardFit) -> String {
    let [r, p, y] = rpy_deg(&fit.mounting);
    format!(
        "roll {r:.1}, pitch {p:.1}, yaw {y:.1} deg (sensor to body; yaw 1-sigma {:.1} deg, \
         {:.1} with the reference's bias)",
        fit.sigma_rad.to_degrees(),
        fit.systematic_sigma_rad().to_degrees()
    )
}

/// When the forward axis estimated from the speed hints was first trusted (s from the first
/// sample), its latest yaw 1-sigma (deg: the fit's noise, and with the reference's bias, the
/// systematic one the position 1-sigma carries), its speed scale and what the filter took of
/// it once observable (fractions: the hints read `1 + k` times the speed); `null` when it was
/// given or never estimated. A run that took the first pass's fit from the start reports
/// when and from what that pass trusted it, and `from_start` true.
fn forward_axis_json(chain: &OfflineChain, read: &Read) -> serde_json::Value {
    let Some(mut f) = chain.second.stage().forward_axis() else {
        return serde_json::Value::Null;
    };
    let first_ns = read.first_ns.unwrap_or(0);
    if let Some(first) = read.first_pass_axis {
        (f.trusted_at_ns, f.source) = (first.trusted_at_ns, first.source);
    }
    let taken = f.scale_taken.map(|t| {
        json!({
            "at_s": t.at_ns.saturating_sub(first_ns) as f64 * 1e-9,
            "fit": t.fit.0,
            "fit_sigma": t.fit.1,
            "prior_sigma": t.prior_sigma,
            "prior_refuted": t.prior_refuted,
            "taken": t.taken.0,
            "taken_sigma": t.taken.1,
        })
    });
    json!({
        "trusted_at_s": f.trusted_at_ns.saturating_sub(first_ns) as f64 * 1e-9,
        "source": f.source.name(),
        "from_start": read.first_pass_axis.is_some(),
        "yaw_sigma_deg": f.fit.sigma_rad.to_degrees(),
        "yaw_systematic_sigma_deg": f.fit.systematic_sigma_rad().to_degrees(),
        "scale_fit": f.fit.scale.map(|k| json!({"k": k, "sigma": f.fit.scale_sigma})),
        "scale_taken": taken,
    })
}

/// The filter's wheel-speed scale error at the end and its 1-sigma (fractions: the speed
/// hints read `1 + k` times the speed); `null` before alignment.
fn speed_scale_json(chain: &OfflineChain) -> serde_json::Value {
    chain.second.stage().speed_scale().map_or(
        serde_json::Value::Null,
        |(k, s)| json!({"k": k, "sigma": s}),
    )
}

/// Whether a run that never aligned may align with the part declared uncalibrated
/// (`--uncalibrated`): its GLRT learned a rest that read gravity like a calibrated part's, so it
/// allowed its gravity reference a calibrated part's offset only, which an offset across
/// gravity (unseen in the magnitude) turned through the first bend or tilt calls motion.
pub fn may_be_uncalibrated(calibration: &CalibrationStage) -> bool {
    let detector = calibration.detector();
    let config = detector.config();
    is_glrt(config.kind)
        && detector
            .reference()
            .is_some_and(|r| !config.uncalibrated(&r))
}

fn is_glrt(kind: DetectorKind) -> bool {
    matches!(kind, DetectorKind::Glrt | DetectorKind::GlrtAccel)
}

/// Why the odometry never aligned, rests shorter than `align_s` seconds not counting: the
/// detector never learned (with the learner's last refusal), or it never flagged rest after
/// it did (with what its learned rest read of gravity and the offset its GLRT allowed).
pub fn why_never_aligned(calibration: &CalibrationStage, align_s: f64) -> String {
    let detector = calibration.detector();
    let kind = detector.config().kind.name();
    let learn_s = detector.config().learn.first_window_s();
    if detector.is_ready() {
        let learned = detector
            .reference()
            .map_or_else(String::new, |r| learned_rest(calibration, &r));
        return format!(
            "the {kind} detector flagged no rest of {align_s} s to align on after it was ready \
             ({} samples flagged rest in all, its gravity reference measured anew {} times){learned}",
            calibration.stats().rest,
            detector.gravity_reanchored(),
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

/// What the learned rest `r` of `calibration`'s detector read of gravity, and the offset its
/// GLRT allowed for, with the flag that changes it (empty for the other detectors).
fn learned_rest(calibration: &CalibrationStage, r: &StaticReference) -> String {
    let config = calibration.detector().config();
    if !is_glrt(config.kind) {
        return String::new();
    }
    let off = 100.0 * (r.magnitude_mps2 / config.learn.gravity_mps2 - 1.0);
    let limit = 100.0 * calibrate::zero_state::learn::CALIBRATED_GRAVITY_ERROR;
    let wide = config.glrt.uncalibrated_accel_bias_sigma_mps2;
    if config.uncalibrated(r) {
        return format!(
            "; its learned rest read gravity {off:+.1} % off, an uncalibrated part's: its \
             gravity reference allowed {wide:.3} m/s^2 of accelerometer offset per axis through \
             turns and tilts (--glrt-uncalibrated-offset-mps2)"
        );
    }
    format!(
        "; its learned rest read gravity {off:+.1} % off, within a calibrated part's {limit:.0} %: \
         its gravity reference allowed {:.4} m/s^2 of accelerometer offset per axis through \
         turns and tilts, and an offset across gravity barely moves the magnitude (0.15 g reads \
         1.1 % off); --uncalibrated allows {wide:.3} m/s^2",
        config.glrt.accel_bias_sigma_mps2
    )
}

/// The error for a run that was stopped (`ran`): a refusal (a hole the odometry does not
/// bridge named with its line and time) or the input's own error.
fn stopped<R: std::fmt::Display>(
    ran: Result<u64, Stop<R, anyhow::Error>>,
    read: &Read,
) -> Result<()> {
    let input = read.input.display();
    match ran {
        Err(Stop::Refused { refusal, .. }) => {
            let refusal = refusal.to_string();
            let t0 = read.first_ns.unwrap_or(0);
            if let Some(h) = read.holes.longest
                && refusal.starts_with(&format!("sample seq {}:", h.seq))
            {
                let line = h.line.map_or(String::new(), |l| format!(":{l}"));
                let t_s = h.t_ns.saturating_sub(t0) as f64 * 1e-9;
                bail!("{input}{line}: at t {t_s:.3} s: {refusal}");
            }
            bail!("{input}: {refusal}")
        }
        Err(Stop::Input(e)) => Err(e),
        Ok(_) => Ok(()),
    }
}

/// Says on stderr where the rest detector learned again from a longer rest (`--learn-s`), if
/// it did; returns that rest's start (s into the recording) and length as JSON, or null.
fn say_learned_again(chain: &OfflineChain, read: &Read) -> serde_json::Value {
    let Some(r) = chain.first.detector().relearned() else {
        return serde_json::Value::Null;
    };
    let start_s = r.t_start_ns.saturating_sub(read.first_ns.unwrap_or(0)) as f64 * 1e-9;
    tracing::info!(
        "the rest detector learned again from {:.1} s of rest from {start_s:.2} s into the \
         recording (much quieter than what its first window learned; --learn-s)",
        r.duration_s
    );
    json!({ "start_s": start_s, "duration_s": r.duration_s })
}

/// Says on stderr when and on what the odometry aligned: a rest of `align_s` seconds, whole
/// steps of a walk, or a cruise at the hints' speed `in_motion` (m/s).
fn say_aligned(aligned_at_s: f64, align_s: f64, in_motion: Option<f64>, chain: &OfflineChain) {
    let on_steps = chain
        .second
        .walking_stats()
        .is_some_and(|w| w.aligned_on_steps);
    match in_motion {
        None if on_steps => tracing::info!(
            "aligned {aligned_at_s:.2} s into the recording on whole steps of a walk (no \
             rest); the position counts from there"
        ),
        None => tracing::info!(
            "aligned {aligned_at_s:.2} s into the recording (at its first rest of {} s); the \
             position counts from there",
            align_s
        ),
        Some(speed) => tracing::info!(
            "aligned {aligned_at_s:.2} s into the recording in motion (a steady cruise of \
             {} s at {speed:.2} m/s by the speed hints, the IMU still); the position counts \
             from there",
            align_s
        ),
    }
}

/// The filter's gyro bias at the end, deg/s, sensor frame: what it still finds in the
/// calibration stage's corrected rates (which read the true rate plus it), and its 1-sigma
/// (the filter's covariance); null before an alignment.
fn gyro_bias_json(chain: &OfflineChain) -> serde_json::Value {
    let Some(kf) = chain.second.stage().filter() else {
        return serde_json::Value::Null;
    };
    let dps = |v: Vector3<f64>| v.map(f64::to_degrees).as_slice().to_vec();
    json!({
        "bias_dps": dps(kf.x.b_g),
        "sigma_dps": dps(kf.gyro_bias_sigma()),
    })
}
