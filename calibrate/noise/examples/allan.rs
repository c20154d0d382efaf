//! `mems-calibrate allan` before the subcommand is wired into `mems-calibrate`:
//! `cargo run --release -p noise --example allan -- --input STATIC_REC [--json] [--plot OUT.png] ...`
//! (same arguments, same output).

use clap::Parser;

/// The `allan` arguments as a stand-alone command.
#[derive(Parser)]
struct Command {
    #[command(flatten)]
    args: noise::Args,
}

fn main() -> anyhow::Result<()> {
    noise::run_allan(&Command::parse().args)
}
