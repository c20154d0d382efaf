//! `mems-replay FILE [--speed X | --max] [--namespace NS] [--wait-subscribers N]
//! [--wait-timeout S]`: publishes a recording's raw samples (MCAP or CSV) on the raw service,
//! and an MCAP recording's robot hints on the hint service.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use clap::Parser;
use iceoryx2::prelude::*;
use ipc_types::service;
use mems_replay::{Pace, ReplayOptions, replay};

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// The recording: MCAP, the canonical CSV, or a thesis time-series CSV.
    file: PathBuf,
    /// Speed factor over the recorded sample times (1 = real time).
    #[arg(long, default_value_t = 1.0, conflicts_with = "max")]
    speed: f64,
    /// As fast as the subscribers take the samples (lossless back-pressure).
    #[arg(long)]
    max: bool,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// Wait until this many subscribers are connected before the first sample, then check
    /// that every sample reaches that many. A sample that reaches fewer while that many are
    /// registered was lost for a subscriber that had not connected: counted, and the exit
    /// status is 1. A subscriber that leaves during the replay (ends, or dies and its node is
    /// removed by any iceoryx2 process) is not a replay failure: the samples sent after it left
    /// are counted and reported, the others still get every sample, and the exit status is 0
    /// (the subscriber's own exit tells why it left).
    #[arg(long, default_value_t = 0)]
    wait_subscribers: usize,
    /// Give up waiting for subscribers after this many seconds.
    #[arg(long, default_value_t = 10.0)]
    wait_timeout: f64,
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    // iceoryx2 warns that it runs without a config file; IOX2_LOG_LEVEL still overrides.
    set_log_level_from_env_or(LogLevel::Error);
    if !(cli.wait_timeout.is_finite() && cli.wait_timeout >= 0.0) {
        bail!(
            "--wait-timeout must be a non-negative number of seconds, got {}",
            cli.wait_timeout
        );
    }
    // MCAP: every acquisition session in order, and the robot hints; CSV: raw samples only.
    let (samples, hints, truncation) = if recording::mcap::has_magic(&cli.file)? {
        let contents = recording::mcap::read_all(&cli.file)?;
        if contents.raw_sessions.len() > 1 {
            eprintln!(
                "mems-replay: {}: {} acquisition sessions, replayed in order",
                cli.file.display(),
                contents.raw_sessions.len()
            );
        }
        (contents.raw, contents.hints, contents.truncation)
    } else {
        let recording = recording::load_raw(&cli.file)?;
        (recording.samples, Vec::new(), recording.truncation)
    };
    if let Some(truncation) = &truncation {
        eprintln!(
            "mems-replay: warning: {}: {truncation}; replaying what was read",
            cli.file.display()
        );
    }
    if samples.is_empty() {
        bail!("{}: holds no raw samples", cli.file.display());
    }
    let options = ReplayOptions {
        pace: if cli.max {
            Pace::Max
        } else {
            Pace::RealTime { speed: cli.speed }
        },
        wait_subscribers: cli.wait_subscribers,
        wait_timeout: Duration::from_secs_f64(cli.wait_timeout),
    };
    let namespace = service::namespace(cli.namespace.as_deref());
    // Before any port exists: a SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node_name = NodeName::new("mems-replay").context("node name")?;
    let node = NodeBuilder::new()
        .name(&node_name)
        .create::<ipc::Service>()
        .map_err(|e| anyhow::anyhow!("cannot create iceoryx2 node: {e:?}"))?;
    let summary = replay(&node, &namespace, &samples, &hints, &options)?;
    println!(
        "mems-replay: sent {} of {} samples and {} of {} hints in {:.3} s ({:.0} samples/s){}",
        summary.sent,
        samples.len(),
        summary.hints_sent,
        hints.len(),
        summary.elapsed.as_secs_f64(),
        summary.rate_hz(),
        if summary.interrupted {
            " (stopped by signal)"
        } else {
            ""
        }
    );
    if summary.after_subscriber_left > 0 {
        println!(
            "mems-replay: {} samples were sent after a subscriber left (fewer than {} registered)",
            summary.after_subscriber_left, options.wait_subscribers
        );
    }
    if summary.short_deliveries > 0 {
        bail!(
            "{} samples reached fewer than {} subscribers while that many were registered: lost \
             for a subscriber that had not connected yet",
            summary.short_deliveries,
            options.wait_subscribers
        );
    }
    Ok(())
}
