//! `mems-calibrate serve`: the live calibration process (raw samples in, corrected samples with
//! the zero-state flag out; see `calibrate::stage`).
//!
//! The offline subcommands (`fit`, `diagnose`, `allan`, `gyrocal`) are the binary `mems-calibrate-offline`
//! of `calibrate-science`: `mems-calibrate fit ...` replaces this process with
//! `mems-calibrate-offline fit ...` (found beside this executable, else on `PATH`), so that the
//! live process links none of the fitting, plotting and reporting code.

use std::ffi::OsString;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod serve;

/// Small blocks come from a bounded pool once `serve` starts its loop (iceoryx2 0.10 allocates
/// one per published sample: see `alloc_count::pool`); before that they come from the system
/// allocator through it. `serve` reports its steady-state counts.
#[global_allocator]
static ALLOCATOR: alloc_count::pool::BlockPool<1024> = alloc_count::pool::BlockPool::new();

#[derive(Parser)]
#[command(
    name = "mems-calibrate",
    version,
    about = "Accelerometer calibration for mems-odometry",
    after_help = "Offline subcommands, run by mems-calibrate-offline (package calibrate-science):\n  \
                  fit       Fit a model and write a calibration file\n  \
                  diagnose  Test a calibration's held-out residuals against candidate effects\n  \
                  allan     Allan deviation and noise parameters of a static recording\n  \
                  gyrocal   Fit the gyro's scale and misalignment from a pose session\n\
                  (mems-calibrate fit --help for their options)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Subscribe to raw samples, calibrate them, detect rest, refine the bias at rest and
    /// publish corrected samples, until SIGINT/SIGTERM.
    // Boxed: the serve options outweigh the other variant by far.
    Serve(Box<serve::ServeArgs>),
    /// An offline subcommand (fit, diagnose, allan, gyrocal): run by mems-calibrate-offline.
    #[command(external_subcommand)]
    Offline(Vec<OsString>),
}

fn main() -> ExitCode {
    mems_log::init("mems-calibrate");
    mems_log::exit(match Cli::parse().command {
        Command::Serve(args) => serve::serve(&args),
        Command::Offline(args) => Err(calibrate::offline::exec_offline(&args)),
    })
}
