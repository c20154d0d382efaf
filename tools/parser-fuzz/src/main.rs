//! `parser-fuzz`: runs mutation campaigns on the file readers (see the library documentation
//! and `docs/input-checks.md`). Exits non-zero when any campaign found a failure; an allocation over
//! the cap aborts the process after printing the command that reproduces it.

use std::path::PathBuf;

use anyhow::Result;
use clap::Parser as _;
use parser_fuzz::{Campaign, Parser};

#[global_allocator]
static ALLOCATOR: alloc_count::Counting = alloc_count::Counting;

/// Options.
#[derive(clap::Parser)]
#[command(about = "Mutation fuzzing of the CSV, MCAP, calibration and means readers")]
struct Args {
    /// The readers to fuzz (default: all four, one after the other).
    #[arg(long, value_enum)]
    parser: Vec<Parser>,
    /// Executions per reader.
    #[arg(long, default_value_t = 1_000_000)]
    runs: u64,
    /// Seed of the mutations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Index of the first execution (with `--runs 1`, replays one input).
    #[arg(long, default_value_t = 0)]
    start: u64,
    /// Cap on a single allocation, MiB.
    #[arg(long, default_value_t = 64)]
    limit_mib: usize,
    /// Directory for the input files.
    #[arg(long, default_value = "/dev/shm/parser-fuzz")]
    dir: PathBuf,
    /// Keep the last input read (`DIR/input-PARSER.bin`) to inspect it.
    #[arg(long)]
    keep: bool,
}

fn main() -> std::process::ExitCode {
    mems_log::init("parser-fuzz");
    mems_log::exit(run(Args::parse()))
}

fn run(args: Args) -> Result<()> {
    let parsers = if args.parser.is_empty() {
        Parser::ALL.to_vec()
    } else {
        args.parser.clone()
    };
    let mut clean = true;
    for parser in parsers {
        let campaign = Campaign {
            parser,
            seed: args.seed,
            start: args.start,
            runs: args.runs,
            allocation_limit: args.limit_mib << 20,
            dir: args.dir.clone(),
        };
        let r = campaign.run()?;
        println!(
            "{}: {} executions in {:.1} s ({:.0}/s): {} accepted, {} refused with a named \
             error, {} panics, {} errors without the file; largest allocation {} bytes, \
             slowest input {:.2} ms (seed {}, inputs {}..{})",
            parser.name(),
            r.executions,
            r.wall.as_secs_f64(),
            r.executions as f64 / r.wall.as_secs_f64(),
            r.accepted,
            r.refused,
            r.panics,
            r.unnamed_errors,
            r.largest_allocation,
            r.slowest.as_secs_f64() * 1e3,
            args.seed,
            args.start,
            args.start + args.runs
        );
        for (index, failure) in &r.failures {
            println!("  input {index}: {failure}");
        }
        clean &= r.clean();
        if !args.keep {
            let _ = std::fs::remove_file(args.dir.join(format!("input-{}.bin", parser.name())));
        }
    }
    if !clean {
        anyhow::bail!("failures found (reproduce one with --start INDEX --runs 1 --keep)");
    }
    Ok(())
}
