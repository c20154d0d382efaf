//! `mems-stack`: the whole pipeline as separate processes (acquire -> calibrate -> odometry,
//! plus the recorder), supervised: a crashed stage is restarted (the calibration stage going on
//! from its predecessor's learned state, `mems-calibrate serve --state`), Ctrl-C stops
//! everything cleanly, and a status line shows rates, losses, zero-state and position.

mod losses;
mod summary;
mod supervisor;

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use acquire::acquisition::SourceSpec;
use anyhow::{Context, Result, bail};
use clap::Parser;
use ipc_types::{
    CorrectedImuSample, Message, OdometryState, RawImuSample, clock::monotonic_ns, corrected_flags,
    odometry_flags, service,
};
use losses::{RecorderLosses, SourceLosses};
use mems_topic::TopicStats;
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
    #[arg(long)]
    detector: Option<String>,
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
        Some(d) => vec!["--detector".into(), d.clone()],
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

/// Refuses, before anything starts, a source that cannot be parsed or a rate its bus cannot
/// carry (acquire's own check, with its arithmetic: 4 kHz needs SPI).
fn check_source(cli: &Cli) -> Result<()> {
    let source: SourceSpec = cli.source.parse().map_err(anyhow::Error::msg)?;
    source
        .check_rate(cli.rate)
        .map_err(|e| anyhow::anyhow!("--source {} --rate {}: {e}", cli.source, cli.rate))?;
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
        Ok(n) => eprintln!("mems-stack: removed the shared memory of {n} dead iceoryx2 nodes"),
        Err(e) => eprintln!("mems-stack: {e}"),
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
            eprintln!(
                "mems-stack: removed {}, left by a stack that died",
                entry.path().display()
            );
        }
    }
}

/// Name of a stack's work directory under the temporary directory, before its process id.
const WORK_DIR_PREFIX: &str = "mems-stack-";

fn main() -> Result<()> {
    let cli = Cli::parse();
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
    let calib = match (&cli.calib, cli.source.as_str()) {
        (Some(c), _) => c.clone(),
        (None, "sim" | "sim-spi") => calibrate_sim(&bins, &work, cli.seed)?,
        (None, other) => bail!("--calib is required for source {other}"),
    };
    let calib = calib
        .to_str()
        .context("calibration path is not UTF-8")?
        .to_string();
    let ns_args = vec!["--namespace".to_string(), namespace.clone()];
    let spec = |name: &str, program: &str, args: Vec<String>| ChildSpec {
        name: name.to_string(),
        program: bins.join(program),
        args: args.into_iter().chain(ns_args.clone()).collect(),
        restart_at_once: false,
        stdout: None,
    };

    // Start order: consumers first, the source last, so nothing is published to nobody.
    let mut specs = Vec::new();
    let recorder_losses = cli.record.is_some().then(RecorderLosses::default);
    let mut source = SourceLosses::new(cli.rate);
    if let Some(out) = &cli.record {
        specs.push(ChildSpec {
            restart_at_once: true,
            stdout: recorder_losses.as_ref().map(RecorderLosses::sink),
            ..spec(
                "record",
                "mems-record",
                vec![
                    "--out".into(),
                    out.display().to_string(),
                    "--continue".into(),
                ],
            )
        });
    }
    if let Some(addr) = &cli.foxglove {
        specs.push(spec(
            "foxglove",
            "mems-foxglove",
            vec!["--listen".into(), addr.clone()],
        ));
    }
    specs.push(spec(
        "odometry",
        "mems-odometry",
        vec!["serve".into(), "--calib".into(), calib.clone()],
    ));
    // A restarted calibration stage goes on from what the killed one had learned, in the
    // stack's work directory (a new stack starts afresh).
    let calibrate_state = work.join("calibrate-state.json").display().to_string();
    specs.push(spec(
        "calibrate",
        "mems-calibrate",
        [
            "serve".into(),
            "--calib".into(),
            calib,
            "--state".into(),
            calibrate_state,
        ]
        .into_iter()
        .chain(detector_args(&cli))
        .collect(),
    ));
    specs.push(spec("acquire", "mems-acquire", acquire_args(&cli)));

    // Before any port exists: a SIGINT/SIGTERM is kept from then on.

    ipc_types::stop::install()?;

    let node = service::node()?;
    let raw = service::open::<RawImuSample>(&node, &service::full_name(&namespace, service::RAW))?;
    let corrected = service::open::<CorrectedImuSample>(
        &node,
        &service::full_name(&namespace, service::CORRECTED),
    )?;
    let odometry =
        service::open::<OdometryState>(&node, &service::full_name(&namespace, service::ODOMETRY))?;
    let raw_sub = service::subscriber(&raw)?;
    let corrected_sub = service::subscriber(&corrected)?;
    let odometry_sub = service::subscriber(&odometry)?;

    for old in &overwrite {
        std::fs::remove_file(old).with_context(|| format!("cannot remove {}", old.display()))?;
    }
    let mut supervisor = Supervisor::start(specs)?;
    eprintln!("mems-stack: running (namespace {namespace:?}); Ctrl-C stops");
    let (mut raw_stats, mut cor_stats, mut odo_stats) =
        (TopicStats::new(), TopicStats::new(), TopicStats::new());
    // The calibration stage's rest verdict on the newest sample; `None` until its detector has
    // learned (no verdict yet).
    let mut zero_state: Option<bool> = None;
    let mut last_state: Option<OdometryState> = None;
    let start = Instant::now();
    let mut last_status = Instant::now();
    let tty = std::io::stderr().is_terminal();
    let deadline = cli.duration.map(Duration::from_secs_f64);
    let mut gave_up: Option<String> = None;

    // SIGINT/SIGTERM ends the loop: the clean way out.
    while !ipc_types::stop::sleep(Duration::from_millis(20)) {
        while let Some(s) = raw_sub.receive()? {
            observe(&mut raw_stats, s.payload());
            source.observe(s.payload());
        }
        while let Some(s) = corrected_sub.receive()? {
            observe(&mut cor_stats, s.payload());
            zero_state = (s.flags & corrected_flags::DETECTOR_READY != 0)
                .then_some(s.flags & corrected_flags::ZERO_STATE != 0);
        }
        while let Some(s) = odometry_sub.receive()? {
            observe(&mut odo_stats, s.payload());
            if s.flags & odometry_flags::REVISION == 0 {
                last_state = Some(*s.payload());
            }
        }
        for event in supervisor.poll() {
            if tty {
                eprintln!();
            }
            match event {
                Event::Exited { name, status } => {
                    eprintln!("mems-stack: {name} exited ({status}); restarting");
                }
                Event::Restarted { name, count } => {
                    eprintln!("mems-stack: {name} restarted ({count} so far)");
                }
                Event::GaveUp { name, status } => {
                    let why = format!(
                        "{name} exited within {:?} of starting {} times in a row (last: \
                         {status}); not restarting it: see its error above",
                        supervisor::FAST_EXIT,
                        supervisor::MAX_FAST_EXITS
                    );
                    eprintln!("mems-stack: {why}; stopping the stack");
                    gave_up.get_or_insert(why);
                }
            }
        }
        if gave_up.is_some() {
            break;
        }
        if last_status.elapsed() >= Duration::from_secs(1) {
            let line = status_line(
                &[&raw_stats, &cor_stats, &odo_stats],
                &source,
                recorder_losses.as_ref(),
                zero_state,
                last_state.as_ref(),
            );
            let elapsed = start.elapsed().as_secs_f64();
            let line = match cli.duration {
                Some(total) => format!("{elapsed:.0}/{total:.0} s | {line}"),
                None => format!("{elapsed:.0} s | {line}"),
            };
            if tty {
                eprint!("\r{line}\x1b[K");
            } else {
                eprintln!("{line}");
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
    let restarts = supervisor
        .restarts()
        .iter()
        .map(|(n, c)| format!("{n} {c}"))
        .collect::<Vec<_>>();
    supervisor.shutdown(Duration::from_secs(3));
    let _ = std::fs::remove_dir_all(&work);
    // The summary goes to stdout (the live status is on stderr), for scripts and tests: for a
    // person, then the status line.
    let summary = summary::Summary {
        elapsed_s: start.elapsed().as_secs_f64(),
        restarts: &restarts,
        topics: [&raw_stats, &cor_stats, &odo_stats],
        source: &source,
        recorder: recorder_losses.as_ref(),
        record: cli.record.as_deref(),
        state: last_state.as_ref(),
    };
    print!("{summary}");
    println!(
        "{}",
        status_line(
            &[&raw_stats, &cor_stats, &odo_stats],
            &source,
            recorder_losses.as_ref(),
            zero_state,
            last_state.as_ref()
        )
    );
    match gave_up {
        Some(why) => bail!("{why}"),
        None => Ok(()),
    }
}

fn observe<T: Message>(stats: &mut TopicStats, m: &T) {
    stats.observe(
        m.seq(),
        m.stamps().sample_ns,
        m.published_ns(),
        monotonic_ns(),
        m.is_revision(),
    );
}

/// The status line: losses at the source (sensor FIFO, acquire restarts), rate and losses
/// per topic (sequence gaps as the stack receives them; for raw also the samples acquire gave
/// up for stalled subscribers), what the recording misses per topic (when recording), the rest
/// verdict of the newest corrected sample, and the newest live odometry state's position (or
/// why there is none).
fn status_line(
    [raw, cor, odo]: &[&TopicStats; 3],
    source: &SourceLosses,
    recorder: Option<&RecorderLosses>,
    zero_state: Option<bool>,
    state: Option<&OdometryState>,
) -> String {
    let (r, c, o) = (raw.report(), cor.report(), odo.report());
    let recording = recorder.map_or(String::new(), |rec| {
        format!(
            " | recording lost {}/{}/{}",
            rec.of(service::RAW),
            rec.of(service::CORRECTED),
            rec.of(service::ODOMETRY)
        )
    });
    let position = match state {
        Some(s) if s.flags & odometry_flags::NO_GYRO != 0 => {
            "no position: the sensor runs without its gyroscope at this rate".to_string()
        }
        Some(s) if s.flags & odometry_flags::ALIGNED != 0 => format!(
            "pos ({:+.2}, {:+.2}, {:+.2}) m +- ({:.2}, {:.2}, {:.2})",
            s.position_m[0],
            s.position_m[1],
            s.position_m[2],
            s.position_sigma_m[0],
            s.position_sigma_m[1],
            s.position_sigma_m[2]
        ),
        Some(_) => "aligning".to_string(),
        None => "no odometry yet".to_string(),
    };
    format!(
        "sensor lost {} + {} across acquire restarts | raw {:.0} Hz lost {} undelivered {} | \
         corrected {:.0} Hz lost {} | odometry {:.0} Hz lost {}{recording} | {} | {}",
        source.fifo,
        source.restarts,
        r.rate_hz,
        r.lost,
        source.undelivered(),
        c.rate_hz,
        c.lost,
        o.rate_hz,
        o.lost,
        match zero_state {
            None => "rest detector learning",
            Some(true) => "at rest",
            Some(false) => "moving",
        },
        position
    )
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
    fn the_status_line_shows_no_position_without_gyro() {
        let stats = TopicStats::new();
        let line = |flags| {
            let state = OdometryState {
                flags,
                position_m: [1.5, -2.0, 0.0],
                ..OdometryState::default()
            };
            let source = SourceLosses::new(1000);
            status_line(&[&stats; 3], &source, None, Some(true), Some(&state))
        };
        let aligned = line(odometry_flags::ALIGNED);
        assert!(aligned.contains("pos (+1.50, -2.00, +0.00) m"), "{aligned}");
        let no_gyro = line(odometry_flags::NO_GYRO);
        assert!(no_gyro.contains("no position"), "{no_gyro}");
        assert!(!no_gyro.contains("pos ("), "{no_gyro}");
        let learning = status_line(&[&stats; 3], &SourceLosses::new(1000), None, None, None);
        assert!(learning.contains("rest detector learning"), "{learning}");
        assert!(
            !learning.contains("at rest") && !learning.contains("moving"),
            "{learning}"
        );
    }

    #[test]
    fn the_status_line_shows_losses_at_every_point() {
        let stats = TopicStats::new();
        let mut source = SourceLosses::new(1000);
        let raw = |seq, t_ms: u64, lost_before, undelivered| RawImuSample {
            seq,
            stamps: ipc_types::Stamps {
                sample_ns: t_ms * 1_000_000,
                ..Default::default()
            },
            lost_before,
            undelivered,
            ..Default::default()
        };
        source.observe(&raw(7, 10, 3, 45));
        source.observe(&raw(0, 240, 0, 0));
        let recorder = RecorderLosses::default();
        recorder.sink()("mems-record: lost 20 of mems/imu/raw (seq 100..=119)");
        let line = status_line(&[&stats; 3], &source, Some(&recorder), None, None);
        for needle in [
            "sensor lost 3 + 229 across acquire restarts",
            "undelivered 45",
            "recording lost 20/0/0",
        ] {
            assert!(line.contains(needle), "{needle:?} missing from: {line}");
        }
        let unrecorded = status_line(&[&stats; 3], &source, None, None, None);
        assert!(!unrecorded.contains("recording"), "{unrecorded}");
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
