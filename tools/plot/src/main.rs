//! `mems-plot FILE.mcap [--out DIR] [--truth SIM.mcap]`: PNGs of a recording's acceleration,
//! zero-state, position with its 1-sigma band, and horizontal track.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;
use mems_plot::{Figure, Outcome, plot_recording};

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// The MCAP recording (from mems-record or mems-sim).
    file: PathBuf,
    /// Directory for the PNGs (default: the recording's directory).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Take the ground truth for the track from this recording (the `mems-sim` file a
    /// `mems-odometry offline --out` run was made from) instead of FILE's own.
    #[arg(long)]
    truth: Option<PathBuf>,
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-plot");
    mems_log::exit(run(Cli::parse()))
}

fn run(cli: Cli) -> Result<()> {
    // One step per file read and per figure drawn.
    let steps = 1 + u64::from(cli.truth.is_some()) + Figure::ALL.len() as u64;
    let progress = mems_log::progress::bar(Some(steps), "mems-plot", "steps");
    let mut contents = recording::mcap::read_all(&cli.file)?;
    progress.inc(1);
    if let Some(truth) = &cli.truth {
        contents.truth = recording::mcap::read_all(truth)?.truth;
        progress.inc(1);
    }
    if let Some(truncation) = &contents.truncation {
        tracing::warn!(
            "{}: {truncation}; plotting what was read",
            cli.file.display()
        );
    }
    let out = cli.out.unwrap_or_else(|| {
        cli.file
            .parent()
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from("."))
    });
    let stem = cli
        .file
        .file_stem()
        .context("the recording's path has no file name")?
        .to_string_lossy();
    let figures = plot_recording(&contents, &stem, &out, |_| progress.inc(1))?;
    progress.finish_and_clear();
    for (figure, outcome) in figures {
        match outcome {
            Outcome::Written(path) => println!("mems-plot: wrote {}", path.display()),
            Outcome::Skipped(why) => println!("mems-plot: skipped {}: {why}", figure.name()),
        }
    }
    Ok(())
}
