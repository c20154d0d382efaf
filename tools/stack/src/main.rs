//! `mems-stack`: the whole pipeline as separate processes (acquire -> calibrate -> odometry,
//! plus the recorder), supervised: a crashed stage is restarted (the calibration stage going on
//! from its predecessor's learned state, `mems-calibrate serve --state`), Ctrl-C stops
//! everything cleanly, and a status line shows rates, losses, zero-state and position.

mod calib;
mod children;
mod cli;
mod config;
mod live;
mod losses;
mod monitor;
mod summary;
mod supervisor;
mod work;

use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use clap::{CommandFactory, FromArgMatches};
use ipc_types::service;

use cli::Cli;
use losses::RecorderLosses;
use monitor::Monitor;
use summary::Summary;
use supervisor::Supervisor;

fn main() -> std::process::ExitCode {
    mems_log::init("mems-stack");
    mems_log::exit(parse().and_then(run))
}

/// The command line, after the settings of its `--config` file (clap's own errors and
/// `--help` exit as clap does).
fn parse() -> Result<Cli> {
    let args = config::expand(std::env::args_os().collect())?;
    let matches = Cli::command().get_matches_from(args);
    let mut cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    cli.settings = config::settings(&matches);
    Ok(cli)
}

/// Checks the options, calibrates a simulated part when no `--calib` is given, starts the
/// stages and supervises them until SIGINT/SIGTERM, `--duration` or a stage that keeps failing
/// at start; then stops them and prints the summary.
fn run(cli: Cli) -> Result<()> {
    let overwrite = cli.check()?;
    work::clean_stale();
    let namespace = service::namespace(cli.namespace.as_deref());
    let bins = children::bin_dir()?;
    let work_dir = work::create()?;
    let work = work_dir.path().to_path_buf();
    let calib = calib::calibration(&cli, &bins, &work)?;
    let calib = calib.to_str().context("calibration path is not UTF-8")?;
    let recorder_losses = cli.record.is_some().then(RecorderLosses::default);
    let losses = recorder_losses.as_ref();
    let specs = children::specs(&cli, &bins, &namespace, calib.to_string(), &work, losses);
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
    let gave_up = live::supervise(&mut supervisor, &mut monitor, losses, cli.duration, start)?;
    let restarts: Vec<String> = supervisor
        .restarts()
        .iter()
        .map(|(n, c)| format!("{n} {c}"))
        .collect();
    supervisor.shutdown(Duration::from_secs(3));
    drop(work_dir);
    // The summary goes to stdout (the live status is on stderr), for scripts and tests: for a
    // person, then the status line.
    let elapsed_s = start.elapsed().as_secs_f64();
    let summary = Summary::of(
        &monitor,
        elapsed_s,
        &restarts,
        losses,
        cli.record.as_deref(),
    );
    print!("{summary}");
    println!("{}", monitor.status(losses));
    match gave_up {
        Some(why) => bail!("{why}"),
        None => Ok(()),
    }
}
