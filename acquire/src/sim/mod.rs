//! A simulated MPU-9250 at register level, behind the same `embedded_hal::i2c::I2c` trait as
//! `linux_embedded_hal::I2cdev`, so the real driver runs against it unchanged.
//!
//! What is modelled (register numbers from RM-MPU-9250A-00, see [`crate::registers`]):
//! - Addressing: the device answers at 0x68 or 0x69 (AD0); any other address, an absent
//!   device, or a device within its start-up time after H_RESET gets
//!   `ErrorKind::NoAcknowledge(Address)`.
//! - Register access: a write operation's first byte sets the register pointer, following
//!   bytes are written with auto-increment; reads auto-increment, except at FIFO_R_W, where
//!   each byte pops the FIFO (an empty FIFO repeats the last byte popped). Writes to read-only
//!   registers (data, INT_STATUS, FIFO_COUNT, WHO_AM_I) and to FIFO_R_W are ignored.
//! - PWR_MGMT_1: H_RESET restores every register's reset value, empties the FIFO and makes the
//!   device unresponsive for [`SimConfig::startup_ns`]; SLEEP stops sampling. PWR_MGMT_2's
//!   standby bits only start the gyro start-up transient when cleared (disabled axes keep
//!   sampling).
//! - Sample rate (the rate of the data registers and of FIFO writes; RM-MPU-9250A-00 register
//!   25: "the FIFO ... \[is\] written at the Sample Rate", and register 35): with the gyro DLPF
//!   on (GYRO_CONFIG.FCHOICE_B = 0 and DLPF_CFG 1-6), 1 kHz / (1 + SMPLRT_DIV); otherwise
//!   8 kHz. With ACCEL_CONFIG2.accel_fchoice_b = 1 the accelerometer itself samples at 4 kHz
//!   (register 29) on the same clock: a FIFO write carries the latest accelerometer sample, so
//!   at an 8 kHz sample rate every accelerometer sample is written twice (PX4's
//!   `MPU9250::ProcessAccel` in src/drivers/imu/invensense/mpu9250: "accel data is doubled in
//!   FIFO"), and at 1 kHz only every fourth reaches the FIFO. The device's clock can be off by
//!   [`SimConfig::rate_error_ppm`] (the internal oscillator varies by +-10 % over temperature,
//!   PS-MPU-9250A-01 section 3.4). Changing the rate restarts the sample grid at the write.
//! - Gyro start-up: for [`SimConfig::gyro_startup_ns`] after the gyros start (the end of an
//!   H_RESET, SLEEP cleared, or their PWR_MGMT_2 standby bits cleared) the gyro outputs carry
//!   [`SimConfig::gyro_startup_offset_dps`] (PS-MPU-9250A-01 table 1: gyro start-up time 35 ms
//!   typical).
//! - Register writes are logged with their times ([`SimMpu9250::write_log`]), so tests can
//!   check the order and timing of a driver's writes.
//! - DLPF (unless [`SimConfig::model_dlpf`] is false): the filters CONFIG.DLPF_CFG with
//!   GYRO_CONFIG.FCHOICE_B and ACCEL_CONFIG2 (accel_fchoice_b, A_DLPF_CFG) select, at the
//!   internal rates the register map gives (`mems_sim::dlpf`), are handed to the
//!   [`SampleSource`] on an internal grid aligned with the output grid, so each output sample
//!   is the filter output at that instant. Without it, samples are what the source returns for
//!   the output rate (white noise at that rate). Either way they are quantized and saturated
//!   at the configured full scale (ACCEL_FS_SEL, GYRO_FS_SEL), temperature by the datasheet
//!   formula.
//! - Data registers (59-72) and shadow registers: the internal set updates at the output rate;
//!   the user-facing set copies it when a transaction starts (the bus is idle between
//!   transactions), so one burst read is a consistent snapshot while high and low bytes read in
//!   separate transactions can come from different samples (torn values), as on real parts.
//! - FIFO: 512 bytes; with USER_CTRL.FIFO_EN each sample appends the FIFO_EN-selected data in
//!   register order (accel, temperature, gyro X/Y/Z), big-endian. A byte arriving at a full FIFO
//!   sets INT_STATUS.FIFO_OFLOW_INT and replaces the oldest byte (CONFIG.FIFO_MODE = 0, which
//!   misaligns frames whose size does not divide 512) or is dropped (FIFO_MODE = 1); both act per
//!   byte, so the last frame written into a full FIFO can be partial. USER_CTRL.FIFO_RST empties
//!   the FIFO. Reading FIFO_COUNTH latches the count that FIFO_COUNTL then returns.
//! - INT_STATUS: FIFO_OFLOW_INT and RAW_DATA_RDY_INT, cleared when read.
//! - Time: a [`SimClock`]. Each transaction takes its duration under an I2C [`BusTiming`]
//!   model, or on SPI (the [`spi`] submodule) an [`SpiTiming`] model: the clock advances by it
//!   (virtual) or the call sleeps until it has passed (real-time pacing). Samples due before a
//!   transaction starts are produced when it starts.
//! - Faults: NACKs and bus errors on chosen transactions or at random from a seed, a wrong
//!   WHO_AM_I value, an absent device; see [`Fault`].

mod fifo;
pub mod spi;

use std::collections::{BTreeMap, VecDeque};

use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation};
use ipc_types::units::{AccelRange, GyroRange, quantize, temp_counts_from_c};
use mems_sim::dlpf::{self, DlpfConfig};
use mems_sim::{DlpfGrid, SampleSource};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::clock::{Clock, SimClock};
use crate::registers as reg;
use fifo::{Fifo, FullPolicy};
pub use spi::SpiTiming;

/// Timing model of an I2C bus: every START, repeated START and STOP condition counts as one SCL
/// period, every byte as nine (eight bits and the acknowledge bit), and each transaction ends
/// with the bus free time t_BUF before the next START (PS-MPU-9250A-01 section 3.5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BusTiming {
    /// SCL clock frequency, Hz.
    pub scl_hz: f64,
    /// Bus free time between a STOP and the next START, ns.
    pub bus_free_ns: u64,
}

impl BusTiming {
    /// I2C fast mode: 400 kHz, t_BUF = 1.3 us (PS-MPU-9250A-01 table 6).
    pub const FAST_MODE: Self = Self {
        scl_hz: 400_000.0,
        bus_free_ns: 1_300,
    };

    /// Duration of a transaction of `scl_periods` SCL periods, including the bus free time, ns.
    pub fn duration_ns(&self, scl_periods: u64) -> u64 {
        (scl_periods as f64 * 1e9 / self.scl_hz).round() as u64 + self.bus_free_ns
    }

    /// SCL periods of a register read of `n` bytes (START, address+W, register, repeated START,
    /// address+R, `n` data bytes, STOP): 30 + 9 n.
    pub fn register_read_periods(n: usize) -> u64 {
        30 + 9 * n as u64
    }
}

/// An injected bus failure: the transaction fails with `kind` after `after_bytes` bytes of its
/// payload (register pointer and data, both directions) were transferred. Those bytes take
/// effect (a FIFO byte that was clocked out is gone); the rest of the transaction does not.
/// An address NACK fails before any byte, whatever `after_bytes` says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Fault {
    /// The error the transaction returns.
    pub kind: ErrorKind,
    /// Payload bytes transferred before the failure.
    pub after_bytes: usize,
}

impl Fault {
    /// The device does not acknowledge its address (no effect at all).
    pub const ADDRESS_NACK: Self = Self {
        kind: ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address),
        after_bytes: 0,
    };

    /// A bus error (e.g. misplaced START/STOP) after `after_bytes` payload bytes.
    pub fn bus_error(after_bytes: usize) -> Self {
        Self {
            kind: ErrorKind::Bus,
            after_bytes,
        }
    }
}

/// Static parameters of the simulated device.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// The I2C address the device answers: 0x68 (AD0 low) or 0x69 (AD0 high).
    pub address: u8,
    /// The value WHO_AM_I returns (0x71 on an MPU-9250; set another to simulate a wrong part).
    pub who_am_i: u8,
    /// The bus timing model.
    pub timing: BusTiming,
    /// Error of the device's sample clock, ppm (positive: samples come faster than nominal).
    pub rate_error_ppm: f64,
    /// Time the device ignores its address after H_RESET, ns.
    pub startup_ns: u64,
    /// Number of most recent produced samples kept for inspection (0 keeps none); the buffer
    /// is allocated once, up front.
    pub history_len: usize,
    /// Whether the sample source applies the DLPF the registers select, as the real part does
    /// (default true; the source must model it, see `SampleSource::set_dlpf`). False gives
    /// the source's samples at the output rate unfiltered, for sources that do not model it.
    pub model_dlpf: bool,
    /// How long the gyro outputs are off after the gyros start, ns.
    pub gyro_startup_ns: u64,
    /// The gyro outputs' offset during start-up, deg/s, on every axis.
    pub gyro_startup_offset_dps: f64,
    /// The SPI timing model (when the device is used through its SPI interface).
    pub spi: SpiTiming,
    /// When the part was powered on, ns on its clock: the origin of its source's time (its
    /// motion and warm-up). `None`: when the device is created. A restarted acquisition that
    /// continues a sensor session gives the session's origin, so the motion goes on in wall
    /// time instead of starting again.
    pub power_on_ns: Option<u64>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            address: reg::ADDRESS_AD0_LOW,
            who_am_i: reg::WHO_AM_I_VALUE,
            timing: BusTiming::FAST_MODE,
            rate_error_ppm: 0.0,
            startup_ns: reg::STARTUP_TYPICAL_NS,
            history_len: 0,
            model_dlpf: true,
            gyro_startup_ns: reg::GYRO_STARTUP_TYPICAL_NS,
            gyro_startup_offset_dps: 20.0,
            spi: SpiTiming::DATASHEET,
            power_on_ns: None,
        }
    }
}

/// One output sample as the device produced it (what the data registers held, in counts).
/// With the accelerometer at 4 kHz and an 8 kHz sample rate, a sample is recorded once, when
/// it first reaches the data registers and the FIFO; its repetition is not a new sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProducedSample {
    /// Index of the sample since the device was created, from 0.
    pub index: u64,
    /// Time the sample was taken, ns of the device's [`SimClock`].
    pub t_ns: u64,
    /// ACCEL_XOUT/YOUT/ZOUT.
    pub accel: [i16; 3],
    /// TEMP_OUT.
    pub temp: i16,
    /// GYRO_XOUT/YOUT/ZOUT.
    pub gyro: [i16; 3],
}

/// Bus counters of the simulated device.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BusStats {
    /// Transactions addressed to any device on this bus.
    pub transactions: u64,
    /// Transactions that returned an error.
    pub errors: u64,
    /// Payload bytes transferred (register pointers and data).
    pub bytes: u64,
    /// Time the bus was busy, ns.
    pub busy_ns: u64,
    /// Bytes lost to FIFO overflow (overwritten or dropped).
    pub fifo_bytes_lost: u64,
    /// SPI transactions clocked faster than the datasheet allows for the registers they
    /// touch (1 MHz for all registers, 20 MHz for sensor and interrupt registers).
    pub spi_overspeed: u64,
}

/// One register write as the device saw it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RegisterWrite {
    /// When the write happened, ns of the device's clock.
    pub t_ns: u64,
    /// Register address.
    pub register: u8,
    /// Value written.
    pub value: u8,
}

/// The simulated MPU-9250; see the module documentation for what it models.
pub struct SimMpu9250<S: SampleSource> {
    config: SimConfig,
    clock: SimClock,
    source: S,
    present: bool,
    created_ns: u64,
    /// The origin of the source's time, ns ([`SimConfig::power_on_ns`]).
    power_on_ns: u64,
    /// Register file; data registers live in `internal` / `shadow`, WHO_AM_I in `config`.
    regs: [u8; 128],
    internal: [u8; reg::SENSOR_DATA_LEN],
    shadow: [u8; reg::SENSOR_DATA_LEN],
    fifo: Fifo,
    fifo_count_latch: u16,
    pointer: u8,
    /// Device ignores its address until this time (start-up after H_RESET).
    responsive_from_ns: u64,
    /// Sample grid: sample `k` of the current grid is due at `grid_start_ns + k * period`.
    grid_start_ns: u64,
    grid_k: u64,
    grid_period_ns: f64,
    produced: u64,
    /// Sample-rate ticks since the device was created (new and repeated samples).
    ticks: u64,
    /// The accelerometer sample (index on the current grid) the data registers hold, in the
    /// 4 kHz accelerometer mode.
    accel_held: Option<u64>,
    /// When the gyros last started, ns.
    gyro_started_ns: u64,
    writes: Vec<RegisterWrite>,
    spi_clock_hz: f64,
    history: VecDeque<ProducedSample>,
    stats: BusStats,
    scheduled_faults: BTreeMap<u64, Fault>,
    random_faults: Option<(f64, Fault, ChaCha8Rng)>,
    /// The DLPF last handed to the source.
    dlpf: Option<DlpfGrid>,
}

impl<S: SampleSource> SimMpu9250<S> {
    /// A powered-up device (past its start-up time, registers at their reset values) sampling
    /// `source`, on `clock`.
    pub fn new(source: S, clock: SimClock, config: SimConfig) -> Self {
        let now = clock.now_ns();
        let power_on_ns = config.power_on_ns.unwrap_or(now).min(now);
        let history = VecDeque::with_capacity(config.history_len);
        let mut sim = Self {
            config,
            clock,
            source,
            present: true,
            created_ns: now,
            power_on_ns,
            regs: [0; 128],
            internal: [0; reg::SENSOR_DATA_LEN],
            shadow: [0; reg::SENSOR_DATA_LEN],
            fifo: Fifo::new(),
            fifo_count_latch: 0,
            pointer: 0,
            responsive_from_ns: now,
            grid_start_ns: now,
            grid_k: 1,
            grid_period_ns: 0.0,
            produced: 0,
            ticks: 0,
            accel_held: None,
            gyro_started_ns: 0,
            writes: Vec::with_capacity(WRITE_LOG_LEN),
            spi_clock_hz: 1e6,
            history,
            stats: BusStats::default(),
            scheduled_faults: BTreeMap::new(),
            random_faults: None,
            dlpf: None,
        };
        sim.hardware_reset(now);
        sim.responsive_from_ns = now;
        sim.gyro_started_ns = now.saturating_sub(sim.config.gyro_startup_ns);
        sim.restart_grid(now);
        sim
    }

    /// The device's clock (a clone shares the same time).
    pub fn clock(&self) -> &SimClock {
        &self.clock
    }

    /// The sample source, e.g. to inspect its ground truth.
    pub fn source(&self) -> &S {
        &self.source
    }

    /// Connects or disconnects the device: an absent device acknowledges nothing.
    pub fn set_present(&mut self, present: bool) {
        self.present = present;
    }

    /// Makes transaction number `index` (counting from 0, see [`BusStats::transactions`]) fail.
    pub fn fail_transaction(&mut self, index: u64, fault: Fault) {
        self.scheduled_faults.insert(index, fault);
    }

    /// Makes every transaction fail with probability `probability`, drawn from a generator
    /// seeded with `seed` (deterministic); a probability of 0 turns random faults off.
    pub fn fail_randomly(&mut self, probability: f64, fault: Fault, seed: u64) {
        self.random_faults =
            (probability > 0.0).then(|| (probability, fault, ChaCha8Rng::seed_from_u64(seed)));
    }

    /// A register's current value as the bus would read it, without a transaction and without
    /// side effects (no FIFO pop, no clear-on-read); data registers show the user-facing set.
    pub fn peek(&self, register: u8) -> u8 {
        match register {
            reg::WHO_AM_I => self.config.who_am_i,
            r if is_data_register(r) => self.shadow[usize::from(r - reg::ACCEL_XOUT_H)],
            reg::FIFO_COUNTH => (self.fifo.len() >> 8) as u8,
            reg::FIFO_COUNTL => self.fifo.len() as u8,
            r => self.regs[usize::from(r & 0x7F)],
        }
    }

    /// Produces the samples due up to the clock's current time (every transaction does this
    /// when it starts; the inspection methods show the state as of the last update).
    pub fn update(&mut self) {
        self.catch_up(self.clock.now_ns());
    }

    /// Bytes currently in the FIFO.
    pub fn fifo_len(&self) -> usize {
        self.fifo.len()
    }

    /// The current output rate, Hz, or `None` while asleep.
    pub fn output_rate_hz(&self) -> Option<f64> {
        if self.regs[usize::from(reg::PWR_MGMT_1)] & reg::PWR_MGMT_1_SLEEP != 0 {
            return None;
        }
        Some(self.nominal_rate_hz() * (1.0 + self.config.rate_error_ppm * 1e-6))
    }

    /// The most recent produced samples, oldest first (at most [`SimConfig::history_len`]).
    pub fn history(&self) -> &VecDeque<ProducedSample> {
        &self.history
    }

    /// The register writes since the device was created or the log was cleared, oldest first
    /// (the first 4096).
    pub fn write_log(&self) -> &[RegisterWrite] {
        &self.writes
    }

    /// Empties the register write log.
    pub fn clear_write_log(&mut self) {
        self.writes.clear();
    }

    /// Number of distinct samples produced since the device was created (a sample the FIFO
    /// receives twice counts once).
    pub fn samples_produced(&self) -> u64 {
        self.produced
    }

    /// Number of sample-rate ticks (data register updates and FIFO writes) since the device
    /// was created.
    pub fn sample_ticks(&self) -> u64 {
        self.ticks
    }

    /// Bus counters.
    pub fn stats(&self) -> BusStats {
        self.stats
    }

    /// Fraction of the time since the device was created that the bus was busy, 0-1.
    pub fn bus_utilisation(&self) -> f64 {
        let elapsed = self.clock.now_ns().saturating_sub(self.created_ns);
        if elapsed == 0 {
            0.0
        } else {
            self.stats.busy_ns as f64 / elapsed as f64
        }
    }

    /// Produces every sample due up to `now_ns`.
    fn catch_up(&mut self, now_ns: u64) {
        if self.output_rate_hz().is_none() || now_ns < self.responsive_from_ns {
            return;
        }
        loop {
            let due =
                self.grid_start_ns + (self.grid_k as f64 * self.grid_period_ns).round() as u64;
            if due > now_ns {
                return;
            }
            self.produce(due, self.grid_k);
            self.grid_k += 1;
        }
    }

    /// Restarts the sample grid at `now_ns` with the current rate (first sample one period on).
    fn restart_grid(&mut self, now_ns: u64) {
        self.grid_start_ns = now_ns;
        self.grid_k = 1;
        self.accel_held = None;
        self.grid_period_ns = self.output_rate_hz().map_or(0.0, |hz| 1e9 / hz);
        self.sync_dlpf(now_ns, true);
    }

    /// Hands the source the DLPF the registers select, on an internal grid starting at
    /// `start_ns` (an output tick, never before a sample already produced), when its filters
    /// differ from the ones it has or `new_grid` (with [`SimConfig::model_dlpf`]).
    fn sync_dlpf(&mut self, start_ns: u64, new_grid: bool) {
        if !self.config.model_dlpf {
            return;
        }
        let r = |register: u8| self.regs[usize::from(register)];
        let accel_config2 = r(reg::ACCEL_CONFIG2);
        let grid = DlpfGrid {
            config: DlpfConfig {
                accel: dlpf::accel_setting(
                    accel_config2 & reg::ACCEL_FCHOICE_B != 0,
                    accel_config2 & 0b111, // A_DLPF_CFG, bits [2:0]
                ),
                gyro: dlpf::gyro_setting(
                    r(reg::GYRO_CONFIG) & reg::GYRO_FCHOICE_B_MASK,
                    r(reg::CONFIG) & reg::CONFIG_DLPF_CFG_MASK,
                ),
            },
            start_s: start_ns.saturating_sub(self.power_on_ns) as f64 * 1e-9,
            clock_scale: 1.0 + self.config.rate_error_ppm * 1e-6,
        };
        if new_grid || self.dlpf.map(|d| d.config) != Some(grid.config) {
            self.source.set_dlpf(Some(grid));
            self.dlpf = Some(grid);
        }
    }

    /// The sample rate the registers select, Hz, before the clock error.
    fn nominal_rate_hz(&self) -> f64 {
        let dlpf_cfg = self.regs[usize::from(reg::CONFIG)] & reg::CONFIG_DLPF_CFG_MASK;
        let fchoice_b = self.regs[usize::from(reg::GYRO_CONFIG)] & reg::GYRO_FCHOICE_B_MASK;
        if fchoice_b == 0 && (1..=6).contains(&dlpf_cfg) {
            let div = f64::from(self.regs[usize::from(reg::SMPLRT_DIV)]);
            reg::INTERNAL_RATE_DLPF_HZ / (1.0 + div)
        } else {
            reg::INTERNAL_RATE_NO_DLPF_HZ
        }
    }

    /// Whether the accelerometer runs at 4 kHz with its DLPF bypassed (accel_fchoice_b = 1).
    fn accel_bypassed(&self) -> bool {
        self.regs[usize::from(reg::ACCEL_CONFIG2)] & reg::ACCEL_FCHOICE_B != 0
    }

    /// Tick `k` of the sample grid at `t_ns`: a new sample, or, when the 4 kHz accelerometer
    /// has not produced one since the last tick, the held one again.
    fn produce(&mut self, t_ns: u64, k: u64) {
        self.ticks += 1;
        let mut rate_hz = self.output_rate_hz().unwrap_or(0.0);
        if self.accel_bypassed() {
            // Both run on the device clock: tick k (from 1) carries accelerometer sample
            // floor((k - 1) * 4000 / sample rate) of the grid.
            let ratio = reg::ACCEL_BYPASS_RATE_HZ / self.nominal_rate_hz();
            let n = ((k - 1) as f64 * ratio).floor() as u64;
            if self.accel_held == Some(n) {
                self.regs[usize::from(reg::INT_STATUS)] |= reg::INT_STATUS_RAW_DATA_RDY;
                self.write_fifo_frame();
                return;
            }
            self.accel_held = Some(n);
            rate_hz = reg::ACCEL_BYPASS_RATE_HZ * (1.0 + self.config.rate_error_ppm * 1e-6);
        }
        let t_s = (t_ns - self.power_on_ns) as f64 * 1e-9;
        let analog = self.source.sample(t_s, rate_hz);
        let accel_range = AccelRange::from_bits(
            self.regs[usize::from(reg::ACCEL_CONFIG)] >> reg::ACCEL_FS_SEL_SHIFT,
        );
        let gyro_range = GyroRange::from_bits(
            self.regs[usize::from(reg::GYRO_CONFIG)] >> reg::GYRO_FS_SEL_SHIFT,
        );
        let accel = analog
            .accel_g
            .map(|g| quantize(g * accel_range.lsb_per_g()));
        let transient = if t_ns < self.gyro_started_ns + self.config.gyro_startup_ns {
            self.config.gyro_startup_offset_dps
        } else {
            0.0
        };
        let gyro = analog
            .gyro_dps
            .map(|w| quantize((w + transient) * gyro_range.lsb_per_dps()));
        let temp = temp_counts_from_c(analog.temp_c);
        for (i, v) in accel.iter().chain([&temp]).chain(gyro.iter()).enumerate() {
            self.internal[2 * i..2 * i + 2].copy_from_slice(&v.to_be_bytes());
        }
        self.regs[usize::from(reg::INT_STATUS)] |= reg::INT_STATUS_RAW_DATA_RDY;
        self.write_fifo_frame();
        if self.config.history_len > 0 {
            if self.history.len() == self.config.history_len {
                self.history.pop_front();
            }
            self.history.push_back(ProducedSample {
                index: self.produced,
                t_ns,
                accel,
                temp,
                gyro,
            });
        }
        self.produced += 1;
    }

    /// Appends the FIFO_EN-selected data of the internal registers to the FIFO.
    fn write_fifo_frame(&mut self) {
        if self.regs[usize::from(reg::USER_CTRL)] & reg::USER_CTRL_FIFO_EN == 0 {
            return;
        }
        let enable = self.regs[usize::from(reg::FIFO_EN)];
        let policy = if self.regs[usize::from(reg::CONFIG)] & reg::CONFIG_FIFO_MODE != 0 {
            FullPolicy::DropNew
        } else {
            FullPolicy::OverwriteOldest
        };
        // Register offsets in `internal` and lengths, in register order, with the FIFO_EN bit
        // selecting each.
        let offset = |register: u8| usize::from(register - reg::ACCEL_XOUT_H);
        let parts = [
            (reg::FIFO_EN_ACCEL, offset(reg::ACCEL_XOUT_H), 6),
            (reg::FIFO_EN_TEMP, offset(reg::TEMP_OUT_H), 2),
            (reg::FIFO_EN_GYRO_X, offset(reg::GYRO_XOUT_H), 2),
            (reg::FIFO_EN_GYRO_Y, offset(reg::GYRO_XOUT_H) + 2, 2),
            (reg::FIFO_EN_GYRO_Z, offset(reg::GYRO_XOUT_H) + 4, 2),
        ];
        for (bit, start, len) in parts {
            if enable & bit == 0 {
                continue;
            }
            for i in start..start + len {
                if self.fifo.push(self.internal[i], policy) {
                    self.stats.fifo_bytes_lost += 1;
                    self.regs[usize::from(reg::INT_STATUS)] |= reg::INT_STATUS_FIFO_OFLOW;
                }
            }
        }
    }

    /// H_RESET: registers to reset values, FIFO empty, start-up time begins.
    fn hardware_reset(&mut self, now_ns: u64) {
        self.regs = [0; 128];
        self.regs[usize::from(reg::PWR_MGMT_1)] = reg::PWR_MGMT_1_RESET_VALUE;
        self.internal = [0; reg::SENSOR_DATA_LEN];
        self.shadow = [0; reg::SENSOR_DATA_LEN];
        self.fifo.clear();
        self.fifo_count_latch = 0;
        self.pointer = 0;
        self.responsive_from_ns = now_ns + self.config.startup_ns;
        self.gyro_started_ns = self.responsive_from_ns;
        self.restart_grid(self.responsive_from_ns);
    }

    /// Whether the gyros run: awake and not all in standby.
    fn gyros_running(&self) -> bool {
        self.regs[usize::from(reg::PWR_MGMT_1)] & reg::PWR_MGMT_1_SLEEP == 0
            && self.regs[usize::from(reg::PWR_MGMT_2)] & reg::PWR_MGMT_2_DISABLE_GYRO
                != reg::PWR_MGMT_2_DISABLE_GYRO
    }

    /// A register write from the bus at `now_ns`.
    fn write_register(&mut self, register: u8, value: u8, now_ns: u64) {
        if self.writes.len() < WRITE_LOG_LEN {
            self.writes.push(RegisterWrite {
                t_ns: now_ns,
                register,
                value,
            });
        }
        let rate_before = self.output_rate_hz();
        let gyros_before = self.gyros_running();
        match register {
            reg::PWR_MGMT_1 if value & reg::PWR_MGMT_1_H_RESET != 0 => {
                self.hardware_reset(now_ns);
                return;
            }
            reg::USER_CTRL => {
                if value & reg::USER_CTRL_FIFO_RST != 0 {
                    self.fifo.clear();
                }
                self.regs[usize::from(reg::USER_CTRL)] = value & !reg::USER_CTRL_FIFO_RST;
            }
            reg::WHO_AM_I
            | reg::INT_STATUS
            | reg::FIFO_COUNTH
            | reg::FIFO_COUNTL
            | reg::FIFO_R_W => {}
            r if is_data_register(r) => {}
            r => self.regs[usize::from(r & 0x7F)] = value,
        }
        if self.output_rate_hz() != rate_before {
            self.restart_grid(now_ns);
        } else {
            // The same grid: a new filter starts at the last tick produced on it.
            let last_tick_ns = self.grid_start_ns
                + (self.grid_k.saturating_sub(1) as f64 * self.grid_period_ns).round() as u64;
            self.sync_dlpf(last_tick_ns, false);
        }
        if self.gyros_running() && !gyros_before {
            self.gyro_started_ns = now_ns;
        }
    }

    /// A register read from the bus, with its side effects.
    fn read_register(&mut self, register: u8) -> u8 {
        match register {
            reg::FIFO_R_W => self.fifo.pop(),
            reg::FIFO_COUNTH => {
                self.fifo_count_latch = self.fifo.len() as u16;
                (self.fifo_count_latch >> 8) as u8
            }
            reg::FIFO_COUNTL => self.fifo_count_latch as u8,
            reg::INT_STATUS => std::mem::take(&mut self.regs[usize::from(reg::INT_STATUS)]),
            r => self.peek(r),
        }
    }

    /// The fault, if any, for the transaction numbered `index`.
    fn fault_for(&mut self, index: u64) -> Option<Fault> {
        if let Some(f) = self.scheduled_faults.remove(&index) {
            return Some(f);
        }
        let (p, fault, rng) = self.random_faults.as_mut()?;
        rng.random_bool(*p).then_some(*fault)
    }

    /// Runs the operations of one transaction addressed to this device; returns the SCL
    /// periods used (without START/STOP) and the result.
    fn run_operations(
        &mut self,
        operations: &mut [Operation<'_>],
        fault: Option<Fault>,
        now_ns: u64,
    ) -> (u64, Result<(), ErrorKind>) {
        let mut periods = 0;
        let mut budget = fault.map(|f| f.after_bytes);
        let mut previous_was_read = None;
        for op in operations.iter_mut() {
            let is_read = matches!(op, Operation::Read(_));
            match previous_was_read {
                None => periods += 9,                           // address + R/W, ACK
                Some(prev) if prev != is_read => periods += 10, // repeated START, address + R/W
                Some(_) => {}
            }
            previous_was_read = Some(is_read);
            let len = match op {
                Operation::Read(buf) => buf.len(),
                Operation::Write(bytes) => bytes.len(),
            };
            for i in 0..len {
                if let Some(left) = budget.as_mut() {
                    if *left == 0 {
                        return (periods, Err(fault.map_or(ErrorKind::Bus, |f| f.kind)));
                    }
                    *left -= 1;
                }
                periods += 9;
                self.stats.bytes += 1;
                match op {
                    Operation::Read(buf) => {
                        buf[i] = self.read_register(self.pointer);
                        self.advance_pointer();
                    }
                    Operation::Write(bytes) => {
                        if i == 0 {
                            self.pointer = bytes[0] & 0x7F;
                        } else {
                            self.write_register(self.pointer, bytes[i], now_ns);
                            self.advance_pointer();
                        }
                    }
                }
            }
        }
        (periods, Ok(()))
    }

    fn advance_pointer(&mut self) {
        if self.pointer != reg::FIFO_R_W {
            self.pointer = (self.pointer + 1) & 0x7F;
        }
    }
}

/// Register writes the log keeps (allocated once).
const WRITE_LOG_LEN: usize = 4096;

impl<S: SampleSource> SimMpu9250<S> {
    /// Starts a transaction now: numbers it, draws its fault, produces the samples due.
    fn begin_transaction(&mut self) -> (u64, Option<Fault>) {
        let start = self.clock.now_ns();
        let index = self.stats.transactions;
        self.stats.transactions += 1;
        let fault = self.fault_for(index);
        self.catch_up(start);
        (start, fault)
    }

    /// Ends a transaction that started at `start_ns` and took `duration_ns`.
    fn end_transaction(&mut self, start_ns: u64, duration_ns: u64, failed: bool) {
        if failed {
            self.stats.errors += 1;
        }
        self.stats.busy_ns += duration_ns;
        self.clock.sleep_until(start_ns + duration_ns);
    }
}

/// Whether `register` is one of the sensor data registers 59-72.
fn is_data_register(register: u8) -> bool {
    (reg::ACCEL_XOUT_H..reg::ACCEL_XOUT_H + reg::SENSOR_DATA_LEN as u8).contains(&register)
}

impl<S: SampleSource> ErrorType for SimMpu9250<S> {
    type Error = ErrorKind;
}

impl<S: SampleSource> I2c for SimMpu9250<S> {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        let (start, fault) = self.begin_transaction();
        let address_nack = address != self.config.address
            || !self.present
            || start < self.responsive_from_ns
            || fault.is_some_and(|f| f.kind == Fault::ADDRESS_NACK.kind);
        // START and STOP, plus the address byte when it is not acknowledged.
        let (periods, result) = if address_nack {
            (2 + 9, Err(Fault::ADDRESS_NACK.kind))
        } else {
            // The bus was idle until now: the user-facing data registers catch up.
            self.shadow = self.internal;
            let (periods, result) = self.run_operations(operations, fault, start);
            (2 + periods, result)
        };
        let duration = self.config.timing.duration_ns(periods);
        self.end_transaction(start, duration, result.is_err());
        result
    }
}
