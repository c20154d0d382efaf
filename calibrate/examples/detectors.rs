//! Measures the zero-state detectors on labelled simulated drives: detection rate (fraction of
//! true-rest samples flagged rest, once the detector is ready) and false alarms (fraction of
//! moving samples flagged rest: all motion, slow cruise below 0.3 m/s, in-place turns).
//!
//! Each seed simulates a ground-robot drive (10 min by default, turns and in-place turns on)
//! measured by the MPU-9250 as it is after calibration (`SensorModel::mpu9250_calibrated`) at
//! 1 kHz through the DLPF our driver configures (184 Hz gyro, 218.1 Hz accelerometer; at 4 kHz
//! the accelerometer bypassed, `mems_sim::dlpf::DlpfConfig::driver`), quantized like the
//! device, and runs it through the calibration stage (identity
//! calibration) once per detector variant.
//!
//! ```text
//! cargo run --release -p calibrate --example detectors -- [--seeds 8] [--duration-s 600] [--vibration 1,0] [--json]
//! cargo run --release -p calibrate --example detectors -- --rate 4000 --no-gyro   # the MPU-9250 at 4 kHz
//! ```
//!
//! With `--no-gyro` the samples carry no gyroscope (`GYRO_VALID` clear), as the MPU-9250's
//! accelerometer-only 4 kHz mode; the variants are then Yu's and the accelerometer-only GLRT's.

use mems_stage::Stage;
use std::time::Instant;

use anyhow::Result;
use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig, Settler};
use calibrate::zero_state::{DetectorConfig, DetectorKind, GlrtStatistic};
use clap::Parser;
use ipc_types::units::{AccelRange, GyroRange};
use ipc_types::{CorrectedImuSample, corrected_flags, raw_flags};
use mems_sim::dlpf::DlpfConfig;
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::scenario::{Drive, DriveParams, DriveSegment, ns_from_s};
use mems_sim::vibration::VibrationModel;
use mems_sim::{DlpfGrid, SimSensor, adc};
use serde::Serialize;

#[derive(Parser)]
struct Cli {
    /// Number of seeds (1..=N).
    #[arg(long, default_value_t = 8)]
    seeds: u64,
    /// Length of each drive, s.
    #[arg(long, default_value_t = 600.0)]
    duration_s: f64,
    /// Vibration levels (1: 0.1 m/s^2 and 0.5 deg/s RMS per axis at 1 m/s).
    #[arg(long, value_delimiter = ',', default_value = "1,0")]
    vibration: Vec<f64>,
    /// Output rate, Hz.
    #[arg(long, default_value_t = 1000.0)]
    rate: f64,
    /// Print JSON instead of a Markdown table.
    #[arg(long)]
    json: bool,
    /// Samples without the gyroscope (accelerometer-only mode): Yu and glrt-accel variants.
    #[arg(long)]
    no_gyro: bool,
    /// White samples: no DLPF (no MPU-9250 produces them; by default the part filters as our
    /// driver configures it for --rate, `mems_sim::dlpf::DlpfConfig::driver`).
    #[arg(long)]
    dlpf_off: bool,
}

/// A detector variant under test.
struct Variant {
    name: String,
    config: DetectorConfig,
}

fn variants(no_gyro: bool) -> Vec<Variant> {
    let g = G_MPS2;
    let mut out = Vec::new();
    for alpha in [1e-3, 1e-2, 1e-1, 3e-1] {
        let mut c = DetectorConfig::new(DetectorKind::Yu, g);
        c.yu.false_alarm = alpha;
        out.push(Variant {
            name: format!("yu a={alpha:e}"),
            config: c,
        });
    }
    if no_gyro {
        for (w, alpha) in [
            (0.125, 1e-2),
            (0.25, 1e-2),
            (0.5, 1e-3),
            (0.5, 1e-2),
            (0.5, 1e-1),
            (1.0, 1e-2),
        ] {
            let mut c = DetectorConfig::new(DetectorKind::GlrtAccel, g);
            c.glrt.window_s = w;
            c.glrt.false_alarm = alpha;
            out.push(Variant {
                name: format!("glrt-accel split W={w}s a={alpha:e}"),
                config: c,
            });
        }
        return out;
    }
    for (w, statistic, alpha) in [
        (0.2, GlrtStatistic::Split, 1e-3),
        (0.2, GlrtStatistic::Combined, 1e-3),
        (0.1, GlrtStatistic::Split, 1e-3),
        (0.5, GlrtStatistic::Split, 1e-3),
        (1.0, GlrtStatistic::Split, 1e-3),
        (0.2, GlrtStatistic::Split, 1e-2),
        (0.5, GlrtStatistic::Split, 1e-2),
        (0.5, GlrtStatistic::Split, 1e-1),
        (0.5, GlrtStatistic::Combined, 1e-2),
    ] {
        let mut c = DetectorConfig::new(DetectorKind::Glrt, g);
        c.glrt.window_s = w;
        c.glrt.statistic = statistic;
        c.glrt.false_alarm = alpha;
        let stat = match statistic {
            GlrtStatistic::Split => "split",
            GlrtStatistic::Combined => "combined",
        };
        out.push(Variant {
            name: format!("glrt {stat} W={w}s a={alpha:e}"),
            config: c,
        });
    }
    out
}

/// Sample counts of one variant: (flagged rest, total) per category.
#[derive(Debug, Clone, Copy, Default, Serialize)]
struct Counts {
    rest: [u64; 2],
    moving: [u64; 2],
    clearly_moving: [u64; 2],
    slow_cruise: [u64; 2],
    in_place_turn: [u64; 2],
}

impl Counts {
    /// Scores one settled sample's zero-state flag against its label (rest counts only once
    /// the detector is ready).
    fn score(&mut self, label: &Label, out: &CorrectedImuSample) {
        let flagged = u64::from(out.flags & corrected_flags::ZERO_STATE != 0);
        if label.rest {
            if out.flags & corrected_flags::DETECTOR_READY != 0 {
                self.rest[0] += flagged;
                self.rest[1] += 1;
            }
            return;
        }
        self.moving[0] += flagged;
        self.moving[1] += 1;
        for (is, count) in [
            (label.clearly_moving, &mut self.clearly_moving),
            (label.slow_cruise, &mut self.slow_cruise),
            (label.in_place_turn, &mut self.in_place_turn),
        ] {
            if is {
                count[0] += flagged;
                count[1] += 1;
            }
        }
    }

    fn add(&mut self, o: &Counts) {
        for (a, b) in [
            (&mut self.rest, o.rest),
            (&mut self.moving, o.moving),
            (&mut self.clearly_moving, o.clearly_moving),
            (&mut self.slow_cruise, o.slow_cruise),
            (&mut self.in_place_turn, o.in_place_turn),
        ] {
            a[0] += b[0];
            a[1] += b[1];
        }
    }
}

/// Speed from which a moving sample counts as clearly moving, m/s.
const CLEAR_SPEED_MPS: f64 = 0.05;
/// Yaw rate from which a moving sample counts as clearly moving, deg/s.
const CLEAR_RATE_DPS: f64 = 1.0;

/// What the truth says about one sample.
#[derive(Clone, Copy)]
struct Label {
    rest: bool,
    clearly_moving: bool,
    slow_cruise: bool,
    in_place_turn: bool,
}

impl Label {
    /// The label of a sample in drive segment `s`, at rest or not, with the truth's
    /// horizontal speed m/s and yaw rate deg/s.
    fn new(s: &DriveSegment, at_rest: bool, speed_mps: f64, rate_dps: f64) -> Self {
        let cruise = !s.at_rest && s.speed_change_mps == 0.0 && s.heading_change_rad == 0.0;
        let spin = !s.at_rest && s.speed0_mps == 0.0 && s.speed_change_mps == 0.0;
        Self {
            rest: at_rest,
            clearly_moving: speed_mps >= CLEAR_SPEED_MPS || rate_dps >= CLEAR_RATE_DPS,
            slow_cruise: cruise && s.speed0_mps < 0.3,
            in_place_turn: spin && s.heading_change_rad != 0.0,
        }
    }
}

fn identity_calibration() -> CalibrationFile {
    CalibrationFile::identity(G_MPS2)
}

/// What one variant gives on one seed.
struct SeedResult {
    counts: Counts,
    /// Refined gyroscope bias minus the true turn-on bias at the end of the drive, deg/s.
    gyro_bias_error_dps: [f64; 3],
    learn_restarts: usize,
}

/// Runs one seed at one vibration level through every variant.
fn run_seed(cli: &Cli, seed: u64, vibration: f64, variants: &[Variant]) -> Result<Vec<SeedResult>> {
    let mut params = DriveParams::new(cli.duration_s);
    params.turns = true;
    params.in_place_turns = true;
    let drive = Drive::new(&params, seed)?;
    let segments = drive.segments().to_vec();
    let mut sim = SimSensor::new(
        drive,
        &SensorModel::mpu9250_calibrated(),
        &VibrationModel::moderate(vibration),
        seed,
    )?;
    sim.set_dlpf((!cli.dlpf_off).then(|| DlpfGrid::from_power_on(DlpfConfig::driver(cli.rate))));
    let calib = identity_calibration();
    let mut stages: Vec<CalibrationStage> = variants
        .iter()
        .map(|v| CalibrationStage::new(&calib, v.config, RefineConfig::default()))
        .collect::<Result<_, _>>()?;
    // The detectors are scored on every sample's final verdict.
    let mut settlers = vec![Settler::default(); variants.len()];
    let mut counts = vec![Counts::default(); variants.len()];
    let n = (cli.duration_s * cli.rate) as u64;
    let mut labels = std::collections::VecDeque::new();
    let mut seg = 0;
    for k in 0..n {
        let t = k as f64 / cli.rate;
        let (analog, truth) = sim.sample_with_truth(t, cli.rate);
        while seg + 1 < segments.len() && segments[seg + 1].start_s <= t {
            seg += 1;
        }
        let speed = truth.velocity_mps[0].hypot(truth.velocity_mps[1]);
        let rate = truth.angular_rate_rps[2].abs().to_degrees();
        labels.push_back(Label::new(&segments[seg], truth.at_rest, speed, rate));
        let mut raw =
            adc::quantize_sample(&analog, AccelRange::G2, GyroRange::Dps250, ns_from_s(t), k);
        if cli.no_gyro {
            raw.flags &= !raw_flags::GYRO_VALID;
            raw.gyro_dps = [0.0; 3];
            raw.gyro_counts = [0; 3];
        }
        // Every stage settles the same samples at the same time (whole batches).
        let mut released = 0;
        for ((stage, c), settler) in stages.iter_mut().zip(counts.iter_mut()).zip(&mut settlers) {
            let mut i = 0;
            stage.process(&raw, &mut |out| {
                settler.push(out, &mut |out| {
                    c.score(&labels[i], out);
                    i += 1;
                })
            })?;
            released = i;
        }
        labels.drain(..released);
    }
    let (_, true_gyro_dps) = sim.sensor().turn_on_bias();
    Ok(stages
        .iter()
        .zip(counts)
        .map(|(stage, counts)| {
            let (_, gyro_rps, _) = stage.refinement();
            SeedResult {
                counts,
                gyro_bias_error_dps: std::array::from_fn(|i| {
                    gyro_rps[i].to_degrees() - true_gyro_dps[i]
                }),
                learn_restarts: stage.detector().learn_rejections().0,
            }
        })
        .collect())
}

#[derive(Serialize)]
struct Row {
    vibration: f64,
    detector: String,
    detection_rate: f64,
    false_alarm_moving: f64,
    false_alarm_clearly_moving: f64,
    false_alarm_slow_cruise: f64,
    false_alarm_in_place_turn: f64,
    counts: Counts,
    per_seed_slow_cruise: Vec<f64>,
    gyro_bias_error_rms_dps: f64,
    learn_restarts: usize,
}

fn ratio(c: [u64; 2]) -> f64 {
    if c[1] == 0 {
        f64::NAN
    } else {
        c[0] as f64 / c[1] as f64
    }
}

fn main() -> std::process::ExitCode {
    mems_log::init("detectors");
    mems_log::exit(evaluate(Cli::parse()))
}

fn evaluate(cli: Cli) -> Result<()> {
    let variants = variants(cli.no_gyro);
    let mut rows = Vec::new();
    for &vibration in &cli.vibration {
        let mut total = vec![Counts::default(); variants.len()];
        let mut per_seed = vec![Vec::new(); variants.len()];
        let mut gyro_sq = vec![0.0; variants.len()];
        let mut restarts = vec![0; variants.len()];
        for seed in 1..=cli.seeds {
            let start = Instant::now();
            let results = run_seed(&cli, seed, vibration, &variants)?;
            for (i, r) in results.iter().enumerate() {
                total[i].add(&r.counts);
                per_seed[i].push(ratio(r.counts.slow_cruise));
                gyro_sq[i] += r.gyro_bias_error_dps.iter().map(|e| e * e).sum::<f64>();
                restarts[i] += r.learn_restarts;
            }
            tracing::info!(
                "vibration {vibration}, seed {seed}: {:.1} s",
                start.elapsed().as_secs_f64()
            );
        }
        for (i, v) in variants.iter().enumerate() {
            let c = total[i];
            rows.push(Row {
                vibration,
                detector: v.name.clone(),
                detection_rate: ratio(c.rest),
                false_alarm_moving: ratio(c.moving),
                false_alarm_clearly_moving: ratio(c.clearly_moving),
                false_alarm_slow_cruise: ratio(c.slow_cruise),
                false_alarm_in_place_turn: ratio(c.in_place_turn),
                counts: c,
                per_seed_slow_cruise: per_seed[i].clone(),
                gyro_bias_error_rms_dps: (gyro_sq[i] / (3 * cli.seeds) as f64).sqrt(),
                learn_restarts: restarts[i],
            });
        }
    }
    if cli.json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
        return Ok(());
    }
    println!(
        "| vibration | detector | detection rate | false alarm: moving | clearly moving | slow cruise < 0.3 m/s | in-place turns | gyro bias error (deg/s RMS) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for r in &rows {
        println!(
            "| {} | {} | {:.1}% | {:.2}% | {:.2}% | {:.2}% | {:.2}% | {} |",
            r.vibration,
            r.detector,
            100.0 * r.detection_rate,
            100.0 * r.false_alarm_moving,
            100.0 * r.false_alarm_clearly_moving,
            100.0 * r.false_alarm_slow_cruise,
            100.0 * r.false_alarm_in_place_turn,
            if cli.no_gyro {
                "n/a (no gyro)".to_string()
            } else {
                format!("{:.4}", r.gyro_bias_error_rms_dps)
            }
        );
        if r.learn_restarts > 0 {
            tracing::info!("{}: {} learning restarts", r.detector, r.learn_restarts);
        }
    }
    Ok(())
}
