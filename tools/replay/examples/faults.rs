//! Fault-injection benchmark of the live pipeline's 1-sigma, with real processes:
//! `mems-replay` -> `mems-calibrate serve` -> `mems-odometry serve` -> this process's
//! subscriber, replaying simulated drives (with their truth) of the part it calibrated. One
//! fault per run, injected while the robot moves:
//!
//! - `none`: the reference;
//! - `kill calibrate`, `kill odometry`: kill -9 of the stage, restarted 0.2 s later (as
//!   `mems-stack` restarts a child);
//! - `stop calibrate 2 s`, `stop odometry 2 s`: SIGSTOP, SIGCONT 2 s later (a stall);
//! - `stop subscriber 2 s`: this process stops receiving for 2 s;
//! - `6 CPU hogs`: six busy processes for the whole run.
//!
//! ```sh
//! cargo build --release -p mems-replay -p mems-sim -p calibrate -p odometry
//! cargo run --release -p mems-replay --example faults [-- --seeds 5 --seconds 60 --speed 2]
//!     [--only TEXT]... [--dump DIR] [--json]
//! ```
//!
//! Each run's live (non-revision) states are compared with the drive's truth in the frame the
//! odometry aligned in (re-anchored at each new alignment: a restarted odometry process aligns
//! afresh). Figures per fault: the horizontal NEES (per-axis sigmas, 2 degrees of freedom) at
//! the end of the run and at the end of every rest after the fault, and the share within the
//! chi-square 95 % bound (5.99); a consistent 1-sigma has 95 % of them within it. Printed as a
//! Markdown table; with `--json` the last line is a JSON object of the same. `--dump DIR` writes
//! each run's aligned live states beside the truth (`t_s,flags,x,y,sx,sy,tx,ty`); `--only TEXT`
//! runs the faults whose label contains TEXT.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use anyhow::{Context, Result, bail};
use common::run;
use ipc_types::wake::{self, WaitMode};
use ipc_types::{OdometryState, odometry_flags, service};
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use recording::Truth;
use serde_json::json;

/// The chi-square 95 % bound with 2 degrees of freedom.
const NEES_95: f64 = 5.991;
/// Rest at the start of each drive, s (the calibration stage learns for 2 s of it).
const INITIAL_REST_S: f64 = 10.0;
/// The fault comes this long into the first motion after `FAULT_AFTER_S`.
const INTO_MOTION_S: f64 = 1.0;
const FAULT_AFTER_S: f64 = 20.0;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Fault {
    None,
    Kill(&'static str),
    Stop(&'static str),
    StopSubscriber,
    Hogs,
}

impl Fault {
    const ALL: [Fault; 7] = [
        Fault::None,
        Fault::Kill("mems-calibrate"),
        Fault::Kill("mems-odometry"),
        Fault::Stop("mems-calibrate"),
        Fault::Stop("mems-odometry"),
        Fault::StopSubscriber,
        Fault::Hogs,
    ];

    fn label(self) -> String {
        let short = |n: &str| n.trim_start_matches("mems-").to_string();
        match self {
            Fault::None => "none".into(),
            Fault::Kill(n) => format!("kill -9 {} (restarted after 0.2 s)", short(n)),
            Fault::Stop(n) => format!("stop {} 2 s", short(n)),
            Fault::StopSubscriber => "stop subscriber 2 s".into(),
            Fault::Hogs => "6 CPU hogs".into(),
        }
    }
}

/// The frame an odometry epoch aligned in: truth positions relative to the truth at alignment,
/// turned by the heading difference (as `mems-odometry offline` compares with truth).
struct Frame {
    origin: Vector3<f64>,
    to_ours: Rotation3<f64>,
}

impl Frame {
    fn new(ours: &OdometryState, truth: &Truth) -> Self {
        let q = |a: [f64; 4]| {
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(a[0], a[1], a[2], a[3]))
        };
        let m = (q(ours.attitude_wxyz) * q(truth.attitude_wxyz).inverse()).to_rotation_matrix();
        Self {
            origin: Vector3::from(truth.position_m),
            to_ours: Rotation3::from_axis_angle(&Vector3::z_axis(), m[(1, 0)].atan2(m[(0, 0)])),
        }
    }

    /// Horizontal NEES of `s` against `truth` with the state's per-axis sigmas.
    fn nees(&self, s: &OdometryState, truth: &Truth) -> (f64, f64) {
        let t = self.to_ours * (Vector3::from(truth.position_m) - self.origin);
        let e = Vector3::from(s.position_m) - t;
        let nees = (0..2).map(|i| (e[i] / s.position_sigma_m[i]).powi(2)).sum();
        (nees, e.xy().norm())
    }
}

/// The stage processes of a run, killed when it ends early (an error).
struct Stages(Vec<(&'static str, Child)>);

impl Drop for Stages {
    fn drop(&mut self) {
        for (_, child) in &mut self.0 {
            signal(child, libc::SIGCONT);
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// What one run measured.
#[derive(Debug, Default)]
struct Outcome {
    /// NEES and horizontal error at the end (None: not aligned at the end).
    end: Option<(f64, f64)>,
    /// NEES at the end of each rest after the fault.
    rest_ends: Vec<f64>,
    /// Live states received, and sequence numbers missing among them.
    states: u64,
    missing: u64,
    gaps_flagged: u64,
    /// `t_s,flags,x,y,sx,sy,tx,ty` per live state, for `--dump`.
    trace: Vec<String>,
}

fn signal(child: &Child, sig: i32) {
    // SAFETY: kill(2) on our own child; no memory is involved.
    unsafe { libc::kill(child.id() as i32, sig) };
}

/// The truth at sample time `t_ns` (the sample's own; the recording has one per sample).
fn truth_at(truth: &[Truth], t_ns: u64) -> Option<&Truth> {
    truth
        .binary_search_by_key(&t_ns, |t| t.t_ns)
        .ok()
        .map(|i| &truth[i])
}

/// The sample time of the fault: `INTO_MOTION_S` into motion, the first after
/// `FAULT_AFTER_S` (at its first moving sample if it stops sooner).
fn fault_time_ns(truth: &[Truth]) -> Result<u64> {
    let t0 = truth.first().context("no truth")?.t_ns;
    let after = t0 + (FAULT_AFTER_S * 1e9) as u64;
    let i = truth
        .iter()
        .position(|t| t.t_ns >= after && !t.at_rest)
        .context("the drive does not move after the warm-up")?;
    let into = truth[i].t_ns + (INTO_MOTION_S * 1e9) as u64;
    let still_moving = truth[i..]
        .iter()
        .take_while(|t| t.t_ns <= into)
        .all(|t| !t.at_rest);
    Ok(if still_moving { into } else { truth[i].t_ns })
}

/// One replay of `drive` through the stages with `fault`, at `speed` times real time.
fn one_run(
    bins: &Path,
    drive: &Path,
    truth: &[Truth],
    calib: &Path,
    fault: Fault,
    speed: f64,
    tag: &str,
) -> Result<Outcome> {
    let fault_ns = fault_time_ns(truth)?;
    let ns = format!("faults-{}-{tag}", std::process::id());
    let node = service::node()?;
    let name = service::full_name(&ns, service::ODOMETRY);
    let svc = service::open::<OdometryState>(&node, &name)?;
    let sub = service::subscriber(&svc)?;
    let listener = wake::listener(&node, &name, WaitMode::Event)?;
    let calib = calib.to_str().context("calibration path is not UTF-8")?;
    // The calibration stage keeps its learned state where its restart finds it, as in
    // mems-stack.
    let state = std::env::temp_dir().join(format!("{ns}-calibrate-state.json"));
    std::fs::remove_file(&state).ok();
    let state_arg = state.to_str().context("state path is not UTF-8")?;
    let spawn = |stage: &str| -> Result<Child> {
        let args: &[&str] = match stage {
            "mems-calibrate" => &[
                "serve",
                "--calib",
                calib,
                "--learn-s",
                "2",
                "--state",
                state_arg,
            ],
            _ => &["serve", "--calib", calib],
        };
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(std::env::temp_dir().join(format!("{ns}-{stage}.log")))?;
        Command::new(bins.join(stage))
            .args(args)
            .args(["--namespace", &ns])
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .with_context(|| format!("cannot start {stage}"))
    };
    let mut stages = Stages(vec![
        ("mems-odometry", spawn("mems-odometry")?),
        ("mems-calibrate", spawn("mems-calibrate")?),
    ]);
    let hogs: Vec<Child> = if fault == Fault::Hogs {
        (0..6)
            .map(|_| {
                Command::new("sh")
                    .args(["-c", "while :; do :; done"])
                    .spawn()
                    .context("cannot start a CPU hog")
            })
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    std::thread::sleep(Duration::from_millis(1500));
    let mut replay = Command::new(bins.join("mems-replay"))
        .arg(drive)
        .args(["--speed", &speed.to_string(), "--wait-subscribers", "1"])
        .args(["--namespace", &ns])
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(
            std::env::temp_dir().join(format!("{ns}-mems-replay.log")),
        )?)
        .spawn()
        .context("cannot start mems-replay")?;

    let mut out = Outcome::default();
    let mut frame: Option<Frame> = None;
    let mut last: Option<OdometryState> = None;
    let mut injected: Option<Instant> = None;
    let mut restored = fault == Fault::None || fault == Fault::Hogs;
    let mut replay_done = false;
    let mut idle_since = Instant::now();
    let judge_rest_end = |s: &OdometryState, frame: &Option<Frame>, out: &mut Outcome| {
        if let (Some(f), Some(t)) = (frame, truth_at(truth, s.stamps.sample_ns))
            && s.stamps.sample_ns > fault_ns
        {
            out.rest_ends.push(f.nees(s, t).0);
        }
    };
    wake::serve_loop(&[listener], Duration::from_millis(20), || -> Result<_> {
        // The fault, once the states reach its sample time; its end after 0.2 s or 2 s.
        if let Some(at) = injected
            && !restored
        {
            let idx = |n: &str| stages.0.iter().position(|(s, _)| *s == n).expect("a stage");
            match fault {
                Fault::Kill(n) if at.elapsed() >= Duration::from_millis(200) => {
                    let i = idx(n);
                    stages.0[i].1 = spawn(n)?;
                    restored = true;
                }
                Fault::Stop(n) if at.elapsed() >= Duration::from_secs(2) => {
                    signal(&stages.0[idx(n)].1, libc::SIGCONT);
                    restored = true;
                }
                Fault::StopSubscriber => {
                    std::thread::sleep(Duration::from_secs(2));
                    restored = true;
                }
                _ => {}
            }
        }
        let mut any = false;
        while let Some(s) = sub.receive()? {
            any = true;
            idle_since = Instant::now();
            let s = *s;
            if s.flags & odometry_flags::REVISION != 0 {
                continue;
            }
            out.states += 1;
            if s.flags & odometry_flags::GAP_BEFORE != 0 {
                out.gaps_flagged += 1;
            }
            if let Some(p) = last
                && s.seq > p.seq + 1
            {
                out.missing += s.seq - p.seq - 1;
            }
            if injected.is_none() && s.stamps.sample_ns >= fault_ns {
                injected = Some(Instant::now());
                match fault {
                    Fault::Kill(n) => {
                        let i = stages
                            .0
                            .iter()
                            .position(|(st, _)| *st == n)
                            .expect("a stage");
                        signal(&stages.0[i].1, libc::SIGKILL);
                        stages.0[i].1.wait()?;
                    }
                    Fault::Stop(n) => {
                        let i = stages
                            .0
                            .iter()
                            .position(|(st, _)| *st == n)
                            .expect("a stage");
                        signal(&stages.0[i].1, libc::SIGSTOP);
                    }
                    _ => {}
                }
            }
            let aligned = s.flags & odometry_flags::ALIGNED != 0;
            let was_aligned = last.is_some_and(|p| p.flags & odometry_flags::ALIGNED != 0);
            if aligned && !was_aligned {
                frame = truth_at(truth, s.stamps.sample_ns).map(|t| Frame::new(&s, t));
            }
            if !aligned {
                frame = None;
            }
            let rest = s.flags & odometry_flags::ZERO_VELOCITY != 0;
            if let (Some(f), Some(t)) = (&frame, truth_at(truth, s.stamps.sample_ns)) {
                let tp = f.to_ours * (Vector3::from(t.position_m) - f.origin);
                out.trace.push(format!(
                    "{:.3},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}",
                    s.stamps.sample_ns as f64 * 1e-9,
                    s.flags,
                    s.position_m[0],
                    s.position_m[1],
                    s.position_sigma_m[0],
                    s.position_sigma_m[1],
                    tp.x,
                    tp.y
                ));
            }
            if let Some(p) = last
                && p.flags & odometry_flags::ZERO_VELOCITY != 0
                && !rest
                && aligned
            {
                judge_rest_end(&p, &frame, &mut out);
            }
            last = Some(s);
        }
        if !replay_done && replay.try_wait()?.is_some() {
            replay_done = true;
        }
        // A stage that exits by itself (not the one just killed) is a finding, not a fault.
        for (name, child) in stages.0.iter_mut() {
            if restored && let Some(status) = child.try_wait()? {
                bail!("{}: {name} exited by itself ({status})", fault.label());
            }
        }
        let done = replay_done && idle_since.elapsed() > Duration::from_millis(1500);
        Ok(if done {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(any)
        })
    })?;
    for (_, stage) in &mut stages.0 {
        signal(stage, libc::SIGTERM);
        stage.wait()?;
    }
    stages.0.clear();
    for mut h in hogs {
        h.kill()?;
        h.wait()?;
    }
    std::fs::remove_file(&state).ok();
    if injected.is_none() {
        bail!(
            "{}: the states never reached the fault's time",
            fault.label()
        );
    }
    if let (Some(s), Some(f)) = (last, &frame)
        && let Some(t) = truth_at(truth, s.stamps.sample_ns)
    {
        out.end = Some(f.nees(&s, t));
    }
    Ok(out)
}

fn main() -> Result<()> {
    let (mut seeds, mut seconds, mut speed, mut as_json) = (5u64, 60u64, 2.0f64, false);
    let mut dump: Option<PathBuf> = None;
    let mut only: Vec<String> = Vec::new();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || it.next().context("a value is missing");
        match a.as_str() {
            "--seeds" => seeds = value()?.parse()?,
            "--seconds" => seconds = value()?.parse()?,
            "--speed" => speed = value()?.parse()?,
            "--json" => as_json = true,
            "--dump" => dump = Some(value()?.into()),
            "--only" => only.push(value()?.clone()),
            _ => bail!(
                "usage: faults [--seeds N] [--seconds S] [--speed X] [--only TEXT]... [--dump DIR] [--json]"
            ),
        }
    }
    let bins = common::bin_dir()?;
    let work = std::env::temp_dir().join(format!("mems-faults-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let path = |name: &str| work.join(name);
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let duration = (seconds as f64 + INITIAL_REST_S).to_string();
    let rest = INITIAL_REST_S.to_string();
    let mut results: Vec<(Fault, Vec<Outcome>)> = Fault::ALL
        .iter()
        .filter(|f| only.is_empty() || only.iter().any(|o| f.label().contains(o.as_str())))
        .map(|f| (*f, vec![]))
        .collect();
    for seed in 1..=seeds {
        // One part per seed, calibrated from its own six-position session, then driven.
        let (six, calib, drive) = (
            path(&format!("six{seed}.csv")),
            path(&format!("calib{seed}.toml")),
            path(&format!("drive{seed}.csv")),
        );
        let part = ["--preset", "datasheet", "--seed", &seed.to_string()].map(String::from);
        let part: Vec<&str> = part.iter().map(String::as_str).collect();
        eprintln!("faults: seed {seed}: calibrating and simulating the drive ...");
        run(
            &bins,
            "mems-sim",
            &[
                &["six-position", "--rate", "200", "--out", &s(&six)][..],
                &part,
            ]
            .concat(),
        )?;
        run(
            &bins,
            "mems-calibrate",
            &[
                "fit",
                "--input",
                &s(&six),
                "--model",
                "full",
                "--out",
                &s(&calib),
            ],
        )?;
        run(
            &bins,
            "mems-sim",
            &[
                &[
                    "drive",
                    "--duration",
                    &duration,
                    "--rate",
                    "1000",
                    "--initial-rest",
                    &rest,
                    "--out",
                    &s(&drive),
                ][..],
                &part,
            ]
            .concat(),
        )?;
        let truth = recording::load_raw(&drive)?
            .truth
            .context("the simulated drive has truth")?;
        for (k, (fault, outcomes)) in results.iter_mut().enumerate() {
            eprintln!("faults: seed {seed}, {} ...", fault.label());
            let tag = format!("{seed}-{k}");
            let o = one_run(&bins, &drive, &truth, &calib, *fault, speed, &tag)?;
            if let Some(dir) = &dump {
                std::fs::create_dir_all(dir)?;
                let file = dir.join(format!(
                    "seed{seed}-{}.csv",
                    fault.label().replace(' ', "_")
                ));
                std::fs::write(file, o.trace.join("\n"))?;
            }
            outcomes.push(o);
        }
    }

    println!(
        "| fault | runs | end NEES within 95 % | end NEES mean | end error max (m) | rest ends after the fault within 95 % | states lost | gaps flagged |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut summary = serde_json::Map::new();
    for (fault, outcomes) in &results {
        let ends: Vec<(f64, f64)> = outcomes.iter().filter_map(|o| o.end).collect();
        let within = ends.iter().filter(|(n, _)| *n <= NEES_95).count();
        let rests: Vec<f64> = outcomes.iter().flat_map(|o| o.rest_ends.clone()).collect();
        let rests_within = rests.iter().filter(|n| **n <= NEES_95).count();
        let mean = ends.iter().map(|(n, _)| n).sum::<f64>() / ends.len().max(1) as f64;
        let max_err = ends.iter().map(|(_, e)| *e).fold(0.0, f64::max);
        let lost: u64 = outcomes.iter().map(|o| o.missing).sum();
        let flagged: u64 = outcomes.iter().map(|o| o.gaps_flagged).sum();
        println!(
            "| {} | {} | {}/{} | {:.2} | {:.2} | {}/{} | {} | {} |",
            fault.label(),
            outcomes.len(),
            within,
            outcomes.len(),
            mean,
            max_err,
            rests_within,
            rests.len(),
            lost,
            flagged
        );
        summary.insert(
            fault.label(),
            json!({
                "runs": outcomes.len(),
                "end_aligned": ends.len(),
                "end_within_95": within,
                "end_nees_mean": mean,
                "end_error_max_m": max_err,
                "rest_ends": rests.len(),
                "rest_ends_within_95": rests_within,
                "states_lost": lost,
                "gaps_flagged": flagged,
            }),
        );
    }
    std::fs::remove_dir_all(&work).ok();
    if as_json {
        println!("{}", serde_json::Value::Object(summary));
    }
    Ok(())
}
