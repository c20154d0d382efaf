//! `mems-replay FILE [--topics T,...] [--start S] [--end S] [--loop] [--speed X | --max]
//! [--progress] [--namespace NS] [--wait-subscribers N] [--wait-timeout S]`: publishes a
//! recording's topics on their iceoryx2 services, each message at its place in recorded time.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context, Result, anyhow, bail};
use clap::Parser;
use iceoryx2::prelude::*;
use ipc_types::service;
use mems_replay::progress::Progress;
use mems_replay::source::{Recording, Survey};
use mems_replay::topics::Replayable;
use mems_replay::{Pace, ReplayOptions, ReplaySummary, replay};

/// Publishes a recording's topics on their services as the live processes would, each message
/// at its place in recorded time (real time by default).
///
/// By default the raw samples and robot hints: the live pipeline (mems-calibrate serve,
/// mems-odometry serve) recomputes everything from them, bit for bit. --topics replays
/// recorded outputs instead (mems/imu/corrected, mems/odometry/state): a control process can
/// then be tested against a run without the pipeline.
#[derive(Parser)]
#[command(version, about, long_about)]
struct Cli {
    /// The recording: MCAP (with its successor segments), the canonical CSV, or a thesis
    /// time-series CSV (raw samples only).
    file: PathBuf,
    /// Topics to replay, by recorded name, comma-separated: mems/imu/raw, mems/robot/hint,
    /// mems/imu/corrected, mems/odometry/state (default: raw and hints).
    #[arg(long, value_delimiter = ',')]
    topics: Option<Vec<String>>,
    /// Start this many seconds after the recording's first message (sample time).
    #[arg(long)]
    start: Option<f64>,
    /// End this many seconds after the recording's first message (sample time), included.
    #[arg(long)]
    end: Option<f64>,
    /// Replay again and again until SIGINT or SIGTERM. Each pass sends the same sequence
    /// numbers and sample times again: our processes take it for a new acquisition session.
    #[arg(long = "loop")]
    looping: bool,
    /// Speed factor over the recorded times (1 = real time).
    #[arg(long, default_value_t = 1.0, conflicts_with = "max")]
    speed: f64,
    /// As fast as the subscribers take the messages (lossless back-pressure).
    #[arg(long)]
    max: bool,
    /// Show the progress line on stderr even when it is not a terminal (one line a second).
    #[arg(long)]
    progress: bool,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// Wait until this many subscribers are connected to each replayed service (the hints'
    /// only when replayed alone) before the first message, then check that every message
    /// reaches that many. A subscriber that leaves during the replay (ends, or is killed: the
    /// replay removes dead processes' nodes every 0.25 s) is not a replay failure: the messages
    /// that reached fewer because of it are counted and reported, the others still get every
    /// message, and the exit status is 0; so are messages given up for a subscriber that took
    /// none for 2 s (dead, or hung). A message lost for a subscriber that had not connected
    /// yet is counted, and the exit status is 1.
    #[arg(long, default_value_t = 0)]
    wait_subscribers: usize,
    /// Give up waiting for subscribers after this many seconds.
    #[arg(long, default_value_t = 10.0)]
    wait_timeout: f64,
}

fn main() -> ExitCode {
    mems_log::init("mems-replay");
    mems_log::exit(run(Cli::parse()))
}

/// Replays `cli.file` as asked.
fn run(cli: Cli) -> Result<()> {
    // iceoryx2 warns that it runs without a config file; IOX2_LOG_LEVEL still overrides.
    set_log_level_from_env_or(LogLevel::Error);
    if !(cli.wait_timeout.is_finite() && cli.wait_timeout >= 0.0) {
        bail!(
            "--wait-timeout must be a non-negative number of seconds, got {}",
            cli.wait_timeout
        );
    }
    let file = cli.file.display();
    let (recording, csv_cut) = Recording::open(&cli.file)?;
    let survey = Survey::of(&recording)?;
    for cut in csv_cut.iter().chain(&survey.truncations) {
        tracing::warn!("{file}: {cut}; replaying what was read");
    }
    let topics = survey
        .select(cli.topics.as_deref())
        .map_err(|e| anyhow!("{file}: {e}"))?;
    let window = survey
        .window(cli.start, cli.end)
        .map_err(|e| anyhow!("{file}: {e}"))?;
    let counts = survey.counts_in(&recording, &topics, window)?;
    if counts.iter().sum::<u64>() == 0 {
        bail!("{file}: no message of the chosen topics between --start and --end");
    }
    if survey.spans.len() > 1 {
        tracing::info!(
            "{file}: its times start over {} times (runs recorded into one file): \
             replayed in order, pacing starting over with each",
            survey.spans.len() - 1
        );
    }
    let options = ReplayOptions {
        pace: if cli.max {
            Pace::Max
        } else {
            Pace::RealTime { speed: cli.speed }
        },
        wait_subscribers: cli.wait_subscribers,
        wait_timeout: Duration::from_secs_f64(cli.wait_timeout),
        looping: cli.looping,
    };
    let namespace = service::namespace(cli.namespace.as_deref());
    // Before any port exists: a SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = NodeBuilder::new()
        .name(&NodeName::new("mems-replay").context("node name")?)
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("cannot create iceoryx2 node: {e:?}"))?;
    let span_ns = window.map_or(survey.span_ns(), |w| w.end_ns - w.start_ns);
    let mut progress = Progress::new(cli.progress, span_ns);
    let summary = replay(
        &node,
        &namespace,
        &recording,
        &topics,
        window,
        &options,
        &mut |s| progress.update(s),
    )?;
    progress.finish(&summary);
    report(&summary, &counts, &topics, &options)
}

/// Prints the summary; an error if messages were lost for a subscriber that had not connected
/// (a departure or a stalled subscriber is reported, not an error).
fn report(
    summary: &ReplaySummary,
    counts: &[u64; 4],
    topics: &[Replayable],
    options: &ReplayOptions,
) -> Result<()> {
    let per_pass: u64 = counts.iter().sum();
    let per_topic: Vec<String> = topics
        .iter()
        .map(|t| format!("{} {}", t.topic(), summary.sent[t.index()]))
        .collect();
    println!(
        "mems-replay: sent {} of {} samples in {} pass{} in {:.3} s ({:.0} samples/s): {}{}",
        summary.total_sent(),
        per_pass * summary.passes.max(1),
        summary.passes,
        if summary.passes == 1 { "" } else { "es" },
        summary.elapsed.as_secs_f64(),
        summary.rate_hz(),
        per_topic.join(", "),
        if summary.interrupted {
            " (stopped by signal)"
        } else {
            ""
        }
    );
    if summary.after_subscriber_left > 0 {
        println!(
            "mems-replay: {} samples reached fewer than {} subscribers after one left (it ended \
             or died)",
            summary.after_subscriber_left, options.wait_subscribers
        );
    }
    if summary.given_up_stalled > 0 {
        println!(
            "mems-replay: {} samples reached fewer than {} subscribers because they were given \
             up for one that took none for {:.0} s (dead, or hung)",
            summary.given_up_stalled,
            options.wait_subscribers,
            service::STALL_TIMEOUT.as_secs_f64()
        );
    }
    if summary.short_deliveries > 0 {
        bail!(
            "{} samples reached fewer than {} subscribers while that many were registered and \
             none had left: lost for a subscriber that had not connected yet",
            summary.short_deliveries,
            options.wait_subscribers
        );
    }
    Ok(())
}
