//! Simulated test material shared by the integration tests and the evaluation example: one
//! powered-on MPU-9250 that first goes through an N-orientation calibration session (held
//! still in well-spread attitudes, rotated by hand between them) and is then mounted on a
//! ground robot for a drive. The drive's rest flags are perfect (taken from the drive plan).
//!
//! Samples go through the ADC's quantization (+-2 g, +-250 deg/s) and are converted to SI,
//! as the calibration stage would publish them; the sensor model is the one the odometry
//! sees after accelerometer calibration (`SensorModel::mpu9250_calibrated`). The raw samples
//! can be had instead, for the live calibration stage's own rest detection
//! ([`Simulation::drive_raw`], [`identity_calibration`]), and the robot controller's hints for
//! the drive ([`Case::hints`]).

#![allow(dead_code)]

use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig};
use calibrate::zero_state::{DetectorConfig, DetectorKind};
use ipc_types::units::{AccelRange, GyroRange};
use ipc_types::{
    CorrectedImuSample, OdometryState, RawImuSample, RobotHint, Stamps, corrected_flags,
    odometry_flags,
};
use mems_sim::SimSensor;
use mems_sim::adc::quantize_sample;
use mems_sim::hints::{HintParams, HintStream, RestSource, drive_hints};
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::scenario::{Drive, DriveParams, PoseParams, PoseSession, Scenario, ns_from_s};
use mems_sim::vibration::{Vibration, VibrationModel};
use mems_stage::Stage;
use nalgebra::{Matrix3, Vector3};
use odometry::config::OdometryConfig;
use odometry::hints::HintConfig;
use odometry::session::{Input, NoGyro, OdometrySession};
use recording::Truth;

/// Number of attitudes in the calibration session.
pub const SESSION_POSES: usize = 12;
/// How long each pose of the session is held, s.
pub const SESSION_HOLD_S: f64 = 5.0;

/// What to simulate.
#[derive(Debug, Clone)]
pub struct Case {
    /// Drive length, s.
    pub duration_s: f64,
    /// Output rate, Hz.
    pub rate_hz: f64,
    /// Turns between legs.
    pub turns: bool,
    /// In-place turns before half of the motions.
    pub in_place_turns: bool,
    /// Vibration level (1: moderate).
    pub vibration: f64,
    /// Accelerometer turn-on bias 1-sigma per axis, mg; `None` keeps the calibrated model's
    /// measured repeatability (4.5 / 2.5 / 6.1 mm/s^2).
    pub accel_turn_on_mg: Option<f64>,
    /// Most legs per motion, and the range of leg lengths, s (see `DriveParams`).
    pub max_legs: u32,
    /// Length of each constant-speed leg, s.
    pub leg_s: [f64; 2],
    /// Replace the simulator's vibration by the same signal without its content below
    /// [`DC_FREE_CUTOFF_HZ`] (an experiment: see [`Simulation`]).
    pub vibration_dc_free: bool,
    /// Turn angles, degrees (the drive's default is 30-120).
    pub turn_angle_deg: [f64; 2],
    /// Peak yaw rate of turns, deg/s (the drive's default is 45).
    pub peak_yaw_rate_dps: f64,
    /// Error terms switched off (for error budgets), see [`Case::model`].
    pub off: Vec<String>,
    /// IMU mounting on the robot, sensor to body (the drive's default is the identity).
    pub mounting: nalgebra::UnitQuaternion<f64>,
    /// Rest at the drive's start, s (0: it starts by driving off).
    pub initial_rest_s: f64,
    /// Range of the legs' cruise speeds, m/s (the drive's default is 0.2-1, a small robot).
    pub cruise_speed_mps: [f64; 2],
    /// Longest motion between two rests, s (see `DriveParams::max_motion_s`).
    pub max_motion_s: f64,
    /// Peak acceleration of every speed change, m/s^2 (the drive's default is 0.5).
    pub peak_accel_mps2: f64,
    /// The part's digital low-pass filters (the default: our driver's at 200 Hz, DLPF_CFG =
    /// A_DLPF_CFG = 2, see `mems_sim::dlpf::DlpfConfig::driver`; `None`: white samples, which
    /// no MPU-9250 produces).
    pub dlpf: Option<mems_sim::dlpf::DlpfConfig>,
}

impl Case {
    /// A straight 10-minute drive at 200 Hz with moderate vibration, with a rest at least every
    /// 30 s: motions of one or two legs of 2-6 s (at most 28 s from start to stop with a
    /// turn between the legs). The rest lengths (1-30 s) and everything else are the
    /// simulator's defaults.
    pub fn straight() -> Self {
        Self {
            max_legs: 2,
            leg_s: [2.0, 6.0],
            vibration_dc_free: false,
            duration_s: 600.0,
            rate_hz: 200.0,
            turns: false,
            in_place_turns: false,
            vibration: 1.0,
            accel_turn_on_mg: None,
            off: Vec::new(),
            turn_angle_deg: [30.0, 120.0],
            peak_yaw_rate_dps: 45.0,
            mounting: nalgebra::UnitQuaternion::identity(),
            initial_rest_s: DriveParams::new(600.0).initial_rest_s,
            max_motion_s: DriveParams::new(600.0).max_motion_s,
            peak_accel_mps2: DriveParams::new(600.0).peak_accel_mps2,
            cruise_speed_mps: DriveParams::new(600.0).cruise_speed_mps,
            dlpf: Some(mems_sim::dlpf::DlpfConfig::driver(200.0)),
        }
    }

    /// A 150 s drive with turns at 100 Hz that starts by driving off: no initial rest and no
    /// vibration (a straight leg at constant speed is then as still to the IMU as a rest).
    pub fn driving_off() -> Self {
        Self {
            duration_s: 150.0,
            rate_hz: 100.0,
            turns: true,
            vibration: 0.0,
            initial_rest_s: 0.0,
            ..Self::straight()
        }
    }

    /// The sensor model of this case.
    pub fn model(&self) -> SensorModel {
        let mut m = SensorModel::mpu9250_calibrated();
        if let Some(mg) = self.accel_turn_on_mg {
            m.accel.turn_on_bias_std = [mg * 1e-3; 3];
        }
        for term in &self.off {
            match term.as_str() {
                "accel-noise" => m.accel.noise_density = [0.0; 3],
                "gyro-noise" => m.gyro.noise_density = [0.0; 3],
                "gyro-noise-xy" => m.gyro.noise_density[..2].fill(0.0),
                "gyro-noise-z" => m.gyro.noise_density[2] = 0.0,
                "accel-scale" => {
                    m.accel.scale = [0.0; 3];
                    m.accel.misalignment = [[0.0; 3]; 3];
                }
                "accel-temp" => m.accel.bias_temp_coeff = [0.0; 3],
                "accel-turn-on" => m.accel.turn_on_bias_std = [0.0; 3],
                "gyro-turn-on" => m.gyro.turn_on_bias_std = [0.0; 3],
                "gyro-scale" => {
                    m.gyro.scale = [0.0; 3];
                    m.gyro.misalignment = [[0.0; 3]; 3];
                }
                "adc" => {}
                other => panic!("unknown error term `{other}`"),
            }
        }
        m
    }

    /// The gyro correction a perfect calibration would give, as an independent reference for
    /// [`calibrate_science::gyrocal::calibrate_gyro`]: the inverse of the gyro model's scale and
    /// misalignment `(I + diag(s) + M)^-1`, turned into the orthonormal frame closest to the
    /// accelerometer's axes (the rotation part `I + (M_a - M_a^T) / 2` of the accelerometer's
    /// residual misalignment).
    pub fn gyro_correction_reference(&self) -> Matrix3<f64> {
        let m = self.model();
        let gyro = Matrix3::identity()
            + Matrix3::from_fn(|i, k| m.gyro.misalignment[i][k])
            + Matrix3::from_diagonal(&Vector3::from(m.gyro.scale));
        let ma = Matrix3::from_fn(|i, k| m.accel.misalignment[i][k]);
        (Matrix3::identity() + 0.5 * (ma - ma.transpose()))
            * gyro.try_inverse().expect("an invertible gyro model")
    }

    /// The vibration the simulated sensor sees (none when it is replaced, see
    /// [`Case::vibration_dc_free`]).
    fn sim_vibration(&self) -> VibrationModel {
        VibrationModel::moderate(if self.vibration_dc_free {
            0.0
        } else {
            self.vibration
        })
    }

    /// Low-frequency (below the chassis resonance) density of the simulated vibration per m/s
    /// of wheel speed: accelerometer in m/s^2/sqrt(Hz), gyro in rad/s/sqrt(Hz). Only the
    /// chassis resonance reaches low frequencies (the wheel and motor lines average out): its
    /// unit-variance second-order response has the one-sided density `8 zeta / omega_0` per
    /// Hz at zero frequency, and it carries 40% of the unit signal's power.
    pub fn vibration_density_per_mps(&self) -> (f64, f64) {
        if self.vibration_dc_free {
            return (0.0, 0.0);
        }
        let m = VibrationModel::moderate(self.vibration);
        let omega0 = std::f64::consts::TAU * m.chassis_hz;
        let unit = (0.4 * 8.0 * m.chassis_damping / omega0).sqrt();
        (m.accel_rms_mps2 * unit, m.gyro_rms_dps.to_radians() * unit)
    }

    /// The drive plan of this case for `seed`.
    pub fn drive(&self, seed: u64) -> Drive {
        let mut p = DriveParams::new(self.duration_s);
        p.turns = self.turns;
        p.in_place_turns = self.in_place_turns;
        p.turn_angle_deg = self.turn_angle_deg;
        p.max_legs = self.max_legs;
        p.leg_s = self.leg_s;
        p.peak_yaw_rate_dps = self.peak_yaw_rate_dps;
        p.mounting = self.mounting;
        p.initial_rest_s = self.initial_rest_s;
        p.max_motion_s = self.max_motion_s;
        p.cruise_speed_mps = self.cruise_speed_mps;
        p.peak_accel_mps2 = self.peak_accel_mps2;
        Drive::new(&p, seed).expect("valid drive parameters")
    }
}

impl Case {
    /// The robot controller's hints during this case's drive for `seed` (times from the
    /// drive's start, like [`Simulation::drive`]'s samples).
    pub fn hints(&self, seed: u64, params: &HintParams) -> HintStream {
        drive_hints(&self.drive(seed), params, seed, 0.0).expect("valid hint parameters")
    }
}

/// An identity accelerometer calibration at standard gravity: the simulated sensor
/// (`SensorModel::mpu9250_calibrated`) is already what a calibration leaves, so the live
/// calibration stage only has to convert units, detect rest and refine the biases.
pub fn identity_calibration() -> CalibrationFile {
    CalibrationFile::identity(G_MPS2)
}

/// The calibration session followed by the drive, as one scenario for one sensor power-on.
/// The sensor is moved from the session's last pose onto the robot at `drive_start_s`.
pub struct SessionThenDrive {
    session: PoseSession,
    drive: Drive,
    drive_start_s: f64,
}

impl SessionThenDrive {
    /// Whether the drive plan has the robot at rest at `t_s` seconds into the drive: the
    /// plan's rest segments. (The truth's own `at_rest` compares the planned speed with zero
    /// exactly, which rounding can miss after several speed changes.)
    fn drive_at_rest(&self, t_s: f64) -> bool {
        let segs = self.drive.segments();
        let i = segs.partition_point(|s| s.start_s <= t_s).max(1) - 1;
        segs[i].at_rest
    }
}

impl Scenario for SessionThenDrive {
    fn truth(&self, t_s: f64) -> Truth {
        if t_s < self.drive_start_s {
            return self.session.truth(t_s);
        }
        let local = t_s - self.drive_start_s;
        let mut truth = self.drive.truth(local);
        truth.t_ns = ns_from_s(t_s);
        truth.at_rest = self.drive_at_rest(local);
        truth
    }

    fn duration_s(&self) -> f64 {
        self.drive_start_s + self.drive.duration_s()
    }

    fn wheel_speed_mps(&self, t_s: f64) -> f64 {
        if t_s < self.drive_start_s {
            0.0
        } else {
            self.drive.wheel_speed_mps(t_s - self.drive_start_s)
        }
    }
}

/// One simulated sensor through a session and a drive.
pub struct Simulation {
    sim: SimSensor<SessionThenDrive>,
    rate_hz: f64,
    drive_start_s: f64,
    drive_duration_s: f64,
    seq: u64,
    quantize: bool,
    dc_free: Option<DcFreeVibration>,
}

/// Cut-off of the high-pass that takes the low-frequency content out of the vibration, Hz.
pub const DC_FREE_CUTOFF_HZ: f64 = 0.2;

/// The simulator's vibration signal (same realisation for the same seed) through a first-order
/// high-pass: what a chassis that vibrates about a fixed attitude and position would add (its
/// angle and displacement stay bounded, so rate and acceleration carry no power at zero
/// frequency). Added after the sensor model rather than before (the 1% gyro scale error on a
/// 0.5 deg/s disturbance is negligible).
struct DcFreeVibration {
    vibration: Vibration,
    prev_in: [f64; 6],
    prev_out: [f64; 6],
}

impl DcFreeVibration {
    /// The disturbance at `t_s`: accelerometer in m/s^2, gyro in deg/s.
    fn step(&mut self, t_s: f64, rate_hz: f64, speed_mps: f64) -> [f64; 6] {
        let (a, g) = self.vibration.step(t_s, rate_hz, speed_mps);
        let x = [a[0], a[1], a[2], g[0], g[1], g[2]];
        let alpha = 1.0 / (1.0 + std::f64::consts::TAU * DC_FREE_CUTOFF_HZ / rate_hz);
        // First-order high-pass (backward-difference discretisation of s / (s + w_c)).
        for ((out, prev), x) in self.prev_out.iter_mut().zip(&mut self.prev_in).zip(x) {
            *out = alpha * (*out + x - *prev);
            *prev = x;
        }
        self.prev_out
    }
}

impl Simulation {
    /// Powers on a sensor with the case's model for `seed`, with the case's session and drive.
    pub fn new(case: &Case, seed: u64) -> Self {
        let session =
            PoseSession::orientations(SESSION_POSES, &PoseParams::new(SESSION_HOLD_S), seed)
                .expect("valid session parameters");
        let drive_start_s = session.duration_s();
        let scenario = SessionThenDrive {
            session,
            drive: case.drive(seed),
            drive_start_s,
        };
        let mut sim = SimSensor::new(scenario, &case.model(), &case.sim_vibration(), seed)
            .expect("valid sensor model");
        sim.set_dlpf(case.dlpf.map(mems_sim::DlpfGrid::from_power_on));
        let dc_free = case.vibration_dc_free.then(|| DcFreeVibration {
            vibration: Vibration::new(&VibrationModel::moderate(case.vibration), seed)
                .expect("valid vibration model"),
            prev_in: [0.0; 6],
            prev_out: [0.0; 6],
        });
        Self {
            sim,
            rate_hz: case.rate_hz,
            drive_start_s,
            drive_duration_s: case.duration_s,
            seq: 0,
            quantize: !case.off.iter().any(|t| t == "adc"),
            dc_free,
        }
    }

    /// The powered-on sensor (turn-on biases).
    pub fn sensor(&self) -> &mems_sim::model::Sensor {
        self.sim.sensor()
    }

    /// The quantized raw sample (sensor units, time from `t0_s`), the same sample converted
    /// to SI with perfect rest flags, and the truth at `t_s`.
    fn sample_both(&mut self, t_s: f64, t0_s: f64) -> (RawImuSample, CorrectedImuSample, Truth) {
        let (mut analog, truth) = self.sim.sample_with_truth(t_s, self.rate_hz);
        if let Some(v) = self.dc_free.as_mut() {
            let speed = self.sim.scenario().wheel_speed_mps(t_s);
            let d = v.step(t_s, self.rate_hz, speed);
            for i in 0..3 {
                analog.accel_g[i] += d[i] / G_MPS2;
                analog.gyro_dps[i] += d[3 + i];
            }
        }
        let sample_ns = ns_from_s(t_s - t0_s);
        let mut raw = quantize_sample(
            &analog,
            AccelRange::G2,
            GyroRange::Dps250,
            sample_ns,
            self.seq,
        );
        if !self.quantize {
            raw.accel_g = analog.accel_g;
            raw.gyro_dps = analog.gyro_dps;
        }
        let sample = CorrectedImuSample {
            stamps: Stamps {
                sample_ns,
                ..Default::default()
            },
            seq: self.seq,
            accel_mps2: raw.accel_g.map(|a| a * G_MPS2),
            gyro_rps: raw.gyro_dps.map(f64::to_radians),
            temp_c: analog.temp_c,
            flags: if truth.at_rest {
                corrected_flags::ZERO_STATE | corrected_flags::DETECTOR_READY
            } else {
                corrected_flags::DETECTOR_READY
            },
            // Passed through, as the calibration stage does (the gyroscope is valid).
            raw_flags: raw.flags,
            ..Default::default()
        };
        self.seq += 1;
        (raw, sample, truth)
    }

    fn sample(&mut self, t_s: f64, t0_s: f64) -> (CorrectedImuSample, Truth) {
        let (_, sample, truth) = self.sample_both(t_s, t0_s);
        (sample, truth)
    }

    /// The calibration session's samples, with perfect rest flags.
    pub fn session(&mut self) -> Vec<CorrectedImuSample> {
        let n = (self.drive_start_s * self.rate_hz).floor() as u64;
        (0..n)
            .map(|k| self.sample(k as f64 / self.rate_hz, 0.0).0)
            .collect()
    }

    /// Runs the drive, calling `f` with each sample (times from the drive's start) and the
    /// truth at it (positions from the drive's start).
    pub fn drive(&mut self, mut f: impl FnMut(&CorrectedImuSample, &Truth)) {
        let n = (self.drive_duration_s * self.rate_hz).round() as u64;
        for k in 0..n {
            let t = self.drive_start_s + k as f64 / self.rate_hz;
            let (s, truth) = self.sample(t, self.drive_start_s);
            f(&s, &truth);
        }
    }

    /// The drive's samples, in order (the truth left out).
    pub fn drive_samples(&mut self) -> Vec<CorrectedImuSample> {
        let mut samples = Vec::new();
        self.drive(|s, _| samples.push(*s));
        samples
    }

    /// Runs the drive like [`Simulation::drive`], but gives the quantized raw samples (sensor
    /// units, as the acquisition publishes them) instead of the corrected ones.
    pub fn drive_raw(&mut self, mut f: impl FnMut(&RawImuSample, &Truth)) {
        let n = (self.drive_duration_s * self.rate_hz).round() as u64;
        for k in 0..n {
            let t = self.drive_start_s + k as f64 / self.rate_hz;
            let (raw, _, truth) = self.sample_both(t, self.drive_start_s);
            f(&raw, &truth);
        }
    }
}

/// Polls `condition` every 20 ms until it holds; panics naming `what` after `timeout`.
pub fn wait_until(timeout: std::time::Duration, what: &str, mut condition: impl FnMut() -> bool) {
    let start = std::time::Instant::now();
    while !condition() {
        assert!(start.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// A scratch directory `TAG-PID` for one test binary, created.
pub fn scratch(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A service namespace unique to this test process and call (`test-{tag}-{pid}-{nanos}`),
/// also used as the name of the test's temporary directory.
pub fn unique_namespace(tag: &str) -> String {
    format!(
        "test-{tag}-{}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos())
    )
}

/// What a run of the session produced: the forward state of every sample, in order, and the
/// session.
pub struct Run {
    pub states: Vec<OdometryState>,
    pub session: OdometrySession,
}

/// How far ahead of their publication the hints of [`run_with_hints`] arrive, ns: earlier
/// than a live pipeline receives them; the session holds each until its time.
pub const HINT_LEAD_NS: u64 = 500_000_000;

/// Runs the odometry session (as the live process does) over `samples`, with each hint
/// arriving [`HINT_LEAD_NS`] before its publication.
pub fn run_with_hints(
    cfg: OdometryConfig,
    hint_cfg: HintConfig,
    samples: &[CorrectedImuSample],
    hints: &[RobotHint],
) -> Run {
    let mut session = OdometrySession::new(cfg, hint_cfg, NoGyro::Unnavigated).unwrap();
    let mut states = Vec::with_capacity(samples.len());
    let mut hints = hints.iter().peekable();
    for s in samples {
        while let Some(h) =
            hints.next_if(|h| h.stamps.acquired_ns <= s.stamps.sample_ns + HINT_LEAD_NS)
        {
            session.process(&Input::Hint(*h), &mut |_| {}).unwrap();
        }
        session
            .process(&Input::Sample(*s), &mut |o| {
                if o.flags & odometry_flags::REVISION == 0 {
                    states.push(*o);
                }
            })
            .unwrap();
    }
    Run { states, session }
}

/// The zero-state detector the live calibration stage runs (`mems-calibrate serve`'s GLRT
/// defaults) with 5 s of start-up learning, for the simulated sensor's gravity.
pub fn live_detector() -> DetectorConfig {
    let mut detector = DetectorConfig::new(DetectorKind::Glrt, G_MPS2);
    detector.learn.duration_s = 5.0;
    detector
}

/// The calibration stage as the live pipeline runs it on the simulated raw samples: the
/// identity calibration ([`identity_calibration`]), `detector`, and the default refinement.
pub fn live_calibration_stage(detector: DetectorConfig) -> CalibrationStage {
    CalibrationStage::new(&identity_calibration(), detector, RefineConfig::default())
        .expect("identity calibration")
}

/// The drive of `case` (power-on `seed`, after its calibration session) as raw samples with
/// the truth on the samples' clock, as `mems-sim drive` records it, and its encoder hints
/// moved onto the same clock (the hints' times count from the drive's start).
pub fn drive_with_encoder_hints(
    case: &Case,
    seed: u64,
) -> (Vec<(RawImuSample, Truth)>, Vec<RobotHint>) {
    drive_with_hints(case, seed, &HintParams::new(RestSource::Encoders))
}

/// [`drive_with_encoder_hints`] with the hint stream's parameters `params`.
pub fn drive_with_hints(
    case: &Case,
    seed: u64,
    params: &HintParams,
) -> (Vec<(RawImuSample, Truth)>, Vec<RobotHint>) {
    let mut sim = Simulation::new(case, seed);
    sim.session();
    let mut raw = Vec::new();
    sim.drive_raw(|r, t| {
        let t = Truth {
            t_ns: r.stamps.sample_ns,
            ..*t
        };
        raw.push((*r, t));
    });
    let t0_ns = raw[0].0.stamps.sample_ns;
    let hints = case
        .hints(seed, params)
        .hints
        .into_iter()
        .map(|mut h| {
            h.stamps.sample_ns += t0_ns;
            h.stamps.acquired_ns += t0_ns;
            h
        })
        .collect();
    (raw, hints)
}

/// Writes the drive of `case` (power-on `seed`) and its encoder hints to the MCAP file `path`,
/// as the recorder logs them: raw samples and the truth at each sample's time, each hint at its
/// acquisition, before the first sample after it.
pub fn write_drive_with_encoder_hints(path: &std::path::Path, case: &Case, seed: u64) {
    let (raw, hints) = drive_with_encoder_hints(case, seed);
    write_drive_with_hints(path, &raw, hints);
}

/// A drive with turns at 8-15 m/s, its IMU rolled 180 degrees on the car (sensor x forward,
/// y right, z down, as the comma2k19 phone of docs/real-data.md), and its encoder hints: the
/// simulated 150 s from the first sample at [`CAR_START_MPS`] on (the car accelerating from its
/// start at 0.5 m/s^2, the simulator's peak), so that the recording starts in motion.
pub fn car_started_in_motion(seed: u64) -> (Vec<(RawImuSample, Truth)>, Vec<RobotHint>) {
    let case = Case {
        cruise_speed_mps: [8.0, 15.0],
        leg_s: [3.0, 8.0],
        max_motion_s: 400.0,
        mounting: nalgebra::UnitQuaternion::from_axis_angle(
            &Vector3::x_axis(),
            180f64.to_radians(),
        ),
        ..Case::driving_off()
    };
    let (raw, hints) = drive_with_encoder_hints(&case, seed);
    let speed = |v: &[f64; 3]| v[0].hypot(v[1]);
    let first = raw
        .iter()
        .position(|(_, t)| speed(&t.velocity_mps) >= CAR_START_MPS)
        .expect("the car reaches its start speed");
    let t0_ns = raw[first].0.stamps.sample_ns;
    let hints = hints
        .into_iter()
        .filter(|h| h.stamps.sample_ns >= t0_ns)
        .collect();
    (raw[first..].to_vec(), hints)
}

/// The speed of [`car_started_in_motion`] at the recording's first sample, m/s.
pub const CAR_START_MPS: f64 = 5.0;

/// Runs `bin offline --json ARGS --input PATH` (`bin` the mems-odometry binary,
/// `env!("CARGO_BIN_EXE_mems-odometry")`, which only a test crate knows), asserts that it
/// succeeded (its stderr in the message) and returns its JSON.
pub fn offline_json(bin: &str, path: &std::path::Path, args: &[&str]) -> serde_json::Value {
    let out = std::process::Command::new(bin)
        .args(["offline", "--json"])
        .args(args)
        .arg("--input")
        .arg(path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "offline failed: {err}");
    serde_json::from_slice(&out.stdout).unwrap_or_else(|e| panic!("{e}: {err}"))
}

/// [`offline_json`] with `--profile vehicle`.
pub fn offline_vehicle_json(bin: &str, path: &std::path::Path, args: &[&str]) -> serde_json::Value {
    offline_json(bin, path, &[&["--profile", "vehicle"], args].concat())
}

/// Writes the drive `raw` and its `hints` ([`write_drive_with_hints`]) into the scratch
/// directory `name`, runs [`offline_vehicle_json`] on the file with `args`, removes the
/// directory and returns the JSON.
pub fn offline_drive_with_hints(
    bin: &str,
    name: &str,
    raw: &[(RawImuSample, Truth)],
    hints: Vec<RobotHint>,
    args: &[&str],
) -> serde_json::Value {
    let dir = scratch(name);
    let path = dir.join("drive.mcap");
    write_drive_with_hints(&path, raw, hints);
    let v = offline_vehicle_json(bin, &path, args);
    std::fs::remove_dir_all(&dir).unwrap();
    v
}

/// Writes raw samples with their truth and the hints `hints` to the MCAP file `path`, as
/// [`write_drive_with_encoder_hints`] does (for hints changed after they were made).
pub fn write_drive_with_hints(
    path: &std::path::Path,
    raw: &[(RawImuSample, Truth)],
    hints: Vec<RobotHint>,
) {
    let mut w = recording::mcap::Writer::create(path).unwrap();
    let raw_ch = w.add_channel::<RawImuSample>().unwrap();
    let truth_ch = w.add_channel::<Truth>().unwrap();
    let hint_ch = w.add_channel::<RobotHint>().unwrap();
    let mut hints = hints.into_iter().peekable();
    for (r, t) in raw {
        while let Some(h) = hints.next_if(|h| h.stamps.acquired_ns <= r.stamps.sample_ns) {
            w.write(hint_ch, &h, h.stamps.acquired_ns).unwrap();
        }
        w.write(raw_ch, r, r.stamps.sample_ns).unwrap();
        w.write(truth_ch, t, r.stamps.sample_ns).unwrap();
    }
    w.finish().unwrap();
}
