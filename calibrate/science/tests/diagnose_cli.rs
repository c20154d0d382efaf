//! End-to-end tests of `mems-calibrate diagnose`: a simulated session written as canonical CSV
//! (JSON summary, plots, the calibration file it writes and the live stage applying it), short
//! poses, calibration and test files of one power-on (`--same-power-on`), bad input, and the
//! thesis's recordings (skipped when the data are absent).

mod sim_sessions;

use mems_stage::Stage;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig, Settler};
use calibrate::zero_state::{DetectorConfig, DetectorKind};
use ipc_types::RawImuSample;
use ipc_types::units::{AccelRange, GyroRange};
use mems_sim::model::{SensorModel, ThermalModel, TriadModel};
use mems_sim::scenario::{PoseParams, PoseSession, Scenario};
use mems_sim::vibration::VibrationModel;
use mems_sim::{SimSensor, adc};
use recording::Truth;

const RATE_HZ: f64 = 200.0;

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("diagnose-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn diagnose(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
        .arg("diagnose")
        .args(args)
        .output()
        .unwrap()
}

/// The file is a PNG of a plausible size.
fn assert_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
    assert!(
        bytes.len() > 10_000,
        "{}: {} bytes",
        path.display(),
        bytes.len()
    );
}

/// A six-position session whose bias follows the die temperature (1.5, -1, 2 mg/degC) while
/// the die warms by self-heating and the room cools.
fn temperature_session() -> (Vec<RawImuSample>, Vec<Truth>, Vec<(f64, f64)>) {
    temperature_poses(PoseSession::six_position(&PoseParams::new(20.0), 11).unwrap())
}

/// `session` measured by a part whose bias follows the die temperature (see
/// [`temperature_session`]).
fn temperature_poses(session: PoseSession) -> (Vec<RawImuSample>, Vec<Truth>, Vec<(f64, f64)>) {
    let mut model = SensorModel::ideal();
    model.accel = TriadModel {
        bias: [0.04, -0.035, 0.055],
        scale: [0.015, -0.02, 0.01],
        noise_density: [300e-6; 3],
        bias_temp_coeff: [1.5e-3, -1.0e-3, 2.0e-3],
        ..TriadModel::ideal()
    };
    model.thermal = ThermalModel {
        ambient_c: 25.0,
        ambient_drift_c_per_s: -0.04,
        self_heating_c: 8.0,
        self_heating_time_constant_s: 40.0,
        reference_c: 25.0,
    };
    let holds = (0..session.poses().len())
        .map(|i| session.hold_interval_s(i))
        .collect();
    let n = (session.duration_s() * RATE_HZ) as usize;
    let mut sim = SimSensor::new(session, &model, &VibrationModel::moderate(0.0), 11).unwrap();
    let (samples, truth) = (0..n)
        .map(|k| {
            let t = k as f64 / RATE_HZ;
            let (a, truth) = sim.sample_with_truth(t, RATE_HZ);
            let s =
                adc::quantize_sample(&a, AccelRange::G2, GyroRange::Dps250, truth.t_ns, k as u64);
            (s, truth)
        })
        .unzip();
    (samples, truth, holds)
}

/// Rms over the holds, split in thirds, of the stage's mean output minus the true specific
/// force, m/s^2 (the bias refinement at rest is held off so that only the file acts).
fn stage_error(
    file: &CalibrationFile,
    samples: &[RawImuSample],
    truth: &[Truth],
    holds: &[(f64, f64)],
) -> f64 {
    let refine = RefineConfig {
        accel_prior_s: 1e12,
        ..RefineConfig::default()
    };
    let mut stage = CalibrationStage::new(
        file,
        DetectorConfig::new(DetectorKind::Yu, file.gravity_mps2),
        refine,
    )
    .unwrap();
    let mut out = Vec::new();
    let mut settler = Settler::default();
    for s in samples {
        stage
            .process(s, &mut |c| settler.push(c, &mut |c| out.push(*c)))
            .unwrap();
    }
    stage.finish(&mut |_| {});
    settler.finish(&mut |c| out.push(*c));
    let mut ss = 0.0;
    let mut count = 0;
    for &(t0, t1) in holds {
        for part in 0..3 {
            let a = t0 + 1.0 + (t1 - t0 - 2.0) * part as f64 / 3.0;
            let b = a + (t1 - t0 - 2.0) / 3.0;
            let (k0, k1) = ((a * RATE_HZ) as usize, (b * RATE_HZ) as usize);
            for i in 0..3 {
                let d = (k0..k1)
                    .map(|k| out[k].accel_mps2[i] - truth[k].specific_force_mps2[i])
                    .sum::<f64>()
                    / (k1 - k0) as f64;
                ss += d * d;
                count += 1;
            }
        }
    }
    (ss / count as f64).sqrt()
}

#[test]
fn simulated_session_json_plots_and_a_calibration_file_the_stage_applies() {
    let (samples, truth, holds) = temperature_session();
    let d = dir("temperature");
    let csv = d.join("session.csv");
    recording::csv::write_raw(&csv, &samples, Some(&truth)).unwrap();
    let plots = d.join("plots");
    let out = d.join("calib.toml");
    let o = diagnose(&[
        "--input",
        csv.to_str().unwrap(),
        "--gravity",
        "9.80665",
        "--json",
        "--plot-dir",
        plots.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // Exactly the specified keys.
    let keys = |v: &serde_json::Value| -> Vec<String> {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.sort();
        k
    };
    assert_eq!(
        keys(&json),
        [
            "baseline",
            "candidates",
            "final",
            "noise_floor_mps2",
            "selected_effect",
            "unexplained_structure"
        ]
    );
    assert_eq!(keys(&json["baseline"]), ["model", "rms_mps2"]);
    assert_eq!(keys(&json["final"]), ["model", "rms_mps2"]);
    let candidates = json["candidates"].as_array().unwrap();
    assert!(candidates.len() >= 5);
    for c in candidates {
        assert_eq!(keys(c), ["effect", "rms_mps2", "score"]);
    }
    assert_eq!(json["selected_effect"], "temperature_bias");
    assert_eq!(json["baseline"]["model"], "full");
    assert_eq!(json["final"]["model"], "full+temperature_bias");
    let base = json["baseline"]["rms_mps2"].as_f64().unwrap();
    let fin = json["final"]["rms_mps2"].as_f64().unwrap();
    let floor = json["noise_floor_mps2"].as_f64().unwrap();
    assert!(fin < 0.5 * base && fin < 1.2 * floor, "{json}");
    assert_eq!(json["unexplained_structure"], false);
    for f in [
        "residuals_vs_time.png",
        "residuals_vs_temperature.png",
        "residuals_vs_specific_force.png",
        "residuals_vs_orientation.png",
        "histogram_standardized.png",
        "histogram_samples.png",
    ] {
        assert_png(&plots.join(f));
    }
    // The file carries the temperature term; the live stage applying it removes the
    // temperature-dependent error that the same file without it leaves.
    let file = CalibrationFile::load(&out).unwrap();
    let c = file
        .temperature
        .bias_g_per_c
        .expect("temperature term written");
    for (got, want) in c.iter().zip([1.5e-3, -1.0e-3, 2.0e-3]) {
        assert!((got - want).abs() < 1e-4, "{c:?}");
    }
    let mut plain = file.clone();
    plain.temperature = Default::default();
    let with_terms = stage_error(&file, &samples, &truth, &holds);
    let without = stage_error(&plain, &samples, &truth, &holds);
    assert!(
        with_terms < 0.2 * without && with_terms < 2e-3,
        "stage error {with_terms} m/s^2 with the term, {without} without"
    );
    std::fs::remove_dir_all(&d).unwrap();
}

/// A multi-position protocol's short poses (imu_tk, Tedaldi et al.: 1-4 s each): 20
/// orientations held 2 s. The default shortest segment takes them and finds the temperature
/// effect; a minimum longer than the poses is refused with the figure and the flag.
#[test]
fn short_poses_are_diagnosed_by_default() {
    let session = PoseSession::orientations(20, &PoseParams::new(2.0), 12).unwrap();
    let (samples, truth, _) = temperature_poses(session);
    let d = dir("short-poses");
    let csv = d.join("session.csv");
    recording::csv::write_raw(&csv, &samples, Some(&truth)).unwrap();
    let o = diagnose(&["--input", csv.to_str().unwrap(), "--min-segment-s", "5"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("at least 5 s") && err.contains("--min-segment-s"),
        "{err}"
    );
    let o = diagnose(&["--input", csv.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(json["selected_effect"], "temperature_bias", "{json}");
    std::fs::remove_dir_all(&d).unwrap();
}

/// The short-pose cases as files (calibration, then test, of one power-on; poses held 2 and
/// 4 s): each is diagnosed as it should be, with `--same-power-on` where the case says; the
/// drift through both files needs it (without, it stays unexplained); files given out of time
/// order are refused under it.
#[test]
fn short_pose_cases_as_files_with_and_without_same_power_on() {
    let d = dir("short-cases");
    let run = |calib: &Path, test: &Path, same_power_on: bool| {
        let mut args = vec![
            "--input",
            calib.to_str().unwrap(),
            "--test",
            test.to_str().unwrap(),
            "--json",
        ];
        if same_power_on {
            args.push("--same-power-on");
        }
        diagnose(&args)
    };
    let json = |o: &Output| -> serde_json::Value {
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    for case in sim_sessions::short_cases() {
        let s = sim_sessions::short_pose_sessions(&case);
        let (calib, test) = (d.join("calib.csv"), d.join("test.csv"));
        recording::csv::write_raw(&calib, &s.calib, None).unwrap();
        recording::csv::write_raw(&test, &s.test, None).unwrap();
        let j = json(&run(&calib, &test, case.same_power_on));
        let want = case.effect.map_or("none", |e| e.name());
        assert_eq!(
            j["selected_effect"], want,
            "{} ({}): {j}",
            case.name, case.what
        );
        assert_eq!(
            j["unexplained_structure"], case.unexplained,
            "{}: {j}",
            case.name
        );
        if !case.unexplained {
            let fin = j["final"]["rms_mps2"].as_f64().unwrap();
            assert!(fin <= 2.0 * s.true_rms_mps2, "{}: {j}", case.name);
        }
        if case.name != "drift" {
            continue;
        }
        let j = json(&run(&calib, &test, false));
        assert_eq!(j["selected_effect"], "none", "{j}");
        assert_eq!(j["unexplained_structure"], true, "{j}");
        let o = run(&test, &calib, true);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains("calib.csv") && err.contains("--same-power-on"),
            "{err}"
        );
    }
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn bad_input_is_refused_with_a_clear_message() {
    let o = diagnose(&["--input", "/nonexistent/recording.csv"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("/nonexistent/recording.csv"), "{err}");
    // A static recording has no labels: reference_tilt cannot be applied.
    let (samples, truth, _) = temperature_session();
    let d = dir("bad");
    let csv = d.join("static.csv");
    let still: Vec<RawImuSample> = samples[..(15.0 * RATE_HZ) as usize].to_vec();
    recording::csv::write_raw(&csv, &still, Some(&truth[..still.len()])).unwrap();
    let o = diagnose(&[
        "--input",
        csv.to_str().unwrap(),
        "--apply",
        "reference_tilt",
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("reference_tilt") && err.contains("labels"),
        "{err}"
    );
    let o = diagnose(&["--input", csv.to_str().unwrap(), "--out", "x.toml"]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--base"), "{err}");
    std::fs::remove_dir_all(&d).unwrap();
}

fn capstone() -> Option<PathBuf> {
    test_support::shared_data("data/capstone")
}

fn json_of(args: &[&str]) -> serde_json::Value {
    let mut all = args.to_vec();
    all.extend(["--gravity", "9.797", "--json"]);
    let o = diagnose(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// The findings of docs/diagnosis.md: the histogram wings are torn reads; the six-position
/// labels are off (reference tilt) when the calibration meets new placements.
#[test]
fn thesis_recordings_torn_reads_and_reference_tilt() {
    let Some(d) = capstone() else { return };
    let trial = d.join("Six-Position-Test/data/trial_1");
    let static_1 = trial.join("six_position_test_data_1.csv");
    let six_1 = trial.join("six_position_data_1.csv");
    let j = json_of(&["--input", static_1.to_str().unwrap()]);
    assert_eq!(j["selected_effect"], "torn_reads", "{j}");
    assert!(
        j["final"]["rms_mps2"].as_f64().unwrap()
            < 0.75 * j["baseline"]["rms_mps2"].as_f64().unwrap()
    );
    let out = dir("thesis").join("six_1.toml");
    let j = json_of(&[
        "--input",
        six_1.to_str().unwrap(),
        "--test",
        static_1.to_str().unwrap(),
        "--apply",
        "torn_reads",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(j["selected_effect"], "reference_tilt", "{j}");
    // The tilt is the set-up's, not the sensor's: the file holds model 3 fitted without it,
    // which on six equally weighted poses is the thesis's own fit.
    let file = CalibrationFile::load(&out).unwrap();
    let thesis = recording::thesis::load_optim_params(trial.join("optim_params_1.csv")).unwrap();
    for r in 0..3 {
        assert!((file.bias_g[r] - thesis.full.bias_g[r]).abs() < 1e-9);
        for c in 0..3 {
            assert!(
                (file.scale[r][c] - thesis.full.s[r][c]).abs() < 1e-9,
                "S[{r}][{c}]"
            );
        }
    }
    assert!(
        j["final"]["rms_mps2"].as_f64().unwrap()
            < 0.5 * j["baseline"]["rms_mps2"].as_f64().unwrap()
    );
    std::fs::remove_dir_all(out.parent().unwrap()).unwrap();
}
