//! The capstone thesis's files: every file loads, its content matches what the data README
//! states, and malformed copies fail with file, line and field.

mod common;

use std::path::{Path, PathBuf};

use common::{capstone_dir, tmp};
use ipc_types::units::AccelRange;
use recording::thesis::{self, ThesisModel};
use recording::{ErrorKind, Format, Position};

/// Every file under `dir`, recursively, sorted.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(files(&path));
        } else {
            out.push(path);
        }
    }
    out.sort();
    out
}

fn name(path: &Path) -> &str {
    path.file_name().unwrap().to_str().unwrap()
}

fn is_six_position(path: &Path) -> bool {
    let name = name(path);
    name.starts_with("six_position_data") || name.contains("combined")
}

#[test]
fn every_thesis_file_loads_with_plausible_content() {
    let Some(dir) = capstone_dir() else { return };
    let (mut series, mut six, mut params) = (0, 0, 0);
    for path in files(&dir) {
        if path.extension().is_none_or(|e| e != "csv") {
            continue;
        }
        if name(&path).starts_with("optim_params") {
            thesis::load_optim_params(&path).unwrap();
            params += 1;
        } else if is_six_position(&path) {
            let six_position = recording::load_six_position(&path).unwrap();
            assert_eq!(six_position.poses.len() % 6, 0, "{}", path.display());
            six += 1;
        } else {
            let rec = recording::load_raw(&path).unwrap();
            check_static_series(&rec);
            series += 1;
        }
    }
    eprintln!("loaded {series} time series, {six} six-position files, {params} parameter files");
    // The published set: 60 start-up runs, the one-minute file, three trials' static files.
    assert!(series >= 64, "{series} time series");
    assert!(six >= 3 && params >= 3);
}

/// What the data README states about every time series: about 60 s at about 180 Hz, monotonic
/// timestamps, every value a multiple of 4 counts at 16384 counts/g, at rest z up.
fn check_static_series(rec: &recording::Recording) {
    let what = rec.source.display();
    assert_eq!(rec.format, Format::ThesisCsv);
    let n = rec.samples.len();
    assert!((10_000..=11_500).contains(&n), "{what}: {n} samples");
    let t: Vec<u64> = rec.samples.iter().map(|s| s.stamps.sample_ns).collect();
    assert!(
        t.windows(2).all(|w| w[1] > w[0]),
        "{what}: time not increasing"
    );
    let duration_s = (t[n - 1] - t[0]) as f64 * 1e-9;
    assert!((59.5..60.5).contains(&duration_s), "{what}: {duration_s} s");
    let mut intervals: Vec<u64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    intervals.sort_unstable();
    let median_ms = intervals[intervals.len() / 2] as f64 * 1e-6;
    assert!(
        (5.0..6.0).contains(&median_ms),
        "{what}: median interval {median_ms} ms"
    );
    for (i, s) in rec.samples.iter().enumerate() {
        assert_eq!(s.seq, i as u64);
        assert_eq!(s.flags, 0);
        for (g, counts) in s.accel_g.iter().zip(s.accel_counts) {
            let exact = g * AccelRange::G2.lsb_per_g();
            assert_eq!(exact.fract(), 0.0, "{what}: {g} g is not a whole count");
            assert_eq!(exact, f64::from(counts));
            assert_eq!(counts % 4, 0, "{what}: {counts} counts");
        }
        // At rest with z up (the level table): z near +1 g less the sensor's large z bias.
        assert!(
            (0.6..1.0).contains(&s.accel_g[2]),
            "{what}: z = {} g",
            s.accel_g[2]
        );
    }
}

/// The trial folders present in the data.
fn trials(dir: &Path) -> Vec<(u32, PathBuf)> {
    (1..=3)
        .map(|n| (n, dir.join(format!("Six-Position-Test/data/trial_{n}"))))
        .filter(|(_, p)| p.is_dir())
        .collect()
}

#[test]
fn six_position_files_hold_the_six_poses_in_the_scripts_order() {
    let Some(dir) = capstone_dir() else { return };
    // collect_data_six_pos.py: z up, z down, y up, y down, x up, x down.
    let expected = [
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
    ];
    for (n, trial) in trials(&dir) {
        let six =
            recording::load_six_position(trial.join(format!("six_position_data_{n}.csv"))).unwrap();
        let truths: Vec<[f64; 3]> = six.poses.iter().map(|p| p.true_g).collect();
        assert_eq!(truths, expected);
        for pose in &six.poses {
            for k in 0..3 {
                // Biases reach -0.25 g on z; noise std a few mg.
                assert!((pose.mean_g[k] - pose.true_g[k]).abs() < 0.3, "{pose:?}");
                assert!((0.001..0.01).contains(&pose.std_g[k]), "{pose:?}");
            }
        }
        // The static file was recorded z up right after the poses: its mean matches pose 1.
        let rec =
            recording::load_raw(trial.join(format!("six_position_test_data_{n}.csv"))).unwrap();
        for k in 0..3 {
            let mean =
                rec.samples.iter().map(|s| s.accel_g[k]).sum::<f64>() / rec.samples.len() as f64;
            assert!(
                (mean - six.poses[0].mean_g[k]).abs() < 0.005,
                "trial {n} axis {k}"
            );
        }
    }
}

/// `S a + b` for a model, g.
fn predict(model: &ThesisModel, a: [f64; 3]) -> [f64; 3] {
    let mut out = model.bias_g;
    for (i, row) in model.s.iter().enumerate() {
        out[i] += row.iter().zip(a).map(|(s, a)| s * a).sum::<f64>();
    }
    out
}

#[test]
fn fitted_parameters_match_least_squares_on_the_six_poses() {
    let Some(dir) = capstone_dir() else { return };
    for (n, trial) in trials(&dir) {
        let params =
            thesis::load_optim_params(trial.join(format!("optim_params_{n}.csv"))).unwrap();
        assert_eq!(
            params.title,
            format!("Accelerometer Model Parameters Optimized - Trial {n}.")
        );
        let six =
            recording::load_six_position(trial.join(format!("six_position_data_{n}.csv"))).unwrap();
        let poses = &six.poses;
        for k in 0..3 {
            // Model 1's least-squares bias is the mean residual over the poses.
            let mean_residual =
                poses.iter().map(|p| p.mean_g[k] - p.true_g[k]).sum::<f64>() / poses.len() as f64;
            assert!(
                (params.bias_only.bias_g[k] - mean_residual).abs() < 1e-9,
                "trial {n}"
            );
            // Model 2's least-squares scale on axis k: half the difference of the axis-up and
            // axis-down means (the other poses have zero true value on k). Poses 4-k, 5-k hold
            // axis k up/down (z: 0/1, y: 2/3, x: 4/5).
            let (up, down) = (&poses[4 - 2 * k], &poses[5 - 2 * k]);
            let slope = (up.mean_g[k] - down.mean_g[k]) / 2.0;
            assert!(
                (params.scale.s[k][k] - slope).abs() < 1e-9,
                "trial {n} axis {k}"
            );
            for j in (0..3).filter(|&j| j != k) {
                assert_eq!(params.scale.s[k][j], 0.0);
                assert_eq!(params.bias_only.s[k][j], 0.0);
            }
            assert_eq!(params.bias_only.s[k][k], 1.0);
        }
        // Each richer model explains the means better; model 3 to within a few mg.
        let worst = |model: &ThesisModel| {
            poses
                .iter()
                .flat_map(|p| {
                    let predicted = predict(model, p.true_g);
                    (0..3).map(move |k| (predicted[k] - p.mean_g[k]).abs())
                })
                .fold(0.0, f64::max)
        };
        let (w1, w2, w3) = (
            worst(&params.bias_only),
            worst(&params.scale),
            worst(&params.full),
        );
        assert!(
            w3 < 0.006 && w3 < w2 && w2 < w1,
            "trial {n}: {w1} {w2} {w3}"
        );
    }
}

#[test]
fn several_placements_concatenate_like_the_combined_files() {
    let Some(dir) = capstone_dir() else { return };
    let trials = trials(&dir);
    // trial_1_2_3_combined.csv (not in the shared set) is the three trials' rows under one header.
    let mut combined = String::new();
    let mut expected = Vec::new();
    for (n, trial) in &trials {
        let path = trial.join(format!("six_position_data_{n}.csv"));
        let text = std::fs::read_to_string(&path).unwrap();
        let mut lines = text.lines();
        let header = lines.next().unwrap();
        if combined.is_empty() {
            combined = format!("{header}\n");
        }
        for line in lines {
            combined.push_str(line);
            combined.push('\n');
        }
        expected.extend(recording::load_six_position(&path).unwrap().poses);
    }
    let path = tmp("trial_1_2_3_combined.csv");
    std::fs::write(&path, combined).unwrap();
    let six = recording::load_six_position(&path).unwrap();
    assert_eq!(six.poses.len(), 6 * trials.len());
    assert_eq!(six.poses, expected);
}

/// Copies a real file with line `line` (1-based) replaced by `f(old line)`.
fn corrupt(src: &Path, name: &str, line: usize, f: impl Fn(&str) -> String) -> PathBuf {
    let text = std::fs::read_to_string(src).unwrap();
    let out: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| if i + 1 == line { f(l) } else { l.to_owned() })
        .collect();
    let path = tmp(name);
    std::fs::write(&path, out.join("\n") + "\n").unwrap();
    path
}

/// Replaces field `k` of a CSV line.
fn replace_field(line: &str, k: usize, value: &str) -> String {
    let mut fields: Vec<&str> = line.split(',').collect();
    fields[k] = value;
    fields.join(",")
}

#[test]
fn corrupted_thesis_files_fail_with_file_line_and_field() {
    let Some(dir) = capstone_dir() else { return };
    let start_up = dir.join("Preliminary-Tests/Start-Up-Shut-Down/Data/start_up_data_1.csv");
    let path = corrupt(&start_up, "start_up_bad_y.csv", 100, |l| {
        replace_field(l, 2, "0.0x1")
    });
    let err = recording::load_raw(&path).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!(
            "{}:100: field \"y (g)\": cannot parse \"0.0x1\" as a number",
            path.display()
        )
    );

    let path = corrupt(&start_up, "start_up_backwards.csv", 50, |l| {
        replace_field(l, 0, "0.1")
    });
    let err = recording::load_raw(&path).unwrap_err();
    assert_eq!(err.position, Some(Position::Line(50)));
    assert_eq!(err.field.as_deref(), Some("time"));
    assert!(matches!(err.kind, ErrorKind::TimeBackwards { .. }), "{err}");

    let Some((n, trial)) = trials(&dir).into_iter().next() else {
        return;
    };
    let static_file = trial.join(format!("six_position_test_data_{n}.csv"));
    let path = corrupt(&static_file, "static_missing_z.csv", 7, |l| {
        l.rsplit_once(',').unwrap().0.to_owned()
    });
    let err = recording::load_raw(&path).unwrap_err();
    assert_eq!(err.position, Some(Position::Line(7)));
    assert_eq!(err.field.as_deref(), Some("z (g)"));
    assert!(
        matches!(
            err.kind,
            ErrorKind::MissingField {
                expected: 4,
                found: 3
            }
        ),
        "{err}"
    );

    let means = trial.join(format!("six_position_data_{n}.csv"));
    let path = corrupt(&means, "six_nan.csv", 3, |l| replace_field(l, 5, "nan"));
    let err = recording::load_six_position(&path).unwrap_err();
    assert_eq!(err.position, Some(Position::Line(3)));
    assert_eq!(err.field.as_deref(), Some("y_std"));
    assert!(matches!(err.kind, ErrorKind::NotFinite { .. }), "{err}");

    let path = corrupt(&means, "six_bad_header.csv", 1, |l| {
        l.replace("y_std", "y_sd")
    });
    let err = recording::load_six_position(&path).unwrap_err();
    assert_eq!(err.position, Some(Position::Line(1)));

    let params = trial.join(format!("optim_params_{n}.csv"));
    // Model 1 (line 3) must store zeros in the S columns.
    let path = corrupt(&params, "params_model1_scale.csv", 3, |l| {
        replace_field(l, 3, "1.0")
    });
    let err = thesis::load_optim_params(&path).unwrap_err();
    assert_eq!(err.position, Some(Position::Line(3)));
    assert_eq!(err.field.as_deref(), Some("Sxx"));
    let path = corrupt(&params, "params_short.csv", 5, |_| String::new());
    let err = thesis::load_optim_params(&path).unwrap_err();
    assert!(
        err.to_string().contains("2 model rows, expected 3"),
        "{err}"
    );
}
