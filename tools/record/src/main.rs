//! `mems-record --out FILE.mcap [--force | --continue] [--namespace NS] [--duration S]`: records
//! every mems service to MCAP until the duration has passed or SIGINT/SIGTERM arrives.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Result, bail};
use clap::Parser;
use iceoryx2::prelude::{LogLevel, set_log_level_from_env_or};
use ipc_types::service;
use mems_record::{RecordOptions, Target, record};

/// The system allocator, counted once armed (see `alloc_count::pool`): a pool without blocks.
/// The recorder publishes nothing, so iceoryx2 makes no per-sample loan for a pool to serve,
/// and the MCAP writer keeps some small blocks per chunk for its summary, which would only
/// fill a pool. The summary gives the steady-state counts.
#[global_allocator]
static ALLOCATOR: alloc_count::pool::BlockPool<0> = alloc_count::pool::BlockPool::new();

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// The MCAP file to write. An existing recording there is refused, unless `--force` or
    /// `--continue` is given.
    #[arg(long)]
    out: PathBuf,
    /// Overwrite the recording at `--out` (its successor segments too).
    #[arg(long, conflicts_with = "continue_run")]
    force: bool,
    /// Continue the run at `--out` if there is one, in its next segment file (`run.1.mcap`,
    /// `run.2.mcap`, ...), with the split recorded: what a supervisor that restarts the
    /// recorder asks for.
    #[arg(long = "continue")]
    continue_run: bool,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// Stop after this many seconds (default: until Ctrl-C or SIGTERM).
    #[arg(long)]
    duration: Option<f64>,
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-record");
    mems_log::exit(run(Cli::parse()))
}

fn run(cli: Cli) -> Result<()> {
    // iceoryx2 warns that it runs without a config file; IOX2_LOG_LEVEL still overrides.
    set_log_level_from_env_or(LogLevel::Error);
    let duration = match cli.duration {
        Some(s) if !(s.is_finite() && s > 0.0) => {
            bail!("--duration must be a positive number of seconds, got {s}")
        }
        s => s.map(Duration::from_secs_f64),
    };
    let target = match (cli.force, cli.continue_run) {
        (true, _) => Target::Overwrite,
        (_, true) => Target::Continue,
        _ => Target::New,
    };
    let options = RecordOptions {
        out: cli.out,
        target,
        namespace: service::namespace(cli.namespace.as_deref()),
        duration,
        allocations: Some(|| ALLOCATOR.counts()),
    };
    // Counted from here on.
    ALLOCATOR.arm();
    let summary = record(&options)?;
    let counts: Vec<String> = summary
        .received
        .iter()
        .map(|(name, n)| format!("{name} {n}"))
        .collect();
    println!(
        "mems-record: wrote {}{} in {:.1} s ({}); {} events{}",
        summary.path.display(),
        if summary.segment > 0 {
            format!(" (segment {} of the run)", summary.segment)
        } else {
            String::new()
        },
        summary.elapsed.as_secs_f64(),
        counts.join(", "),
        summary.events.len(),
        if summary.interrupted {
            " (stopped by signal)"
        } else {
            ""
        }
    );
    if let Some(steady) = &summary.steady {
        tracing::info!(
            "{}, {} chunks flushed",
            steady.summary(),
            summary.steady_flushes
        );
    }
    Ok(())
}
