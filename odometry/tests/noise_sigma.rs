//! The odometry's reported position 1-sigma follows the calibration file's `[noise]` table: a
//! calibration file is written with a given accelerometer white noise density, loaded, turned
//! into the stage's configuration by `odometry::config::from_calibration`, and the stage is run
//! over the same samples (1.5 s at rest, then 20 s flagged as motion with no zero-velocity
//! updates). Only the accelerometer's white noise differs between the runs, so the position
//! variance must differ by exactly what velocity random walk integrates to, `(N2^2 - N1^2)
//! T^3 / 3` per axis (T the time since the last zero-velocity update), whatever the other terms
//! (bias prior, tilt, gyro noise) contribute.

use std::path::{Path, PathBuf};

use calibrate::calibfile::CalibrationFile;
use calibrate::noise_params::{AxisNoise, Estimate, NoiseParams, SensorNoise};
use ipc_types::{CorrectedImuSample, OdometryState, Stamps, corrected_flags};
use odometry::config::OdometryConfig;
use odometry::config::from_calibration;
use odometry::stage::OdometryStage;

const G: f64 = 9.797;
const RATE: f64 = 200.0;
const REST_S: f64 = 1.5;
const MOTION_S: f64 = 20.0;

fn estimate(value: f64) -> Option<Estimate> {
    Some(Estimate {
        value,
        sigma: 0.01 * value,
    })
}

/// Noise parameters with accelerometer white noise `accel_n` (m/s^2/sqrt(Hz)) on every axis;
/// the other terms fixed.
fn noise(accel_n: f64) -> NoiseParams {
    let accel = AxisNoise {
        white_noise_density: estimate(accel_n),
        bias_instability: estimate(1e-3),
        random_walk: estimate(5e-5),
        ..Default::default()
    };
    let gyro = AxisNoise {
        white_noise_density: estimate(1.7e-4),
        random_walk: estimate(2e-6),
        ..Default::default()
    };
    NoiseParams {
        source: "static.csv".into(),
        sample_rate_hz: RATE,
        record_length_s: 3600.0,
        samples: 720_000,
        gravity_mps2: G,
        accel: SensorNoise {
            unit: "m/s^2".into(),
            x: accel,
            y: accel,
            z: accel,
        },
        gyro: Some(SensorNoise {
            unit: "rad/s".into(),
            x: gyro,
            y: gyro,
            z: gyro,
        }),
    }
}

/// Writes the identity calibration with `noise` as its `[noise]` table.
fn write_calibration(dir: &Path, name: &str, noise: Option<NoiseParams>) -> PathBuf {
    let mut file = CalibrationFile::identity(G);
    file.noise = noise;
    let path = dir.join(name);
    file.save(&path).unwrap();
    path
}

/// Runs the stage over the rest-then-motion stream; returns the last state and the time from
/// the last zero-velocity update that stands (the last rest flag at least the rest hindsight
/// before the first motion sample; the later ones are withdrawn) to the last sample, s.
fn run(config: OdometryConfig) -> (OdometryState, f64) {
    let mut stage = OdometryStage::new(config);
    let mut last = None;
    let n = ((REST_S + MOTION_S) * RATE) as u64;
    let first_motion_ns = (REST_S * 1e9) as u64;
    let hindsight_ns = (config.rest_hindsight_s * 1e9) as u64;
    let mut last_rest_ns = 0;
    for k in 0..n {
        let t_ns = k * (1e9 / RATE) as u64;
        let rest = (k as f64) < REST_S * RATE;
        if rest && t_ns + hindsight_ns <= first_motion_ns {
            last_rest_ns = t_ns;
        }
        let sample = CorrectedImuSample {
            stamps: Stamps {
                sample_ns: t_ns,
                ..Default::default()
            },
            seq: k,
            accel_mps2: [0.0, 0.0, G],
            // The calibration stage's detector has learned (ready) throughout.
            flags: corrected_flags::DETECTOR_READY
                | if rest { corrected_flags::ZERO_STATE } else { 0 },
            ..Default::default()
        };
        stage.process(&sample, &mut |s| last = Some(*s)).unwrap();
    }
    assert!(stage.aligned());
    let last = last.expect("states emitted");
    let t = (last.stamps.sample_ns - last_rest_ns) as f64 * 1e-9;
    (last, t)
}

#[test]
fn position_sigma_follows_the_white_noise_density_in_the_calibration_file() {
    let dir = std::env::temp_dir().join(format!("noise-sigma-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (n1, n2) = (2e-3, 8e-3);
    let load = |name: &str, noise: Option<NoiseParams>| {
        let path = write_calibration(&dir, name, noise);
        from_calibration(&CalibrationFile::load(&path).unwrap())
    };
    let quiet = load("quiet.toml", Some(noise(n1)));
    let noisy = load("noisy.toml", Some(noise(n2)));
    assert_eq!(quiet.config.noise.accel_noise_density, n1);
    assert!(quiet.defaulted.is_empty(), "{:?}", quiet.defaulted);
    let (s1, t) = run(quiet.config);
    let (s2, t2) = run(noisy.config);
    assert_eq!(t, t2);
    let hindsight = quiet.config.rest_hindsight_s;
    assert!((t - MOTION_S - hindsight).abs() < 0.1, "{t}");
    // Velocity random walk of density N integrated to position over T: N^2 T^3 / 3.
    let expected = (n2 * n2 - n1 * n1) * t.powi(3) / 3.0;
    for axis in 0..3 {
        let (a, b) = (s1.position_sigma_m[axis], s2.position_sigma_m[axis]);
        let got = b * b - a * a;
        assert!(
            (got / expected - 1.0).abs() < 0.01,
            "axis {axis}: sigma {a} -> {b} m, variance change {got} m^2, expected {expected} m^2"
        );
    }

    // Without a [noise] table the stage runs with the MPU-9250 defaults, and says which.
    let bare = load("bare.toml", None);
    assert_eq!(bare.config, OdometryConfig::mpu9250(G));
    assert!(
        bare.defaults_note()
            .unwrap()
            .contains("accel.white_noise_density")
    );
    let (s0, _) = run(bare.config);
    let (d0, _) = run(OdometryConfig::mpu9250(G));
    assert_eq!(s0.position_sigma_m, d0.position_sigma_m);
    std::fs::remove_dir_all(&dir).unwrap();
}
