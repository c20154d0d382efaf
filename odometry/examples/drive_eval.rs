//! Evaluation of the odometry stage on simulated 10-minute ground-robot drives with perfect
//! rest flags: per case, the end position error as % of distance travelled (median, p90) over
//! many seeds, and how well the reported 1-sigma covers it.
//!
//! Each seed powers on one simulated MPU-9250, runs an N-orientation calibration session
//! (from which the gyro correction is fitted, unless `--gyro-cal none`), then mounts the
//! sensor on the robot and drives.
//!
//! cargo run --release -p odometry --example drive_eval -- [--seeds N] [--rate HZ]
//!     [--case straight|turns|in-place|vib0|bias20|bias20-straight|all] [--gyro-cal session|none|model]
//!     [--per-seed]

#[path = "../tests/common/mod.rs"]
mod common;

use common::{Case, Simulation};
use ipc_types::odometry_flags;
use nalgebra::{Matrix2, Matrix3, Vector2};
use odometry::gyrocal::{GyroCalConfig, calibrate_gyro};
use odometry::stage::{OdometryConfig, OdometryStage};

#[derive(Clone, Copy, PartialEq)]
enum GyroCal {
    Session,
    None,
    /// The inverse of the model's true scale/misalignment: a diagnostic upper bound only.
    Model,
}

struct Args {
    seeds: u64,
    rate_hz: f64,
    cases: Vec<String>,
    gyro_cal: GyroCal,
    per_seed: bool,
    /// Use the simulator's default motions (up to three legs of 2-10 s).
    sim_default_legs: bool,
    /// Error terms of the sensor model switched off.
    off: Vec<String>,
    /// Configuration overrides, `name=value`.
    overrides: Vec<(String, f64)>,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        seeds: 20,
        rate_hz: 200.0,
        cases: Vec::new(),
        gyro_cal: GyroCal::Session,
        per_seed: false,
        sim_default_legs: false,
        overrides: Vec::new(),
        off: Vec::new(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        let mut value = |name: &str| it.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--seeds" => {
                a.seeds = value("--seeds")?
                    .parse()
                    .map_err(|e| format!("--seeds: {e}"))?
            }
            "--rate" => {
                a.rate_hz = value("--rate")?
                    .parse()
                    .map_err(|e| format!("--rate: {e}"))?
            }
            "--case" => a.cases.push(value("--case")?),
            "--gyro-cal" => {
                a.gyro_cal = match value("--gyro-cal")?.as_str() {
                    "session" => GyroCal::Session,
                    "none" => GyroCal::None,
                    "model" => GyroCal::Model,
                    other => return Err(format!("--gyro-cal: unknown `{other}`")),
                }
            }
            "--per-seed" => a.per_seed = true,
            "--sim-default-legs" => a.sim_default_legs = true,
            "--off" => a.off.push(value("--off")?),
            "--set" => {
                let kv = value("--set")?;
                let (k, v) = kv
                    .split_once('=')
                    .ok_or(format!("--set {kv}: expected name=value"))?;
                let v: f64 = v.parse().map_err(|e| format!("--set {kv}: {e}"))?;
                a.overrides.push((k.to_string(), v));
            }
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    if a.cases.is_empty() || a.cases.iter().any(|c| c == "all") {
        a.cases = [
            "straight",
            "turns",
            "in-place",
            "vib0",
            "vib-dc-free",
            "bias20-straight",
            "bias20",
        ]
        .map(String::from)
        .to_vec();
    }
    Ok(a)
}

/// The simulated case and the stage configuration for a case name.
fn case(name: &str, args: &Args) -> Result<(Case, OdometryConfig), String> {
    let mut c = Case::straight();
    c.rate_hz = args.rate_hz;
    if args.sim_default_legs {
        c.max_legs = 3;
        c.leg_s = [2.0, 10.0];
    }
    let mut cfg = OdometryConfig::mpu9250(mems_sim::model::G_MPS2);
    match name {
        "straight" => {}
        "turns" => c.turns = true,
        "in-place" => {
            c.turns = true;
            c.in_place_turns = true;
        }
        "vib0" => {
            c.turns = true;
            c.vibration = 0.0;
        }
        "vib-dc-free" => {
            c.turns = true;
            c.vibration_dc_free = true;
        }
        "bias20" | "bias20-straight" => {
            c.turns = name == "bias20";
            c.accel_turn_on_mg = Some(20.0);
            // An uncalibrated accelerometer: the configuration says so.
            cfg.accel_bias_sigma_mps2 = [20e-3 * mems_sim::model::G_MPS2; 3];
        }
        other => return Err(format!("unknown case `{other}`")),
    }
    // The robot's vibration, as a measurement of it would give (see Case).
    let (accel, gyro) = c.vibration_density_per_mps();
    cfg.noise.vibration_accel_density_per_mps = accel;
    cfg.noise.vibration_gyro_density_per_mps = gyro;
    c.off.clone_from(&args.off);
    Ok((c, cfg))
}

/// Result of one drive.
struct Outcome {
    distance_m: f64,
    error_m: Vector2<f64>,
    sigma_m: Vector2<f64>,
    nees: f64,
    /// Per rest end (just before motion resumes) and axis: whether |error| <= sigma.
    rest_covered: (usize, usize),
    /// Largest error of the session's gyro correction against the model's (NaN without one).
    gyro_cal_error: f64,
    /// RMS horizontal error of the revised history and of the forward states it replaces,
    /// each relative to the error at the start of its motion, m.
    history_rms_m: (f64, f64),
}

fn run(c: &Case, mut cfg: OdometryConfig, seed: u64, gyro_cal: GyroCal) -> Outcome {
    let mut sim = Simulation::new(c, seed);
    let session = sim.session();
    let model_correction = c.gyro_correction_reference();
    let mut gyro_cal_error = f64::NAN;
    cfg.gyro_correction = match gyro_cal {
        GyroCal::None => Matrix3::identity(),
        GyroCal::Session => {
            let cal = calibrate_gyro(&session, &GyroCalConfig::new(mems_sim::model::G_MPS2))
                .expect("the simulated session calibrates the gyro");
            gyro_cal_error = (cal.correction - model_correction).abs().max();
            cal.correction
        }
        GyroCal::Model => model_correction,
    };
    let mut stage = OdometryStage::new(cfg);
    let mut distance_m = 0.0;
    let mut prev_truth: Option<[f64; 3]> = None;
    let mut last = None;
    let mut end_truth = None;
    let mut was_rest = false;
    let mut rest_covered = (0, 0);
    // Horizontal truth and forward estimate per sample (by sequence number), to score the
    // revised history against both.
    let mut truth_xy: Vec<[f64; 2]> = Vec::new();
    let mut forward_xy: Vec<[f64; 2]> = Vec::new();
    let mut first_seq = None;
    let mut revised: Vec<(u64, [f64; 2])> = Vec::new();
    // Sequence numbers where motions start: the history of a motion is scored relative to the
    // error at its start, which the revision leaves as it is.
    let mut motion_starts: Vec<u64> = Vec::new();
    sim.drive(|s, truth| {
        first_seq.get_or_insert(s.seq);
        truth_xy.push([truth.position_m[0], truth.position_m[1]]);
        if let Some(p) = prev_truth {
            distance_m += (truth.position_m[0] - p[0]).hypot(truth.position_m[1] - p[1]);
        }
        prev_truth = Some(truth.position_m);
        stage
            .process(s, &mut |o| {
                if o.flags & odometry_flags::REVISION == 0 {
                    last = Some(*o);
                } else {
                    revised.push((o.seq, [o.position_m[0], o.position_m[1]]));
                }
            })
            .expect("valid samples");
        let o = last.expect("a state per sample");
        forward_xy.push([o.position_m[0], o.position_m[1]]);
        if was_rest && !truth.at_rest {
            motion_starts.push(s.seq);
        }
        if was_rest && !truth.at_rest && o.flags & odometry_flags::ALIGNED != 0 {
            for i in 0..2 {
                rest_covered.1 += 1;
                if (o.position_m[i] - truth.position_m[i]).abs() <= o.position_sigma_m[i] {
                    rest_covered.0 += 1;
                }
            }
        }
        was_rest = truth.at_rest;
        end_truth = Some(*truth);
    });
    let o = last.expect("states");
    let truth = end_truth.expect("truth");
    let first_seq = first_seq.expect("samples");
    let (mut se_rev, mut se_fwd) = (0.0, 0.0);
    for (seq, p) in &revised {
        let i = (seq - first_seq) as usize;
        let k = motion_starts.partition_point(|m| m <= seq);
        let i0 = (motion_starts[k.max(1) - 1] - first_seq) as usize;
        let e0 = [0, 1].map(|a| forward_xy[i0][a] - truth_xy[i0][a]);
        let e_rev = [0, 1].map(|a| p[a] - truth_xy[i][a] - e0[a]);
        let e_fwd = [0, 1].map(|a| forward_xy[i][a] - truth_xy[i][a] - e0[a]);
        se_rev += e_rev[0].powi(2) + e_rev[1].powi(2);
        se_fwd += e_fwd[0].powi(2) + e_fwd[1].powi(2);
    }
    let n_rev = revised.len().max(1) as f64;
    let history_rms_m = ((se_rev / n_rev).sqrt(), (se_fwd / n_rev).sqrt());
    let error_m = Vector2::new(
        o.position_m[0] - truth.position_m[0],
        o.position_m[1] - truth.position_m[1],
    );
    let cov: Matrix2<f64> = stage
        .filter()
        .expect("aligned")
        .cov
        .fixed_view::<2, 2>(0, 0)
        .into_owned();
    let nees = error_m.dot(&(cov.try_inverse().expect("positive definite") * error_m));
    Outcome {
        distance_m,
        error_m,
        sigma_m: Vector2::new(o.position_sigma_m[0], o.position_sigma_m[1]),
        nees,
        rest_covered,
        gyro_cal_error,
        history_rms_m,
    }
}

/// The `p`-quantile (0..1) of sorted values, nearest rank.
fn quantile(sorted: &[f64], p: f64) -> f64 {
    let rank = ((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

fn main() {
    let args = parse_args().unwrap_or_else(|e| {
        eprintln!("drive_eval: {e}");
        std::process::exit(2);
    });
    println!(
        "{} seeds, {} Hz, gyro calibration: {}",
        args.seeds,
        args.rate_hz,
        match args.gyro_cal {
            GyroCal::Session => "from the session",
            GyroCal::None => "none",
            GyroCal::Model => "model truth (diagnostic)",
        }
    );
    println!(
        "| case | median % | p90 % | max % | end within 1 sigma (per axis) | NEES/2 mean | rest ends within 1 sigma | motion drift RMS revised / forward, m |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for name in &args.cases {
        let (c, cfg) = case(name, &args).unwrap_or_else(|e| {
            eprintln!("drive_eval: {e}");
            std::process::exit(2);
        });
        let mut cfg = cfg;
        for (k, v) in &args.overrides {
            match k.as_str() {
                "gyro_rw" => cfg.noise.gyro_bias_random_walk = *v,
                "accel_rw" => cfg.noise.accel_bias_random_walk = *v,
                "gyro_n" => cfg.noise.gyro_noise_density = *v,
                "accel_n" => cfg.noise.accel_noise_density = *v,
                "zupt" => cfg.zupt_sigma_mps = *v,
                "vib_a" => cfg.noise.vibration_accel_density_per_mps = *v,
                "vib_g" => cfg.noise.vibration_gyro_density_per_mps = *v,
                "ba_sigma" => cfg.accel_bias_sigma_mps2 = [*v; 3],
                other => {
                    eprintln!("drive_eval: unknown setting `{other}`");
                    std::process::exit(2);
                }
            }
        }
        let mut pct = Vec::new();
        let (mut covered, mut axes, mut nees, mut rc, mut rn) = (0, 0, 0.0, 0, 0);
        let (mut hist_rev, mut hist_fwd) = (0.0, 0.0);
        for seed in 0..args.seeds {
            let o = run(&c, cfg, seed, args.gyro_cal);
            let p = 100.0 * o.error_m.norm() / o.distance_m;
            if args.per_seed {
                eprintln!(
                    "{name} seed {seed}: distance {:.1} m, error ({:.3}, {:.3}) m = {p:.2}%, sigma ({:.3}, {:.3}) m, NEES {:.2}, gyro correction error {:.1e}",
                    o.distance_m,
                    o.error_m.x,
                    o.error_m.y,
                    o.sigma_m.x,
                    o.sigma_m.y,
                    o.nees,
                    o.gyro_cal_error
                );
            }
            pct.push(p);
            for i in 0..2 {
                axes += 1;
                if o.error_m[i].abs() <= o.sigma_m[i] {
                    covered += 1;
                }
            }
            nees += o.nees;
            hist_rev += o.history_rms_m.0.powi(2);
            hist_fwd += o.history_rms_m.1.powi(2);
            rc += o.rest_covered.0;
            rn += o.rest_covered.1;
        }
        pct.sort_by(f64::total_cmp);
        println!(
            "| {name} | {:.2} | {:.2} | {:.2} | {:.0}% | {:.2} | {:.0}% | {:.2} / {:.2} |",
            quantile(&pct, 0.5),
            quantile(&pct, 0.9),
            pct[pct.len() - 1],
            100.0 * covered as f64 / axes as f64,
            nees / (2.0 * args.seeds as f64),
            100.0 * rc as f64 / rn.max(1) as f64,
            (hist_rev / args.seeds as f64).sqrt(),
            (hist_fwd / args.seeds as f64).sqrt(),
        );
    }
}
