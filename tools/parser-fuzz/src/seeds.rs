//! Seed inputs: small valid files of each format, written by the project's own writers where it
//! has them (so the seeds follow the formats as they change), and by hand where the format comes
//! from elsewhere (the thesis's files). Each exercises the optional parts of its format: gyro,
//! temperature, flags and truth columns; several MCAP topics and chunks; every optional section
//! of a calibration file. Beside them, the committed corpus (`corpus/PARSER/`, see
//! [`corpus_dir`]) holds files the writers here do not make: a logger's CSV with repeated rows,
//! a fitted calibration with a `[noise]` table, the identity file `tools/real-data/bench.py`
//! writes, ...

use std::path::{Path, PathBuf};

use calibrate::calibfile::CalibrationFile;
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint, Stamps, raw_flags};
use recording::Truth;

use crate::Parser;

/// The seed files of `parser`'s format, as bytes: those the writers make now (`dir` holds the
/// files they need), then the committed corpus.
pub fn for_parser(parser: Parser, dir: &Path) -> std::io::Result<Vec<Vec<u8>>> {
    let mut seeds = match parser {
        Parser::Csv => vec![canonical_csv(dir)?, thesis_series()],
        Parser::Mcap => vec![mcap(dir)?],
        Parser::Calib => vec![calibration().into_bytes()],
        Parser::Means => vec![means()],
    };
    for path in corpus(&corpus_dir(parser))? {
        seeds.push(std::fs::read(path)?);
    }
    Ok(seeds)
}

/// The committed corpus of `parser`: `tools/parser-fuzz/corpus/NAME/`, files its reader accepts.
pub fn corpus_dir(parser: Parser) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(parser.name())
}

/// The files of corpus directory `dir`, by name.
pub fn corpus(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let entries = std::fs::read_dir(dir)
        .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", dir.display())))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry?.path();
        if path.is_file() {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// `n` raw samples of a level sensor at 1 kHz with a little motion, gyro and temperature valid.
fn samples(n: u64) -> Vec<RawImuSample> {
    (0..n)
        .map(|k| {
            let wobble = (k as f64 * 0.7).sin() * 0.01;
            RawImuSample {
                stamps: Stamps {
                    sample_ns: 1_000_000_000 + k * 1_000_000,
                    ..Stamps::default()
                },
                seq: k,
                accel_g: [wobble, -0.02 + wobble, 1.0 - wobble],
                gyro_dps: [0.5 + wobble, -1.0, 12.0 * wobble],
                temp_c: 31.5 + wobble,
                flags: raw_flags::GYRO_VALID | raw_flags::TEMP_VALID,
                lost_before: u32::from(k == 5),
                ..RawImuSample::default()
            }
        })
        .collect()
}

/// Ground truth at the samples' times.
fn truth(samples: &[RawImuSample]) -> Vec<Truth> {
    samples
        .iter()
        .map(|s| Truth {
            t_ns: s.stamps.sample_ns,
            position_m: [0.1, -0.2, 0.0],
            velocity_mps: [0.01, 0.0, 0.0],
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            specific_force_mps2: [0.0, 0.0, 9.81],
            angular_rate_rps: [0.0; 3],
            at_rest: s.seq % 2 == 0,
        })
        .collect()
}

/// A canonical CSV with every optional column.
fn canonical_csv(dir: &Path) -> std::io::Result<Vec<u8>> {
    let path = dir.join("seed.csv");
    let samples = samples(8);
    recording::csv::write_raw(&path, &samples, Some(&truth(&samples))).map_err(io)?;
    std::fs::read(&path)
}

/// A thesis time-series file with its title line and the published malformed header.
fn thesis_series() -> Vec<u8> {
    let mut text = String::from("Raw accelerometer data\ntime (s)x (g),y (g),z (g)\n");
    for k in 0..8 {
        let t = 0.01 * f64::from(k) + 0.0004 * f64::from(k % 3);
        text.push_str(&format!("{t},0.0{k},-0.01,0.99{k}\n"));
    }
    text.into_bytes()
}

/// An MCAP recording with raw samples, truth, corrected samples, states and hints, in two
/// chunks.
fn mcap(dir: &Path) -> std::io::Result<Vec<u8>> {
    let path = dir.join("seed.mcap");
    let samples = samples(12);
    let mut w = recording::mcap::Writer::create(&path).map_err(io)?;
    let raw = w.add_channel::<RawImuSample>().map_err(io)?;
    let truth_channel = w.add_channel::<Truth>().map_err(io)?;
    let corrected = w.add_channel::<CorrectedImuSample>().map_err(io)?;
    let states = w.add_channel::<OdometryState>().map_err(io)?;
    let hints = w.add_channel::<RobotHint>().map_err(io)?;
    for (k, (s, t)) in samples.iter().zip(truth(&samples)).enumerate() {
        let log_ns = s.stamps.sample_ns + 1000;
        w.write(raw, s, log_ns).map_err(io)?;
        w.write(truth_channel, &t, log_ns).map_err(io)?;
        let c = CorrectedImuSample {
            stamps: s.stamps,
            seq: s.seq,
            accel_mps2: s.accel_g.map(|a| a * 9.81),
            gyro_rps: s.gyro_dps.map(f64::to_radians),
            temp_c: s.temp_c,
            raw_flags: s.flags,
            ..CorrectedImuSample::default()
        };
        w.write(corrected, &c, log_ns).map_err(io)?;
        let o = OdometryState {
            stamps: s.stamps,
            seq: s.seq,
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            position_sigma_m: [0.01; 3],
            ..OdometryState::default()
        };
        w.write(states, &o, log_ns).map_err(io)?;
        if k % 4 == 0 {
            let h = RobotHint {
                stamps: s.stamps,
                seq: k as u64 / 4,
                forward_speed_mps: 0.2,
                forward_speed_sigma_mps: 0.05,
                ..RobotHint::default()
            };
            w.write(hints, &h, log_ns).map_err(io)?;
        }
        if k == 6 {
            w.flush().map_err(io)?;
        }
    }
    w.finish().map_err(io)?;
    std::fs::read(&path)
}

/// A calibration file with every optional section but `[noise]`.
fn calibration() -> String {
    let mut f = CalibrationFile::identity(9.797);
    f.bias_g = [0.02, -0.01, 0.05];
    f.scale = [
        [1.01, 0.003, -0.002],
        [0.0, 0.995, 0.004],
        [0.001, -0.003, 1.02],
    ];
    f.temperature.reference_c = Some(25.0);
    f.temperature.bias_g_per_c = Some([1e-4, -2e-4, 3e-4]);
    f.temperature.scale_per_c = Some([1e-5, 0.0, -1e-5]);
    f.time.drift_g_per_s = Some([1e-6, 0.0, 2e-6]);
    f.time.drift_max_s = Some(600.0);
    f.time.warm_up_g = Some([0.001, 0.0, -0.002]);
    f.time.warm_up_time_constant_s = Some(30.0);
    f.nonlinearity.quadratic_g_per_g2 = Some([1e-3, 0.0, -1e-3]);
    f.gyro.bias_dps = Some([0.5, -1.2, 0.3]);
    f.gyro.correction = Some([[1.01, 0.002, 0.0], [0.0, 0.99, 0.01], [-0.003, 0.0, 1.0]]);
    f.gyro.correction_sigma = Some([[1e-3; 3]; 3]);
    f.temperature_range_c = Some([22.0, 41.0]);
    f.to_toml()
}

/// A six-position means file: the six poses of one placement.
fn means() -> Vec<u8> {
    let mut text = String::from(
        "x_true (g),x_mean (g),x_std,y_true (g),y_mean (g),y_std,z_true (g),z_mean (g),z_std\n",
    );
    for axis in 0..3 {
        for sign in [1.0, -1.0] {
            let mut cells = Vec::new();
            for k in 0..3 {
                let truth: f64 = if k == axis { sign } else { 0.0 };
                let mean = truth * 1.01 + 0.02 * (k as f64 - 1.0);
                cells.push(format!("{truth},{mean},0.00{}", k + 2));
            }
            text.push_str(&cells.join(","));
            text.push('\n');
        }
    }
    text.into_bytes()
}

/// A writer's error as an I/O error (the seeds are the writers' own output: a failure is a
/// broken writer or a full disk).
fn io(e: impl std::fmt::Display) -> std::io::Error {
    std::io::Error::other(e.to_string())
}
