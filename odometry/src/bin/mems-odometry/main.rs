//! `mems-odometry`: odometry from calibrated samples, live (`serve`: `mems/imu/corrected` and
//! `mems/robot/hint` in, `mems/odometry/state` out) or offline over a raw recording (`offline`:
//! the calibration stage and the odometry stage in one process, the same code the live
//! processes run, with the recording's robot hints). `gyrocal` fits the gyro's scale and
//! misalignment correction from a recorded pose session into the calibration file: it is
//! `mems-calibrate gyrocal`, run by `mems-calibrate-offline` (package calibrate-science).
//! `diagnose` runs `offline` on a recording, tests effects the model lacks on its rests and
//! reruns with those the data support.

mod diagnose;
mod diagnose_text;
mod hint_args;
mod load;
mod offline;
mod out;
mod serve;

/// Small blocks come from a bounded pool once `serve` starts its loop (iceoryx2 0.10 allocates
/// one per published state: see `alloc_count::pool`); the other subcommands never arm it, so
/// they use the system allocator through it. `serve` reports its steady-state counts.
#[global_allocator]
static ALLOCATOR: alloc_count::pool::BlockPool<1024> = alloc_count::pool::BlockPool::new();

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Subscribe to corrected samples and publish odometry states.
    Serve(serve::ServeArgs),
    /// Run calibration and odometry over a raw recording (CSV or MCAP).
    Offline(Box<offline::OfflineArgs>),
    /// Diagnose a run: test effects the model lacks on its rests, rerun with what the data
    /// support, print the error before and after (`odometry::diagnose`).
    Diagnose(diagnose::DiagnoseArgs),
    /// Fit the gyro's scale and misalignment correction from a recorded pose session and
    /// optionally store it in the calibration file's `[gyro]` table (`mems-calibrate gyrocal`:
    /// see its --help).
    #[command(disable_help_flag = true)]
    Gyrocal {
        /// Arguments of `mems-calibrate gyrocal`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<std::ffi::OsString>,
    },
}

fn main() -> ExitCode {
    mems_log::init("mems-odometry");
    mems_log::exit(match Cli::parse().command {
        Command::Serve(args) => serve::run(args),
        Command::Offline(args) => offline::run(*args),
        Command::Diagnose(args) => diagnose::run(args),
        Command::Gyrocal { args } => Err(calibrate::offline::exec_offline(
            std::iter::once("gyrocal".as_ref()).chain(args.iter().map(|a| a.as_os_str())),
        )),
    })
}
