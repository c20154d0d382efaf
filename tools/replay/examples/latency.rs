//! Latency, CPU and throughput benchmark of the live pipeline, with real processes:
//! `mems-replay` -> `mems-calibrate serve` -> `mems-odometry serve` -> this process's
//! subscriber, against bare iceoryx2 hops between processes with the same service settings and
//! the same event-driven waiting (a publisher notifies the service's event after each send; a
//! subscriber sleeps in a WaitSet on its listener).
//!
//! ```sh
//! cargo build --release -p mems-replay -p mems-calibrate ... (the workspace binaries)
//! cargo run --release -p mems-replay --example latency [-- --seconds 30] [--cpu-seconds 30] [--json]
//! ```
//!
//! Measures, each as an hdrhistogram of nanoseconds (reported in us), at 1 kHz and 4 kHz:
//! - the bare hop: a publisher thread here sends a raw sample per period with its publish time
//!   in `stamps.acquired_ns`; a subscriber process records receive time - publish time;
//! - three bare hops in a chain: publisher -> relay process -> relay process -> subscriber
//!   process (the pipeline's shape without its stages);
//! - the pipeline, replaying a simulated drive of the part it calibrated (so the odometry
//!   aligns: checked) at real time: per hop from the stamps every state carries and end to end,
//!   over the live (non-revision) states that are aligned (at rest and moving, both counted);
//! - each process's CPU use over the real-time replays at 1 kHz and 4 kHz (utime + stime from
//!   /proc), which last at least `--cpu-seconds` (default 30), and of the stages idle; checked
//!   against the targets (idle < 1 % of a core per process, each stage < 10 % at 1 kHz);
//! - plain, and pinned with SCHED_FIFO (publisher/replay and the last subscriber on CPU 0, the
//!   relays/stages on CPU 1), at 1 kHz;
//! - throughput: a drive replayed with `--max` through both stages.
//!
//! With `--json` the last line is a JSON object of the headline figures. Every time is
//! `CLOCK_MONOTONIC` on one machine, so differences between processes are valid.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use anyhow::{Context, Result, bail};
use common::run;
use hdrhistogram::Histogram;
use iceoryx2::service::port_factory::PortFactory as _;
use ipc_types::clock::monotonic_ns;
use ipc_types::wake::{self, Output, WaitMode};
use ipc_types::{OdometryState, RawImuSample, Stamps, odometry_flags, service};
use serde_json::{Value, json};
use std::ops::ControlFlow;

/// Warm-up of the pipeline's drive: the calibration stage learns for `LEARN_S` before its first
/// rule (`--learn-first-s`), the odometry aligns on the next second of rest; the states timed
/// are the aligned ones after it.
const LEARN_S: &str = "2";
/// Rest at the start of the drive, s: learning (`LEARN_S`), the detector's window and the
/// alignment fit in it with room (the stage aligns 4.6 s in). With 4 s it aligned in the
/// motion, took the cruise that followed for rest, and few moving states were timed.
const INITIAL_REST_S: u64 = 8;
/// Longest idle measurement, s.
const IDLE_S: u64 = 10;
/// CPU targets: an idle process, and a stage at 1 kHz, % of one core.
const IDLE_MAX_PERCENT: f64 = 1.0;
const STAGE_MAX_PERCENT_1KHZ: f64 = 10.0;

/// One latency distribution.
fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 100_000_000_000, 3).expect("valid histogram bounds")
}

/// `p50 / p99 / p99.9 / max` in us, and the count.
fn row(h: &Histogram<u64>) -> String {
    let [p50, p99, p999, max] = quantiles(h);
    format!(
        "| {p50:.1} | {p99:.1} | {p999:.1} | {max:.1} | {} |",
        h.len()
    )
}

/// p50, p99, p99.9 and max in us.
fn quantiles(h: &Histogram<u64>) -> [f64; 4] {
    let us = |q: f64| h.value_at_quantile(q) as f64 / 1000.0;
    [us(0.5), us(0.99), us(0.999), h.max() as f64 / 1000.0]
}

/// Pins the calling thread to `cpu` and, if `priority` is given, makes it SCHED_FIFO. Returns a
/// note when SCHED_FIFO was refused (the caller goes on pinned only).
fn realtime(cpu: usize, priority: Option<u8>) -> Result<Option<String>> {
    let core = core_affinity::get_core_ids()
        .unwrap_or_default()
        .into_iter()
        .find(|c| c.id == cpu)
        .with_context(|| format!("no CPU {cpu}"))?;
    if !core_affinity::set_for_current(core) {
        bail!("cannot pin to CPU {cpu}");
    }
    let Some(priority) = priority else {
        return Ok(None);
    };
    use thread_priority::{
        RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
        set_thread_priority_and_policy, thread_native_id,
    };
    let value = ThreadPriorityValue::try_from(priority).map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .err()
    .map(|e| format!("SCHED_FIFO {priority} refused ({e:?}): pinned only")))
}

/// A chain's receiving end (child process): relays `n` raw samples from service `input` to
/// `output` (keeping `acquired_ns`), or, with `output` "-", records receive time - publish
/// time and prints the histogram serialised as `p50 p99 p999 max count` (ns) on stdout.
fn chain_child(input: &str, output: &str, n: u64, cpu: Option<usize>) -> Result<()> {
    if let Some(cpu) = cpu
        && let Some(note) = realtime(cpu, Some(50))?
    {
        tracing::info!("chain: {note}");
    }
    let node = service::node()?;
    let svc = service::open::<RawImuSample>(&node, input)?;
    let sub = service::subscriber(&svc)?;
    let listener = wake::listener(&node, input, WaitMode::Event)?;
    let mut out = if output == "-" {
        None
    } else {
        let svc = service::open::<RawImuSample>(&node, output)?;
        Some(Output::new(&node, &svc, output)?)
    };
    let mut h = histogram();
    let mut got = 0u64;
    let start = Instant::now();
    wake::serve_loop(&[listener], Duration::from_millis(100), || -> Result<_> {
        let mut any = false;
        while let Some(s) = sub.receive()? {
            any = true;
            got += 1;
            match out.as_mut() {
                Some(o) => {
                    o.send(*s.payload());
                    o.end_of_input()?;
                }
                None => h.record(monotonic_ns().saturating_sub(s.stamps.acquired_ns).max(1))?,
            }
        }
        let done = got >= n || start.elapsed() > Duration::from_secs(300);
        Ok(if done {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(any)
        })
    })?;
    if out.is_none() {
        println!(
            "{} {} {} {} {}",
            h.value_at_quantile(0.5),
            h.value_at_quantile(0.99),
            h.value_at_quantile(0.999),
            h.max(),
            h.len()
        );
    } else {
        // Let the next process take the last samples before the ports close.
        std::thread::sleep(Duration::from_millis(300));
    }
    Ok(())
}

/// `hops` bare event-driven hops in a chain at `rate_hz` for `seconds`: the publisher is a
/// thread here, the relays and the subscriber child processes. Returns p50, p99, p99.9, max
/// (us) and the count at the subscriber.
fn chain(bench: &Path, hops: usize, rate_hz: u64, seconds: u64, pinned: bool) -> Result<[f64; 5]> {
    let id = format!(
        "latency-chain-{}-{hops}-{rate_hz}-{pinned}",
        std::process::id()
    );
    let names: Vec<String> = (0..=hops).map(|k| format!("{id}/s{k}")).collect();
    let n = seconds * rate_hz;
    let mut children = Vec::new();
    for k in 0..hops {
        let output = if k + 1 == hops {
            "-"
        } else {
            names[k + 1].as_str()
        };
        // Relays on CPU 1, the subscriber with the publisher on CPU 0 (as the pipeline).
        let cpu = if k + 1 == hops { "0" } else { "1" };
        children.push(
            Command::new(bench)
                .args(["chain", &names[k], output, &n.to_string()])
                .arg(if pinned { cpu } else { "-" })
                .stdout(Stdio::piped())
                .spawn()
                .context("cannot start a chain process")?,
        );
    }
    let first = names[0].clone();
    let publisher = std::thread::spawn(move || -> Result<()> {
        if pinned && let Some(note) = realtime(0, Some(40))? {
            tracing::info!("chain publisher: {note}");
        }
        let node = service::node()?;
        let svc = service::open::<RawImuSample>(&node, &first)?;
        let mut out = Output::new(&node, &svc, &first)?;
        let wait = Instant::now();
        while svc.dynamic_config().number_of_subscribers() < 1 {
            if wait.elapsed() > Duration::from_secs(20) {
                bail!("the chain did not connect");
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(500));
        let period = Duration::from_nanos(1_000_000_000 / rate_hz);
        let start = Instant::now();
        for seq in 0..n {
            let due = start + period * seq as u32;
            if let Some(d) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(d);
            }
            let now = monotonic_ns();
            out.send(RawImuSample {
                stamps: Stamps {
                    sample_ns: now,
                    acquired_ns: now,
                    ..Stamps::default()
                },
                seq,
                ..RawImuSample::default()
            });
            out.end_of_input()?;
        }
        std::thread::sleep(Duration::from_millis(500));
        Ok(())
    });
    let mut outputs = Vec::new();
    for c in children {
        outputs.push(c.wait_with_output()?);
    }
    publisher.join().expect("publisher thread")?;
    let last = outputs.last().expect("one hop at least");
    if outputs.iter().any(|o| !o.status.success()) {
        bail!("a chain process failed");
    }
    let v: Vec<f64> = String::from_utf8_lossy(&last.stdout)
        .split_whitespace()
        .map(|x| x.parse::<f64>())
        .collect::<Result<_, _>>()?;
    let [p50, p99, p999, max, count] = v[..] else {
        bail!("chain subscriber printed {v:?}");
    };
    Ok([p50 / 1e3, p99 / 1e3, p999 / 1e3, max / 1e3, count])
}

/// A command for workspace binary `name`, under `taskset -c CPU chrt -f PRIO` when `rt` is given.
fn command(bins: &Path, name: &str, rt: Option<(usize, u8)>) -> Command {
    match rt {
        Some((cpu, priority)) => {
            let mut c = Command::new("taskset");
            c.args(["-c", &cpu.to_string(), "chrt", "-f", &priority.to_string()]);
            c.arg(bins.join(name));
            c
        }
        None => Command::new(bins.join(name)),
    }
}

/// CPU time (user + system) of process `pid` so far, s.
fn cpu_s(pid: u32) -> Result<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    // Fields after the command name (which may hold spaces): state is field 3, utime 14.
    let rest = &stat[stat.rfind(')').context("malformed /proc stat")? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    Ok((f[11].parse::<f64>()? + f[12].parse::<f64>()?) / ticks_per_s())
}

/// `/proc`'s clock ticks (USER_HZ) per second.
fn ticks_per_s() -> f64 {
    // SAFETY: sysconf has no preconditions.
    unsafe { libc::sysconf(libc::_SC_CLK_TCK) as f64 }
}

/// One pipeline run: what its subscriber measured, its rate, and its processes' CPU use.
struct PipelineRun {
    timing: Timing,
    /// Live states per second at the subscriber.
    rate_hz: f64,
    replay_line: String,
    /// Percent of one core per process over the replay.
    cpu: Vec<(String, f64)>,
    /// Length of the CPU measurement (the replay), s.
    cpu_span_s: f64,
    /// Time each vCPU was stolen by the hypervisor over the replay, ms (`/proc/stat`).
    steal_ms: Vec<f64>,
    /// Process ids of the replay, the calibration and odometry stages and the subscriber.
    pids: [u32; 4],
}

/// End-to-end latency above which a state is listed with its stamps, ns.
const TAIL_NS: u64 = 1_000_000;
/// States listed per run.
const MAX_TAILS: usize = 200;

/// The timed states above `TAIL_NS`: their publish time (`CLOCK_MONOTONIC`, to match against
/// `perf sched record -k CLOCK_MONOTONIC`) and per-hop latencies, ns.
struct Tails {
    count: u64,
    kept: Vec<(u64, [u64; 4])>,
}

impl Tails {
    fn new() -> Self {
        Self {
            count: 0,
            kept: Vec::with_capacity(MAX_TAILS),
        }
    }

    fn note(&mut self, acquired_ns: u64, hops: [u64; 4]) {
        self.count += 1;
        if self.kept.len() < MAX_TAILS {
            self.kept.push((acquired_ns, hops));
        }
    }
}

/// Each vCPU's steal time so far, ms (the 8th value of `/proc/stat`'s `cpuN` lines, in
/// USER_HZ ticks, proc(5)).
fn steal_ms() -> Result<Vec<f64>> {
    let stat = std::fs::read_to_string("/proc/stat")?;
    let tick_ms = 1000.0 / ticks_per_s();
    stat.lines()
        .filter(|l| l.starts_with("cpu") && !l.starts_with("cpu "))
        .map(|l| {
            let ticks: f64 = l
                .split_whitespace()
                .nth(8)
                .context("/proc/stat: a cpu line without a steal field")?
                .parse()?;
            Ok(ticks * tick_ms)
        })
        .collect()
}

/// The stages' options for a drive at `rate_hz`: the 4 kHz MPU-9250 has no gyroscope.
fn stage_args(rate_hz: u64) -> Vec<&'static str> {
    if rate_hz > 1000 {
        vec!["--detector", "glrt-accel"]
    } else {
        vec![]
    }
}

/// What the subscriber measured over the live (non-revision) states: per-hop latency and the
/// counts.
struct Timing {
    hops: [Histogram<u64>; 4],
    /// When the first and the last live state arrived, `CLOCK_MONOTONIC` ns.
    first: Option<u64>,
    last: u64,
    states: u64,
    rest: u64,
    moving: u64,
    untimed: u64,
    tails: Tails,
}

impl Timing {
    fn new() -> Self {
        Self {
            hops: [histogram(), histogram(), histogram(), histogram()],
            first: None,
            last: 0,
            states: 0,
            rest: 0,
            moving: 0,
            untimed: 0,
            tails: Tails::new(),
        }
    }

    /// Takes a state received at `now` (ns). Only aligned states are timed unless `all`.
    fn take(&mut self, s: &OdometryState, now: u64, all: bool) -> Result<()> {
        if s.flags & odometry_flags::REVISION != 0 {
            return Ok(());
        }
        self.first.get_or_insert(now);
        self.last = now;
        self.states += 1;
        if s.flags & odometry_flags::ALIGNED == 0 && !all {
            self.untimed += 1;
            return Ok(());
        }
        if s.flags & odometry_flags::ZERO_VELOCITY != 0 {
            self.rest += 1;
        } else {
            self.moving += 1;
        }
        let st = s.stamps;
        let hop_ns = [
            st.calibrated_ns.saturating_sub(st.acquired_ns),
            st.odometry_ns.saturating_sub(st.calibrated_ns),
            now.saturating_sub(st.odometry_ns),
            now.saturating_sub(st.acquired_ns),
        ];
        for (h, ns) in self.hops.iter_mut().zip(hop_ns) {
            h.record(ns.max(1))?;
        }
        if hop_ns[3] > TAIL_NS {
            self.tails.note(st.acquired_ns, hop_ns);
        }
        Ok(())
    }
}

/// Starts the odometry and calibration stages (in that order) in namespace `ns`, then, once
/// they are up, the replay of `recording` (`--speed 1`, or `--max`), pinned if asked.
fn start(
    bins: &Path,
    ns: &str,
    recording: &Path,
    calib: &Path,
    rate_hz: u64,
    max: bool,
    pinned: bool,
) -> Result<(Vec<(&'static str, Child)>, Child)> {
    let rt_stage = pinned.then_some((1, 50));
    let calib = calib.to_str().context("calibration path is not UTF-8")?;
    let spawn = |name: &str, args: &[&str], rt| -> Result<Child> {
        command(bins, name, rt)
            .args(args)
            .args(["--namespace", ns])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot start {name}"))
    };
    let mut calibrate_args = vec!["serve", "--calib", calib, "--learn-s", LEARN_S];
    calibrate_args.extend(["--learn-first-s", LEARN_S]);
    calibrate_args.extend(stage_args(rate_hz));
    let stages = vec![
        (
            "mems-odometry",
            spawn("mems-odometry", &["serve", "--calib", calib], rt_stage)?,
        ),
        (
            "mems-calibrate",
            spawn("mems-calibrate", &calibrate_args, rt_stage)?,
        ),
    ];
    std::thread::sleep(Duration::from_millis(1500));
    let recording = recording.to_str().context("recording path is not UTF-8")?;
    let pace: &[&str] = if max { &["--max"] } else { &["--speed", "1"] };
    let replay = command(bins, "mems-replay", pinned.then_some((0, 40)))
        .arg(recording)
        .args(pace)
        .args(["--wait-subscribers", "1", "--namespace", ns])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .context("cannot start mems-replay")?;
    Ok((stages, replay))
}

/// Replays `recording` (`--speed 1` or `--max`) through calibrate and odometry processes and
/// measures at this process's odometry subscriber.
fn pipeline(
    bins: &Path,
    recording: &Path,
    calib: &Path,
    rate_hz: u64,
    max: bool,
    pinned: bool,
) -> Result<PipelineRun> {
    let ns = format!(
        "latency-pipe-{}-{rate_hz}-{max}-{pinned}",
        std::process::id()
    );
    let node = service::node()?;
    let name = service::full_name(&ns, service::ODOMETRY);
    let svc = service::open::<OdometryState>(&node, &name)?;
    let sub = service::subscriber(&svc)?;
    let listener = wake::listener(&node, &name, WaitMode::Event)?;
    let (mut stages, replay) = start(bins, &ns, recording, calib, rate_hz, max, pinned)?;
    let replay_pid = replay.id();
    let cpu0: Vec<f64> = stages
        .iter()
        .map(|(_, c)| cpu_s(c.id()))
        .chain([cpu_s(replay_pid)])
        .collect::<Result<_>>()?;
    let steal0 = steal_ms()?;
    let t0 = Instant::now();
    let replay_out = std::thread::spawn(move || replay.wait_with_output());
    let mut timing = Timing::new();
    let mut idle_since = Instant::now();
    let mut cpu1: Option<(Vec<f64>, f64, Vec<f64>)> = None;
    // The replay's CPU time, read while it runs (its /proc entry goes when it is reaped).
    let mut replay_cpu = (cpu0[2], Instant::now());
    wake::serve_loop(&[listener], Duration::from_millis(20), || -> Result<_> {
        let mut any = false;
        while let Some(s) = sub.receive()? {
            any = true;
            idle_since = Instant::now();
            timing.take(&s, monotonic_ns(), max)?;
        }
        if !replay_out.is_finished()
            && replay_cpu.1.elapsed() > Duration::from_millis(100)
            && let Ok(c) = cpu_s(replay_pid)
        {
            replay_cpu = (c, Instant::now());
        }
        if replay_out.is_finished() && cpu1.is_none() {
            let mut now: Vec<f64> = stages
                .iter()
                .map(|(_, c)| cpu_s(c.id()))
                .collect::<Result<_>>()?;
            now.push(replay_cpu.0);
            cpu1 = Some((now, t0.elapsed().as_secs_f64(), steal_ms()?));
        }
        let done = replay_out.is_finished() && idle_since.elapsed() > Duration::from_millis(1500);
        Ok(if done {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(any)
        })
    })?;
    let out = replay_out.join().expect("replay waiter")?;
    let (cpu1, span, steal1) = cpu1.context("the replay did not finish")?;
    for (_, stage) in &mut stages {
        // SAFETY: kill(2) on our own child; no memory is involved.
        unsafe { libc::kill(stage.id() as i32, libc::SIGTERM) };
        stage.wait()?;
    }
    if !out.status.success() {
        bail!("mems-replay failed: {}", out.status);
    }
    let pids = [
        replay_pid,
        stages[1].1.id(),
        stages[0].1.id(),
        std::process::id(),
    ];
    let names = ["mems-odometry", "mems-calibrate", "mems-replay"];
    let cpu = names
        .iter()
        .zip(cpu0.iter().zip(&cpu1))
        .map(|(n, (a, b))| (n.to_string(), 100.0 * (b - a) / span))
        .collect();
    let span_s = timing
        .first
        .map_or(0.0, |f| (timing.last - f) as f64 * 1e-9);
    Ok(PipelineRun {
        rate_hz: if span_s > 0.0 {
            (timing.states - 1) as f64 / span_s
        } else {
            0.0
        },
        timing,
        replay_line: String::from_utf8_lossy(&out.stdout).trim().to_owned(),
        cpu,
        cpu_span_s: span,
        steal_ms: steal1.iter().zip(&steal0).map(|(b, a)| b - a).collect(),
        pids,
    })
}

/// CPU use of the two stages with no input for `seconds`, percent of a core.
fn idle_cpu(bins: &Path, calib: &Path, seconds: u64) -> Result<Vec<(String, f64)>> {
    let ns = format!("latency-idle-{}", std::process::id());
    let calib = calib.to_str().context("calibration path is not UTF-8")?;
    let mut out = Vec::new();
    let mut children = Vec::new();
    for (name, args) in [
        ("mems-calibrate", vec!["serve", "--calib", calib]),
        ("mems-odometry", vec!["serve", "--calib", calib]),
    ] {
        let c = Command::new(bins.join(name))
            .args(&args)
            .args(["--namespace", &ns])
            .stderr(Stdio::null())
            .spawn()?;
        children.push((name, c));
    }
    // Start-up (loading, allocating) is not idling.
    std::thread::sleep(Duration::from_secs(1));
    let before: Vec<f64> = children
        .iter()
        .map(|(_, c)| cpu_s(c.id()))
        .collect::<Result<_>>()?;
    std::thread::sleep(Duration::from_secs(seconds));
    for ((name, c), b) in children.iter_mut().zip(before) {
        out.push((
            name.to_string(),
            100.0 * (cpu_s(c.id())? - b) / seconds as f64,
        ));
        // SAFETY: kill(2) on our own child; no memory is involved.
        unsafe { libc::kill(c.id() as i32, libc::SIGTERM) };
        c.wait()?;
    }
    Ok(out)
}

/// Prints one pipeline run as a markdown table.
fn print_pipeline(title: &str, run: &PipelineRun) {
    let names = [
        "replay -> calibrate",
        "calibrate -> odometry",
        "odometry -> subscriber",
        "end to end (replay -> subscriber)",
    ];
    println!(
        "## {title}\n\n{} live states, {} timed: aligned at rest {}, aligned moving {} \
         (not timed: {} before alignment); {}\n",
        run.timing.states,
        run.timing.rest + run.timing.moving,
        run.timing.rest,
        run.timing.moving,
        run.timing.untimed,
        run.replay_line
    );
    println!("| hop | p50 us | p99 us | p99.9 us | max us | states |");
    println!("| --- | --- | --- | --- | --- | --- |");
    for (name, h) in names.iter().zip(&run.timing.hops) {
        println!("| {name} {}", row(h));
    }
    let cpu: Vec<String> = run
        .cpu
        .iter()
        .map(|(n, p)| format!("{n} {p:.1}%"))
        .collect();
    let steal: Vec<String> = run.steal_ms.iter().map(|s| format!("{s:.0}")).collect();
    println!(
        "\nLive states arrived from CLOCK_MONOTONIC {} to {} ns (pids: replay {}, calibrate {}, \
         odometry {}, subscriber {}). CPU over the {:.0} s replay (% of one core): {}; vCPU time \
         stolen by the hypervisor over it (ms per vCPU): {}\n",
        run.timing.first.unwrap_or(0),
        run.timing.last,
        run.pids[0],
        run.pids[1],
        run.pids[2],
        run.pids[3],
        run.cpu_span_s,
        cpu.join(", "),
        steal.join(", ")
    );
    print_tails(&run.timing.tails);
}

/// Lists the states above `TAIL_NS` end to end with their publish time, to be matched
/// against a scheduler trace taken with the same clock.
fn print_tails(tails: &Tails) {
    let over = format!(
        "{} timed states above {} ms end to end",
        tails.count,
        TAIL_NS / 1_000_000
    );
    if tails.kept.is_empty() {
        println!("{over}\n");
        return;
    }
    println!(
        "{over}; the first {} (publish time CLOCK_MONOTONIC ns; hops in us):\n",
        tails.kept.len()
    );
    println!(
        "| published ns | replay -> calibrate | calibrate -> odometry | odometry -> subscriber | end to end |"
    );
    println!("| --- | --- | --- | --- | --- |");
    for (t, h) in &tails.kept {
        let us = h.map(|ns| ns as f64 / 1000.0);
        println!(
            "| {t} | {:.1} | {:.1} | {:.1} | {:.1} |",
            us[0], us[1], us[2], us[3]
        );
    }
    println!();
}

fn cpu_json(cpu: &[(String, f64)]) -> Value {
    Value::Object(
        cpu.iter()
            .map(|(n, p)| (n.clone(), json!((p * 10.0).round() / 10.0)))
            .collect(),
    )
}

/// The benchmark's options.
struct Options {
    /// Length of each bare chain run, s (the drives are at least 20 s).
    seconds: u64,
    /// Shortest real-time replay for the CPU figures, s.
    cpu_seconds: u64,
    /// Print the headline figures as JSON last.
    as_json: bool,
}

fn options(args: &[String]) -> Result<Options> {
    let mut o = Options {
        seconds: 20,
        cpu_seconds: 30,
        as_json: false,
    };
    let mut it = args.iter().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--seconds" => o.seconds = it.next().context("--seconds needs a value")?.parse()?,
            "--cpu-seconds" => {
                o.cpu_seconds = it.next().context("--cpu-seconds needs a value")?.parse()?;
            }
            "--json" => o.as_json = true,
            _ => bail!("usage: latency [--seconds S] [--cpu-seconds S] [--json]"),
        }
    }
    Ok(o)
}

/// The simulated drives and the calibration every pipeline run uses.
struct Inputs {
    work: PathBuf,
    drive: PathBuf,
    drive4k: PathBuf,
    long: PathBuf,
    calib: PathBuf,
}

/// Simulates one part (preset and seed) for the calibration and every drive, so the odometry
/// aligns: a 1 kHz and a 4 kHz drive for the real-time runs, a longer one for throughput, and
/// the six-position session its calibration is fitted from.
fn inputs(bins: &Path, o: &Options) -> Result<Inputs> {
    // Private (0700, a new random name); removed at the end of the benchmark.
    let work = mems_files::private_dir("mems-latency-")?.keep();
    let path = |name: &str| work.join(name);
    let i = Inputs {
        drive: path("drive.mcap"),
        drive4k: path("drive4k.mcap"),
        long: path("long.mcap"),
        calib: path("calib.toml"),
        work: work.clone(),
    };
    let six = path("six.csv");
    let text = |p: &Path| {
        p.to_str()
            .context("work path is not UTF-8")
            .map(str::to_owned)
    };
    tracing::info!("simulating the recordings and calibrating ...");
    let part = ["--preset", "datasheet", "--seed", "1"];
    let rest = INITIAL_REST_S.to_string();
    let sim_drive = |out: &Path, secs: u64, rate: &str| -> Result<String> {
        let secs = (secs + INITIAL_REST_S).to_string();
        let drive = [
            "drive",
            "--duration",
            &secs,
            "--rate",
            rate,
            "--initial-rest",
            &rest,
        ];
        run(
            bins,
            "mems-sim",
            &[&drive[..], &part, &["--out", &text(out)?]].concat(),
        )
    };
    // The drive plan drops a motion that does not fit: at least 20 s hold a drive and a rest.
    // The real-time replays at 1 and 4 kHz give the CPU figures: at least --cpu-seconds.
    sim_drive(&i.drive, o.seconds.max(20).max(o.cpu_seconds), "1000")?;
    sim_drive(&i.drive4k, o.seconds.max(o.cpu_seconds), "4000")?;
    sim_drive(&i.long, o.seconds * 6, "1000")?;
    common::calibrate_part(bins, &part, &six, &i.calib)?;
    Ok(i)
}

/// The headline figures, printed as JSON last.
type Figures = serde_json::Map<String, Value>;

/// Runs and prints one bare chain: p50, p99, p99.9, max (us) and the count.
fn bare(
    bench: &Path,
    label: &str,
    hops: usize,
    rate: u64,
    o: &Options,
    pinned: bool,
) -> Result<[f64; 5]> {
    tracing::info!("{label} ...");
    let r = chain(bench, hops, rate, o.seconds, pinned)?;
    println!(
        "| {label} | {:.1} | {:.1} | {:.1} | {:.1} | {} |",
        r[0], r[1], r[2], r[3], r[4]
    );
    Ok(r)
}

/// The plain bare hops: one hop and three at 1 kHz, three at 4 kHz. Returns the three hops'
/// figures at 1 kHz.
fn bare_runs(bench: &Path, o: &Options, j: &mut Figures) -> Result<[f64; 5]> {
    println!("## Bare iceoryx2 hops, event-driven, lossless settings\n");
    println!("| run | p50 us | p99 us | p99.9 us | max us | samples |");
    println!("| --- | --- | --- | --- | --- | --- |");
    let hop1 = bare(bench, "one hop, 1 kHz, plain", 1, 1000, o, false)?;
    let chain3 = bare(bench, "three hops, 1 kHz, plain", 3, 1000, o, false)?;
    let chain3_4k = bare(bench, "three hops, 4 kHz, plain", 3, 4000, o, false)?;
    println!();
    j.insert("bare_hop_p99_us".into(), json!(hop1[1]));
    j.insert("bare_chain3_p50_us".into(), json!(chain3[0]));
    j.insert("bare_chain3_p99_us".into(), json!(chain3[1]));
    j.insert("bare_chain3_p999_us".into(), json!(chain3[2]));
    j.insert("bare_chain3_4k_p99_us".into(), json!(chain3_4k[1]));
    Ok(chain3)
}

/// The plain pipeline at 1 kHz (checked to time aligned states at rest and moving) and at
/// 4 kHz, and the idle stages, with the CPU targets checked. Returns the 1 kHz run.
fn realtime_runs(
    bins: &Path,
    i: &Inputs,
    o: &Options,
    j: &mut Figures,
    cpu: &mut Figures,
) -> Result<PipelineRun> {
    tracing::info!("pipeline at 1 kHz, plain ...");
    let p = pipeline(bins, &i.drive, &i.calib, 1000, false, false)?;
    print_pipeline("Pipeline at 1 kHz, real time, plain", &p);
    if p.timing.rest == 0 || p.timing.moving == 0 {
        bail!(
            "the timed states must be aligned at rest and moving: {} at rest, {} moving",
            p.timing.rest,
            p.timing.moving
        );
    }
    let [p50, p99, p999, max] = quantiles(&p.timing.hops[3]);
    let hop_p99: Vec<f64> = p.timing.hops[..3].iter().map(|h| quantiles(h)[1]).collect();
    for (k, v) in [
        ("pipeline_p50_us", json!(p50)),
        ("pipeline_p99_us", json!(p99)),
        ("pipeline_p999_us", json!(p999)),
        ("pipeline_max_us", json!(max)),
        ("pipeline_states_over_1ms", json!(p.timing.tails.count)),
        ("pipeline_hop_p99_us", json!(hop_p99)),
        ("timed_states_aligned_rest", json!(p.timing.rest)),
        ("timed_states_aligned_moving", json!(p.timing.moving)),
    ] {
        j.insert(k.into(), v);
    }
    cpu.insert("1kHz".into(), cpu_json(&p.cpu));

    tracing::info!("pipeline at 4 kHz, plain ...");
    let p4 = pipeline(bins, &i.drive4k, &i.calib, 4000, false, false)?;
    print_pipeline(
        "Pipeline at 4 kHz (accelerometer only: states NO_GYRO), real time, plain",
        &p4,
    );
    let [_, p4_99, p4_999, _] = quantiles(&p4.timing.hops[3]);
    j.insert("pipeline_4k_p99_us".into(), json!(p4_99));
    j.insert("pipeline_4k_p999_us".into(), json!(p4_999));
    cpu.insert("4kHz".into(), cpu_json(&p4.cpu));
    j.insert("cpu_seconds_1khz".into(), json!(p.cpu_span_s.round()));
    j.insert("cpu_seconds_4khz".into(), json!(p4.cpu_span_s.round()));
    cpu_targets(bins, i, o, &p, j, cpu)?;
    Ok(p)
}

/// Measures the idle stages and checks the CPU targets against them and the 1 kHz run `p`.
fn cpu_targets(
    bins: &Path,
    i: &Inputs,
    o: &Options,
    p: &PipelineRun,
    j: &mut Figures,
    cpu: &mut Figures,
) -> Result<()> {
    tracing::info!("idle stages ...");
    let idle_s = o.cpu_seconds.clamp(1, IDLE_S);
    let idle = idle_cpu(bins, &i.calib, idle_s)?;
    println!(
        "Idle stages, no input for {idle_s} s (% of one core): {}\n",
        idle.iter()
            .map(|(n, p)| format!("{n} {p:.2}%"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    cpu.insert("idle".into(), cpu_json(&idle));
    let idle_ok = idle.iter().all(|(_, p)| *p < IDLE_MAX_PERCENT);
    let stages_ok = p
        .cpu
        .iter()
        .filter(|(n, _)| n != "mems-replay")
        .all(|(_, c)| *c < STAGE_MAX_PERCENT_1KHZ);
    println!(
        "CPU targets: idle < {IDLE_MAX_PERCENT} % of a core per process: {}; each stage < \
         {STAGE_MAX_PERCENT_1KHZ} % at 1 kHz (over {:.0} s): {}\n",
        if idle_ok { "met" } else { "NOT met" },
        p.cpu_span_s,
        if stages_ok { "met" } else { "NOT met" },
    );
    j.insert("idle_under_1_percent".into(), json!(idle_ok));
    j.insert("stages_1khz_under_10_percent".into(), json!(stages_ok));
    Ok(())
}

/// The long drive replayed with `--max` through both stages.
fn throughput_run(bins: &Path, i: &Inputs, j: &mut Figures, cpu: &mut Figures) -> Result<()> {
    tracing::info!("throughput with --max ...");
    let t = pipeline(bins, &i.long, &i.calib, 1000, true, false)?;
    println!(
        "## Throughput, `mems-replay --max` through calibrate and odometry (plain)\n\n\
         {} states at {:.0} states/s at the subscriber; {}\n\n\
         CPU over the replay (% of one core): {}\n",
        t.timing.states,
        t.rate_hz,
        t.replay_line,
        t.cpu
            .iter()
            .map(|(n, p)| format!("{n} {p:.1}%"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    j.insert("throughput_states_per_s".into(), json!(t.rate_hz.round()));
    cpu.insert("throughput".into(), cpu_json(&t.cpu));
    Ok(())
}

/// The pinned SCHED_FIFO runs: three bare hops and the pipeline at 1 kHz. Returns the bare
/// chain's and the pipeline's p99, us. Run last: this process's threads stay pinned.
fn pinned_runs(
    bench: &Path,
    bins: &Path,
    i: &Inputs,
    o: &Options,
    j: &mut Figures,
    cpu: &mut Figures,
) -> Result<(f64, f64)> {
    println!(
        "## Pinned (CPU 0: publisher/replay and subscriber; CPU 1: relays/stages), SCHED_FIFO\n"
    );
    println!("| run | p50 us | p99 us | p99.9 us | max us | samples |");
    println!("| --- | --- | --- | --- | --- | --- |");
    let chain3 = bare(bench, "three hops, 1 kHz, pinned", 3, 1000, o, true)?;
    println!();
    j.insert("pinned_bare_chain3_p99_us".into(), json!(chain3[1]));
    if let Some(note) = realtime(0, Some(45))? {
        tracing::info!("pipeline subscriber: {note}");
    }
    tracing::info!("pipeline at 1 kHz, pinned ...");
    let pp = pipeline(bins, &i.drive, &i.calib, 1000, false, true)?;
    print_pipeline("Pipeline at 1 kHz, real time, pinned, SCHED_FIFO", &pp);
    let [p50, p99, p999, max] = quantiles(&pp.timing.hops[3]);
    for (k, v) in [
        ("pinned_pipeline_p50_us", json!(p50)),
        ("pinned_pipeline_p99_us", json!(p99)),
        ("pinned_pipeline_p999_us", json!(p999)),
        ("pinned_pipeline_max_us", json!(max)),
        (
            "pinned_pipeline_states_over_1ms",
            json!(pp.timing.tails.count),
        ),
    ] {
        j.insert(k.into(), v);
    }
    cpu.insert("1kHz_pinned".into(), cpu_json(&pp.cpu));
    Ok((chain3[1], p99))
}

fn main() -> Result<()> {
    mems_log::init("latency");
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("chain") {
        let [_, _, input, output, n, cpu] = &args[..] else {
            bail!("usage: latency chain IN OUT|- N CPU|-");
        };
        return chain_child(input, output, n.parse()?, cpu.parse().ok());
    }
    let o = options(&args)?;
    let bench = std::env::current_exe()?;
    let bins = common::bin_dir()?;
    let i = inputs(&bins, &o)?;
    let (mut j, mut cpu) = (Figures::new(), Figures::new());
    let chain3 = bare_runs(&bench, &o, &mut j)?;
    let p = realtime_runs(&bins, &i, &o, &mut j, &mut cpu)?;
    throughput_run(&bins, &i, &mut j, &mut cpu)?;
    let (pinned_chain3_p99, pinned_p99) = pinned_runs(&bench, &bins, &i, &o, &mut j, &mut cpu)?;
    j.insert("cpu_percent_per_process".into(), Value::Object(cpu));
    let ratio = quantiles(&p.timing.hops[3])[1] / chain3[1];
    let pinned_ratio = pinned_p99 / pinned_chain3_p99;
    let hundredths = |x: f64| json!((x * 100.0).round() / 100.0);
    j.insert("pipeline_over_chain3_p99".into(), hundredths(ratio));
    j.insert(
        "pinned_pipeline_over_chain3_p99".into(),
        hundredths(pinned_ratio),
    );
    println!(
        "Pipeline p99 / three bare hops' p99 in the same run: plain {ratio:.2}, pinned \
         {pinned_ratio:.2}; the timed states were aligned ({} at rest, {} moving)\n",
        p.timing.rest, p.timing.moving
    );
    std::fs::remove_dir_all(&i.work)?;
    if o.as_json {
        println!("{}", Value::Object(j));
    }
    Ok(())
}
