//! `mems-acquire`: reads an MPU-9250 (simulated by default, or real over Linux I2C or SPI) and
//! publishes every sample on `mems/imu/raw`, losslessly.

use std::convert::Infallible;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use acquire::acquisition::{
    Acquisition, SourceSpec, config_for_rate, default_read_interval_ns, fifo_fill_ns,
};
use acquire::clock::{Clock, MonotonicClock, SimClock};
use acquire::driver::Mpu9250;
use acquire::sim::{SimConfig, SimMpu9250};
use acquire::spi::SpiRegisters;
use alloc_count::pool::BlockPool;
use anyhow::{Context, Result, bail};
use clap::{Parser, ValueEnum};
use embedded_hal::i2c::I2c;
use ipc_types::wake::Output;
use ipc_types::{RawImuSample, service};
use mems_sim::model::Preset;
use mems_sim::scenario::{Drive, DriveParams, PoseSession};
use mems_sim::vibration::VibrationModel;
use mems_sim::{SampleSource, SimSensor};
use nalgebra::UnitQuaternion;

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
    /// Run the loop under SCHED_FIFO at this priority (1-99).
    #[arg(long)]
    sched_fifo: Option<u8>,
    /// Pin the process to this CPU core.
    #[arg(long)]
    cpu: Option<usize>,
    /// Lock all memory (mlockall) so that no page fault stalls the loop.
    #[arg(long)]
    mlock: bool,
    /// Simulated scenario (sim source only).
    #[arg(long, value_enum, default_value_t = Scenario::Drive)]
    scenario: Scenario,
    /// Simulated sensor's error model (sim source only): ideal, datasheet or calibrated.
    #[arg(long, default_value = "datasheet")]
    preset: Preset,
    /// Seed of the simulated sensor and scenario (sim source only).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Error of the simulated part's sample clock, ppm (positive: fast). The internal
    /// oscillator may be off by up to +-10 % (100000 ppm) over temperature (sim sources only).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    sim_clock_ppm: f64,
}

#[derive(Clone, Copy, ValueEnum)]
enum Scenario {
    /// A ground-robot drive with turns, rests and vibration, longer than any run.
    Drive,
    /// Lying still, level, z up.
    Static,
}

fn main() -> ExitCode {
    mems_log::init("mems-acquire");
    mems_log::exit(acquire(Cli::parse()))
}

fn acquire(cli: Cli) -> Result<()> {
    realtime_setup(&cli)?;
    let config = config_for_rate(cli.rate, cli.dlpf).map_err(anyhow::Error::msg)?;
    let read_interval_ns = match cli.read_interval_ms {
        Some(ms) if ms.is_finite() && ms > 0.0 => (ms * 1e6) as u64,
        Some(ms) => bail!("--read-interval-ms must be > 0, got {ms}"),
        None => default_read_interval_ns(&config),
    };
    match cli.source.clone() {
        SourceSpec::Sim | SourceSpec::SimSpi => {
            let model = cli.preset.model();
            let g = mems_sim::model::G_MPS2;
            // Long enough for any run; the drive plans its motions from the seed.
            let horizon_s = 24.0 * 3600.0;
            match cli.scenario {
                Scenario::Drive => {
                    let mut params = DriveParams::new(horizon_s);
                    params.turns = true;
                    let drive = Drive::new(&params, cli.seed)?;
                    let sensor =
                        SimSensor::new(drive, &model, &VibrationModel::moderate(1.0), cli.seed)?;
                    run_sim(&cli, sensor, config, read_interval_ns)
                }
                Scenario::Static => {
                    let pose = PoseSession::static_pose(UnitQuaternion::identity(), horizon_s, g)?;
                    let sensor =
                        SimSensor::new(pose, &model, &VibrationModel::moderate(0.0), cli.seed)?;
                    run_sim(&cli, sensor, config, read_interval_ns)
                }
            }
        }
        SourceSpec::I2c { device, address } => {
            let bus = linux_embedded_hal::I2cdev::new(&device)
                .with_context(|| format!("cannot open I2C bus {device}"))?;
            let driver = Mpu9250::new(bus, device.as_str(), address);
            run(&cli, driver, MonotonicClock, config, read_interval_ns)
        }
        SourceSpec::Spi { device } => {
            let mut spi = linux_embedded_hal::SpidevDevice::open(&device)
                .with_context(|| format!("cannot open SPI device {device}"))?;
            // Mode 3 (clock idle high, data latched on the rising edge; PS-MPU-9250A-01
            // section 7.5), 8-bit words.
            let options = linux_embedded_hal::spidev::SpidevOptions::new()
                .bits_per_word(8)
                .mode(linux_embedded_hal::spidev::SpiModeFlags::SPI_MODE_3)
                .max_speed_hz(acquire::spi::REGISTER_CLOCK_HZ)
                .build();
            spi.configure(&options)
                .with_context(|| format!("cannot configure SPI device {device}"))?;
            let driver = Mpu9250::new_spi(spi, device.as_str());
            run(&cli, driver, MonotonicClock, config, read_interval_ns)
        }
    }
}

/// Runs the simulated part on `sensor`, on the simulated I2C bus or SPI as the source says.
fn run_sim<S: SampleSource>(
    cli: &Cli,
    sensor: S,
    config: acquire::driver::Config,
    read_interval_ns: u64,
) -> Result<()> {
    let clock = SimClock::real_time();
    let device_config = SimConfig {
        rate_error_ppm: cli.sim_clock_ppm,
        ..SimConfig::default()
    };
    let address = device_config.address;
    let device = SimMpu9250::new(sensor, clock.clone(), device_config);
    if cli.source == SourceSpec::SimSpi {
        let driver: Mpu9250<SpiRegisters<_>> = Mpu9250::new_spi(device, "sim-spi");
        run(cli, driver, clock, config, read_interval_ns)
    } else {
        let driver = Mpu9250::new(device, "sim", address);
        run(cli, driver, clock, config, read_interval_ns)
    }
}

/// Applies the real-time options: memory locking, CPU pinning, SCHED_FIFO.
fn realtime_setup(cli: &Cli) -> Result<()> {
    if cli.mlock {
        // SAFETY: mlockall has no memory-safety preconditions.
        let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
        if rc != 0 {
            bail!("mlockall failed: {}", std::io::Error::last_os_error());
        }
    }
    if let Some(cpu) = cli.cpu {
        let ids = core_affinity::get_core_ids().unwrap_or_default();
        let Some(id) = ids.into_iter().find(|c| c.id == cpu) else {
            bail!("cannot pin to CPU {cpu}: no such core");
        };
        if !core_affinity::set_for_current(id) {
            bail!("cannot pin to CPU {cpu}");
        }
    }
    if let Some(priority) = cli.sched_fifo {
        use thread_priority::{
            RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue,
            ThreadSchedulePolicy, set_thread_priority_and_policy, thread_native_id,
        };
        let value = ThreadPriorityValue::try_from(priority)
            .map_err(|e| anyhow::anyhow!("bad SCHED_FIFO priority {priority}: {e}"))?;
        set_thread_priority_and_policy(
            thread_native_id(),
            ThreadPriority::Crossplatform(value),
            ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
        )
        .map_err(|e| anyhow::anyhow!("cannot set SCHED_FIFO {priority}: {e:?}"))?;
    }
    Ok(())
}

/// Publishes until the duration is over or SIGINT/SIGTERM arrives; then prints a summary.
fn run<I2C: I2c, C: Clock>(
    cli: &Cli,
    driver: Mpu9250<I2C>,
    clock: C,
    config: acquire::driver::Config,
    read_interval_ns: u64,
) -> Result<()> {
    let namespace = service::namespace(cli.namespace.as_deref());
    let name = service::full_name(&namespace, service::RAW);
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let raw = service::open::<RawImuSample>(&node, &name)?;
    // A subscriber whose buffer is full (stopped, hung) is waited for at most an eighth of the
    // FIFO's fill time, then its samples are given up and counted for it: the loop never waits
    // on a subscriber for as long as the FIFO lasts, so the sensor loses nothing for it.
    let stall_wait = Duration::from_nanos(fifo_fill_ns(&config) / 8);
    let (publisher, undelivered) = service::publisher_waiting_at_most(&raw, stall_wait)?;
    // Wakes the subscribers after a read's first sample and after its last.
    let mut out = Output::with_publisher(&node, publisher, &name)?;

    let mut acq = Acquisition::start(driver, clock, config, read_interval_ns)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    tracing::info!(
        "{} ({}) at {} Hz on {name}, reading every {:.2} ms",
        acq.driver().bus_label(),
        acq.driver().part().unwrap_or("?"),
        config.output_rate_hz(),
        read_interval_ns as f64 * 1e-6
    );
    let start = Instant::now();
    let deadline = cli.duration.map(Duration::from_secs_f64);
    // Start-up is over: from here on small blocks come from the pool.
    ALLOCATOR.arm();
    loop {
        // An absolute-deadline sleep (a relative one would add any preemption between reading
        // the clock and sleeping); then SIGINT/SIGTERM ends the loop: the clean way out.
        acq.clock().sleep_until(acq.next_read_ns());
        if ipc_types::stop::requested() {
            break;
        }
        let Ok(read) = acq.read_and_publish(&mut |s| {
            out.send(RawImuSample {
                undelivered: u32::try_from(undelivered.total()).unwrap_or(u32::MAX),
                ..*s
            });
            Ok::<_, Infallible>(())
        });
        out.end_of_input()?;
        if let Err(e) = read {
            tracing::warn!("read failed, device re-initialising: {e}");
        }
        if deadline.is_some_and(|d| start.elapsed() >= d) {
            break;
        }
    }
    report(&acq, &undelivered, start.elapsed());
    Ok(())
}

/// The run's summary on stderr: read lateness, FIFO timing, and the counts of samples
/// published, lost and discarded.
fn report<I2C: I2c, C: Clock>(
    acq: &Acquisition<I2C, C>,
    undelivered: &service::Undelivered,
    elapsed: Duration,
) {
    let stats = acq.stats();
    let driver = acq.driver().stats();
    let late = acq.lateness();
    // The histogram reports a bucket's upper end (2 significant digits): never above the
    // exact maximum.
    let us = |q: f64| late.value_at_quantile(q).min(stats.max_late_ns.max(1)) as f64 * 1e-3;
    tracing::info!(
        "read lateness p50 {:.0} us, p99 {:.0} us, p99.9 {:.0} us, max {:.0} us; \
         fullest FIFO {} of 512 bytes",
        us(0.5),
        us(0.99),
        us(0.999),
        stats.max_late_ns as f64 * 1e-3,
        driver.max_fifo_bytes
    );
    if let Some((ahead, behind)) = stats.sample_time_excursion_ns {
        tracing::info!(
            "newest sample's FIFO time at most {:.3} ms after its acquisition and \
             {:.3} ms before its read's start minus a period (<= 0: on the clock); duplicates \
             dropped {}, settling frames dropped {}, pair mismatches {}",
            ahead as f64 * 1e-6,
            behind as f64 * 1e-6,
            driver.duplicates,
            driver.settling_discarded,
            driver.pair_mismatches
        );
    }
    let per_subscriber: Vec<String> = undelivered
        .per_subscriber()
        .iter()
        .map(|(port, n)| format!("{n} for subscriber port {port:#x}"))
        .collect();
    tracing::info!(
        "published {} samples in {:.1} s; reads {}, failed {}, overflows {}, \
         gaps {}, lost {}, bus errors {}, re-inits {}; discarded for stalled subscribers {}{}; \
         small-block pool: peak {} of 1024 blocks, {} requests found it empty",
        stats.published,
        elapsed.as_secs_f64(),
        stats.reads,
        stats.failed_reads,
        driver.overflows,
        driver.gaps,
        driver.lost_samples,
        driver.bus_errors,
        driver.reinits,
        undelivered.total(),
        if per_subscriber.is_empty() {
            String::new()
        } else {
            format!(" ({})", per_subscriber.join(", "))
        },
        ALLOCATOR.peak_blocks(),
        ALLOCATOR.fallbacks()
    );
}
