//! Evaluation of the odometry stage on simulated 10-minute ground-robot drives: per case, the
//! end position error as % of distance travelled (median, p90) over many seeds, and how well
//! the reported 1-sigma covers it.
//!
//! Each seed powers on one simulated MPU-9250, runs an N-orientation calibration session
//! (from which the gyro correction is fitted, unless `--gyro-cal none`), then mounts the
//! sensor on the robot and drives. Rest flags are perfect (the drive plan's) or, with
//! `--rest imu`, the live calibration stage's zero-state detector on the raw samples (as
//! `mems-calibrate serve` runs it with its defaults). `--hints` adds the robot controller's
//! hints (`mems_sim::hints`), fed to the stage by publication time as `mems-odometry serve`
//! receives them.
//!
//! `cargo run --release -p odometry --example drive_eval -- --help` lists the options; the
//! tables in docs/odometry.md give the commands that produced them.

#[path = "../tests/common/mod.rs"]
mod common;

use calibrate_science::gyrocal::{GyroCalConfig, calibrate_gyro};
use clap::{Parser, ValueEnum};
use common::{Case, Simulation, live_calibration_stage, live_detector};
use ipc_types::{CorrectedImuSample, OdometryState, RobotHint, corrected_flags, odometry_flags};
use mems_sim::hints::{HintParams, RestSource};
use mems_stage::Stage;
use nalgebra::{Matrix2, Matrix3, Vector2};
use odometry::config::OdometryConfig;
use odometry::hints::HintConfig;
use odometry::session::{Input, NoGyro, OdometrySession};
use statrs::statistics::{Data, Max, Median, OrderStatistics};

/// Where the gyro correction comes from.
#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum GyroCal {
    /// Fitted to the pose session of the same power-on.
    Session,
    /// Identity: the gyro's 1% scale and 0.5% misalignment stay.
    None,
    /// The simulator's own model, inverted: a diagnostic reference only.
    Model,
}

/// Where the rest flags come from.
#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum Rest {
    /// The drive plan's rest segments.
    Perfect,
    /// The calibration stage's zero-state detector (GLRT, live defaults) on the raw samples.
    Imu,
}

/// Which robot hints the stage gets.
#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum Hints {
    /// None: the IMU alone.
    None,
    /// Every hint the controller publishes (no losses).
    All,
    /// The simulator's default losses: 2% independently and a 0.2-2 s burst every 2 min.
    Realistic,
    /// Half of the hints lost independently, and the default bursts.
    Half,
}

/// Source of the hints' stationary flag.
#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum HintRest {
    /// Wheel encoders (no tick in the window).
    Encoders,
    /// The controller's command (leads the motion by 75 ms).
    Commanded,
}

/// A simulated case (everything else as in `Case::straight`).
#[derive(Clone, Copy, PartialEq, ValueEnum)]
enum CaseName {
    /// One straight line.
    Straight,
    /// Turns of 30-120 degrees between legs.
    Turns,
    /// Turns, and half of the motions start with an in-place turn and a rest.
    InPlace,
    /// Turns, no vibration.
    Vib0,
    /// Turns, vibration without its content below 0.2 Hz (see `Case::vibration_dc_free`).
    VibDcFree,
    /// Straight, accelerometer turn-on bias of 20 mg (1-sigma), configured as such.
    Bias20Straight,
    /// Turns, accelerometer turn-on bias of 20 mg (1-sigma), configured as such.
    Bias20,
}

#[derive(Parser)]
#[command(about = "Odometry on simulated 10-minute drives")]
struct Args {
    /// Number of seeds per case.
    #[arg(long, default_value_t = 20)]
    seeds: u64,
    /// First seed (seeds run from here on).
    #[arg(long, default_value_t = 0)]
    first_seed: u64,
    /// Output rate, Hz.
    #[arg(long = "rate", default_value_t = 200.0)]
    rate_hz: f64,
    /// Cases to run (repeatable; all when none is given).
    #[arg(long = "case", value_enum)]
    cases: Vec<CaseName>,
    /// Where the gyro correction comes from.
    #[arg(long, value_enum, default_value_t = GyroCal::Session)]
    gyro_cal: GyroCal,
    /// Print every seed's outcome on stderr (info events).
    #[arg(long)]
    per_seed: bool,
    /// Use the simulator's default motions (up to three legs of 2-10 s, at most 30 s of motion
    /// between rests) instead of at most two legs of 2-6 s (a rest at least every 28 s).
    #[arg(long)]
    sim_default_legs: bool,
    /// Switch off a term of the sensor model (repeatable), for error budgets: accel-noise,
    /// accel-scale, accel-temp, accel-turn-on, gyro-noise, gyro-noise-xy, gyro-noise-z,
    /// gyro-turn-on, gyro-scale, adc.
    #[arg(long)]
    off: Vec<String>,
    /// Where the rest flags come from.
    #[arg(long, value_enum, default_value_t = Rest::Perfect)]
    rest: Rest,
    /// Robot hints given to the stage.
    #[arg(long, value_enum, default_value_t = Hints::None)]
    hints: Hints,
    /// Source of the hints' stationary flag.
    #[arg(long, value_enum, default_value_t = HintRest::Encoders)]
    hint_rest: HintRest,
    /// Estimate the IMU-to-body mounting from the first drive instead of configuring it.
    #[arg(long)]
    estimate_mounting: bool,
    /// The IMU's mounting on the simulated robot: yaw about the body's z axis, degrees
    /// (configured as such unless `--estimate-mounting`).
    #[arg(long, default_value_t = 0.0)]
    mount_yaw_deg: f64,
    /// Smooth floor: no vibration (for every case).
    #[arg(long)]
    smooth: bool,
    /// The part's digital low-pass filter, DLPF_CFG and A_DLPF_CFG both: `driver` (the
    /// default: what our driver picks for --rate, `mems_sim::dlpf::cfg_for_rate`: 1 at 1 kHz,
    /// 2 at 200 Hz), 0-7 (1: 184 Hz gyro / 218 Hz accel; 2: 92 / 99 Hz; 3: 41 / 45 Hz; 4:
    /// 20 / 21 Hz), or `off`: white samples, which no MPU-9250 produces.
    #[arg(long, default_value = "driver", value_parser = parse_dlpf_cfg)]
    dlpf_cfg: DlpfCfg,
    /// The stage's rest hindsight, s (`OdometryConfig::rest_hindsight_s`; default: the
    /// configuration's, 0.5 s).
    #[arg(long)]
    rest_hindsight_s: Option<f64>,
    /// With `--rest imu`: add the calibration stage's refined gyro bias back to its output
    /// (a diagnostic: the odometry then sees the gyro as if the stage did not refine it).
    #[arg(long)]
    undo_gyro_refinement: bool,
    /// With `--rest imu`: the detector's options (default: the vehicle profile's).
    #[command(flatten)]
    detector: calibrate::zero_state::args::DetectorArgs,
}

/// A `--dlpf-cfg` value.
#[derive(Clone, Copy)]
enum DlpfCfg {
    /// No filter: white samples.
    Off,
    /// What our driver picks for the rate.
    Driver,
    /// DLPF_CFG = A_DLPF_CFG = this.
    Cfg(u8),
}

impl DlpfCfg {
    /// The filters for output rate `rate_hz`, or `None` for white samples.
    fn config(self, rate_hz: f64) -> Option<mems_sim::dlpf::DlpfConfig> {
        match self {
            Self::Off => None,
            Self::Driver => Some(mems_sim::dlpf::DlpfConfig::driver(rate_hz)),
            Self::Cfg(cfg) => Some(mems_sim::dlpf::DlpfConfig::both(cfg)),
        }
    }
}

/// Parses a `--dlpf-cfg` value: `off`, `driver` or a DLPF_CFG of 0-7.
fn parse_dlpf_cfg(s: &str) -> Result<DlpfCfg, String> {
    match s {
        "off" => return Ok(DlpfCfg::Off),
        "driver" => return Ok(DlpfCfg::Driver),
        _ => {}
    }
    match s.parse::<u8>() {
        Ok(cfg) if cfg <= 7 => Ok(DlpfCfg::Cfg(cfg)),
        _ => Err(format!(
            "expected `off`, `driver` or a DLPF_CFG of 0-7, got {s:?}"
        )),
    }
}

/// The simulated case and the stage configuration for a case name.
fn case(name: CaseName, args: &Args) -> (Case, OdometryConfig) {
    let mut c = Case::straight();
    c.rate_hz = args.rate_hz;
    c.dlpf = args.dlpf_cfg.config(args.rate_hz);
    if args.sim_default_legs {
        c.max_legs = 3;
        c.leg_s = [2.0, 10.0];
    }
    let mut cfg = OdometryConfig::mpu9250(mems_sim::model::G_MPS2);
    match name {
        CaseName::Straight => {}
        CaseName::Turns => c.turns = true,
        CaseName::InPlace => {
            c.turns = true;
            c.in_place_turns = true;
        }
        CaseName::Vib0 => {
            c.turns = true;
            c.vibration = 0.0;
        }
        CaseName::VibDcFree => {
            c.turns = true;
            c.vibration_dc_free = true;
        }
        CaseName::Bias20Straight | CaseName::Bias20 => {
            c.turns = name == CaseName::Bias20;
            c.accel_turn_on_mg = Some(20.0);
            // An uncalibrated accelerometer: the configuration says so.
            cfg.accel_bias_sigma_mps2 = [20e-3 * mems_sim::model::G_MPS2; 3];
        }
    }
    if args.smooth {
        c.vibration = 0.0;
    }
    c.mounting = nalgebra::UnitQuaternion::from_axis_angle(
        &nalgebra::Vector3::z_axis(),
        args.mount_yaw_deg.to_radians(),
    );
    // The robot's vibration, as a measurement of it would give (see Case).
    let (accel, gyro) = c.vibration_density_per_mps();
    cfg.noise.vibration_accel_density_per_mps = accel;
    cfg.noise.vibration_gyro_density_per_mps = gyro;
    c.off.clone_from(&args.off);
    if let Some(h) = args.rest_hindsight_s {
        cfg.rest_hindsight_s = h;
    }
    (c, cfg)
}

/// Result of one drive.
struct Outcome {
    distance_m: f64,
    error_m: Vector2<f64>,
    sigma_m: Vector2<f64>,
    nees: f64,
    /// Per rest end (just before motion resumes) and axis: whether |error| <= sigma.
    rest_covered: (usize, usize),
    /// Largest error of the session's gyro correction against the model's (NaN without one).
    gyro_cal_error: f64,
    /// RMS horizontal error of the revised history and of the forward states it replaces,
    /// each relative to the error at the start of its motion, m.
    history_rms_m: (f64, f64),
    /// Speed updates applied, samples where hint and detector disagreed, samples flagged
    /// stale.
    hint_counts: (u64, u32, u64),
    /// Wheel-speed scale: the filter's estimate minus the simulated encoder's, and the
    /// filter's 1-sigma of it.
    scale_error: f64,
    scale_sigma: f64,
    /// Angle between the estimated (or configured) mounting and the true one, degrees.
    mounting_error_deg: f64,
    /// 1-sigma of one sample's zero-velocity update over the configured one: the square root
    /// of the effective-sample factor the stage estimated at alignment.
    zupt_widening: f64,
    /// The rest flags the stage got, scored against the drive's truth.
    flags: FlagScore,
    /// Time of the alignment, s.
    aligned_at_s: f64,
}

/// Rest flags against the truth: what the zero-velocity updates of wrong flags cost.
#[derive(Default, Clone, Copy)]
struct FlagScore {
    /// Samples at rest, and how many of them were flagged rest.
    rest: (u64, u64),
    /// Samples moving, and how many of them were flagged rest (false rest).
    moving: (u64, u64),
    /// False-rest runs (maximal runs of moving samples flagged rest), by where they end: within
    /// 1 s of the motion's start, within 1 s of its end, or in between.
    runs: [u64; 3],
    /// Sum over false-rest runs of the truth speed at the run's last sample times the motion
    /// time left after it, m: the distance a zero-velocity update at that speed would cut if
    /// nothing repaired it, by the same three places.
    cut_m: [f64; 3],
    /// Rests with no sample flagged, and the longest of them, s.
    missed_rests: (u64, f64),
    /// Longest time between two flagged rests, s.
    longest_unflagged_s: f64,
}

impl FlagScore {
    /// Scores `flags` (rest flag, truth at rest, truth speed m/s, time s) per sample.
    fn new(samples: &[(bool, bool, f64, f64)]) -> Self {
        let mut f = Self::default();
        let mut i = 0;
        while i < samples.len() {
            let (_, at_rest, ..) = samples[i];
            let end = samples[i..]
                .iter()
                .position(|s| s.1 != at_rest)
                .map_or(samples.len(), |k| i + k);
            let seg = &samples[i..end];
            let flagged = seg.iter().filter(|s| s.0).count() as u64;
            let n = seg.len() as u64;
            if at_rest {
                f.rest.0 += n;
                f.rest.1 += flagged;
                if flagged == 0 && i > 0 {
                    f.missed_rests.0 += 1;
                    f.missed_rests.1 = f.missed_rests.1.max(seg[seg.len() - 1].3 - seg[0].3);
                }
            } else {
                f.moving.0 += n;
                f.moving.1 += flagged;
                let (t0, t1) = (seg[0].3, seg[seg.len() - 1].3);
                for (k, s) in seg.iter().enumerate() {
                    let last_of_run = s.0 && seg.get(k + 1).is_none_or(|n| !n.0);
                    if last_of_run {
                        let place = if s.3 - t0 < 1.0 {
                            0
                        } else if t1 - s.3 < 1.0 {
                            1
                        } else {
                            2
                        };
                        f.runs[place] += 1;
                        f.cut_m[place] += s.2 * (t1 - s.3);
                    }
                }
            }
            i = end;
        }
        let mut last_flag = None;
        for s in samples.iter().filter(|s| s.0) {
            if let Some(t) = last_flag {
                f.longest_unflagged_s = f.longest_unflagged_s.max(s.3 - t);
            }
            last_flag = Some(s.3);
        }
        f
    }

    fn add(&mut self, o: &Self) {
        self.rest.0 += o.rest.0;
        self.rest.1 += o.rest.1;
        self.moving.0 += o.moving.0;
        self.moving.1 += o.moving.1;
        for i in 0..3 {
            self.runs[i] += o.runs[i];
            self.cut_m[i] += o.cut_m[i];
        }
        self.missed_rests.0 += o.missed_rests.0;
        self.missed_rests.1 = self.missed_rests.1.max(o.missed_rests.1);
        self.longest_unflagged_s = self.longest_unflagged_s.max(o.longest_unflagged_s);
    }
}

/// The hint stream of a seed for the options, or none.
fn hint_stream(c: &Case, seed: u64, args: &Args) -> (Vec<RobotHint>, f64) {
    let source = match args.hint_rest {
        HintRest::Encoders => RestSource::Encoders,
        HintRest::Commanded => RestSource::Commanded,
    };
    let mut p = HintParams::new(source);
    match args.hints {
        Hints::None => return (Vec::new(), 0.0),
        Hints::All => {
            p.drop_fraction = 0.0;
            p.bursts_per_min = 0.0;
        }
        Hints::Realistic => {}
        Hints::Half => p.drop_fraction = 0.5,
    }
    let s = c.hints(seed, &p);
    (s.hints, s.speed_scale)
}

/// The gyro correction the options ask for, in the stage configuration, and its largest error
/// against the model's (NaN unless fitted to the session).
fn with_gyro_correction(
    c: &Case,
    mut cfg: OdometryConfig,
    sim: &mut Simulation,
    gyro_cal: GyroCal,
) -> (OdometryConfig, f64) {
    let session = sim.session();
    let model_correction = c.gyro_correction_reference();
    let mut gyro_cal_error = f64::NAN;
    match gyro_cal {
        GyroCal::None => cfg.gyro_correction = Matrix3::identity(),
        GyroCal::Session => {
            let cal = calibrate_gyro(&session, &GyroCalConfig::new(mems_sim::model::G_MPS2))
                .expect("the simulated session calibrates the gyro");
            gyro_cal_error = (cal.correction - model_correction).abs().max();
            cfg = cfg.with_gyro_calibration(cal.correction, cal.correction_sigma);
        }
        GyroCal::Model => {
            cfg.gyro_correction = model_correction;
            cfg.gyro_correction_sigma = Matrix3::zeros();
        }
    };
    (cfg, gyro_cal_error)
}

/// What one drive records per sample: the stage's newest state, the truth in our frame, and
/// what the scores need.
struct Track {
    /// The newest forward state.
    last: Option<OdometryState>,
    /// Revised states: sequence number and horizontal position.
    revised: Vec<(u64, [f64; 2])>,
    /// Our navigation frame starts at the sensor's position at alignment, with its heading
    /// (the yaw of its attitude) then: the truth is expressed in that frame. Before alignment
    /// the truth frame is turned by the mounting yaw (the sensor's heading at the start).
    to_ours: (nalgebra::Vector3<f64>, nalgebra::Rotation3<f64>),
    /// Time of the alignment, s.
    aligned_at: Option<f64>,
    prev_truth: Option<[f64; 3]>,
    /// Horizontal distance travelled from alignment on, m.
    distance_m: f64,
    /// Horizontal truth and forward estimate per sample (by sequence number), to score the
    /// revised history against both.
    truth_xy: Vec<[f64; 2]>,
    forward_xy: Vec<[f64; 2]>,
    first_seq: Option<u64>,
    /// Sequence numbers where motions start: the history of a motion is scored relative to
    /// the error at its start, which the revision leaves as it is.
    motion_starts: Vec<u64>,
    /// Per sample: rest flag given to the stage, truth at rest, truth speed m/s, time s.
    flag_log: Vec<(bool, bool, f64, f64)>,
    /// Samples flagged hint-stale.
    stale: u64,
    was_rest: bool,
    /// Per rest end and axis: within 1 sigma, of all.
    rest_covered: (usize, usize),
    end_truth: Option<recording::Truth>,
}

impl Track {
    fn new(mount_yaw_deg: f64) -> Self {
        Self {
            last: None,
            revised: Vec::new(),
            to_ours: (
                nalgebra::Vector3::zeros(),
                nalgebra::Rotation3::from_axis_angle(
                    &nalgebra::Vector3::z_axis(),
                    -mount_yaw_deg.to_radians(),
                ),
            ),
            aligned_at: None,
            prev_truth: None,
            distance_m: 0.0,
            truth_xy: Vec::new(),
            forward_xy: Vec::new(),
            first_seq: None,
            motion_starts: Vec::new(),
            flag_log: Vec::new(),
            stale: 0,
            was_rest: false,
            rest_covered: (0, 0),
            end_truth: None,
        }
    }

    /// One corrected sample and the truth at it, in order.
    fn step(
        &mut self,
        s: &CorrectedImuSample,
        truth: &recording::Truth,
        session: &mut OdometrySession,
    ) {
        session
            .process(&Input::Sample(*s), &mut |o| {
                if o.flags & odometry_flags::REVISION == 0 {
                    self.last = Some(*o);
                } else {
                    self.revised
                        .push((o.seq, [o.position_m[0], o.position_m[1]]));
                }
            })
            .expect("valid samples");
        self.follow_alignment(s, truth);
        // Distance from the truth itself (the frame changes at alignment), from alignment on.
        if let Some(p) = self.prev_truth
            && self.aligned_at.is_some()
        {
            self.distance_m += (truth.position_m[0] - p[0]).hypot(truth.position_m[1] - p[1]);
        }
        self.prev_truth = Some(truth.position_m);
        let truth = recording::Truth {
            position_m: (self.to_ours.1
                * (nalgebra::Vector3::from(truth.position_m) - self.to_ours.0))
                .into(),
            ..*truth
        };
        self.score(s, &truth);
    }

    /// Moves our frame to the truth at alignment (again if the alignment was withdrawn with
    /// the rest it stood on).
    fn follow_alignment(&mut self, s: &CorrectedImuSample, truth: &recording::Truth) {
        let aligned = self
            .last
            .is_some_and(|o| o.flags & odometry_flags::ALIGNED != 0);
        if !aligned {
            self.aligned_at = None;
        }
        if self.aligned_at.is_none() && aligned {
            let [w, x, y, z] = truth.attitude_wxyz;
            let q =
                nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
            self.to_ours = (
                nalgebra::Vector3::from(truth.position_m),
                nalgebra::Rotation3::from_axis_angle(
                    &nalgebra::Vector3::z_axis(),
                    -q.euler_angles().2,
                ),
            );
            self.aligned_at = Some(s.stamps.sample_ns as f64 * 1e-9);
        }
    }

    /// Records the sample's flags, truth (in our frame) and forward state for the scores.
    fn score(&mut self, s: &CorrectedImuSample, truth: &recording::Truth) {
        self.first_seq.get_or_insert(s.seq);
        let v = truth.velocity_mps;
        self.flag_log.push((
            s.flags & corrected_flags::ZERO_STATE != 0,
            truth.at_rest,
            (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(),
            s.stamps.sample_ns as f64 * 1e-9,
        ));
        self.truth_xy
            .push([truth.position_m[0], truth.position_m[1]]);
        let o = self.last.expect("a state per sample");
        self.stale += u64::from(o.flags & odometry_flags::HINT_STALE != 0);
        self.forward_xy.push([o.position_m[0], o.position_m[1]]);
        if self.was_rest && !truth.at_rest {
            self.motion_starts.push(s.seq);
        }
        if self.was_rest && !truth.at_rest && o.flags & odometry_flags::ALIGNED != 0 {
            for i in 0..2 {
                self.rest_covered.1 += 1;
                if (o.position_m[i] - truth.position_m[i]).abs() <= o.position_sigma_m[i] {
                    self.rest_covered.0 += 1;
                }
            }
        }
        self.was_rest = truth.at_rest;
        self.end_truth = Some(*truth);
    }

    /// RMS horizontal error of the revised history and of the forward states it replaced,
    /// each relative to the error at the start of its motion, m.
    fn history_rms_m(&self) -> (f64, f64) {
        let first_seq = self.first_seq.expect("samples");
        let (mut se_rev, mut se_fwd) = (0.0, 0.0);
        for (seq, p) in &self.revised {
            let i = (seq - first_seq) as usize;
            let k = self.motion_starts.partition_point(|m| m <= seq);
            let i0 = (self.motion_starts[k.max(1) - 1] - first_seq) as usize;
            let e0 = [0, 1].map(|a| self.forward_xy[i0][a] - self.truth_xy[i0][a]);
            let e_rev = [0, 1].map(|a| p[a] - self.truth_xy[i][a] - e0[a]);
            let e_fwd = [0, 1].map(|a| self.forward_xy[i][a] - self.truth_xy[i][a] - e0[a]);
            se_rev += e_rev[0].powi(2) + e_rev[1].powi(2);
            se_fwd += e_fwd[0].powi(2) + e_fwd[1].powi(2);
        }
        let n_rev = self.revised.len().max(1) as f64;
        ((se_rev / n_rev).sqrt(), (se_fwd / n_rev).sqrt())
    }
}

/// The robot's hints, handed to the session as they arrive. Here they arrive
/// [`HINT_LEAD_NS`] before their publication, earlier than any live pipeline receives them:
/// the session holds each until the samples reach its publication, so the states are those
/// of a live run.
struct HintFeed<'a> {
    hints: &'a [RobotHint],
    next: usize,
}

/// How far ahead of the samples the hints arrive, ns.
const HINT_LEAD_NS: u64 = 500_000_000;

impl HintFeed<'_> {
    /// Hands the session the hints that arrived by the time of a sample at `t_ns`.
    fn feed(&mut self, t_ns: u64, session: &mut OdometrySession) {
        while let Some(h) = self.hints.get(self.next)
            && h.stamps.acquired_ns <= t_ns + HINT_LEAD_NS
        {
            session
                .process(&Input::Hint(*h), &mut |_| {})
                .expect("valid simulated hints");
            self.next += 1;
        }
    }
}

/// The calibration stage that flags rest with `--rest imu`.
fn rest_detector_stage(c: &Case, args: &Args) -> calibrate::stage::CalibrationStage {
    let mut detector = args
        .detector
        .apply(live_detector())
        .expect("valid detector options");
    if let Some(mg) = c.accel_turn_on_mg {
        // An uncalibrated part: the start-up learning accepts a gravity magnitude off by up to
        // 5 sigma of the bias on every axis (the default 5% refuses some), and the gravity
        // reference holds a bias of that sigma.
        detector.learn.max_gravity_error = detector
            .learn
            .max_gravity_error
            .max(5.0 * 3f64.sqrt() * mg * 1e-3);
        detector.glrt.accel_bias_sigma_mps2 = mg * 1e-3 * mems_sim::model::G_MPS2;
    }
    live_calibration_stage(detector)
}

/// Drives the simulation through the stage, with the hints and the rest flags the options
/// ask for.
fn drive(
    c: &Case,
    sim: &mut Simulation,
    args: &Args,
    stage: &mut OdometrySession,
    feed: &mut HintFeed,
    track: &mut Track,
) {
    match args.rest {
        Rest::Perfect => sim.drive(|s, truth| {
            feed.feed(s.stamps.sample_ns, stage);
            track.step(s, truth, stage);
        }),
        Rest::Imu => {
            let mut calibration = rest_detector_stage(c, args);
            // Each sample leaves the calibration stage in the call that takes it.
            sim.drive_raw(|raw, truth| {
                feed.feed(raw.stamps.sample_ns, stage);
                // The refinement in force when the sample arrives is the one it was corrected
                // with.
                let (_, gyro_refined, _) = calibration.refinement();
                calibration
                    .process(raw, &mut |c| {
                        let mut c = *c;
                        if args.undo_gyro_refinement {
                            for (w, b) in c.gyro_rps.iter_mut().zip(gyro_refined) {
                                *w += b;
                            }
                        }
                        track.step(&c, truth, stage);
                    })
                    .expect("valid raw samples");
            });
            calibration.finish(&mut |_| {});
        }
    }
}

fn run(c: &Case, cfg: OdometryConfig, seed: u64, args: &Args) -> Outcome {
    let mut sim = Simulation::new(c, seed);
    let (cfg, gyro_cal_error) = with_gyro_correction(c, cfg, &mut sim, args.gyro_cal);
    let hint_cfg = HintConfig {
        mounting: if args.estimate_mounting {
            None
        } else {
            Some(c.mounting)
        },
        ..HintConfig::default()
    };
    let mut session =
        OdometrySession::new(cfg, hint_cfg, NoGyro::Unnavigated).expect("valid hint configuration");
    let (hints, true_scale) = hint_stream(c, seed, args);
    let mut track = Track::new(args.mount_yaw_deg);
    let mut feed = HintFeed {
        hints: &hints,
        next: 0,
    };
    drive(c, &mut sim, args, &mut session, &mut feed, &mut track);
    let stage = session.stage();
    let o = track.last.expect("states");
    let truth = track.end_truth.expect("truth");
    let error_m = Vector2::new(
        o.position_m[0] - truth.position_m[0],
        o.position_m[1] - truth.position_m[1],
    );
    let cov: Matrix2<f64> = stage
        .filter()
        .expect("the stage aligned (never: the detector never learned its references)")
        .cov
        .fixed_view::<2, 2>(0, 0)
        .into_owned();
    let nees = error_m.dot(&(cov.try_inverse().expect("positive definite") * error_m));
    let h = stage.hint_stats();
    let kf = stage.filter().expect("aligned");
    let true_mounting = c.drive(seed).params().mounting;
    Outcome {
        hint_counts: (h.speed_updates, o.hint_disagreements, track.stale),
        scale_error: if hints.is_empty() {
            f64::NAN
        } else {
            kf.x.k - true_scale
        },
        scale_sigma: kf.cov[(odometry::eskf::KS, odometry::eskf::KS)].sqrt(),
        mounting_error_deg: stage
            .mounting()
            .map_or(f64::NAN, |m| m.angle_to(&true_mounting).to_degrees()),
        zupt_widening: stage.zupt_sigma_mps() / cfg.zupt_sigma_mps,
        distance_m: track.distance_m,
        error_m,
        sigma_m: Vector2::new(o.position_sigma_m[0], o.position_sigma_m[1]),
        nees,
        rest_covered: track.rest_covered,
        gyro_cal_error,
        history_rms_m: track.history_rms_m(),
        flags: FlagScore::new(&track.flag_log),
        aligned_at_s: track.aligned_at.expect("aligned"),
    }
}

/// The table's title line: the options the rows were run with.
fn print_title(args: &Args) {
    println!(
        "seeds {}-{}, {} Hz, {}, gyro correction: {}, rest flags: {} (hindsight {} s), hints: {}{}{}",
        args.first_seed,
        args.first_seed + args.seeds - 1,
        args.rate_hz,
        if args.sim_default_legs {
            "motions of up to three 2-10 s legs"
        } else {
            "motions of up to two 2-6 s legs"
        },
        match args.gyro_cal {
            GyroCal::Session => "from the session",
            GyroCal::None => "none",
            GyroCal::Model => "the model's (diagnostic)",
        },
        match args.rest {
            Rest::Perfect => "perfect",
            Rest::Imu => "IMU detector (GLRT)",
        },
        args.rest_hindsight_s
            .unwrap_or(OdometryConfig::mpu9250(mems_sim::model::G_MPS2).rest_hindsight_s),
        args.hints.to_possible_value().expect("named").get_name(),
        match (args.hints, args.hint_rest) {
            (Hints::None, _) => "",
            (_, HintRest::Encoders) => " (stationary from encoders)",
            (_, HintRest::Commanded) => " (stationary commanded)",
        },
        match (args.smooth, args.estimate_mounting) {
            (false, false) => "",
            (true, false) => ", smooth floor",
            (false, true) => ", mounting estimated",
            (true, true) => ", smooth floor, mounting estimated",
        }
    );
}

/// One seed's outcome (`--per-seed`).
fn print_seed(label: &str, seed: u64, o: &Outcome, p: f64, args: &Args) {
    tracing::info!(
        "{label} seed {seed}: distance {:.1} m, error ({:.3}, {:.3}) m = {p:.2}%, sigma ({:.3}, {:.3}) m, NEES {:.2}, gyro correction error {:.1e}, speed updates {}, disagreements {}, stale samples {}, scale error {:+.2}% (sigma {:.2}%), mounting error {:.2} deg, zero-velocity update's effective-sample factor {:.2}",
        o.distance_m,
        o.error_m.x,
        o.error_m.y,
        o.sigma_m.x,
        o.sigma_m.y,
        o.nees,
        o.gyro_cal_error,
        o.hint_counts.0,
        o.hint_counts.1,
        o.hint_counts.2,
        100.0 * o.scale_error,
        100.0 * o.scale_sigma,
        o.mounting_error_deg,
        o.zupt_widening.powi(2)
    );
    if args.rest == Rest::Imu {
        tracing::info!(
            "  seed {seed}: aligned at {:.1} s, rests missed {} (longest {:.1} s), longest between flagged rests {:.1} s, false-rest runs {:?}",
            o.aligned_at_s,
            o.flags.missed_rests.0,
            o.flags.missed_rests.1,
            o.flags.longest_unflagged_s,
            o.flags.runs
        );
    }
}

/// One case's outcomes summed over its seeds.
#[derive(Default)]
struct CaseTotals {
    /// End error as % of distance, per seed.
    pct: Vec<f64>,
    /// Axes whose end error is within 1 sigma, of all.
    covered: (usize, usize),
    nees: f64,
    rest_covered: (usize, usize),
    /// Sums of the squared history RMS, revised and forward.
    history_ss: (f64, f64),
    hint_totals: (u64, u64, u64),
    flags: FlagScore,
    scale_se: f64,
    mounting_max: f64,
}

impl CaseTotals {
    fn add(&mut self, o: &Outcome, p: f64) {
        self.flags.add(&o.flags);
        self.hint_totals.0 += o.hint_counts.0;
        self.hint_totals.1 += u64::from(o.hint_counts.1);
        self.hint_totals.2 += o.hint_counts.2;
        if o.scale_error.is_finite() {
            self.scale_se += o.scale_error.powi(2);
        }
        if o.mounting_error_deg.is_finite() {
            self.mounting_max = self.mounting_max.max(o.mounting_error_deg);
        }
        self.pct.push(p);
        for i in 0..2 {
            self.covered.1 += 1;
            if o.error_m[i].abs() <= o.sigma_m[i] {
                self.covered.0 += 1;
            }
        }
        self.nees += o.nees;
        self.history_ss.0 += o.history_rms_m.0.powi(2);
        self.history_ss.1 += o.history_rms_m.1.powi(2);
        self.rest_covered.0 += o.rest_covered.0;
        self.rest_covered.1 += o.rest_covered.1;
    }

    /// The case's table row, then its rest-flag and hint notes on stderr.
    fn print(self, label: &str, args: &Args) {
        let seeds = args.seeds as f64;
        let mut pct = Data::new(self.pct);
        println!(
            "| {label} | {:.2} | {:.2} | {:.2} | {:.0}% | {:.2} | {:.0}% | {:.2} / {:.2} |",
            pct.median(),
            pct.quantile(0.9),
            pct.max(),
            100.0 * self.covered.0 as f64 / self.covered.1 as f64,
            self.nees / (2.0 * seeds),
            100.0 * self.rest_covered.0 as f64 / self.rest_covered.1.max(1) as f64,
            (self.history_ss.0 / seeds).sqrt(),
            (self.history_ss.1 / seeds).sqrt(),
        );
        let (flags, n) = (&self.flags, seeds);
        if args.rest == Rest::Imu {
            tracing::info!(
                "  {label}: rest flagged {:.1}% of rest, {:.2}% of motion; false-rest runs per drive ending at a motion's start / end / in between: {:.1} / {:.1} / {:.1}, speed x motion left after them {:.2} / {:.2} / {:.2} m; rests missed per drive {:.1} (longest {:.1} s), longest time between flagged rests {:.1} s",
                100.0 * flags.rest.1 as f64 / flags.rest.0.max(1) as f64,
                100.0 * flags.moving.1 as f64 / flags.moving.0.max(1) as f64,
                flags.runs[0] as f64 / n,
                flags.runs[1] as f64 / n,
                flags.runs[2] as f64 / n,
                flags.cut_m[0] / n,
                flags.cut_m[1] / n,
                flags.cut_m[2] / n,
                flags.missed_rests.0 as f64 / n,
                flags.missed_rests.1,
                flags.longest_unflagged_s,
            );
        }
        if args.hints != Hints::None {
            tracing::info!(
                "  {label}: per drive {:.0} speed updates, {:.0} samples of hint/detector disagreement, {:.0} samples stale; scale error RMS {:.2}%; mounting error max {:.3} deg",
                self.hint_totals.0 as f64 / n,
                self.hint_totals.1 as f64 / n,
                self.hint_totals.2 as f64 / n,
                100.0 * (self.scale_se / n).sqrt(),
                self.mounting_max
            );
        }
    }
}

fn main() {
    mems_log::init("drive_eval");
    let mut args = Args::parse();
    if args.cases.is_empty() {
        args.cases = CaseName::value_variants().to_vec();
    }
    print_title(&args);
    println!(
        "| case | median % | p90 % | max % | end within 1 sigma (per axis) | NEES/2 mean | rest ends within 1 sigma | motion drift RMS revised / forward, m |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for &name in &args.cases {
        let (c, cfg) = case(name, &args);
        let label = name.to_possible_value().expect("no skipped variants");
        let mut totals = CaseTotals::default();
        for seed in args.first_seed..args.first_seed + args.seeds {
            let o = run(&c, cfg, seed, &args);
            let p = 100.0 * o.error_m.norm() / o.distance_m;
            if args.per_seed {
                print_seed(label.get_name(), seed, &o, p, &args);
            }
            totals.add(&o, p);
        }
        totals.print(label.get_name(), &args);
    }
}
