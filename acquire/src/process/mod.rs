//! The `mems-acquire` process, so that its binary is its command line and one call
//! ([`run`]): the source opened (the simulated part on its scenario, [`SimPart`], or a real part
//! on a Linux I2C bus or SPI device), the real-time setup ([`Realtime`]), the publishing loop
//! ([`Publish`]) and its summary ([`Summary`]).

mod publish;
mod reads;
mod summary;

pub use publish::Publish;
pub use summary::Summary;

use anyhow::{Context, Result, bail};
use clap::ValueEnum;
use linux_embedded_hal::SpidevDevice;
use linux_embedded_hal::spidev::{SpiModeFlags, SpidevOptions};
use mems_sim::model::Preset;
use mems_sim::scenario::{Drive, DriveParams, PoseSession};
use mems_sim::vibration::VibrationModel;
use mems_sim::{SampleSource, SimSensor};
use nalgebra::UnitQuaternion;

use crate::acquisition::SourceSpec;
use crate::clock::{MonotonicClock, SimClock};
use crate::driver::{self, Mpu9250};
use crate::session::Session;
use crate::sim::{SimConfig, SimMpu9250};
use crate::spi::SpiRegisters;

/// The real-time options of the acquisition loop.
#[derive(clap::Args, Clone, Debug)]
pub struct Realtime {
    /// Run the loop under SCHED_FIFO at this priority (1-99).
    #[arg(long)]
    pub sched_fifo: Option<u8>,
    /// Pin the process to this CPU core.
    #[arg(long)]
    pub cpu: Option<usize>,
    /// Lock all memory (mlockall) so that no page fault stalls the loop.
    #[arg(long)]
    pub mlock: bool,
}

impl Realtime {
    /// Applies the options to this process (and its calling thread): memory locking, CPU
    /// pinning, SCHED_FIFO.
    pub fn apply(&self) -> Result<()> {
        if self.mlock {
            // SAFETY: mlockall has no memory-safety preconditions.
            let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
            if rc != 0 {
                bail!("mlockall failed: {}", std::io::Error::last_os_error());
            }
        }
        if let Some(cpu) = self.cpu {
            let ids = core_affinity::get_core_ids().unwrap_or_default();
            let Some(id) = ids.into_iter().find(|c| c.id == cpu) else {
                bail!("cannot pin to CPU {cpu}: no such core");
            };
            if !core_affinity::set_for_current(id) {
                bail!("cannot pin to CPU {cpu}");
            }
        }
        if let Some(priority) = self.sched_fifo {
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
}

/// What the simulated part does.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Scenario {
    /// A ground-robot drive with turns, rests and vibration, longer than any run.
    Drive,
    /// Lying still, level, z up.
    Static,
}

/// The simulated part (the `sim` and `sim-spi` sources).
#[derive(clap::Args, Clone, Debug)]
pub struct SimPart {
    /// Simulated scenario (sim source only).
    #[arg(long, value_enum, default_value_t = Scenario::Drive)]
    pub scenario: Scenario,
    /// Simulated sensor's error model (sim source only): ideal, datasheet or calibrated.
    #[arg(long, default_value = "datasheet")]
    pub preset: Preset,
    /// Seed of the simulated sensor and scenario (sim source only).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Error of the simulated part's sample clock, ppm (positive: fast). The internal
    /// oscillator may be off by up to +-10 % (100000 ppm) over temperature (sim sources only).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub sim_clock_ppm: f64,
}

/// The time between FIFO reads, ns: `ms` (`--read-interval-ms`, which must be positive), or
/// by default an eighth of the FIFO's fill time at `config`.
pub fn read_interval_ns(ms: Option<f64>, config: &driver::Config) -> Result<u64> {
    Ok(match ms {
        Some(ms) if ms.is_finite() && ms > 0.0 => (ms * 1e6) as u64,
        Some(ms) => bail!("--read-interval-ms must be > 0, got {ms}"),
        None => crate::acquisition::default_read_interval_ns(config),
    })
}

/// Opens `source` (`sim` describing the simulated part) and publishes from it with `publish`
/// until its duration is over or SIGINT/SIGTERM arrives.
pub fn run<const N: usize>(
    source: &SourceSpec,
    sim: &SimPart,
    publish: &Publish<'_, N>,
) -> Result<()> {
    let session = publish.session(source, sim)?;
    match source {
        SourceSpec::Sim | SourceSpec::SimSpi => {
            let spi = *source == SourceSpec::SimSpi;
            let model = sim.preset.model();
            // Long enough for any run; the drive plans its motions from the seed.
            let horizon_s = 24.0 * 3600.0;
            match sim.scenario {
                Scenario::Drive => {
                    let mut params = DriveParams::new(horizon_s);
                    params.turns = true;
                    let drive = Drive::new(&params, sim.seed)?;
                    let vibration = VibrationModel::moderate(1.0);
                    let sensor = SimSensor::new(drive, &model, &vibration, sim.seed)?;
                    run_sim(sensor, spi, sim, publish, session)
                }
                Scenario::Static => {
                    let g = mems_sim::model::G_MPS2;
                    let pose = PoseSession::static_pose(UnitQuaternion::identity(), horizon_s, g)?;
                    let vibration = VibrationModel::moderate(0.0);
                    let sensor = SimSensor::new(pose, &model, &vibration, sim.seed)?;
                    run_sim(sensor, spi, sim, publish, session)
                }
            }
        }
        SourceSpec::I2c { device, address } => {
            let bus = linux_embedded_hal::I2cdev::new(device)
                .with_context(|| format!("cannot open I2C bus {device}"))?;
            let driver = Mpu9250::new(bus, device.as_str(), *address);
            publish.run(driver, MonotonicClock, session)
        }
        SourceSpec::Spi { device } => publish.run(open_spi(device)?, MonotonicClock, session),
    }
}

/// The MPU-9250 on Linux SPI device `device`, in mode 3 (clock idle high, data latched on the
/// rising edge; PS-MPU-9250A-01 section 7.5), 8-bit words, at the register clock.
pub fn open_spi(device: &str) -> Result<Mpu9250<SpiRegisters<SpidevDevice>>> {
    let mut spi =
        SpidevDevice::open(device).with_context(|| format!("cannot open SPI device {device}"))?;
    let options = SpidevOptions::new()
        .bits_per_word(8)
        .mode(SpiModeFlags::SPI_MODE_3)
        .max_speed_hz(crate::spi::REGISTER_CLOCK_HZ)
        .build();
    spi.configure(&options)
        .with_context(|| format!("cannot configure SPI device {device}"))?;
    Ok(Mpu9250::new_spi(spi, device))
}

/// Publishes from the simulated part measuring `sensor`, on the simulated I2C bus or (`spi`)
/// SPI, paced in real time, in `session` (the part powered on at its origin, so that a
/// continued session's motion goes on in wall time).
fn run_sim<S: SampleSource, const N: usize>(
    sensor: S,
    spi: bool,
    sim: &SimPart,
    publish: &Publish<'_, N>,
    session: Session,
) -> Result<()> {
    let clock = SimClock::real_time();
    let device_config = SimConfig {
        rate_error_ppm: sim.sim_clock_ppm,
        power_on_ns: Some(session.origin_ns()),
        ..SimConfig::default()
    };
    let address = device_config.address;
    let device = SimMpu9250::new(sensor, clock.clone(), device_config);
    if spi {
        let driver: Mpu9250<SpiRegisters<_>> = Mpu9250::new_spi(device, "sim-spi");
        publish.run(driver, clock, session)
    } else {
        let driver = Mpu9250::new(device, "sim", address);
        publish.run(driver, clock, session)
    }
}
