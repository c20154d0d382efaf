//! `mems-calibrate allan` as a real process: the Allan analysis of a simulated static recording
//! with known white noise, stored with `--into` as a calibration file's `[noise]` table, and
//! the calibration file's handling of that table (validation naming the field, legacy tables).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use calibrate::calibfile::{CalibFileError, CalibrationFile};
use calibrate::model::{AccelModel, ModelKind, ParamCovariance};
use calibrate::zero_state::{DetectorConfig, DetectorKind, NoiseFloor};
use nalgebra::{Matrix3, Vector3};
use noise::synth::white_static_samples;

/// Local gravity of the calibration file (the thesis's), m/s^2.
const GRAVITY: f64 = 9.797;
/// White noise density of each simulated accelerometer axis, m/s^2/sqrt(Hz).
const ACCEL_N: f64 = 1.2e-3;
/// The same for the gyro, rad/s/sqrt(Hz).
const GYRO_N: f64 = 2e-4;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("allan-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// 30 000 samples at 200 Hz of white noise on both sensors, written as a canonical CSV.
fn write_static(dir: &Path) -> PathBuf {
    let samples = white_static_samples(ACCEL_N, GYRO_N, 30_000, 0.005, GRAVITY, 11);
    let path = dir.join("static.csv");
    recording::csv::write_raw(&path, &samples, None).unwrap();
    path
}

/// A model-3 calibration file without noise parameters.
fn write_calibration(dir: &Path) -> (PathBuf, CalibrationFile) {
    let s = Matrix3::new(
        1.002, 0.008, 0.009, -0.006, 1.0004, 0.0106, -0.0102, -0.0044, 1.02,
    );
    let model = AccelModel::new(ModelKind::Full, s, Vector3::new(0.09, 0.047, -0.25)).unwrap();
    let mut file = CalibrationFile::identity(GRAVITY);
    file.set_accel_model(&model, &(ParamCovariance::identity() * 1e-8));
    let path = dir.join("calib.toml");
    file.save(&path).unwrap();
    (path, file)
}

fn mems_calibrate(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
        .args(args)
        .output()
        .expect("mems-calibrate runs")
}

#[test]
fn allan_into_stores_the_fitted_parameters_in_the_noise_table() {
    let dir = scratch("into");
    let input = write_static(&dir);
    let (calib, original) = write_calibration(&dir);
    let kalibr = dir.join("imu.yaml");
    let out = mems_calibrate(&[
        "allan",
        "--input",
        input.to_str().unwrap(),
        "--json",
        "--into",
        calib.to_str().unwrap(),
        "--kalibr",
        kalibr.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let stored = CalibrationFile::load(&calib).unwrap();
    let noise = stored.noise.clone().expect("a [noise] table");
    // The table is the report's parameters, converted with the file's gravity.
    let from_report: noise::NoiseParams = serde_json::from_value(report["params"].clone()).unwrap();
    assert_eq!(noise, from_report);
    assert_eq!(noise.gravity_mps2, GRAVITY);
    assert_eq!(noise.source, input.display().to_string());
    assert!((noise.sample_rate_hz - 200.0).abs() < 1e-6, "{noise:?}");
    // The white noise the record was made with, within 4 sigma on every axis of both sensors
    // (quantisation adds (LSB^2/12) / rate in quadrature: 0.4% of the accelerometer's).
    let gyro = noise.gyro.as_ref().expect("the recording has the gyro");
    for (sensor, truth) in [(&noise.accel, ACCEL_N), (gyro, GYRO_N)] {
        for axis in sensor.axes() {
            let n = axis.white_noise_density.expect("white noise resolved");
            assert!(
                (n.value - truth).abs() < 4.0 * n.sigma + 0.01 * truth,
                "{} {n:?} vs {truth}",
                sensor.unit
            );
        }
    }
    // The calibration stage hands the table to its zero-state detector as the noise floor.
    let stage = calibrate::stage::CalibrationStage::new(
        &stored,
        DetectorConfig::new(DetectorKind::Glrt, GRAVITY),
        calibrate::stage::RefineConfig::default(),
    )
    .unwrap();
    let floor = stage.detector().config().noise.expect("a noise floor");
    assert_eq!(floor, NoiseFloor::from_params(&noise, GRAVITY));
    let n = noise.accel.x.white_noise_density.unwrap().value;
    assert!((floor.accel_sigma_mps2[0].unwrap() - n * 200f64.sqrt()).abs() < 1e-12);
    // Nothing else in the file changed.
    let mut without = stored.clone();
    without.noise = None;
    assert_eq!(without, original);
    assert!(
        std::fs::read_to_string(&kalibr)
            .unwrap()
            .contains("accelerometer_noise_density")
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn allan_into_refuses_a_different_gravity_and_a_bad_file() {
    let dir = scratch("refuse");
    let input = write_static(&dir);
    let (calib, _) = write_calibration(&dir);
    let out = mems_calibrate(&[
        "allan",
        "--input",
        input.to_str().unwrap(),
        "--gravity",
        "9.81",
        "--into",
        calib.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--gravity 9.81") && err.contains("calib.toml"),
        "{err}"
    );
    assert!(CalibrationFile::load(&calib).unwrap().noise.is_none());

    let missing = dir.join("missing.toml");
    let out = mems_calibrate(&[
        "allan",
        "--input",
        input.to_str().unwrap(),
        "--into",
        missing.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("missing.toml"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn noise_table_is_validated_and_legacy_tables_read_as_absent() {
    let dir = scratch("table");
    let (calib, file) = write_calibration(&dir);
    let text = file.to_toml();
    assert!(
        !text.contains("[noise"),
        "no table without parameters:\n{text}"
    );

    // A table from before the Allan analysis: no parameters.
    std::fs::write(
        &calib,
        format!("{text}\n[noise]\nwhite_sigma_g = [1e-3, 1e-3, 2e-3]\nsample_rate_hz = 180.0\n"),
    )
    .unwrap();
    assert_eq!(CalibrationFile::load(&calib).unwrap().noise, None);

    // A negative sigma is named by its field.
    let table = "[noise]\nsource = \"s.csv\"\nsample_rate_hz = 200.0\nrecord_length_s = 60.0\n\
                 samples = 12000\ngravity_mps2 = 9.797\n[noise.accel]\nunit = \"m/s^2\"\n\
                 [noise.accel.x.white_noise_density]\nvalue = 1e-3\nsigma = -1e-5\n\
                 [noise.accel.y]\n[noise.accel.z]\n";
    std::fs::write(&calib, format!("{text}\n{table}")).unwrap();
    let err = CalibrationFile::load(&calib).unwrap_err();
    assert!(matches!(err, CalibFileError::Invalid { .. }), "{err}");
    let err = err.to_string();
    assert!(
        err.contains("calib.toml") && err.contains("noise.accel.x.white_noise_density.sigma"),
        "{err}"
    );

    // An incomplete table is a parse error naming the table.
    std::fs::write(&calib, format!("{text}\n[noise]\nsource = \"s.csv\"\n")).unwrap();
    let err = CalibrationFile::load(&calib).unwrap_err().to_string();
    assert!(
        err.contains("calib.toml") && err.contains("[noise]"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
