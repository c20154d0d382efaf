//! The `allan` command end to end on a simulated canonical CSV with known white noise and
//! injected torn reads: text and JSON reports, TOML parameters, Kalibr file, PNG plot, and
//! clear errors.

use std::path::{Path, PathBuf};

use clap::Parser;
use ipc_types::units::STANDARD_GRAVITY_MPS2;
use noise::synth::{NoiseModel, static_samples, white_static_samples};
use noise::{Args, NoiseParams};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The command line as `mems-calibrate allan` parses it.
#[derive(Parser)]
struct Command {
    #[command(flatten)]
    args: Args,
}

fn parse(args: &[&str]) -> Args {
    let mut argv = vec!["allan"];
    argv.extend_from_slice(args);
    Command::try_parse_from(argv).expect("valid arguments").args
}

const ACCEL_N: f64 = 1e-3;
const GYRO_N: f64 = 1.7e-4;
const TEARS: usize = 50;

/// A scratch directory for this test binary.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("noise-cli-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// 20 000 samples at 200 Hz of white noise (accelerometer ACCEL_N, 23 counts rms; gyro GYRO_N,
/// 18 counts rms), with TEARS torn reads on accelerometer x, each consistent with the value it
/// corrupts (x and y read about 0 g and z 1 g = 0x4000 counts: all sit on a byte boundary).
fn write_recording(dir: &Path) -> PathBuf {
    let mut samples =
        white_static_samples(ACCEL_N, GYRO_N, 20_000, 0.005, STANDARD_GRAVITY_MPS2, 5);
    let mut injected = 0;
    let mut i = 100;
    while injected < TEARS {
        let count = samples[i].accel_counts[0];
        let low = i32::from(count).rem_euclid(256);
        // A value just below a byte boundary reads 256 too high, just above one 256 too low.
        let shift = if low >= 0xC0 {
            256
        } else if low < 0x40 {
            -256
        } else {
            i += 1;
            continue;
        };
        samples[i].accel_counts[0] = (i32::from(count) + shift) as i16;
        samples[i].accel_g[0] = f64::from(samples[i].accel_counts[0]) / 16384.0;
        injected += 1;
        i += 300;
    }
    let path = dir.join("static.csv");
    recording::csv::write_raw(&path, &samples, None).unwrap();
    path
}

fn number(value: &serde_json::Value, path: &[&str]) -> f64 {
    let mut v = value;
    for key in path {
        v = &v[*key];
    }
    v.as_f64()
        .unwrap_or_else(|| panic!("{} is not a number: {v}", path.join(".")))
}

#[test]
fn writes_reports_parameters_kalibr_and_plot() {
    let dir = scratch("outputs");
    let input = write_recording(&dir);
    let (toml, kalibr, png) = (
        dir.join("noise.toml"),
        dir.join("imu.yaml"),
        dir.join("adev.png"),
    );
    let args = parse(&[
        "--input",
        input.to_str().unwrap(),
        "--json",
        "--toml",
        toml.to_str().unwrap(),
        "--kalibr",
        kalibr.to_str().unwrap(),
        "--plot",
        png.to_str().unwrap(),
    ]);
    let mut out = Vec::new();
    let report = noise::cli::run_allan_to(&args, &mut out).unwrap();
    let json: serde_json::Value = serde_json::from_slice(&out).unwrap();

    // The tears were found, and only they.
    assert_eq!(json["torn"]["accel"][0]["repaired"], TEARS);
    assert_eq!(json["torn"]["accel"][1]["repaired"], 0);
    assert_eq!(json["torn"]["gyro"][2]["repaired"], 0);
    assert_eq!(json["torn"]["samples_repaired"], TEARS);

    // White noise recovered within 4 sigma; nothing else in the record.
    for (sensor, truth) in [("accel", ACCEL_N), ("gyro", GYRO_N)] {
        for axis in ["x", "y", "z"] {
            let base = ["params", sensor, axis, "white_noise_density"];
            let value = number(&json, &[base[0], base[1], base[2], base[3], "value"]);
            let sigma = number(&json, &[base[0], base[1], base[2], base[3], "sigma"]);
            assert!(
                (value - truth).abs() < 4.0 * sigma && sigma < 0.03 * truth,
                "{sensor} {axis}: {value} +- {sigma} vs {truth}"
            );
            let limits = &json["params"][sensor][axis]["upper_limits"];
            assert!(
                limits["random_walk"].is_number(),
                "{sensor} {axis}: {limits}"
            );
        }
    }
    assert!((number(&json, &["params", "sample_rate_hz"]) - 200.0).abs() < 1e-6);

    // The TOML file holds the same parameters.
    let params = NoiseParams::from_toml(&std::fs::read_to_string(&toml).unwrap()).unwrap();
    assert_eq!(params, report.params);

    // Kalibr: the largest axis of each sensor.
    let yaml = std::fs::read_to_string(&kalibr).unwrap();
    let value = |key: &str| -> f64 {
        let line = yaml.lines().find(|l| l.starts_with(key)).unwrap();
        let text = line.split(':').nth(1).unwrap().split('#').next().unwrap();
        text.trim().parse().unwrap()
    };
    let largest = |sensor: &noise::params::SensorNoise| {
        sensor
            .axes()
            .iter()
            .map(|a| a.white_noise_density.unwrap().value)
            .fold(0.0, f64::max)
    };
    let relative = |a: f64, b: f64| (a / b - 1.0).abs();
    assert!(relative(value("accelerometer_noise_density"), largest(&params.accel)) < 1e-6);
    let gyro = params.gyro.as_ref().unwrap();
    assert!(relative(value("gyroscope_noise_density"), largest(gyro)) < 1e-6);
    assert!(relative(value("update_rate"), 200.0) < 1e-6);
    assert!(yaml.contains("rostopic: /imu0"));

    // The plot: a PNG of two panels (accelerometer, gyro), 1000 x 1240 pixels.
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let width = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let height = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!((width, height), (1000, 1240));
    assert!(bytes.len() > 20_000, "{} bytes", bytes.len());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn text_report_names_what_it_found() {
    let dir = scratch("text");
    let input = write_recording(&dir);
    let mut out = Vec::new();
    noise::cli::run_allan_to(&parse(&["--input", input.to_str().unwrap()]), &mut out).unwrap();
    let text = String::from_utf8(out).unwrap();
    assert!(text.contains("20000 samples over 100.00 s"), "{text}");
    assert!(
        text.contains(&format!("torn reads repaired: accel x {TEARS}, y 0, z 0")),
        "{text}"
    );
    assert!(text.contains("gyroscope (rad/s)"), "{text}");
    assert!(text.contains("x K: random walk (K^2)"), "{text}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn errors_name_the_file_and_the_problem() {
    let dir = scratch("errors");
    let missing = dir.join("missing.csv");
    let err = noise::cli::run_allan_to(
        &parse(&["--input", missing.to_str().unwrap()]),
        &mut Vec::new(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("missing.csv"), "{err}");

    let short = dir.join("short.csv");
    let samples = &static_samples(
        &[
            NoiseModel::default(),
            NoiseModel::default(),
            NoiseModel::default(),
        ],
        None,
        20,
        0.005,
        STANDARD_GRAVITY_MPS2,
        &mut ChaCha8Rng::seed_from_u64(1),
    );
    recording::csv::write_raw(&short, samples, None).unwrap();
    let err = noise::cli::run_allan_to(
        &parse(&["--input", short.to_str().unwrap()]),
        &mut Vec::new(),
    )
    .unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("short.csv") && text.contains("20 samples"),
        "{text}"
    );

    // Kalibr needs the gyro.
    let accel_only = dir.join("accel.csv");
    let model = NoiseModel {
        white_density: ACCEL_N,
        ..Default::default()
    };
    let samples = static_samples(
        &[model.clone(), model.clone(), model],
        None,
        2_000,
        0.005,
        STANDARD_GRAVITY_MPS2,
        &mut ChaCha8Rng::seed_from_u64(2),
    );
    recording::csv::write_raw(&accel_only, &samples, None).unwrap();
    let yaml = dir.join("imu.yaml");
    let args = parse(&[
        "--input",
        accel_only.to_str().unwrap(),
        "--kalibr",
        yaml.to_str().unwrap(),
    ]);
    let err = noise::cli::run_allan_to(&args, &mut Vec::new()).unwrap_err();
    assert!(err.to_string().contains("needs the gyroscope"), "{err}");
    assert!(!yaml.exists());

    // Nonsense options.
    let err = noise::cli::run_allan_to(
        &parse(&["--input", accel_only.to_str().unwrap(), "--gravity=-9.8"]),
        &mut Vec::new(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("--gravity -9.8"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
