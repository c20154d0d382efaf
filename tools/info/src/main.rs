//! `mems-info RUN.mcap [--json]`: what a recording holds: its files (a run recorded across
//! recorder restarts is read as one), duration, topics with counts, rates, sequence gaps and
//! losses, the recorder's events and the calibration the run used.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Result;
use clap::Parser;

/// Summarises an MCAP recording made by mems-record, mems-sim or mems-odometry.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// The run's first file; its successor segments (`RUN.1.mcap`, ...) are read with it.
    file: PathBuf,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-info");
    mems_log::exit(run(Cli::parse()))
}

fn run(cli: Cli) -> Result<()> {
    let info = mems_info::RunInfo::read(&cli.file)?;
    for file in &info.files {
        for damage in &file.damaged {
            tracing::warn!("{}: {damage}", file.path.display());
        }
    }
    let text = if cli.json {
        serde_json::to_string_pretty(&info)? + "\n"
    } else {
        info.table()
    };
    // A reader that stops early (`| head`) is not an error.
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}
