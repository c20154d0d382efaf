//! Simulated calibration sessions shared by the diagnosis's tests (`tests/diagnose.rs`) and
//! the example that writes the short-pose sessions of docs/diagnosis.md
//! (`examples/short_pose_sessions.rs`): the part they simulate, the true-model residual a
//! fit can reach, and the short-pose cases (calibration and test file of one power-on, poses
//! held 2 and 4 s).

use calibrate_science::diagnose::Effect;
use ipc_types::RawImuSample;
use ipc_types::units::{AccelRange, GyroRange, STANDARD_GRAVITY_MPS2};
use mems_sim::model::{SensorModel, ThermalModel, TriadModel};
use mems_sim::scenario::{PoseParams, PoseSession, Scenario};
use mems_sim::vibration::VibrationModel;
use mems_sim::{SimSensor, adc};

/// Output data rate of every simulated session, Hz.
pub const RATE_HZ: f64 = 200.0;

/// The part every session shares: bias, scale, a small misalignment and white noise
/// (300 ug/sqrt(Hz): 4.2 mg per sample at 200 Hz), at a constant 25 degC.
pub fn base_model() -> SensorModel {
    let mut m = SensorModel::ideal();
    m.accel = TriadModel {
        bias: [0.04, -0.035, 0.055],
        scale: [0.015, -0.02, 0.01],
        misalignment: [
            [0.0, 0.002, -0.001],
            [-0.001, 0.0, 0.002],
            [0.002, -0.001, 0.0],
        ],
        noise_density: [300e-6; 3],
        ..TriadModel::ideal()
    };
    m
}

/// A die temperature that rises by self-heating and falls with the room: not a function of
/// time that a drift or a warm-up can follow.
pub fn varying_temperature() -> ThermalModel {
    ThermalModel {
        ambient_c: 25.0,
        ambient_drift_c_per_s: -0.04,
        self_heating_c: 8.0,
        self_heating_time_constant_s: 40.0,
        reference_c: 25.0,
    }
}

/// A simulated session: the quantized samples and, per sample, the noiseless reading (g).
pub struct Session {
    /// The quantized samples.
    pub samples: Vec<RawImuSample>,
    /// The noiseless reading of each sample, g.
    pub exact: Vec<[f64; 3]>,
    /// The hold interval of each pose, s.
    pub holds: Vec<(f64, f64)>,
}

/// Simulates `scenario` with `model`, plus `extra(t)` (g) added to the accelerometer, as a
/// recording that starts `t_off_s` after power-on: its stamps and `extra` run on the power-on
/// clock (the model's own time terms, warm-up and die temperature, start again at 0).
pub fn simulate_poses(
    scenario: PoseSession,
    model: &SensorModel,
    seed: u64,
    t_off_s: f64,
    extra: impl Fn(f64) -> [f64; 3],
) -> Session {
    let holds: Vec<(f64, f64)> = (0..scenario.poses().len())
        .map(|i| scenario.hold_interval_s(i))
        .collect();
    let duration = scenario.duration_s();
    let mut quiet = model.clone();
    quiet.accel.noise_density = [0.0; 3];
    quiet.gyro.noise_density = [0.0; 3];
    let vib = VibrationModel::moderate(0.0);
    let mut noisy = SimSensor::new(scenario.clone(), model, &vib, seed).unwrap();
    let mut clean = SimSensor::new(scenario, &quiet, &vib, seed).unwrap();
    let n = (duration * RATE_HZ) as usize;
    let mut samples = Vec::with_capacity(n);
    let mut exact = Vec::with_capacity(n);
    for k in 0..n {
        let t = k as f64 / RATE_HZ;
        let add = extra(t_off_s + t);
        let (mut a, _) = noisy.sample_with_truth(t, RATE_HZ);
        let (mut c, _) = clean.sample_with_truth(t, RATE_HZ);
        for (i, x) in add.iter().enumerate() {
            a.accel_g[i] += x;
            c.accel_g[i] += x;
        }
        samples.push(adc::quantize_sample(
            &a,
            AccelRange::G2,
            GyroRange::Dps250,
            ((t_off_s + t) * 1e9).round() as u64,
            k as u64,
        ));
        exact.push(c.accel_g);
    }
    Session {
        samples,
        exact,
        holds,
    }
}

/// The held-out rms a fit with the true model achieves, m/s^2: 1 s block means of
/// `samples - exact` inside the holds (1 s trimmed at each end, an eighth of the hold for
/// holds shorter than 8 s; a last block of 0.5-1 s kept), rms over blocks and axes.
pub fn true_model_rms(samples: &[RawImuSample], exact: &[[f64; 3]], holds: &[(f64, f64)]) -> f64 {
    let mut ss = 0.0;
    let mut count = 0;
    for &(t0, t1) in holds {
        let trim = ((t1 - t0) / 8.0).min(1.0);
        let mut t = t0 + trim;
        while t + 0.5 <= t1 - trim {
            let k0 = (t * RATE_HZ).round() as usize;
            let k1 = ((t + 1.0).min(t1 - trim) * RATE_HZ).round() as usize;
            let d: [f64; 3] = std::array::from_fn(|axis| {
                (k0..k1)
                    .map(|k| samples[k].accel_g[axis] - exact[k][axis])
                    .sum::<f64>()
                    / (k1 - k0) as f64
            });
            ss += d.iter().map(|x| x * x).sum::<f64>();
            count += 3;
            t += 1.0;
        }
    }
    (ss / count as f64).sqrt() * STANDARD_GRAVITY_MPS2
}

/// Poses held 2 s in the calibration session and 4 s in the test session.
pub const SHORT_HOLDS_S: [f64; 2] = [2.0, 4.0];
/// The test session starts this long after the calibration session ends, s.
pub const BETWEEN_FILES_S: f64 = 10.0;

/// One short-pose case: a part with one effect (or none, or one outside the diagnosis's
/// library) and what the diagnosis should make of it.
pub struct ShortCase {
    /// Its name (file names and tables).
    pub name: &'static str,
    /// What the part has, in words.
    pub what: &'static str,
    /// The part.
    pub model: SensorModel,
    /// Added to the accelerometer at `t` s since power-on, g.
    pub extra: fn(f64) -> [f64; 3],
    /// Whether the diagnosis is told the two files share a power-on (`--same-power-on`).
    pub same_power_on: bool,
    /// The effect it should select.
    pub effect: Option<Effect>,
    /// Whether it should report unexplained structure.
    pub unexplained: bool,
}

/// A bias drifting 30, -25, 35 ug/s since power-on, through both files (g at `t` s).
pub fn drift_since_power_on(t: f64) -> [f64; 3] {
    [30e-6 * t, -25e-6 * t, 35e-6 * t]
}

/// 3 mg at a 5 s period on x (g at `t` s): no candidate has that shape.
pub fn periodic_bias(t: f64) -> [f64; 3] {
    [0.003 * (std::f64::consts::TAU * t / 5.0).sin(), 0.0, 0.0]
}

/// Nothing added.
pub fn no_extra(_: f64) -> [f64; 3] {
    [0.0; 3]
}

/// The short-pose cases: clean, temperature bias (1.5, -1, 2 mg/degC), quadratic scale
/// nonlinearity (10, -8, 12 mg/g^2), a bias drift through both files, a periodic bias.
pub fn short_cases() -> Vec<ShortCase> {
    let warm = || {
        let mut m = base_model();
        m.thermal = varying_temperature();
        m
    };
    let mut temperature = warm();
    temperature.accel.bias_temp_coeff = [1.5e-3, -1.0e-3, 2.0e-3];
    let mut nonlinear = base_model();
    nonlinear.accel.nonlinearity = [0.01, -0.008, 0.012];
    let case = |name, what, model, extra: fn(f64) -> [f64; 3], same_power_on, effect| ShortCase {
        name,
        what,
        model,
        extra,
        same_power_on,
        effect,
        unexplained: false,
    };
    vec![
        case(
            "clean",
            "nothing beyond model 3 (die temperature varying)",
            warm(),
            no_extra,
            true,
            None,
        ),
        case(
            "temperature",
            "bias 1.5, -1, 2 mg/degC",
            temperature,
            no_extra,
            false,
            Some(Effect::TemperatureBias),
        ),
        case(
            "nonlinearity",
            "quadratic scale 10, -8, 12 mg/g^2",
            nonlinear,
            no_extra,
            false,
            Some(Effect::ScaleNonlinearity),
        ),
        case(
            "drift",
            "bias drift 30, -25, 35 ug/s since power-on, through both files",
            base_model(),
            drift_since_power_on,
            true,
            Some(Effect::BiasDrift),
        ),
        ShortCase {
            unexplained: true,
            ..case(
                "periodic",
                "3 mg at a 5 s period on x (no candidate's shape)",
                base_model(),
                periodic_bias,
                true,
                None,
            )
        },
    ]
}

/// A case's two files and the true-model rms of the test file (the held-out data), m/s^2.
pub struct ShortSessions {
    /// The calibration file: the six positions twice, held 2 s each, from power-on.
    pub calib: Vec<RawImuSample>,
    /// The test file: the six positions held 4 s each, 10 s after the calibration file.
    pub test: Vec<RawImuSample>,
    /// The held-out rms a fit with the true model achieves on the test file, m/s^2.
    pub true_rms_mps2: f64,
}

/// Simulates a case's calibration and test file, one after the other in one power-on.
pub fn short_pose_sessions(case: &ShortCase) -> ShortSessions {
    let six = |hold_s: f64, seed: u64| {
        PoseSession::six_position(&PoseParams::new(hold_s), seed)
            .unwrap()
            .poses()
            .to_vec()
    };
    let [calib_hold, test_hold] = SHORT_HOLDS_S;
    let twice = [six(calib_hold, 21), six(calib_hold, 22)].concat();
    let calib_poses = PoseSession::from_poses(twice, &PoseParams::new(calib_hold)).unwrap();
    let t_off = calib_poses.duration_s() + BETWEEN_FILES_S;
    let calib = simulate_poses(calib_poses, &case.model, 21, 0.0, case.extra);
    let test_poses =
        PoseSession::from_poses(six(test_hold, 23), &PoseParams::new(test_hold)).unwrap();
    let test = simulate_poses(test_poses, &case.model, 23, t_off, case.extra);
    ShortSessions {
        true_rms_mps2: true_model_rms(&test.samples, &test.exact, &test.holds),
        calib: calib.samples,
        test: test.samples,
    }
}
