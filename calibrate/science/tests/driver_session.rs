//! A six-position session at 1 kHz read by the real driver from the simulated register map,
//! through the DLPF the driver selects for that rate (184 Hz gyro / 218.1 Hz accelerometer:
//! successive samples correlate about 0.5), fitted by `mems-calibrate fit` as a user would:
//! the static segments are found, no noise is "repaired" as torn reads, and the weighted fit
//! recovers the simulated part within its stated uncertainty.

mod common;

use std::path::PathBuf;
use std::process::Command;

use acquire::clock::{Clock, SimClock};
use acquire::driver::{Mpu9250, OutputMode};
use acquire::registers as reg;
use acquire::sim::{SimConfig, SimMpu9250};
use calibrate::calibfile::CalibrationFile;
use calibrate::model::{N_PARAMS, PARAM_NAMES};
use ipc_types::RawImuSample;
use mems_sim::SimSensor;
use mems_sim::model::{SensorModel, TriadModel};
use mems_sim::scenario::{PoseParams, PoseSession, Scenario};
use mems_sim::vibration::VibrationModel;

/// A part with only the terms the calibration models (bias, scale, misalignment, the
/// datasheet's 300 ug/sqrt(Hz) white noise before the DLPF), at a constant temperature.
fn sensor_model() -> SensorModel {
    let mut m = SensorModel::ideal();
    m.accel = TriadModel {
        bias: [0.04, -0.035, 0.055],
        scale: [0.015, -0.02, 0.01],
        misalignment: [
            [0.0, 0.01, -0.015],
            [-0.005, 0.0, 0.012],
            [0.008, -0.01, 0.0],
        ],
        noise_density: [300e-6; 3],
        ..TriadModel::ideal()
    };
    m
}

/// The whole session as the driver reads it at `rate_hz` (its own DLPF choice).
fn read_session(rate_hz: u32) -> Vec<RawImuSample> {
    let session = PoseSession::six_position(&PoseParams::new(20.0), 3).unwrap();
    let duration_ns = (session.duration_s() * 1e9) as u64;
    let sensor =
        SimSensor::new(session, &sensor_model(), &VibrationModel::moderate(0.0), 5).unwrap();
    let clock = SimClock::new_virtual(1_000_000_000);
    let start = clock.now_ns();
    let sim = SimMpu9250::new(sensor, clock.clone(), SimConfig::default());
    let mut drv = Mpu9250::new(sim, "sim", reg::ADDRESS_AD0_LOW);
    let config = acquire::acquisition::config_for_rate(rate_hz, None).unwrap();
    assert!(matches!(config.mode, OutputMode::Imu { .. }));
    drv.init(config, &clock).expect("init");
    let mut buf = [RawImuSample::default(); 128];
    let mut out = Vec::new();
    while clock.now_ns() < start + duration_ns {
        clock.sleep_until(clock.now_ns() + 5_000_000);
        let got = drv.read_samples(&clock, &mut buf).expect("read_samples");
        out.extend_from_slice(&buf[..got]);
    }
    out
}

#[test]
fn a_1khz_session_through_the_driver_dlpf_is_fitted_within_its_uncertainty() {
    let samples = read_session(1000);
    let dir = std::env::temp_dir().join(format!("calibrate-driver-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv: PathBuf = dir.join("six-1khz.csv");
    recording::csv::write_raw(&csv, &samples, None).unwrap();
    let toml = dir.join("six-1khz.toml");
    let out = Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
        .args([
            "fit",
            "--model",
            "full",
            "--weighted",
            "--gravity",
            "9.80665",
        ])
        .arg("--input")
        .arg(&csv)
        .arg("--out")
        .arg(&toml)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains(" 0 torn reads repaired") && stderr.contains("6 static segments"),
        "{stderr}"
    );
    let file = CalibrationFile::load(&toml).unwrap();
    let p = file.accel_model().unwrap().params();
    let t = common::true_model(&sensor_model().accel).params();
    for j in 0..N_PARAMS {
        let (s, err) = (file.sigma[j], (p[j] - t[j]).abs());
        if s == 0.0 {
            assert!(err < 1e-12, "{}: {} vs {}", PARAM_NAMES[j], p[j], t[j]);
        } else {
            assert!(
                err <= 4.0 * s,
                "{}: {} vs truth {} (sigma {s:e})",
                PARAM_NAMES[j],
                p[j],
                t[j]
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
