//! Throughput of the residual diagnosis on 1 M samples (the budget: at most 1 s).
//! Run with `cargo bench -p calibrate --bench diagnose`; plain timing (no harness): each
//! figure is the median of 5 runs of `diagnose` on a session already in memory.

use std::hint::black_box;
use std::time::{Duration, Instant};

use calibrate_science::diagnose::{DiagnoseConfig, SessionInput, diagnose};
use ipc_types::RawImuSample;
use ipc_types::units::{AccelRange, GyroRange, STANDARD_GRAVITY_MPS2};
use mems_sim::model::{SensorModel, ThermalModel, TriadModel};
use mems_sim::scenario::{PoseParams, PoseSession, Scenario};
use mems_sim::vibration::VibrationModel;
use mems_sim::{SimSensor, adc};
use nalgebra::UnitQuaternion;

const RATE_HZ: f64 = 1000.0;

/// Bias, scale, misalignment, noise and a temperature bias, with a die temperature that
/// varies (self-heating and a falling room temperature).
fn model() -> SensorModel {
    let mut m = SensorModel::ideal();
    m.accel = TriadModel {
        bias: [0.04, -0.035, 0.055],
        scale: [0.015, -0.02, 0.01],
        noise_density: [300e-6; 3],
        bias_temp_coeff: [1e-3, -0.8e-3, 1.2e-3],
        ..TriadModel::ideal()
    };
    m.thermal = ThermalModel {
        ambient_c: 25.0,
        ambient_drift_c_per_s: -0.004,
        self_heating_c: 6.0,
        self_heating_time_constant_s: 300.0,
        reference_c: 25.0,
    };
    m
}

fn samples(session: PoseSession, model: &SensorModel) -> Vec<RawImuSample> {
    let n = (session.duration_s() * RATE_HZ) as usize;
    let mut sim = SimSensor::new(session, model, &VibrationModel::moderate(0.0), 1).unwrap();
    (0..n)
        .map(|k| {
            let t = k as f64 / RATE_HZ;
            let (a, _) = sim.sample_with_truth(t, RATE_HZ);
            adc::quantize_sample(
                &a,
                AccelRange::G2,
                GyroRange::Dps250,
                (t * 1e9).round() as u64,
                k as u64,
            )
        })
        .collect()
}

fn median_time(runs: usize, mut f: impl FnMut()) -> Duration {
    let mut t: Vec<Duration> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed()
        })
        .collect();
    t.sort();
    t[runs / 2]
}

fn bench(name: &str, samples: Vec<RawImuSample>) {
    let n = samples.len();
    let input = [SessionInput::Raw {
        name: name.into(),
        samples,
    }];
    let cfg = DiagnoseConfig {
        gravity_mps2: STANDARD_GRAVITY_MPS2,
        ..DiagnoseConfig::default()
    };
    let mut selected = None;
    let t = median_time(5, || {
        let d = diagnose(black_box(&input), &[], &cfg).unwrap();
        selected = d.selected;
    });
    let secs = t.as_secs_f64();
    println!(
        "diagnose, {name}: {n} samples in {:.3} s ({:.2} M samples/s; selected {}) {}",
        secs,
        n as f64 / secs / 1e6,
        selected.map_or("none", |e| e.name()),
        if secs * 1e6 / n as f64 <= 1.0 {
            "within the 1 s per 1 M samples budget"
        } else {
            "OVER the 1 s per 1 M samples budget"
        }
    );
}

fn main() {
    // Six positions held 163 s each with 4 s rotations: 1 M samples at 1 kHz.
    let six = PoseSession::six_position(&PoseParams::new(163.3), 1).unwrap();
    bench("six-position, model 3", samples(six, &model()));
    let still = || {
        PoseSession::static_pose(UnitQuaternion::identity(), 1000.0, STANDARD_GRAVITY_MPS2).unwrap()
    };
    bench("static, session mean", samples(still(), &model()));
    let many = PoseSession::orientations(24, &PoseParams::new(38.0), 2).unwrap();
    bench("24 orientations, label-free", samples(many, &model()));
    // The thesis's acquisition: less noise (52 counts), y 16 counts below a byte boundary, and
    // 10% of y reads torn (high byte from the next conversion).
    let mut quiet = model();
    quiet.accel.noise_density = [100e-6; 3];
    quiet.accel.bias[1] = 1008.0 / 16384.0;
    let mut torn = samples(still(), &quiet);
    for k in (0..torn.len() - 1).step_by(10) {
        let a = i32::from(torn[k].accel_counts[1]);
        let b = i32::from(torn[k + 1].accel_counts[1]);
        let v = (b >> 8) * 256 + (a & 0xff);
        torn[k].accel_counts[1] = v as i16;
        torn[k].accel_g[1] = f64::from(v) / 16384.0;
    }
    bench("static with torn reads, session mean", torn);
}
