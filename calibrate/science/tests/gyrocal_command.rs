//! `mems-calibrate gyrocal` (`mems-calibrate-offline gyrocal`, which `mems-odometry gyrocal`
//! also runs) as a process on simulated pose sessions (raw samples written to MCAP
//! and CSV and read back): the correction it fits against the simulator's own gyro model, the
//! calibration file it writes and what `odometry::config::from_calibration` then makes of it,
//! and its refusals.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use calibrate::calibfile::CalibrationFile;
use ipc_types::RawImuSample;
use ipc_types::units::{AccelRange, GyroRange};
use mems_sim::SimSensor;
use mems_sim::adc::quantize_sample;
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::scenario::{PoseParams, PoseSession, Scenario, ns_from_s};
use mems_sim::vibration::VibrationModel;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use odometry::config::from_calibration;

/// Output rate of the simulated sessions, Hz.
const RATE_HZ: f64 = 100.0;
/// How long each pose is held, s (the first hold is also the detector's 5 s of learning).
const HOLD_S: f64 = 10.0;

/// An identity accelerometer calibration at standard gravity: the simulated sensor
/// (`SensorModel::mpu9250_calibrated`) is already what a calibration leaves.
fn identity_calibration() -> CalibrationFile {
    CalibrationFile::identity(G_MPS2)
}

/// The gyro correction a perfect calibration would give, as an independent reference for
/// `calibrate_gyro`: the inverse of the simulated gyro's scale and misalignment
/// `(I + diag(s) + M)^-1`, turned into the orthonormal frame closest to the accelerometer's axes
/// (the rotation part `I + (M_a - M_a^T) / 2` of the accelerometer's residual misalignment).
fn gyro_correction_reference() -> Matrix3<f64> {
    let m = SensorModel::mpu9250_calibrated();
    let gyro = Matrix3::identity()
        + Matrix3::from_fn(|i, k| m.gyro.misalignment[i][k])
        + Matrix3::from_diagonal(&Vector3::from(m.gyro.scale));
    let ma = Matrix3::from_fn(|i, k| m.accel.misalignment[i][k]);
    (Matrix3::identity() + 0.5 * (ma - ma.transpose()))
        * gyro.try_inverse().expect("an invertible gyro model")
}

/// A scratch directory for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("gyrocal-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The quantized raw samples (as the acquisition publishes them) of `session` on a powered-on
/// MPU-9250 after accelerometer calibration (`SensorModel::mpu9250_calibrated`, the model
/// [`gyro_correction_reference`] inverts).
fn raw_session(session: PoseSession, seed: u64) -> Vec<RawImuSample> {
    let duration = session.duration_s();
    let mut sim = SimSensor::new(
        session,
        &SensorModel::mpu9250_calibrated(),
        &VibrationModel::moderate(0.0),
        seed,
    )
    .unwrap();
    (0..(duration * RATE_HZ) as u64)
        .map(|k| {
            let t = k as f64 / RATE_HZ;
            let (analog, _) = sim.sample_with_truth(t, RATE_HZ);
            quantize_sample(&analog, AccelRange::G2, GyroRange::Dps250, ns_from_s(t), k)
        })
        .collect()
}

/// `n` well-spread orientations held [`HOLD_S`] each.
fn orientations(n: usize, seed: u64) -> Vec<RawImuSample> {
    raw_session(
        PoseSession::orientations(n, &PoseParams::new(HOLD_S), seed).unwrap(),
        seed,
    )
}

fn write_mcap(path: &Path, samples: &[RawImuSample]) {
    let mut w = recording::mcap::Writer::create(path).unwrap();
    let raw = w.add_channel::<RawImuSample>().unwrap();
    for s in samples {
        w.write(raw, s, s.stamps.sample_ns).unwrap();
    }
    w.finish().unwrap();
}

fn gyrocal(args: &[&Path]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
        .arg("gyrocal")
        .args(args)
        .output()
        .unwrap()
}

/// Runs `mems-calibrate gyrocal` with `args` (paths and flags) and returns its stderr, failing
/// unless it fails.
fn refused(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
        .arg("gyrocal")
        .args(args)
        .output()
        .unwrap();
    assert!(!out.status.success(), "{args:?} succeeded");
    String::from_utf8(out.stderr).unwrap()
}

/// A JSON array of three rows of three numbers as a matrix.
fn matrix(v: &serde_json::Value) -> Matrix3<f64> {
    Matrix3::from_fn(|r, k| v[r][k].as_f64().unwrap())
}

#[test]
fn the_fitted_correction_matches_the_simulated_gyro_and_reaches_the_odometry_config() {
    let dir = scratch("fit");
    let session = dir.join("session.mcap");
    write_mcap(&session, &orientations(12, 5));
    let calib = dir.join("calib.toml");
    let mut original = identity_calibration();
    // Something else in the file, to see it kept.
    original.temperature_range_c = Some([24.5, 27.0]);
    original.save(&calib).unwrap();

    // Without a correction the odometry runs an uncalibrated gyro, and says so.
    let before = from_calibration(&CalibrationFile::load(&calib).unwrap());
    assert_eq!(before.config.gyro_correction, Matrix3::identity());
    assert!(before.gyro_uncalibrated);
    assert!(
        before
            .defaults_note()
            .unwrap()
            .contains("no gyro.correction")
    );

    let out = gyrocal(&[
        Path::new("--input"),
        &session,
        Path::new("--calib"),
        &calib,
        Path::new("--into"),
        &calib,
        Path::new("--json"),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let c = matrix(&json["correction"]);
    let sigma = matrix(&json["correction_sigma"]);
    // 12 orientations, the detector may split a pose where a window looks like motion.
    assert!(json["poses"].as_u64().unwrap() >= 12, "{json}");

    // Against the simulator's model inverted (the gyro is 1% off in scale, 0.5% misaligned).
    let reference = gyro_correction_reference();
    for r in 0..3 {
        for k in 0..3 {
            let err = c[(r, k)] - reference[(r, k)];
            let s = sigma[(r, k)];
            assert!(
                err.abs() < 4.0 * s && s < 1e-3,
                "C[{r}][{k}]: error {err:.2e}, sigma {s:.2e}"
            );
        }
    }

    // Stored in [gyro], the rest of the file as it was.
    let stored = CalibrationFile::load(&calib).unwrap();
    let rows = |m: &Matrix3<f64>| -> [[f64; 3]; 3] {
        std::array::from_fn(|r| std::array::from_fn(|k| m[(r, k)]))
    };
    assert_eq!(stored.gyro.correction, Some(rows(&c)));
    assert_eq!(stored.gyro.correction_sigma, Some(rows(&sigma)));
    let mut rest = stored.clone();
    rest.gyro.correction = None;
    rest.gyro.correction_sigma = None;
    assert_eq!(rest, original);
    assert!(stderr.contains("wrote the gyro correction"), "{stderr}");

    // serve and offline take it from there.
    let after = from_calibration(&stored);
    assert_eq!(after.config.gyro_correction, c);
    assert!(!after.gyro_uncalibrated);
    let note = after.defaults_note().unwrap_or_default();
    assert!(!note.contains("gyro.correction"), "{note}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn poor_sessions_and_bad_files_are_refused_naming_the_problem() {
    let dir = scratch("refused");
    let calib = dir.join("calib.toml");
    identity_calibration().save(&calib).unwrap();
    let calib_s = calib.to_str().unwrap();
    let path = |name: &str| dir.join(name).to_str().unwrap().to_string();

    // Five orientations: too few poses for 18 parameters.
    let five = path("five.csv");
    recording::csv::write_raw(&five, &orientations(5, 2), None).unwrap();
    let err = refused(&["--input", &five, "--calib", calib_s]);
    assert!(
        err.contains("five.csv") && err.contains("the gyro fit needs at least 9"),
        "{err}"
    );

    // Ten poses turned about the sensor's x axis only: nothing shows the gyro's response
    // about y or z.
    let one_axis = path("one-axis.csv");
    let attitudes = (0..10)
        .map(|k| UnitQuaternion::from_scaled_axis(Vector3::x() * (0.6 * k as f64)))
        .collect();
    let session = PoseSession::from_poses(attitudes, &PoseParams::new(HOLD_S)).unwrap();
    recording::csv::write_raw(&one_axis, &raw_session(session, 3), None).unwrap();
    let err = refused(&["--input", &one_axis, "--calib", calib_s]);
    assert!(
        err.contains("one-axis.csv") && err.contains("rotate about more varied axes"),
        "{err}"
    );

    // Unreadable files, named.
    let err = refused(&["--input", &path("absent.mcap"), "--calib", calib_s]);
    assert!(err.contains("absent.mcap"), "{err}");
    let err = refused(&["--input", &five, "--calib", &path("absent.toml")]);
    assert!(
        err.contains("cannot load calibration") && err.contains("absent.toml"),
        "{err}"
    );

    // A file with another accelerometer calibration is left alone.
    let other = path("other.toml");
    CalibrationFile::identity(9.80)
        .save(Path::new(&other))
        .unwrap();
    let text = std::fs::read_to_string(&other).unwrap();
    let err = refused(&["--input", &five, "--calib", calib_s, "--into", &other]);
    assert!(
        err.contains("other.toml") && err.contains("holds a different calibration"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&other).unwrap(), text);
    std::fs::remove_dir_all(&dir).unwrap();
}
