//! `mems-stack`: the whole pipeline as separate processes (acquire -> calibrate -> odometry,
//! plus the recorder), supervised: a crashed stage is restarted (the calibration stage going on
//! from its predecessor's learned state, `mems-calibrate serve --state`), Ctrl-C stops
//! everything cleanly, and a status line shows rates, losses, zero-state and position.

mod losses;
mod monitor;
mod summary;
mod supervisor;

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use acquire::acquisition::SourceSpec;
use anyhow::{Context, Result, bail};
use calibrate::zero_state::DetectorKind;
use clap::Parser;
use ipc_types::service;
use losses::RecorderLosses;
use monitor::Monitor;
use supervisor::{ChildSpec, Event, Supervisor};

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// `sim` (the simulated MPU-9250 on simulated I2C), `sim-spi` (the same on simulated SPI),
    /// `i2c:/dev/i2c-N[@0x68]` or `spi:/dev/spidevB.C`.
    #[arg(long, default_value = "sim")]
    source: String,
    /// Output rate of the sensor, Hz (1000/n with gyro; 4000 is accelerometer-only and needs
    /// SPI: the odometry then estimates no position and the status line says so).
    #[arg(long, default_value_t = 1000)]
    rate: u32,
    /// Record every topic to this MCAP file, checked before anything starts (its directory
    /// must exist and be writable; an existing recording is refused unless `--force`). A
    /// recorder that dies is restarted and continues the run in the file's next segment
    /// (`run.1.mcap`, ...), which the readers and `mems-replay` read with it as one run.
    #[arg(long)]
    record: Option<PathBuf>,
    /// Overwrite the recording at `--record` (its successor segments too), once the stack
    /// starts its stages.
    #[arg(long, requires = "record")]
    force: bool,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long)]
    duration: Option<f64>,
    /// Calibration file. Required for a real sensor; for `sim` the stack calibrates the
    /// simulated part from simulated six-position and orientation sessions when it is not given.
    #[arg(long)]
    calib: Option<PathBuf>,
    /// Zero-state detector of the calibration stage (default: `glrt`, which needs the
    /// gyroscope; above 1000 Hz, where the sensor runs accelerometer-only, `glrt-accel` over a
    /// 0.5 s window). `yu` is the thesis's detector.
    #[arg(long, value_enum)]
    detector: Option<DetectorKind>,
    /// Seed of the simulated sensor and its drive.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// Run the acquisition loop under SCHED_FIFO at this priority (1-99), as `mems-acquire
    /// --sched-fifo`. Needs CAP_SYS_NICE or an RLIMIT_RTPRIO of at least PRIO: where it is
    /// refused, acquire fails at start-up and the stack stops with its error.
    #[arg(long, value_name = "PRIO", value_parser = clap::value_parser!(u8).range(1..=99))]
    sched_fifo: Option<u8>,
    /// Pin the acquisition process to this CPU core, as `mems-acquire --cpu`.
    #[arg(long, value_name = "N")]
    cpu: Option<usize>,
    /// Lock the acquisition process's memory (mlockall), as `mems-acquire --mlock`.
    #[arg(long)]
    mlock: bool,
    /// Serve the live topics to the Foxglove app over its WebSocket protocol at HOST:PORT
    /// (`mems-foxglove`; off by default). Use a loopback address unless the network is trusted:
    /// anyone who can connect sees the robot's odometry.
    #[arg(long, value_name = "HOST:PORT")]
    foxglove: Option<String>,
}

/// Window of the accelerometer-only GLRT, s: 0.5 s, as the GLRT's default at 1 kHz (measured
/// at 4 kHz in docs/detectors.md).
const ACCEL_GLRT_WINDOW_S: f64 = 0.5;

/// `mems-calibrate serve`'s detector arguments for `cli`: the one asked for, else the GLRT, on
/// the accelerometer alone over [`ACCEL_GLRT_WINDOW_S`] above 1000 Hz (no gyroscope there).
fn detector_args(cli: &Cli) -> Vec<String> {
    match &cli.detector {
        Some(d) => vec!["--detector".into(), d.name().into()],
        None if cli.rate > 1000 => {
            // Batches of 20 samples (calibrate::zero_state::BATCH_LEN).
            let batches = (ACCEL_GLRT_WINDOW_S * f64::from(cli.rate) / 20.0)
                .round()
                .max(1.0);
            vec![
                "--detector".into(),
                "glrt-accel".into(),
                "--glrt-window".into(),
                batches.to_string(),
            ]
        }
        None => vec!["--detector".into(), "glrt".into()],
    }
}

/// Refuses, before anything starts, a source that cannot be parsed, a rate its bus cannot
/// carry (acquire's own check, with its arithmetic: 4 kHz needs SPI), and a detector that needs
/// the gyroscope above 1000 Hz, where the sensor runs accelerometer-only.
fn check_source(cli: &Cli) -> Result<()> {
    let source: SourceSpec = cli.source.parse().map_err(anyhow::Error::msg)?;
    source
        .check_rate(cli.rate)
        .map_err(|e| anyhow::anyhow!("--source {} --rate {}: {e}", cli.source, cli.rate))?;
    if let Some(d) = cli.detector
        && d.needs_gyro()
        && cli.rate > 1000
    {
        bail!(
            "--detector {} needs the gyroscope, which the sensor does not sample above 1000 Hz \
             (--rate {}): use glrt-accel or yu",
            d.name(),
            cli.rate
        );
    }
    Ok(())
}

/// `mems-acquire`'s arguments for `cli` (the namespace is added by the caller): the source,
/// rate and seed, and the real-time options passed through. Every restart uses the same.
fn acquire_args(cli: &Cli) -> Vec<String> {
    let mut args = vec![
        "--source".into(),
        cli.source.clone(),
        "--rate".into(),
        cli.rate.to_string(),
        "--seed".into(),
        cli.seed.to_string(),
    ];
    if let Some(priority) = cli.sched_fifo {
        args.extend(["--sched-fifo".into(), priority.to_string()]);
    }
    if let Some(cpu) = cli.cpu {
        args.extend(["--cpu".into(), cpu.to_string()]);
    }
    if cli.mlock {
        args.push("--mlock".into());
    }
    args
}

/// The directory holding this executable, where the other `mems-*` binaries are built.
fn bin_dir() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot locate mems-stack's own executable")?;
    Ok(exe
        .parent()
        .context("mems-stack's executable has no parent directory")?
        .to_path_buf())
}

/// Runs a preparatory command to completion, failing with its name if it fails.
fn run_step(program: &Path, args: &[&str]) -> Result<()> {
    let status = Command::new(program)
        .args(args)
        .status()
        .with_context(|| format!("cannot run {}", program.display()))?;
    if !status.success() {
        bail!("{} {} failed: {status}", program.display(), args.join(" "));
    }
    Ok(())
}

/// Calibrates the simulated part: a six-position session of the same simulated MPU-9250
/// (datasheet-level errors, a different power-on than the live run, so the turn-on bias is not
/// known exactly), fitted with model 3; then the gyro's scale and misalignment from a session of
/// 16 orientations (`mems-odometry gyrocal`: the six positions are too few poses for it).
fn calibrate_sim(bins: &Path, work: &Path, seed: u64) -> Result<PathBuf> {
    let utf8 = |p: &Path| -> Result<String> {
        Ok(p.to_str()
            .context("temporary path is not UTF-8")?
            .to_owned())
    };
    let six = utf8(&work.join("six-position.csv"))?;
    let poses = utf8(&work.join("orientations.csv"))?;
    let calib = work.join("calib.toml");
    let calib_str = utf8(&calib)?;
    let seed = (seed + 1000).to_string();
    // Both sessions of the same simulated power-on, at 200 Hz.
    let session = |kind: &[&str], out: &str| {
        let common = [
            "--preset",
            "datasheet",
            "--seed",
            &seed,
            "--rate",
            "200",
            "--out",
        ];
        let args: Vec<&str> = kind.iter().chain(&common).copied().chain([out]).collect();
        run_step(&bins.join("mems-sim"), &args)
    };
    session(&["six-position"], &six)?;
    run_step(
        &bins.join("mems-calibrate"),
        &[
            "fit", "--input", &six, "--model", "full", "--out", &calib_str,
        ],
    )?;
    session(&["orientations", "--n", "16"], &poses)?;
    run_step(
        &bins.join("mems-odometry"),
        &[
            "gyrocal", "--input", &poses, "--calib", &calib_str, "--into", &calib_str,
        ],
    )?;
    Ok(calib)
}

/// Removes what a previous stack killed with SIGKILL left behind: the iceoryx2 resources of
/// dead nodes (its own and, if they died with it, its children's) and the work directories
/// of stacks whose process is gone.
fn clean_stale() {
    match service::remove_dead_nodes() {
        Ok(0) => {}
        Ok(n) => tracing::info!("removed the shared memory of {n} dead iceoryx2 nodes"),
        Err(e) => tracing::warn!("{e}"),
    }
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) = name
            .to_str()
            .and_then(|n| n.strip_prefix(WORK_DIR_PREFIX))
            .and_then(|p| p.parse::<i32>().ok())
        else {
            continue;
        };
        // SAFETY: kill(2) with signal 0 only checks whether the process exists.
        let gone = unsafe { libc::kill(pid, 0) } != 0
            && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH);
        if gone && std::fs::remove_dir_all(entry.path()).is_ok() {
            tracing::info!(
                "removed {}, left by a stack that died",
                entry.path().display()
            );
        }
    }
}

/// Name of a stack's work directory under the temporary directory, before its process id.
const WORK_DIR_PREFIX: &str = "mems-stack-";

/// The supervised processes, in start order: consumers first, the source last, so nothing is
/// published to nobody. `calib` is the calibration file, `work` the stack's work directory.
fn child_specs(
    cli: &Cli,
    bins: &Path,
    namespace: &str,
    calib: String,
    work: &Path,
    recorder_losses: Option<&RecorderLosses>,
) -> Vec<ChildSpec> {
    let spec = |name: &str, program: &str, args: Vec<String>| ChildSpec {
        name: name.to_string(),
        program: bins.join(program),
        args: args
            .into_iter()
            .chain(["--namespace".to_string(), namespace.to_string()])
            .collect(),
        restart_at_once: false,
        stdout: None,
    };
    let mut specs = Vec::new();
    if let Some(out) = &cli.record {
        let args = vec![
            "--out".into(),
            out.display().to_string(),
            "--continue".into(),
        ];
        specs.push(ChildSpec {
            restart_at_once: true,
            stdout: recorder_losses.map(RecorderLosses::sink),
            ..spec("record", "mems-record", args)
        });
    }
    if let Some(addr) = &cli.foxglove {
        let args = vec!["--listen".into(), addr.clone()];
        specs.push(spec("foxglove", "mems-foxglove", args));
    }
    let args = vec!["serve".into(), "--calib".into(), calib.clone()];
    specs.push(spec("odometry", "mems-odometry", args));
    // A restarted calibration stage goes on from what the killed one had learned, in the
    // stack's work directory (a new stack starts afresh).
    let state = work.join("calibrate-state.json").display().to_string();
    let args = [
        "serve".into(),
        "--calib".into(),
        calib,
        "--state".into(),
        state,
    ];
    let args = args.into_iter().chain(detector_args(cli)).collect();
    specs.push(spec("calibrate", "mems-calibrate", args));
    specs.push(spec("acquire", "mems-acquire", acquire_args(cli)));
    specs
}

/// Says on stderr what the supervisor reports; returns why the stack must stop, if a child
/// keeps failing at start.
fn announce(events: Vec<Event>, tty: bool) -> Option<String> {
    let mut gave_up = None;
    for event in events {
        if tty {
            eprintln!();
        }
        match event {
            Event::Exited { name, status } => {
                tracing::warn!("{name} exited ({status}); restarting");
            }
            Event::Restarted { name, count } => {
                tracing::info!("{name} restarted ({count} so far)");
            }
            Event::GaveUp { name, status } => {
                let why = format!(
                    "{name} exited within {:?} of starting {} times in a row (last: {status}); \
                     not restarting it: see its error above",
                    supervisor::FAST_EXIT,
                    supervisor::MAX_FAST_EXITS
                );
                // The error itself is printed once, as the stack's exit error.
                tracing::info!("{name} keeps failing at start; stopping the stack");
                gave_up.get_or_insert(why);
            }
        }
    }
    gave_up
}

/// The calibration file the stack runs with: `--calib`, or for a simulated source one
/// calibrated now in `work`.
fn calibration(cli: &Cli, bins: &Path, work: &Path) -> Result<PathBuf> {
    Ok(match (&cli.calib, cli.source.as_str()) {
        (Some(c), _) => c.clone(),
        (None, "sim" | "sim-spi") => calibrate_sim(bins, work, cli.seed)?,
        (None, other) => bail!("--calib is required for source {other}"),
    })
}

/// Supervises the children and shows the live status line until SIGINT/SIGTERM, the
/// `duration` (s) since `start`, or a child that keeps failing at start (returned: why).
fn supervise(
    supervisor: &mut Supervisor,
    monitor: &mut Monitor,
    recorder_losses: Option<&RecorderLosses>,
    duration: Option<f64>,
    start: Instant,
) -> Result<Option<String>> {
    let mut last_status = Instant::now();
    let tty = std::io::stderr().is_terminal();
    let deadline = duration.map(Duration::from_secs_f64);
    let mut gave_up: Option<String> = None;
    // SIGINT/SIGTERM ends the loop: the clean way out.
    while !ipc_types::stop::sleep(Duration::from_millis(20)) && gave_up.is_none() {
        monitor.drain()?;
        gave_up = announce(supervisor.poll(), tty);
        if last_status.elapsed() >= Duration::from_secs(1) {
            let line = monitor.status(recorder_losses);
            let elapsed = start.elapsed().as_secs_f64();
            let line = match duration {
                Some(total) => format!("{elapsed:.0}/{total:.0} s | {line}"),
                None => format!("{elapsed:.0} s | {line}"),
            };
            // On a terminal one status line, rewritten in place; otherwise a line each time.
            if tty {
                eprint!("\r{line}\x1b[K");
            } else {
                tracing::info!("{line}");
            }
            last_status = Instant::now();
        }
        if deadline.is_some_and(|d| start.elapsed() >= d) {
            break;
        }
    }
    if tty {
        eprintln!();
    }
    Ok(gave_up)
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-stack");
    mems_log::exit(run(Cli::parse()))
}

fn run(cli: Cli) -> Result<()> {
    check_source(&cli)?;
    // Before calibrating: a stack that cannot record must not start, nor touch a recording.
    let overwrite = match &cli.record {
        Some(out) => recording::segment::check_target(out, cli.force)?,
        None => Vec::new(),
    };
    if let Some(addr) = &cli.foxglove {
        std::net::ToSocketAddrs::to_socket_addrs(addr.as_str())
            .with_context(|| format!("--foxglove {addr:?}: expected HOST:PORT"))?;
    }
    clean_stale();
    let namespace = service::namespace(cli.namespace.as_deref());
    let bins = bin_dir()?;
    let work = std::env::temp_dir().join(format!("{WORK_DIR_PREFIX}{}", std::process::id()));
    std::fs::create_dir_all(&work).with_context(|| format!("cannot create {}", work.display()))?;
    let calib = calibration(&cli, &bins, &work)?;
    let calib = calib.to_str().context("calibration path is not UTF-8")?;
    let recorder_losses = cli.record.is_some().then(RecorderLosses::default);
    let specs = child_specs(
        &cli,
        &bins,
        &namespace,
        calib.to_string(),
        &work,
        recorder_losses.as_ref(),
    );
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let mut monitor = Monitor::new(&node, &namespace, cli.rate)?;
    for old in &overwrite {
        std::fs::remove_file(old).with_context(|| format!("cannot remove {}", old.display()))?;
    }
    let mut supervisor = Supervisor::start(specs)?;
    tracing::info!("running (namespace {namespace:?}); Ctrl-C stops");
    let start = Instant::now();
    let gave_up = supervise(
        &mut supervisor,
        &mut monitor,
        recorder_losses.as_ref(),
        cli.duration,
        start,
    )?;
    let restarts = supervisor
        .restarts()
        .iter()
        .map(|(n, c)| format!("{n} {c}"))
        .collect::<Vec<_>>();
    supervisor.shutdown(Duration::from_secs(3));
    let _ = std::fs::remove_dir_all(&work);
    // The summary goes to stdout (the live status is on stderr), for scripts and tests: for a
    // person, then the status line.
    let [raw, corrected, odometry] = &monitor.stats;
    let summary = summary::Summary {
        elapsed_s: start.elapsed().as_secs_f64(),
        restarts: &restarts,
        topics: [raw, corrected, odometry],
        source: &monitor.source,
        recorder: recorder_losses.as_ref(),
        record: cli.record.as_deref(),
        state: monitor.last_state.as_ref(),
    };
    print!("{summary}");
    println!("{}", monitor.status(recorder_losses.as_ref()));
    match gave_up {
        Some(why) => bail!("{why}"),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn acquire_args_for(args: &[&str]) -> Vec<String> {
        let cli =
            Cli::try_parse_from(std::iter::once("mems-stack").chain(args.iter().copied())).unwrap();
        acquire_args(&cli)
    }

    /// `flag`'s value in `args`, `None` when absent.
    fn value<'a>(args: &'a [String], flag: &str) -> Option<&'a str> {
        let i = args.iter().position(|a| a == flag)?;
        Some(args.get(i + 1).expect("flag has a value").as_str())
    }

    #[test]
    fn real_time_options_are_passed_to_acquire() {
        let args = acquire_args_for(&[
            "--rate",
            "4000",
            "--sched-fifo",
            "50",
            "--cpu",
            "1",
            "--mlock",
        ]);
        assert_eq!(value(&args, "--sched-fifo"), Some("50"));
        assert_eq!(value(&args, "--cpu"), Some("1"));
        assert_eq!(value(&args, "--rate"), Some("4000"));
        assert!(args.iter().any(|a| a == "--mlock"), "{args:?}");
    }

    #[test]
    fn rates_the_bus_cannot_carry_are_refused_before_start() {
        let check = |args: &[&str]| {
            let cli =
                Cli::try_parse_from(std::iter::once("mems-stack").chain(args.iter().copied()))
                    .unwrap();
            check_source(&cli).map_err(|e| e.to_string())
        };
        let err = check(&["--rate", "4000"]).unwrap_err();
        for needle in [
            "--source sim --rate 4000",
            "400 kHz I2C",
            "108 %",
            "sim-spi",
        ] {
            assert!(err.contains(needle), "{needle:?} missing from: {err}");
        }
        assert!(check(&["--rate", "4000", "--source", "i2c:/dev/i2c-1"]).is_err());
        check(&["--rate", "4000", "--source", "sim-spi"]).unwrap();
        check(&["--rate", "4000", "--source", "spi:/dev/spidev0.0"]).unwrap();
        check(&["--rate", "1000"]).unwrap();
        assert!(check(&["--rate", "3000", "--source", "sim-spi"]).is_err());
        assert!(check(&["--source", "usb"]).is_err());
        let err = check(&[
            "--rate",
            "4000",
            "--source",
            "sim-spi",
            "--detector",
            "glrt",
        ])
        .unwrap_err();
        assert!(err.contains("--detector glrt needs the gyroscope"), "{err}");
        check(&["--rate", "4000", "--source", "sim-spi", "--detector", "yu"]).unwrap();
    }

    #[test]
    fn an_unknown_detector_is_refused_by_the_parser() {
        let err = Cli::try_parse_from(["mems-stack", "--detector", "foo"])
            .err()
            .expect("--detector foo parses");
        assert!(err.to_string().contains("glrt-accel"), "{err}");
    }

    #[test]
    fn without_real_time_options_acquire_gets_none() {
        let args = acquire_args_for(&[]);
        for flag in ["--sched-fifo", "--cpu", "--mlock"] {
            assert!(!args.iter().any(|a| a == flag), "{flag} in {args:?}");
        }
        assert_eq!(value(&args, "--source"), Some("sim"));
    }

    #[test]
    fn the_detector_needs_no_gyro_above_1_khz() {
        let detector = |args: &[&str]| {
            let cli =
                Cli::try_parse_from(std::iter::once("mems-stack").chain(args.iter().copied()))
                    .unwrap();
            detector_args(&cli)
        };
        // 4 kHz is accelerometer-only: the accelerometer GLRT over 0.5 s = 100 batches of 20.
        let at_4k = detector(&["--rate", "4000"]);
        assert_eq!(value(&at_4k, "--detector"), Some("glrt-accel"));
        assert_eq!(value(&at_4k, "--glrt-window"), Some("100"));
        let at_1k = detector(&["--rate", "1000"]);
        assert_eq!(value(&at_1k, "--detector"), Some("glrt"));
        assert_eq!(value(&at_1k, "--glrt-window"), None);
        let asked = detector(&["--rate", "4000", "--detector", "yu"]);
        assert_eq!(asked, vec!["--detector".to_string(), "yu".to_string()]);
    }

    #[test]
    fn a_priority_outside_1_to_99_is_refused_by_the_stack_itself() {
        for bad in ["0", "100"] {
            let err = Cli::try_parse_from(["mems-stack", "--sched-fifo", bad])
                .err()
                .unwrap_or_else(|| panic!("--sched-fifo {bad} accepted"));
            assert!(err.to_string().contains("--sched-fifo"), "{err}");
        }
    }
}
