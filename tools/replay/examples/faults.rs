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
use std::os::unix::fs::OpenOptionsExt;
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

/// How a run's stage processes are started (and restarted after a kill).
struct Launcher<'a> {
    bins: &'a Path,
    ns: &'a str,
    calib: &'a str,
    /// Where the calibration stage keeps its learned state for its restart, as in mems-stack.
    state: &'a str,
    /// The private work directory, for the stages' logs.
    work: &'a Path,
}

impl Launcher<'_> {
    fn spawn(&self, stage: &str) -> Result<Child> {
        let args: &[&str] = match stage {
            "mems-calibrate" => &[
                "serve",
                "--calib",
                self.calib,
                "--learn-s",
                "2",
                "--learn-first-s",
                "2",
                "--state",
                self.state,
            ],
            _ => &["serve", "--calib", self.calib],
        };
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .mode(mems_files::FILE_MODE)
            .open(self.work.join(format!("{}-{stage}.log", self.ns)))?;
        Command::new(self.bins.join(stage))
            .args(args)
            .args(["--namespace", self.ns])
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .with_context(|| format!("cannot start {stage}"))
    }
}

/// Six busy processes for the `Hogs` fault, none for the others.
fn hogs(fault: Fault) -> Result<Vec<Child>> {
    if fault != Fault::Hogs {
        return Ok(Vec::new());
    }
    (0..6)
        .map(|_| {
            Command::new("sh")
                .args(["-c", "while :; do :; done"])
                .spawn()
                .context("cannot start a CPU hog")
        })
        .collect()
}

/// The fault's state within a run: injected when the states reach its sample time, ended
/// (restarted, continued) after 0.2 s or 2 s.
struct Injection {
    fault: Fault,
    at_ns: u64,
    injected: Option<Instant>,
    restored: bool,
}

impl Injection {
    fn new(fault: Fault, at_ns: u64) -> Self {
        Self {
            fault,
            at_ns,
            injected: None,
            restored: fault == Fault::None || fault == Fault::Hogs,
        }
    }

    /// Injects the fault once a state of sample time `sample_ns` reaches it.
    fn inject(&mut self, sample_ns: u64, stages: &mut Stages) -> Result<()> {
        if self.injected.is_some() || sample_ns < self.at_ns {
            return Ok(());
        }
        self.injected = Some(Instant::now());
        match self.fault {
            Fault::Kill(n) => {
                let child = stages.get(n);
                signal(child, libc::SIGKILL);
                child.wait()?;
            }
            Fault::Stop(n) => signal(stages.get(n), libc::SIGSTOP),
            _ => {}
        }
        Ok(())
    }

    /// Ends the fault when its time has come.
    fn restore(&mut self, stages: &mut Stages, launch: &Launcher) -> Result<()> {
        let Some(at) = self.injected.filter(|_| !self.restored) else {
            return Ok(());
        };
        match self.fault {
            Fault::Kill(n) if at.elapsed() >= Duration::from_millis(200) => {
                *stages.get(n) = launch.spawn(n)?;
                self.restored = true;
            }
            Fault::Stop(n) if at.elapsed() >= Duration::from_secs(2) => {
                signal(stages.get(n), libc::SIGCONT);
                self.restored = true;
            }
            Fault::StopSubscriber => {
                std::thread::sleep(Duration::from_secs(2));
                self.restored = true;
            }
            _ => {}
        }
        Ok(())
    }
}

impl Stages {
    fn get(&mut self, name: &str) -> &mut Child {
        let i = self
            .0
            .iter()
            .position(|(s, _)| *s == name)
            .expect("a stage");
        &mut self.0[i].1
    }
}

/// Judges a run's live states against the truth: losses, the frame of each alignment, the
/// NEES at the end of each rest after the fault, and the `--dump` trace.
struct Judge<'a> {
    truth: &'a [Truth],
    fault_ns: u64,
    frame: Option<Frame>,
    last: Option<OdometryState>,
    out: Outcome,
}

impl Judge<'_> {
    fn take(&mut self, s: OdometryState) {
        self.out.states += 1;
        if s.flags & odometry_flags::GAP_BEFORE != 0 {
            self.out.gaps_flagged += 1;
        }
        if let Some(p) = self.last
            && s.seq > p.seq + 1
        {
            self.out.missing += s.seq - p.seq - 1;
        }
        let truth = truth_at(self.truth, s.stamps.sample_ns);
        let aligned = s.flags & odometry_flags::ALIGNED != 0;
        let was_aligned = self
            .last
            .is_some_and(|p| p.flags & odometry_flags::ALIGNED != 0);
        if !aligned {
            self.frame = None;
        } else if !was_aligned {
            self.frame = truth.map(|t| Frame::new(&s, t));
        }
        if let (Some(f), Some(t)) = (&self.frame, truth) {
            let tp = f.to_ours * (Vector3::from(t.position_m) - f.origin);
            self.out.trace.push(format!(
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
        let rest = s.flags & odometry_flags::ZERO_VELOCITY != 0;
        if let Some(p) = self.last
            && p.flags & odometry_flags::ZERO_VELOCITY != 0
            && !rest
            && aligned
            && p.stamps.sample_ns > self.fault_ns
            && let (Some(f), Some(t)) = (&self.frame, truth_at(self.truth, p.stamps.sample_ns))
        {
            self.out.rest_ends.push(f.nees(&p, t).0);
        }
        self.last = Some(s);
    }

    /// The outcome, with the NEES of the last state if aligned.
    fn finish(mut self) -> Outcome {
        if let (Some(s), Some(f)) = (self.last, &self.frame)
            && let Some(t) = truth_at(self.truth, s.stamps.sample_ns)
        {
            self.out.end = Some(f.nees(&s, t));
        }
        self.out
    }
}

/// One replay of `drive` through the stages with `fault`, at `speed` times real time, with the
/// programs in `bins` and logs and state in the private directory `work`.
fn one_run(
    (bins, work): (&Path, &Path),
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
    let state = work.join(format!("{ns}-calibrate-state.json"));
    std::fs::remove_file(&state).ok();
    let launch = Launcher {
        bins,
        ns: &ns,
        calib: calib.to_str().context("calibration path is not UTF-8")?,
        state: state.to_str().context("state path is not UTF-8")?,
        work,
    };
    let mut stages = Stages(vec![
        ("mems-odometry", launch.spawn("mems-odometry")?),
        ("mems-calibrate", launch.spawn("mems-calibrate")?),
    ]);
    let hogs = hogs(fault)?;
    std::thread::sleep(Duration::from_millis(1500));
    let mut replay = Command::new(bins.join("mems-replay"))
        .arg(drive)
        .args(["--speed", &speed.to_string(), "--wait-subscribers", "1"])
        .args(["--namespace", &ns])
        .stdout(Stdio::null())
        .stderr(mems_files::create_new(
            work.join(format!("{ns}-mems-replay.log")),
            None,
        )?)
        .spawn()
        .context("cannot start mems-replay")?;
    let mut judge = Judge {
        truth,
        fault_ns,
        frame: None,
        last: None,
        out: Outcome::default(),
    };
    let mut injection = Injection::new(fault, fault_ns);
    let mut replay_done = false;
    let mut idle_since = Instant::now();
    wake::serve_loop(&[listener], Duration::from_millis(20), || -> Result<_> {
        injection.restore(&mut stages, &launch)?;
        let mut any = false;
        while let Some(s) = sub.receive()? {
            any = true;
            idle_since = Instant::now();
            if s.flags & odometry_flags::REVISION != 0 {
                continue;
            }
            injection.inject(s.stamps.sample_ns, &mut stages)?;
            judge.take(*s);
        }
        replay_done = replay_done || replay.try_wait()?.is_some();
        // A stage that exits by itself (not the one just killed) is a finding, not a fault.
        for (name, child) in stages.0.iter_mut() {
            if injection.restored
                && let Some(status) = child.try_wait()?
            {
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
    if injection.injected.is_none() {
        bail!(
            "{}: the states never reached the fault's time",
            fault.label()
        );
    }
    Ok(judge.finish())
}

/// The benchmark's options.
struct Options {
    seeds: u64,
    seconds: u64,
    speed: f64,
    as_json: bool,
    dump: Option<PathBuf>,
    only: Vec<String>,
}

fn options() -> Result<Options> {
    let mut o = Options {
        seeds: 5,
        seconds: 60,
        speed: 2.0,
        as_json: false,
        dump: None,
        only: Vec::new(),
    };
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || it.next().context("a value is missing");
        match a.as_str() {
            "--seeds" => o.seeds = value()?.parse()?,
            "--seconds" => o.seconds = value()?.parse()?,
            "--speed" => o.speed = value()?.parse()?,
            "--json" => o.as_json = true,
            "--dump" => o.dump = Some(value()?.into()),
            "--only" => o.only.push(value()?.clone()),
            _ => bail!(
                "usage: faults [--seeds N] [--seconds S] [--speed X] [--only TEXT]... [--dump DIR] [--json]"
            ),
        }
    }
    Ok(o)
}

/// Simulates seed `seed`'s part: its six-position session, the calibration fitted from it,
/// and a drive with truth. Returns the drive's path, the calibration's and the truth.
fn simulate(
    bins: &Path,
    work: &Path,
    seed: u64,
    seconds: u64,
) -> Result<(PathBuf, PathBuf, Vec<Truth>)> {
    let path = |name: String| work.join(name);
    let (six, calib, drive) = (
        path(format!("six{seed}.csv")),
        path(format!("calib{seed}.toml")),
        path(format!("drive{seed}.csv")),
    );
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let seed_text = seed.to_string();
    let part = ["--preset", "datasheet", "--seed", &seed_text];
    common::calibrate_part(bins, &part, &six, &calib)?;
    let duration = (seconds as f64 + INITIAL_REST_S).to_string();
    let rest = INITIAL_REST_S.to_string();
    let sim = [
        "drive",
        "--duration",
        &duration,
        "--rate",
        "1000",
        "--initial-rest",
        &rest,
        "--out",
        &s(&drive),
    ];
    run(bins, "mems-sim", &[&sim[..], &part].concat())?;
    let truth = recording::load_raw(&drive)?
        .truth
        .context("the simulated drive has truth")?;
    Ok((drive, calib, truth))
}

/// Prints one fault's row of the table and returns its JSON summary.
fn summarize(fault: Fault, outcomes: &[Outcome]) -> serde_json::Value {
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
    })
}

fn main() -> Result<()> {
    mems_log::init("faults");
    let o = options()?;
    let bins = common::bin_dir()?;
    let work_dir = mems_files::private_dir("mems-faults-")?;
    let work = work_dir.path();
    let mut results: Vec<(Fault, Vec<Outcome>)> = Fault::ALL
        .iter()
        .filter(|f| o.only.is_empty() || o.only.iter().any(|t| f.label().contains(t.as_str())))
        .map(|f| (*f, vec![]))
        .collect();
    for seed in 1..=o.seeds {
        // One part per seed, calibrated from its own six-position session, then driven.
        tracing::info!("seed {seed}: calibrating and simulating the drive ...");
        let (drive, calib, truth) = simulate(&bins, work, seed, o.seconds)?;
        for (k, (fault, outcomes)) in results.iter_mut().enumerate() {
            tracing::info!("seed {seed}, {} ...", fault.label());
            let tag = format!("{seed}-{k}");
            let run = one_run((&bins, work), &drive, &truth, &calib, *fault, o.speed, &tag)?;
            if let Some(dir) = &o.dump {
                mems_files::create_dir(dir, Some("--dump"))?;
                let name = format!("seed{seed}-{}.csv", fault.label().replace(' ', "_"));
                let trace = run.trace.join("\n");
                let replace = mems_files::Existing::Replace;
                mems_files::write(dir.join(name), Some("--dump"), replace, trace.as_bytes())?;
            }
            outcomes.push(run);
        }
    }
    println!(
        "| fault | runs | end NEES within 95 % | end NEES mean | end error max (m) | rest ends after the fault within 95 % | states lost | gaps flagged |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut summary = serde_json::Map::new();
    for (fault, outcomes) in &results {
        summary.insert(fault.label(), summarize(*fault, outcomes));
    }
    drop(work_dir);
    if o.as_json {
        println!("{}", serde_json::Value::Object(summary));
    }
    Ok(())
}
