//! Latency and throughput benchmark of the live pipeline, with real processes:
//! `mems-replay` -> `mems-calibrate serve` -> `mems-odometry serve` -> this process's
//! subscriber, and the bare iceoryx2 hop between two processes with the same service settings.
//!
//! ```sh
//! cargo build --release --workspace
//! cargo run --release -p mems-replay --example latency [-- --seconds 20]
//! ```
//!
//! Measures, each as an hdrhistogram of nanoseconds (reported in us):
//! - the bare hop: a publisher (this process) sends a raw sample every 1 ms with its publish time
//!   in `stamps.acquired_ns`; a subscriber process polls as the stages do (`node.wait(1 ms)`,
//!   then drains) and records receive time - publish time. Once plain, once with the publisher
//!   pinned to CPU 0 and the subscriber to CPU 1, both SCHED_FIFO (publisher 40, subscriber
//!   50), falling back to pinning alone (and saying so) where SCHED_FIFO is not permitted;
//! - the pipeline, replaying a simulated 1 kHz drive at real time: per hop from the stamps every
//!   state carries (replay publish -> calibrate publish, which includes the calibration stage's
//!   20-sample batch; calibrate -> odometry publish; odometry -> this subscriber) and end to end.
//!   Once plain, once with every process under `taskset`/`chrt -f` (replay and subscriber on
//!   CPU 0, the stages on CPU 1);
//! - throughput: a longer drive replayed with `--max` through both stages, in states per second
//!   at the subscriber.
//!
//! Every time is `CLOCK_MONOTONIC` on one machine, so differences between processes are valid.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use hdrhistogram::Histogram;
use iceoryx2::service::port_factory::PortFactory as _;
use ipc_types::clock::monotonic_ns;
use ipc_types::{OdometryState, RawImuSample, Stamps, odometry_flags, service};

/// Samples per second of the hop benchmark's publisher (the stack's usual rate).
const HOP_RATE_HZ: u64 = 1000;

/// One latency distribution.
fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 100_000_000_000, 3).expect("valid histogram bounds")
}

/// `p50 / p99 / p99.9 / max` in us, and the count.
fn row(h: &Histogram<u64>) -> String {
    let us = |q: f64| h.value_at_quantile(q) as f64 / 1000.0;
    format!(
        "| {:.1} | {:.1} | {:.1} | {:.1} | {} |",
        us(0.5),
        us(0.99),
        us(0.999),
        h.max() as f64 / 1000.0,
        h.len()
    )
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

/// The hop benchmark's subscriber process: receives `n` samples on the raw service of `ns`,
/// polling as the stages do, and prints `p50 p99 p99.9 max count` in ns on stdout.
fn hop_subscriber(ns: &str, n: usize, pinned: bool) -> Result<()> {
    if pinned && let Some(note) = realtime(1, Some(50))? {
        eprintln!("hop subscriber: {note}");
    }
    let node = service::node()?;
    let svc = service::open::<RawImuSample>(&node, &service::full_name(ns, service::RAW))?;
    let sub = service::subscriber(&svc)?;
    let mut h = histogram();
    let start = Instant::now();
    while h.len() < n as u64 && start.elapsed() < Duration::from_secs(120) {
        if node.wait(Duration::from_millis(1)).is_err() {
            break;
        }
        while let Some(s) = sub.receive()? {
            h.record(monotonic_ns().saturating_sub(s.stamps.acquired_ns).max(1))?;
        }
    }
    println!(
        "{} {} {} {} {}",
        h.value_at_quantile(0.5),
        h.value_at_quantile(0.99),
        h.value_at_quantile(0.999),
        h.max(),
        h.len()
    );
    Ok(())
}

/// Runs the bare hop for `seconds` (publisher here, subscriber in a child process).
fn hop(bench: &Path, seconds: u64, pinned: bool) -> Result<String> {
    let ns = format!("latency-hop-{}-{pinned}", std::process::id());
    let n = (seconds * HOP_RATE_HZ) as usize;
    let child = Command::new(bench)
        .args(["hop-subscriber", &ns, &n.to_string(), &pinned.to_string()])
        .stdout(Stdio::piped())
        .spawn()
        .context("cannot start the hop subscriber")?;
    let publisher_thread = std::thread::spawn(move || -> Result<Option<String>> {
        let note = if pinned { realtime(0, Some(40))? } else { None };
        let node = service::node()?;
        let svc = service::open::<RawImuSample>(&node, &service::full_name(&ns, service::RAW))?;
        let publisher = service::publisher(&svc)?;
        let wait = Instant::now();
        while svc.dynamic_config().number_of_subscribers() < 1 {
            if wait.elapsed() > Duration::from_secs(20) {
                bail!("the hop subscriber did not connect");
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        std::thread::sleep(Duration::from_millis(200));
        let period = Duration::from_nanos(1_000_000_000 / HOP_RATE_HZ);
        let start = Instant::now();
        for seq in 0..n as u64 {
            let due = start + period * seq as u32;
            if let Some(d) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(d);
            }
            let now = monotonic_ns();
            publisher.send_copy(RawImuSample {
                stamps: Stamps {
                    sample_ns: now,
                    acquired_ns: now,
                    ..Stamps::default()
                },
                seq,
                ..RawImuSample::default()
            })?;
        }
        std::thread::sleep(Duration::from_millis(300));
        Ok(note)
    });
    let output = child.wait_with_output()?;
    let note = publisher_thread.join().expect("publisher thread")?;
    if !output.status.success() {
        bail!("hop subscriber failed: {}", output.status);
    }
    let v: Vec<f64> = String::from_utf8_lossy(&output.stdout)
        .split_whitespace()
        .map(|x| x.parse::<f64>())
        .collect::<Result<_, _>>()?;
    let [p50, p99, p999, max, count] = v[..] else {
        bail!("hop subscriber printed {v:?}");
    };
    Ok(format!(
        "| {} | {:.1} | {:.1} | {:.1} | {:.1} | {count} |{}",
        if pinned {
            "pinned (CPU 0 -> 1), SCHED_FIFO 40/50"
        } else {
            "plain"
        },
        p50 / 1000.0,
        p99 / 1000.0,
        p999 / 1000.0,
        max / 1000.0,
        note.map_or(String::new(), |n| format!(" {n}"))
    ))
}

/// Runs a workspace binary to completion.
fn run(bins: &Path, name: &str, args: &[&str]) -> Result<String> {
    let out = Command::new(bins.join(name))
        .args(args)
        .output()
        .with_context(|| format!("cannot run {name}"))?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        bail!("{name} {args:?} failed: {}: {stderr}", out.status);
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
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

/// Per-hop and end-to-end latency of the pipeline, and its rate at the subscriber.
struct PipelineRun {
    hops: [Histogram<u64>; 4],
    states: u64,
    rate_hz: f64,
    replay_line: String,
}

/// Replays `recording` (`--speed 1` or `--max`) through calibrate and odometry processes and
/// measures at this process's odometry subscriber.
fn pipeline(
    bins: &Path,
    recording: &Path,
    calib: &Path,
    max: bool,
    pinned: bool,
) -> Result<PipelineRun> {
    let ns = format!("latency-pipe-{}-{max}-{pinned}", std::process::id());
    let rt_stage = pinned.then_some((1, 50));
    let rt_replay = pinned.then_some((0, 40));
    let note = if pinned { realtime(0, Some(45))? } else { None };
    if let Some(note) = note {
        eprintln!("pipeline subscriber: {note}");
    }
    let node = service::node()?;
    let svc = service::open::<OdometryState>(&node, &service::full_name(&ns, service::ODOMETRY))?;
    let sub = service::subscriber(&svc)?;
    let calib = calib.to_str().context("calibration path is not UTF-8")?;
    let spawn = |name: &str, args: &[&str], rt| -> Result<Child> {
        command(bins, name, rt)
            .args(args)
            .args(["--namespace", &ns])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot start {name}"))
    };
    let mut stages = vec![
        spawn("mems-odometry", &["serve", "--calib", calib], rt_stage)?,
        spawn("mems-calibrate", &["serve", "--calib", calib], rt_stage)?,
    ];
    std::thread::sleep(Duration::from_millis(1500));
    let pace = if max { "--max" } else { "--speed" };
    let mut replay_args = vec![
        recording.to_str().context("recording path is not UTF-8")?,
        pace,
    ];
    if !max {
        replay_args.push("1");
    }
    replay_args.extend(["--wait-subscribers", "1", "--namespace", &ns]);
    let replay = command(bins, "mems-replay", rt_replay)
        .args(&replay_args)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .context("cannot start mems-replay")?;
    let replay_out = std::thread::spawn(move || replay.wait_with_output());

    let mut hops = [histogram(), histogram(), histogram(), histogram()];
    let (mut first, mut last, mut states) = (None, 0u64, 0u64);
    let mut idle_since = Instant::now();
    while !(replay_out.is_finished() && idle_since.elapsed() > Duration::from_millis(1500)) {
        node.wait(Duration::from_millis(1))
            .map_err(|e| anyhow::anyhow!("interrupted: {e:?}"))?;
        while let Some(s) = sub.receive()? {
            let now = monotonic_ns();
            idle_since = Instant::now();
            if s.flags & odometry_flags::REVISION != 0 {
                continue;
            }
            let st = s.stamps;
            for (h, ns) in hops.iter_mut().zip([
                st.calibrated_ns.saturating_sub(st.acquired_ns),
                st.odometry_ns.saturating_sub(st.calibrated_ns),
                now.saturating_sub(st.odometry_ns),
                now.saturating_sub(st.acquired_ns),
            ]) {
                h.record(ns.max(1))?;
            }
            first.get_or_insert(now);
            last = now;
            states += 1;
        }
    }
    let out = replay_out.join().expect("replay waiter")?;
    for stage in &mut stages {
        // SAFETY: kill(2) on our own child; no memory is involved.
        unsafe { libc::kill(stage.id() as i32, libc::SIGTERM) };
        stage.wait()?;
    }
    if !out.status.success() {
        bail!("mems-replay failed: {}", out.status);
    }
    let span_s = first.map_or(0.0, |f| (last - f) as f64 * 1e-9);
    Ok(PipelineRun {
        hops,
        states,
        rate_hz: if span_s > 0.0 {
            (states - 1) as f64 / span_s
        } else {
            0.0
        },
        replay_line: String::from_utf8_lossy(&out.stdout).trim().to_owned(),
    })
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("hop-subscriber") {
        let [_, _, ns, n, pinned] = &args[..] else {
            bail!("usage: latency hop-subscriber NS N PINNED");
        };
        return hop_subscriber(ns, n.parse()?, pinned.parse()?);
    }
    let seconds: u64 = match (args.get(1).map(String::as_str), args.get(2)) {
        (Some("--seconds"), Some(s)) => s.parse()?,
        (None, _) => 20,
        _ => bail!("usage: latency [--seconds S]"),
    };
    let bench = std::env::current_exe()?;
    // target/<profile>/examples/latency -> target/<profile>
    let bins: PathBuf = bench
        .parent()
        .and_then(Path::parent)
        .context("the example lives in target/<profile>/examples")?
        .to_path_buf();
    let work = std::env::temp_dir().join(format!("mems-latency-{}", std::process::id()));
    std::fs::create_dir_all(&work)?;
    let path = |name: &str| work.join(name).to_string_lossy().into_owned();
    let (drive, long, six, calib) = (
        path("drive.mcap"),
        path("long.mcap"),
        path("six.csv"),
        path("calib.toml"),
    );
    eprintln!("latency: simulating the recordings and calibrating ...");
    let secs = seconds.to_string();
    // Two seconds of rest, then driving: the odometry aligns and then works on motion.
    let rest = ["--initial-rest", "2"];
    run(
        &bins,
        "mems-sim",
        &[&["drive", "--duration", &secs, "--out", &drive][..], &rest].concat(),
    )?;
    let long_secs = (seconds * 6).to_string();
    run(
        &bins,
        "mems-sim",
        &[
            &["drive", "--duration", &long_secs, "--out", &long][..],
            &rest,
        ]
        .concat(),
    )?;
    run(
        &bins,
        "mems-sim",
        &[
            "six-position",
            "--preset",
            "datasheet",
            "--rate",
            "200",
            "--out",
            &six,
        ],
    )?;
    run(
        &bins,
        "mems-calibrate",
        &["fit", "--input", &six, "--model", "full", "--out", &calib],
    )?;

    eprintln!("latency: bare iceoryx2 hop ...");
    let hop_plain = hop(&bench, seconds / 2, false)?;
    let hop_pinned = hop(&bench, seconds / 2, true)?;

    println!("## Bare iceoryx2 hop, 1 kHz, lossless settings, subscriber polls every 1 ms\n");
    println!("| run | p50 us | p99 us | p99.9 us | max us | samples |");
    println!("| --- | --- | --- | --- | --- | --- |");
    println!("{hop_plain}\n{hop_pinned}\n");

    let names = [
        "replay -> calibrate (incl. 20-sample batch)",
        "calibrate -> odometry",
        "odometry -> subscriber",
        "end to end (replay -> subscriber)",
    ];
    // The pinned run last: it pins and raises this (the subscriber's) thread for good.
    for pinned in [false, true] {
        if pinned {
            throughput(&bins, Path::new(&long), Path::new(&calib))?;
        }
        eprintln!("latency: pipeline at real time (pinned {pinned}) ...");
        let run = pipeline(&bins, Path::new(&drive), Path::new(&calib), false, pinned)?;
        println!(
            "## Pipeline at real time, {} ({} states; {})\n",
            if pinned {
                "replay and subscriber on CPU 0, stages on CPU 1, all SCHED_FIFO"
            } else {
                "plain"
            },
            run.states,
            run.replay_line
        );
        println!("| hop | p50 us | p99 us | p99.9 us | max us | states |");
        println!("| --- | --- | --- | --- | --- | --- |");
        for (name, h) in names.iter().zip(&run.hops) {
            println!("| {name} {}", row(h));
        }
        println!();
    }
    std::fs::remove_dir_all(&work)?;
    Ok(())
}

/// Throughput: `recording` replayed with `--max` through both stages, unpinned.
fn throughput(bins: &Path, recording: &Path, calib: &Path) -> Result<()> {
    eprintln!("latency: throughput with --max ...");
    let run = pipeline(bins, recording, calib, true, false)?;
    println!(
        "## Throughput, `mems-replay --max` through calibrate and odometry (plain)\n\n\
         {} states at {:.0} states/s at the subscriber; {}\n",
        run.states, run.rate_hz, run.replay_line
    );
    Ok(())
}
