//! The `mems-sim` binary: every scenario written to CSV and MCAP and read back with the
//! recording crate, identical to what the library computes; clear errors on bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use ipc_types::RawImuSample;
use ipc_types::units::{AccelRange, GyroRange, STANDARD_GRAVITY_MPS2};
use mems_sim::adc::quantize_sample;
use mems_sim::dlpf::{Coefficients, DlpfConfig};
use mems_sim::model::SensorModel;
use mems_sim::scenario::{Drive, DriveParams, PoseParams, PoseSession, Scenario, ns_from_s};
use mems_sim::vibration::VibrationModel;
use mems_sim::{DlpfGrid, SimSensor};
use nalgebra::{UnitQuaternion, Vector3};
use recording::{Format, Truth};

/// A path for a test's output, nothing there (mems-sim refuses an existing --out).
fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("mems-sim-cli");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    let _ = std::fs::remove_file(&path);
    path
}

fn mems_sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mems-sim"))
        .args(args)
        .output()
        .expect("running mems-sim")
}

/// Runs mems-sim and asserts success.
fn ok(args: &[&str]) {
    let out = mems_sim(args);
    assert!(
        out.status.success(),
        "mems-sim {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Runs mems-sim, asserts failure, and returns its stderr.
fn fails(args: &[&str]) -> String {
    let out = mems_sim(args);
    assert!(!out.status.success(), "mems-sim {args:?} should fail");
    String::from_utf8(out.stderr).unwrap()
}

/// What the library produces for `scenario` with the default (calibrated) model at `rate_hz`
/// through the default DLPF, our driver's for that rate.
fn expected(
    scenario: impl Scenario,
    vibration: f64,
    seed: u64,
    rate_hz: f64,
) -> (Vec<RawImuSample>, Vec<Truth>) {
    let n = (scenario.duration_s() * rate_hz).floor() as u64 + 1;
    let mut sim = SimSensor::new(
        scenario,
        &SensorModel::mpu9250_calibrated(),
        &VibrationModel::moderate(vibration),
        seed,
    )
    .unwrap();
    sim.set_dlpf(Some(DlpfGrid::from_power_on(DlpfConfig::driver(rate_hz))));
    (0..n)
        .map(|k| {
            let t_s = k as f64 / rate_hz;
            let (a, t) = sim.sample_with_truth(t_s, rate_hz);
            let raw = quantize_sample(&a, AccelRange::G2, GyroRange::Dps250, ns_from_s(t_s), k);
            (raw, t)
        })
        .unzip()
}

/// Reads `path` back and checks it holds exactly `want` (samples and truth).
fn check_file(path: &Path, want: &(Vec<RawImuSample>, Vec<Truth>)) {
    let rec = recording::load_raw(path).unwrap();
    let truth = rec.truth.expect("the file holds truth");
    assert_eq!(rec.samples.len(), want.0.len(), "{}", path.display());
    assert_eq!(truth, want.1, "{}", path.display());
    if rec.format == Format::Mcap {
        assert_eq!(rec.samples, want.0);
    } else {
        assert_eq!(rec.format, Format::CanonicalCsv);
        // CSV keeps the values, times and flags (counts and seq are re-derived on reading).
        for (got, want) in rec.samples.iter().zip(&want.0) {
            assert_eq!(got.stamps.sample_ns, want.stamps.sample_ns);
            assert_eq!(got.accel_g, want.accel_g);
            assert_eq!(got.gyro_dps, want.gyro_dps);
            assert_eq!(got.temp_c, want.temp_c);
            assert_eq!(got.flags, want.flags);
            assert_eq!(got.accel_counts, want.accel_counts);
        }
    }
}

#[test]
fn six_position_and_orientations_are_written_with_truth() {
    let params = PoseParams {
        rotate_s: 1.0,
        ..PoseParams::new(2.0)
    };
    let six = expected(
        PoseSession::six_position(&params, 4).unwrap(),
        0.0,
        4,
        100.0,
    );
    assert_eq!(six.0.len(), (6 * 2 + 5) * 100 + 1);
    for out in [tmp("six.csv"), tmp("six.mcap")] {
        let o = out.to_str().unwrap();
        ok(&[
            "six-position",
            "--hold",
            "2",
            "--rotate",
            "1",
            "--rate",
            "100",
            "--seed",
            "4",
            "--out",
            o,
        ]);
        check_file(&out, &six);
    }
    let params = PoseParams {
        rotate_s: 1.0,
        ..PoseParams::new(1.0)
    };
    let many = expected(
        PoseSession::orientations(9, &params, 4).unwrap(),
        0.0,
        4,
        100.0,
    );
    let out = tmp("orientations.csv");
    let o = out.to_str().unwrap();
    ok(&[
        "orientations",
        "--n",
        "9",
        "--hold",
        "1",
        "--rotate",
        "1",
        "--rate",
        "100",
        "--seed",
        "4",
        "--out",
        o,
    ]);
    check_file(&out, &many);
}

#[test]
fn static_run_is_written_with_truth() {
    let s =
        PoseSession::static_pose(UnitQuaternion::identity(), 5.0, STANDARD_GRAVITY_MPS2).unwrap();
    let want = expected(s, 0.0, 2, 200.0);
    let out = tmp("static.csv");
    ok(&[
        "static",
        "--duration",
        "5",
        "--rate",
        "200",
        "--seed",
        "2",
        "--out",
        out.to_str().unwrap(),
    ]);
    check_file(&out, &want);
    assert!(want.1.iter().all(|t| t.at_rest));
}

#[test]
fn drive_is_written_and_its_file_truth_integrates_to_its_positions() {
    let params = DriveParams {
        turns: true,
        in_place_turns: true,
        ..DriveParams::new(90.0)
    };
    let want = expected(Drive::new(&params, 6).unwrap(), 0.5, 6, 100.0);
    let (csv, mcap) = (tmp("drive.csv"), tmp("drive.mcap"));
    for out in [&csv, &mcap] {
        ok(&[
            "drive",
            "--duration",
            "90",
            "--vibration",
            "0.5",
            "--turns",
            "on",
            "--in-place-turns",
            "on",
            "--rate",
            "100",
            "--seed",
            "6",
            "--out",
            out.to_str().unwrap(),
        ]);
        check_file(out, &want);
    }
    // The truth read back from the file: trapezoid integration of its accelerations
    // (R f + g_nav) at the file's rate reproduces its velocities and positions within the rule's
    // own error, 2 h^2 / 6 max|jerk| and 2 h^2 / 6 max|a| (derived in tests/scenarios.rs).
    let truth = recording::load_raw(&csv).unwrap().truth.unwrap();
    let h = 0.01;
    let a: Vec<Vector3<f64>> = truth
        .iter()
        .map(|t| {
            let [w, x, y, z] = t.attitude_wxyz;
            let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
            q * Vector3::from(t.specific_force_mps2) - Vector3::new(0.0, 0.0, STANDARD_GRAVITY_MPS2)
        })
        .collect();
    let a_max = a.iter().map(|v| v.norm()).fold(0.0, f64::max);
    let jerk_max = a
        .windows(3)
        .map(|w| ((w[2] - w[0]) / (2.0 * h)).norm())
        .fold(0.0, f64::max);
    let (mut v, mut p) = (Vector3::zeros(), Vector3::zeros());
    let (mut ev, mut ep) = (0.0f64, 0.0f64);
    for k in 1..truth.len() {
        let v_next = v + 0.5 * h * (a[k - 1] + a[k]);
        p += 0.5 * h * (v + v_next);
        v = v_next;
        ev = ev.max((v - Vector3::from(truth[k].velocity_mps)).norm());
        ep = ep.max((p - Vector3::from(truth[k].position_m)).norm());
    }
    assert!(ev <= 2.0 * h * h / 6.0 * jerk_max, "velocity error {ev}");
    assert!(ep <= 2.0 * h * h / 6.0 * a_max, "position error {ep}");
    let end = Vector3::from(truth.last().unwrap().position_m).norm();
    assert!(end > 5.0, "the drive went {end} m");
}

#[test]
fn ranges_and_models_are_applied() {
    // +-16 g: every accelerometer value is a whole number of 1/2048 g counts, and the preset
    // printed as TOML and passed back gives the same file as the preset itself.
    let model = tmp("datasheet.toml");
    let printed = mems_sim(&["print-model", "--preset", "datasheet"]);
    assert!(printed.status.success());
    let text = String::from_utf8(printed.stdout).unwrap();
    let parsed: SensorModel = toml::from_str(&text).unwrap();
    assert_eq!(parsed, SensorModel::mpu9250_datasheet());
    std::fs::write(&model, &text).unwrap();
    let (a, b) = (tmp("range-a.mcap"), tmp("range-b.mcap"));
    let common = [
        "static",
        "--duration",
        "2",
        "--rate",
        "50",
        "--accel-range",
        "16",
        "--gyro-range",
        "2000",
    ];
    ok(&[
        &common[..],
        &["--preset", "datasheet", "--out", a.to_str().unwrap()],
    ]
    .concat());
    ok(&[
        &common[..],
        &[
            "--model",
            model.to_str().unwrap(),
            "--out",
            b.to_str().unwrap(),
        ],
    ]
    .concat());
    let ra = recording::load_raw(&a).unwrap();
    let rb = recording::load_raw(&b).unwrap();
    assert_eq!(ra.samples, rb.samples);
    for s in &ra.samples {
        for i in 0..3 {
            assert_eq!(s.accel_g[i] * 2048.0, f64::from(s.accel_counts[i]));
            assert!((s.gyro_dps[i] * 16.4 - f64::from(s.gyro_counts[i])).abs() < 1e-9);
        }
    }
    // The noise override: an ideal model with accelerometer noise only.
    let noisy = tmp("noisy.csv");
    ok(&[
        "static",
        "--duration",
        "20",
        "--rate",
        "100",
        "--dlpf",
        "184",
        "--preset",
        "ideal",
        "--accel-noise-ug",
        "1000",
        "--out",
        noisy.to_str().unwrap(),
    ]);
    let rec = recording::load_raw(&noisy).unwrap();
    let x: Vec<f64> = rec.samples.iter().map(|s| s.accel_g[0]).collect();
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let std = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
    // 1000 ug/sqrt(Hz) drawn at the 1 kHz internal rate (0.0316 g per internal sample) through
    // the accelerometer DLPF `--dlpf 184` selects (A_DLPF_CFG = 1, 218.1 Hz): variance ratio K / (1 + K),
    // 0.0212 g; quantization adds 1/16384/sqrt(12), negligible. Every tenth internal sample
    // is kept, whose lag-10 correlation (1 + p) p^9 / 2 is below 1e-8: independent samples,
    // 4-sigma sampling bound on the std.
    let c = Coefficients::new(&DlpfConfig::both(1).accel);
    assert!(c.autocorrelation(10) < 1e-8);
    let want = 1000e-6 * 1000f64.sqrt() * c.noise_variance_ratio().sqrt();
    assert!(
        (std - want).abs() < 4.0 * want / (2.0 * (n - 1.0)).sqrt(),
        "std {std}, filtered white noise {want}"
    );
}

#[test]
fn bad_input_gets_a_clear_error() {
    let out = tmp("bad.csv");
    let o = out.to_str().unwrap();
    let e = fails(&[
        "static",
        "--duration",
        "1",
        "--out",
        tmp("x.txt").to_str().unwrap(),
    ]);
    assert!(e.contains(".csv or .mcap"), "{e}");
    let e = fails(&["orientations", "--n", "0", "--out", o]);
    assert!(e.contains("`n`"), "{e}");
    let e = fails(&["drive", "--duration", "60", "--vibration=-1", "--out", o]);
    assert!(e.contains("--vibration"), "{e}");
    let e = fails(&[
        "drive",
        "--duration",
        "60",
        "--initial-rest",
        "100",
        "--out",
        o,
    ]);
    assert!(e.contains("initial_rest_s"), "{e}");
    let e = fails(&["static", "--duration", "1", "--rate", "0", "--out", o]);
    assert!(e.contains("--rate"), "{e}");
    let e = fails(&["arm", "--accel-lag-s", "0.7", "--out", o]);
    assert!(e.contains("--accel-lag-s") && e.contains("0.7"), "{e}");
    let e = fails(&["arm", "--lever-arm-m", "-20,0,0", "--out", o]);
    assert!(e.contains("--lever-arm-m") && e.contains("-20"), "{e}");
    let e = fails(&[
        "static",
        "--duration",
        "1",
        "--out",
        o,
        "--model",
        "/nonexistent/model.toml",
    ]);
    assert!(e.contains("/nonexistent/model.toml"), "{e}");

    // A model file with a negative noise density: the error names the file and the field.
    let model = tmp("negative.toml");
    let mut m = SensorModel::ideal();
    m.accel.noise_density[2] = -1.0;
    std::fs::write(&model, toml::to_string(&m).unwrap()).unwrap();
    let e = fails(&[
        "static",
        "--duration",
        "1",
        "--out",
        o,
        "--model",
        model.to_str().unwrap(),
    ]);
    assert!(
        e.contains("accel.noise_density[2]") && e.contains("negative.toml"),
        "{e}"
    );
    // A misspelt field: the TOML error names it, with its line.
    let typo = tmp("typo.toml");
    std::fs::write(
        &typo,
        toml::to_string(&SensorModel::ideal())
            .unwrap()
            .replace("noise_density", "noise_densty"),
    )
    .unwrap();
    let e = fails(&[
        "static",
        "--duration",
        "1",
        "--out",
        o,
        "--model",
        typo.to_str().unwrap(),
    ]);
    assert!(
        e.contains("noise_densty") && e.contains("typo.toml") && e.contains("line"),
        "{e}"
    );
}

/// Lag-1 autocorrelation of `x`.
fn lag1(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
    x.windows(2)
        .map(|w| (w[0] - mean) * (w[1] - mean))
        .sum::<f64>()
        / var
}

#[test]
fn dlpf_option_correlates_the_samples_and_checks_the_rate() {
    // DLPF_CFG = 4 (gyro 20 Hz) at 100 Hz output: lag-1 autocorrelation (1 + p) p^9 / 2 with
    // p = (1 - K) / (1 + K), K = tan(pi 20 / 1000); off: white.
    let k = (std::f64::consts::PI * 20.0 / 1000.0).tan();
    let p = (1.0 - k) / (1.0 + k);
    let want = (1.0 + p) * p.powi(9) / 2.0;
    for (dlpf, want) in [("20", want), ("off", 0.0)] {
        let out = tmp(&format!("dlpf-{dlpf}.csv"));
        let out_s = out.to_str().unwrap();
        ok(&[
            "static",
            "--duration",
            "300",
            "--rate",
            "100",
            "--dlpf",
            dlpf,
            "--out",
            out_s,
        ]);
        let rec = recording::load_raw(&out).unwrap();
        let n = rec.samples.len() as f64;
        for axis in 0..3 {
            let g: Vec<f64> = rec.samples.iter().map(|s| s.gyro_dps[axis]).collect();
            let r1 = lag1(&g);
            let se = (2.0 * (1.0 + want) / (1.0 - want) / n).sqrt();
            assert!(
                (r1 - want).abs() < 5.0 * se,
                "--dlpf {dlpf} gyro {axis}: lag-1 {r1}, closed form {want}"
            );
        }
    }
    let out = tmp("dlpf-bad.csv");
    let out_s = out.to_str().unwrap();
    for (dlpf, rate, says) in [
        ("184", "4000", "1000/n Hz"),
        ("driver", "300", "1000/n Hz"),
        ("250", "1000", "8000 Hz"),
    ] {
        let e = fails(&[
            "static",
            "--duration",
            "1",
            "--rate",
            rate,
            "--dlpf",
            dlpf,
            "--out",
            out_s,
        ]);
        assert!(e.contains("--rate") && e.contains(says), "{e}");
    }
    assert!(
        fails(&["static", "--duration", "1", "--dlpf", "93", "--out", out_s])
            .contains("unknown DLPF")
    );
}

#[test]
fn log_defects_and_a_start_in_motion_are_written() {
    let out = tmp("defects.csv");
    let out_s = out.to_str().unwrap();
    ok(&[
        "drive",
        "--duration",
        "60",
        "--rate",
        "1000",
        "--start-at",
        "motion",
        // A 4 ms host clock (Linux jiffies at HZ = 250): three of four rows repeat a time.
        "--quantum-ms",
        "4",
        "--repeat-fraction",
        "0.1",
        "--out",
        out_s,
    ]);
    // MCAP recordings need strictly increasing times: refused up front.
    let mcap = tmp("defects.mcap");
    let e = fails(&[
        "static",
        "--duration",
        "1",
        "--quantum-ms",
        "1",
        "--out",
        mcap.to_str().unwrap(),
    ]);
    assert!(e.contains("write a .csv"), "{e}");
    // Equal timestamps: the canonical reader refuses the file, naming the time column.
    let e = recording::load_raw(&out).unwrap_err().to_string();
    assert!(e.contains("t_s"), "{e}");
    let text = std::fs::read_to_string(&out).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    // The recording starts moving: the first row is not at rest and has speed.
    let first = &rows[0];
    assert_eq!(first[col("truth_rest")], 0.0);
    let speed = first[col("truth_vx_mps")].hypot(first[col("truth_vy_mps")]);
    assert!(speed > 0.1, "first row's speed {speed} m/s");
    let t: Vec<f64> = rows.iter().map(|r| r[col("t_s")]).collect();
    assert!(t.windows(2).all(|w| w[1] >= w[0]));
    let equal = t.windows(2).filter(|w| w[1] == w[0]).count();
    assert!(
        equal > rows.len() / 2,
        "{equal} equal times of {}",
        rows.len()
    );
    assert!(
        t.iter()
            .all(|x| (x * 1000.0 - (x * 1000.0).round()).abs() < 1e-6)
    );
}

#[test]
fn walk_is_written_with_truth_that_closes_the_loop() {
    use mems_sim::scenario::{Walk, WalkParams};
    let out = tmp("walk.csv");
    let out_s = out.to_str().unwrap();
    ok(&[
        "walk",
        "--laps",
        "1",
        "--rate",
        "200",
        "--initial-rest",
        "2",
        "--accel-range",
        "16",
        "--gyro-range",
        "2000",
        "--out",
        out_s,
    ]);
    let rec = recording::load_raw(&out).unwrap();
    let truth = rec.truth.expect("the file holds truth");
    let params = WalkParams {
        initial_rest_s: 2.0,
        ..WalkParams::new(1)
    };
    let walk = Walk::new(&params, 1).unwrap();
    assert_eq!(
        truth.len(),
        (walk.duration_s() * 200.0).floor() as usize + 1
    );
    for (k, t) in truth.iter().enumerate().step_by(97) {
        assert_eq!(*t, walk.truth(k as f64 / 200.0), "row {k}");
    }
    assert!(truth[0].at_rest && truth.last().unwrap().at_rest);
    let end = Vector3::from(truth.last().unwrap().position_m);
    assert!(end.norm() < 1e-9, "the walk ends {end:?} from its start");
    assert!(
        rec.samples
            .iter()
            .all(|s| s.flags & ipc_types::raw_flags::SATURATED == 0)
    );
}

/// An existing --out, or a symbolic link planted there, is refused without --force (the error
/// names the path and the flag; the link's target untouched); with --force the link itself is
/// replaced; the file is 0600.
#[test]
fn an_existing_or_planted_out_is_refused_without_force() {
    use std::os::unix::fs::PermissionsExt;
    let out = tmp("planted.csv");
    let victim = tmp("victim.txt");
    std::fs::write(&victim, "precious").unwrap();
    std::os::unix::fs::symlink(&victim, &out).unwrap();
    let args = |force: bool| {
        let mut a = vec!["six-position", "--preset", "datasheet", "--rate", "100"];
        a.extend(["--out", out.to_str().unwrap()]);
        if force {
            a.push("--force");
        }
        a
    };
    let refused = mems_sim(&args(false));
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success(), "a planted link is refused");
    assert!(
        err.contains("--out") && err.contains(out.to_str().unwrap()) && err.contains("--force"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");

    ok(&args(true));
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
    let meta = std::fs::symlink_metadata(&out).unwrap();
    assert!(meta.is_file(), "the link was replaced by the file");
    assert_eq!(meta.permissions().mode() & 0o777, 0o600);
    let again = mems_sim(&args(false));
    assert!(!again.status.success(), "an existing file is refused");
}
