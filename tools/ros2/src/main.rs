//! `mems-ros2 export RUN.mcap --out BAG.mcap [--force]`: a recorded run (its segment files
//! with it) as a ROS 2 bag (see the library). Prints, per topic, one line on stdout:
//! `TOPIC TYPE COUNT`.

use std::io::Write;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use mems_ros2::export::{self, IMU_TOPIC, ODOM_TOPIC, REVISED_TOPIC, TF_TOPIC};
use mems_ros2::msg::{Imu, Odometry, RosMessage, TfMessage};
use recording::mcap::run::RunReader;

/// Our recordings as ROS 2 messages.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Writes a recording's corrected samples and odometry states as a ROS 2 bag (one MCAP
    /// file): /imu/data, /odom, /odom/revised, /tf.
    Export {
        /// The run's first file; its successor segments (`RUN.1.mcap`, ...) are read with it.
        input: PathBuf,
        /// The bag to write (an MCAP file).
        #[arg(long)]
        out: PathBuf,
        /// Replace `--out` if it exists.
        #[arg(long)]
        force: bool,
    },
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-ros2");
    mems_log::exit(run(Cli::parse()))
}

fn run(cli: Cli) -> Result<()> {
    let Command::Export { input, out, force } = cli.command;
    // The input is opened first: a missing or foreign input never costs an existing --out.
    let reader = RunReader::open(&input)?;
    clear_target(&input, &out, force)?;
    let counts = export::export(reader, &input, &out)?;
    let lines = [
        (IMU_TOPIC, Imu::TYPE_NAME, counts.imu),
        (ODOM_TOPIC, Odometry::TYPE_NAME, counts.odom),
        (REVISED_TOPIC, Odometry::TYPE_NAME, counts.revised),
        (TF_TOPIC, TfMessage::TYPE_NAME, counts.tf),
    ];
    let mut stdout = std::io::stdout().lock();
    for (topic, type_name, count) in lines {
        writeln!(stdout, "{topic} {type_name} {count}")?;
    }
    Ok(())
}

/// Makes room for the bag at `out`: an existing file (or symbolic link, never followed) is
/// refused unless `force`, and never removed when it is one of the input run's files.
fn clear_target(input: &Path, out: &Path, force: bool) -> Result<()> {
    let Ok(existing) = std::fs::symlink_metadata(out) else {
        return Ok(());
    };
    if !force {
        bail!("{} exists: give --force to replace it", out.display());
    }
    for file in recording::segment::existing(input) {
        let meta = std::fs::metadata(&file).with_context(|| format!("{}", file.display()))?;
        if (meta.dev(), meta.ino()) == (existing.dev(), existing.ino()) {
            bail!(
                "--out {} is the input's file {}",
                out.display(),
                file.display()
            );
        }
    }
    std::fs::remove_file(out).with_context(|| format!("cannot remove {}", out.display()))
}
