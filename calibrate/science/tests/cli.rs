//! End-to-end tests of `mems-calibrate fit`: on simulated raw sessions (mems-sim, written as
//! canonical CSV) and on the thesis's six-position files (skipped when the data is absent).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use calibrate::calibfile::{CalibrationFile, FitMethod};
use calibrate::model::{AccelModel, ModelKind, N_PARAMS, PARAM_NAMES};
use ipc_types::units::{AccelRange, GyroRange};
use mems_sim::model::{SensorModel, TriadModel};
use mems_sim::scenario::Scenario;
use mems_sim::scenario::{PoseParams, PoseSession};
use mems_sim::vibration::VibrationModel;
use mems_sim::{SimSensor, adc};

const RATE_HZ: f64 = 100.0;

/// A sensor with only the terms the calibration models: bias, scale, misalignment and white
/// noise (300 ug/sqrt(Hz), 3 mg per sample at 100 Hz), at a constant temperature.
fn sensor_model() -> SensorModel {
    let mut m = SensorModel::ideal();
    m.accel = TriadModel {
        bias: [0.09, 0.047, -0.25],
        scale: [0.004, -0.012, 0.022],
        misalignment: [
            [0.0, 0.008, 0.009],
            [-0.006, 0.0, 0.011],
            [-0.010, -0.004, 0.0],
        ],
        noise_density: [300e-6; 3],
        ..TriadModel::ideal()
    };
    m
}

/// Simulates `session` at 100 Hz and writes it as a canonical CSV in a fresh directory.
fn write_session(session: PoseSession, name: &str) -> PathBuf {
    let duration = session.duration_s();
    let mut sim =
        SimSensor::new(session, &sensor_model(), &VibrationModel::moderate(0.0), 7).unwrap();
    let n = (duration * RATE_HZ) as usize;
    let samples: Vec<_> = (0..n)
        .map(|k| {
            let t = k as f64 / RATE_HZ;
            let (analog, _) = sim.sample_with_truth(t, RATE_HZ);
            adc::quantize_sample(
                &analog,
                AccelRange::G2,
                GyroRange::Dps250,
                (t * 1e9).round() as u64,
                k as u64,
            )
        })
        .collect();
    let dir = std::env::temp_dir().join(format!("calibrate-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{name}.csv"));
    recording::csv::write_raw(&path, &samples, None).unwrap();
    path
}

fn fit(input: &Path, extra: &[&str]) -> (Output, PathBuf) {
    let out = input.with_extension("toml");
    let output = Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
        .args(["fit", "--model", "full", "--input"])
        .arg(input)
        .arg("--out")
        .arg(&out)
        .args(extra)
        .output()
        .unwrap();
    (output, out)
}

/// The file is a PNG of a plausible size.
fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(
        &bytes[..8],
        b"\x89PNG\r\n\x1a\n",
        "{} is not a PNG",
        path.display()
    );
    assert!(
        bytes.len() > 10_000,
        "{}: only {} bytes",
        path.display(),
        bytes.len()
    );
}

/// Each parameter within `k` reported sigmas of the truth (parameters with zero sigma must
/// match exactly: they are structural).
fn assert_within(file: &CalibrationFile, truth: &AccelModel, k: f64) {
    let p = file.accel_model().unwrap().params();
    let t = truth.params();
    for j in 0..N_PARAMS {
        let s = file.sigma[j];
        let err = (p[j] - t[j]).abs();
        if s == 0.0 {
            assert!(err < 1e-12, "{}: {} vs {}", PARAM_NAMES[j], p[j], t[j]);
        } else {
            assert!(
                err <= k * s,
                "{}: {} vs truth {} (sigma {s:e})",
                PARAM_NAMES[j],
                p[j],
                t[j]
            );
        }
    }
}

/// A simulated six-position session: auto labels find six axis-aligned static segments and the
/// weighted fit recovers every parameter within 4 sigma; `--labels none` is refused with a
/// message that says why.
#[test]
fn six_position_raw_session_auto_labels_and_label_free_refusal() {
    let session = PoseSession::six_position(&PoseParams::new(20.0), 3).unwrap();
    let csv = write_session(session, "six");
    let png = csv.with_extension("png");
    let plot = [
        "--weighted",
        "--gravity",
        "9.80665",
        "--plot",
        png.to_str().unwrap(),
    ];
    let (output, toml) = fit(&csv, &plot);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_png(&png);
    let file = CalibrationFile::load(&toml).unwrap();
    assert_eq!(file.method, FitMethod::Labelled);
    assert_eq!(file.source.poses, 6);
    assert_eq!(file.source.kind, "canonical_csv");
    assert_within(&file, &common::true_model(&sensor_model().accel), 4.0);

    let (output, _) = fit(&csv, &["--labels", "none", "--force"]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("six.csv")
            && stderr.contains("at least 9")
            && stderr.contains("6 distinct orientations"),
        "{stderr}"
    );
    std::fs::remove_dir_all(csv.parent().unwrap()).unwrap();
}

/// A simulated session in 14 well-spread orientations: auto labels see that the poses are not
/// axis aligned and fit label-free; the result matches the truth's upper-triangular form (the
/// rotation is unobservable from magnitudes) within 4 sigma.
#[test]
fn many_orientations_fit_label_free() {
    let session = PoseSession::orientations(14, &PoseParams::new(15.0), 11).unwrap();
    let csv = write_session(session, "orient");
    let (output, toml) = fit(&csv, &["--weighted"]);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let file = CalibrationFile::load(&toml).unwrap();
    assert_eq!(file.method, FitMethod::LabelFree);
    assert_eq!(file.source.poses, 14);
    let qr = common::true_model(&sensor_model().accel).scale_inv().qr();
    let mut r = qr.r();
    for i in 0..3 {
        if r[(i, i)] < 0.0 {
            r.row_mut(i).neg_mut();
        }
    }
    let upper = AccelModel::new(
        ModelKind::Full,
        r.try_inverse().unwrap(),
        *common::true_model(&sensor_model().accel).bias_g(),
    )
    .unwrap();
    assert_within(&file, &upper, 4.0);
    std::fs::remove_dir_all(csv.parent().unwrap()).unwrap();
}

/// Bad input names the file.
#[test]
fn unreadable_input_names_the_file() {
    let dir = std::env::temp_dir().join(format!("calibrate-cli-{}-bad", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("garbage.csv");
    std::fs::write(&bad, "hello,world\n1,2\n").unwrap();
    let (output, _) = fit(&bad, &[]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("garbage.csv") && stderr.contains("neither a six-position means file"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

fn thesis_six(trial: usize) -> Option<PathBuf> {
    test_support::shared_data(&format!(
        "data/capstone/Six-Position-Test/data/trial_{trial}/six_position_data_{trial}.csv"
    ))
}

/// On the thesis's six-position file: the unweighted fit written by the CLI equals the stored
/// model 3 (1e-6), records the gravity given, and the label-free request is refused.
#[test]
fn thesis_six_position_file() {
    let Some(six) = thesis_six(1) else { return };
    let dir = std::env::temp_dir().join(format!("calibrate-cli-{}-thesis", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("calib.toml");
    let output = Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
        .args(["fit", "--model", "full", "--gravity", "9.797", "--input"])
        .arg(&six)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let file = CalibrationFile::load(&out).unwrap();
    assert_eq!(file.gravity_mps2, 9.797);
    assert_eq!(file.source.kind, "six_position_means");
    let stored =
        recording::thesis::load_optim_params(six.with_file_name("optim_params_1.csv")).unwrap();
    let p = file.accel_model().unwrap().params();
    for i in 0..3 {
        assert!((p[i] - stored.full.bias_g[i]).abs() < 1e-6);
        for j in 0..3 {
            assert!((p[3 + 3 * i + j] - stored.full.s[i][j]).abs() < 1e-6);
        }
    }
    let output = Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
        .args(["fit", "--model", "full", "--labels", "none", "--input"])
        .arg(&six)
        .arg("--out")
        .arg(dir.join("refused.toml"))
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("six_position_data_1.csv") && stderr.contains("at least 9"),
        "{stderr}"
    );
    assert!(!dir.join("refused.toml").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A six-position means file of a part with the thesis's large z bias, without the poses of
/// `drop` (e.g. `["-x"]`), each pose's mean off the model by a few mg.
fn means_file(name: &str, drop: &[&str]) -> PathBuf {
    let truth = common::true_model(&sensor_model().accel);
    let mut text =
        "x_true (g),x_mean (g),x_std,y_true (g),y_mean (g),y_std,z_true (g),z_mean (g),z_std\n"
            .to_string();
    let poses = [("+z", 2, 1.0), ("-z", 2, -1.0), ("+y", 1, 1.0)];
    let poses = poses
        .into_iter()
        .chain([("-y", 1, -1.0), ("+x", 0, 1.0), ("-x", 0, -1.0)]);
    for (k, (label, axis, sign)) in poses.enumerate() {
        if drop.contains(&label) {
            continue;
        }
        let mut t = nalgebra::Vector3::zeros();
        t[axis] = sign;
        let m = truth.measure(&t);
        let cells: Vec<String> = (0..3)
            .map(|i| {
                let off = 0.003 * ((3 * k + i) as f64 * 1.7).sin();
                format!("{},{},0.003", t[i], m[i] + off)
            })
            .collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    let dir = std::env::temp_dir().join(format!("calibrate-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{name}.csv"));
    std::fs::write(&path, text).unwrap();
    path
}

/// A six-position session without its -x pose: `fit` succeeds and warns that the -x pose is
/// missing, that the +x pose alone determines S_xx, S_yx and S_zx, and that each axis' 1-sigma
/// rests on one residual; the complete session warns of nothing.
#[test]
fn a_session_missing_a_pose_warns_what_is_poorly_determined() {
    let five = means_file("five", &["-x"]);
    let (output, _) = fit(&five, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    for expected in [
        "mems-calibrate: warning: ",
        "five.csv: a six-position session without a pose with -x up (5 of the 6 axis directions)",
        "five.csv: S_xx, S_yx, S_zx rest on pose 5 (+x up) alone",
        "five.csv: S_xx, S_xy, S_xz, b_x (x axis) have a 1-sigma scaled by a single residual: \
         one time in 20 it is 16 times too small",
    ] {
        assert!(stderr.contains(expected), "{expected}\n{stderr}");
    }
    let six = means_file("six-means", &[]);
    let (output, _) = fit(&six, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success() && !stderr.contains("warning"),
        "{stderr}"
    );
    for f in [five, six] {
        std::fs::remove_dir_all(f.parent().unwrap()).unwrap();
    }
}
