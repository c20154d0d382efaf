//! `mems-acquire`: reads an MPU-9250 (simulated by default, or real over Linux I2C or SPI) and
//! publishes every sample on `mems/imu/raw`, losslessly.

use std::process::ExitCode;

use acquire::acquisition::{SourceSpec, config_for_rate};
use acquire::process::{self, Publish, Realtime, SimPart};
use alloc_count::pool::BlockPool;
use anyhow::Result;
use clap::Parser;

/// Small blocks come from a bounded lock-free pool once the loop starts: iceoryx2 0.10
/// allocates one small block per published sample (see `alloc_count::pool`), which the pool
/// recycles without reaching the system allocator. Start-up allocates from the system (a
/// simulated day's drive plan alone keeps thousands of small blocks), so 1024 blocks of 64
/// bytes (64 KiB) are for the loop only; the summary line reports the peak use and any request
/// that found the pool empty.
#[global_allocator]
static ALLOCATOR: BlockPool<1024> = BlockPool::new();

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// `sim` (the simulated MPU-9250 on a simulated 400 kHz I2C bus, paced in real time),
    /// `sim-spi` (the same on simulated SPI), `i2c:/dev/i2c-N[@0x68]` or `spi:/dev/spidevB.C`.
    #[arg(long, default_value = "sim")]
    source: SourceSpec,
    /// Output rate, Hz: 4000 (accelerometer only, DLPF bypassed; SPI only: its FIFO data need
    /// 108 % of a 400 kHz I2C bus) or 1000/n (accel + gyro + temperature).
    #[arg(long, default_value_t = 1000)]
    rate: u32,
    /// Digital low-pass filter, gyro bandwidth in Hz (184, 92, 41, 20, 10 or 5; the
    /// accelerometer gets the same A_DLPF_CFG). Default: picked from --rate as Linux's driver
    /// does, about half the rate or less (184 Hz at 1000 and 500 Hz, 92 Hz at 200 Hz). Not
    /// used at 4000 Hz.
    #[arg(long)]
    dlpf: Option<acquire::driver::Dlpf>,
    /// Stop after this many seconds (default: until SIGINT/SIGTERM).
    #[arg(long)]
    duration: Option<f64>,
    /// Time between FIFO reads, ms (the 512-byte FIFO holds 10.6 ms at 4 kHz, 36 ms at
    /// 1 kHz). Default: an eighth of the FIFO's fill time (1.33 ms at 4 kHz, 4.5 ms at 1 kHz).
    #[arg(long)]
    read_interval_ms: Option<f64>,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// The sensor session's state file: a restart with the same part and options continues
    /// the session in it (numbering and clock; the simulated motion in wall time), the hole
    /// counted as lost samples. Default: every start is a new session.
    #[arg(long)]
    session: Option<std::path::PathBuf>,
    #[command(flatten)]
    realtime: Realtime,
    #[command(flatten)]
    sim: SimPart,
}

fn main() -> ExitCode {
    mems_log::init("mems-acquire");
    mems_log::exit(acquire(Cli::parse()))
}

fn acquire(cli: Cli) -> Result<()> {
    cli.realtime.apply()?;
    let config = config_for_rate(cli.rate, cli.dlpf).map_err(anyhow::Error::msg)?;
    let publish = Publish {
        namespace: cli.namespace,
        duration_s: cli.duration,
        read_interval_ns: process::read_interval_ns(cli.read_interval_ms, &config)?,
        config,
        pool: &ALLOCATOR,
        session_file: cli.session,
    };
    process::run(&cli.source, &cli.sim, &publish)
}
