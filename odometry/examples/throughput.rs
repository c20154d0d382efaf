//! Throughput of post-mortem replay on one MCAP recording, stage by stage, in samples per
//! second of raw samples (docs/offline.md):
//!
//! - `scan`: the run's messages framed and decompressed, not decoded
//!   (`recording::mcap::run::RunReader`);
//! - `raw read`: the raw samples and truth decoded and checked (`RawRun`, what `offline`
//!   reads);
//! - `calibration stage` and `odometry stage`: each stage alone, timed over blocks of raw
//!   samples read ahead (the read is not counted), with `mems-odometry offline`'s defaults
//!   (identity calibration, vehicle profile, default hindsight); the calibration stage's
//!   start-up (`CalibrationStage::new`) separately;
//! - `offline end-to-end`: the built `mems-odometry offline --json` as a process, its wall
//!   time and peak RSS (`/usr/bin/time`);
//! - with `--python`, the official Python `mcap` reader on the same file
//!   (`odometry/examples/mcap_read.py`): the raw topic's messages read, then also decoded
//!   (protobuf with `mcap-protobuf-support`'s decoder factory, or `json.loads` for an older
//!   JSON recording).
//!
//! Each figure is given on the wall clock and on the CPU time of the thread (or process) that
//! ran it: on a shared machine the second is the one that does not depend on the load.
//!
//! `cargo run --release -p odometry --example throughput -- --input drive.mcap
//! [--python python3]` (build `mems-odometry` first: `cargo build --release -p odometry`).

use mems_stage::Stage;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use calibrate::calibfile::CalibrationFile;
use calibrate::stage::{CalibrationStage, RefineConfig};
use clap::Parser;
use ipc_types::{CorrectedImuSample, RawImuSample, odometry_flags};
use odometry::profile::Profile;
use odometry::stage::OdometryStage;
use recording::mcap::run::{Item, RawRun, RunReader};

#[derive(Parser)]
struct Args {
    /// The MCAP recording (the first file of a run).
    #[arg(long)]
    input: PathBuf,
    /// Raw samples per timed block of the stage measurements.
    #[arg(long, default_value_t = 1 << 16)]
    block: usize,
    /// Python interpreter with the `mcap` package, to time the official reader too.
    #[arg(long)]
    python: Option<PathBuf>,
}

/// A wall time and a CPU time.
#[derive(Debug, Clone, Copy, Default)]
struct Times {
    wall: Duration,
    cpu: Duration,
}

impl Times {
    /// Times `f`.
    fn of<T>(f: impl FnOnce() -> T) -> Result<(T, Self)> {
        let (wall, cpu) = (Instant::now(), thread_cpu()?);
        let out = f();
        let times = Self {
            wall: wall.elapsed(),
            cpu: thread_cpu()? - cpu,
        };
        Ok((out, times))
    }

    fn add(&mut self, other: Self) {
        self.wall += other.wall;
        self.cpu += other.cpu;
    }

    /// `n` samples over these times: rate on the wall clock, on the CPU, and the times.
    fn show(&self, n: u64) -> String {
        let rate = |t: Duration| n as f64 / t.as_secs_f64() * 1e-6;
        format!(
            "{:>6.2} M samples/s wall {:>6.2} CPU  ({:.2} s wall, {:.2} s CPU, {:.3} us/sample CPU)",
            rate(self.wall),
            rate(self.cpu),
            self.wall.as_secs_f64(),
            self.cpu.as_secs_f64(),
            self.cpu.as_secs_f64() * 1e6 / n as f64
        )
    }
}

/// CPU time of the calling thread (`/proc/thread-self/schedstat`, its first field, ns).
fn thread_cpu() -> Result<Duration> {
    let stat = std::fs::read_to_string("/proc/thread-self/schedstat")?;
    let ns = stat
        .split_whitespace()
        .next()
        .and_then(|v| v.parse().ok())
        .context("no CPU time in /proc/thread-self/schedstat")?;
    Ok(Duration::from_nanos(ns))
}

fn main() -> Result<()> {
    let args = Args::parse();
    let input = &args.input;

    let (messages, scan) = Times::of(|| -> Result<u64> {
        let mut reader = RunReader::open(input)?;
        let mut messages = 0u64;
        while let Some(m) = reader.next() {
            m?;
            messages += 1;
        }
        Ok(messages)
    })?;
    let messages = messages?;
    let (raw, read) = Times::of(|| -> Result<u64> {
        let mut raw = 0u64;
        for item in RawRun::open(input, false)? {
            raw += u64::from(matches!(item?, Item::Raw(_)));
        }
        Ok(raw)
    })?;
    let raw = raw?;
    if raw == 0 {
        bail!("{}: no raw samples", input.display());
    }
    println!(
        "{}: {raw} raw samples, {messages} messages",
        input.display()
    );
    println!("scan (framing, zstd)     {}", scan.show(raw));
    println!("raw read (decoded)       {}", read.show(raw));

    let (startup, calibration, odometry) = stages(input, args.block)?;
    println!(
        "calibration stage        {} start-up {:.0} us",
        calibration.show(raw),
        startup.wall.as_secs_f64() * 1e6
    );
    println!("odometry stage           {}", odometry.show(raw));

    let (e2e, peak_kb) = end_to_end(input)?;
    println!(
        "offline end-to-end       {} peak RSS {:.0} MB",
        e2e.show(raw),
        peak_kb as f64 / 1024.0
    );
    println!(
        "this benchmark's peak RSS {:.0} MB",
        vm_hwm_kb()? as f64 / 1024.0
    );

    if let Some(python) = &args.python {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/mcap_read.py");
        let out = Command::new(python)
            .arg(&script)
            .arg(input)
            .output()
            .with_context(|| format!("cannot run {}", python.display()))?;
        if !out.status.success() {
            bail!(
                "{}: {}",
                script.display(),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        print!("{}", String::from_utf8_lossy(&out.stdout));
    }
    Ok(())
}

/// The calibration stage's start-up, then the time each stage takes over the recording.
fn stages(input: &Path, block: usize) -> Result<(Times, Times, Times)> {
    let file = CalibrationFile::identity(ipc_types::units::STANDARD_GRAVITY_MPS2);
    let detector = Profile::Other.detector(file.gravity_mps2);
    let (calibration, startup) =
        Times::of(|| CalibrationStage::new(&file, detector, RefineConfig::default()))?;
    let mut calibration = calibration?;
    let config = Profile::Other.odometry(odometry::config::from_calibration(&file).config);
    let mut odometry = OdometryStage::new(config);

    let mut raw: Vec<RawImuSample> = Vec::with_capacity(block);
    let mut corrected: Vec<CorrectedImuSample> = Vec::with_capacity(2 * block);
    let (mut t_cal, mut t_odo) = (Times::default(), Times::default());
    let mut states = 0u64;
    let mut items = RawRun::open(input, false)?;
    loop {
        raw.clear();
        for item in items.by_ref() {
            if let Item::Raw(r) = item? {
                raw.push(r);
                if raw.len() == block {
                    break;
                }
            }
        }
        if raw.is_empty() {
            break;
        }
        corrected.clear();
        let (result, t) = Times::of(|| -> Result<()> {
            for r in &raw {
                calibration.process(r, &mut |c| corrected.push(*c))?;
            }
            Ok(())
        })?;
        result?;
        t_cal.add(t);
        let (result, t) = Times::of(|| -> Result<()> {
            for c in &corrected {
                odometry.process(c, &mut |s| {
                    states += u64::from(s.flags & odometry_flags::REVISION == 0)
                })?;
            }
            Ok(())
        })?;
        result?;
        t_odo.add(t);
    }
    if states == 0 {
        bail!("{}: the odometry stage gave no state", input.display());
    }
    Ok((startup, t_cal, t_odo))
}

/// Wall and CPU (user + system) time and peak RSS (KiB) of `mems-odometry offline --json` on
/// `input`.
fn end_to_end(input: &Path) -> Result<(Times, u64)> {
    let exe = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../target/release/mems-odometry")
        .canonicalize()
        .context("build mems-odometry first: cargo build --release -p odometry")?;
    let start = Instant::now();
    let out = Command::new("/usr/bin/time")
        .args(["-f", "peak_rss_kb %M cpu_s %U %S"])
        .arg(&exe)
        .args(["offline", "--json", "--input"])
        .arg(input)
        .output()
        .context("cannot run /usr/bin/time")?;
    let wall = start.elapsed();
    let err = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        bail!("mems-odometry offline failed: {err}");
    }
    let fields: Vec<&str> = err
        .lines()
        .find_map(|l| l.strip_prefix("peak_rss_kb "))
        .context("no peak RSS from /usr/bin/time")?
        .split_whitespace()
        .collect();
    let number = |i: usize| -> Result<f64> {
        fields
            .get(i)
            .and_then(|v| v.parse().ok())
            .context("unexpected /usr/bin/time output")
    };
    let cpu = Duration::from_secs_f64(number(2)? + number(3)?);
    Ok((Times { wall, cpu }, number(0)? as u64))
}

/// This process's peak resident set, KiB (`VmHWM` in /proc/self/status).
fn vm_hwm_kb() -> Result<u64> {
    let status = std::fs::read_to_string("/proc/self/status")?;
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .context("no VmHWM in /proc/self/status")
}
