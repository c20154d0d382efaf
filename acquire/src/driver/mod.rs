//! A small MPU-9250 driver over `embedded_hal::i2c::I2c`, written against the register map
//! RM-MPU-9250A-00 rev 1.6 (see [`crate::registers`]).
//!
//! Acquisition goes through the FIFO only, with burst reads only: FIFO_COUNTH/L (one two-byte
//! transaction), whole frames from FIFO_R_W in one transaction, then INT_STATUS (one byte, for
//! FIFO_OFLOW_INT). No sample is ever assembled from two transactions, so no sample can be
//! torn. Reading INT_STATUS last attributes every overflow to the poll it happened in: one
//! before the count shows as a full FIFO (512 bytes), one after it as the flag, and then the
//! partial frame the overflow left behind the frames just read is dropped with the rest of the
//! FIFO instead of misaligning the next read.
//!
//! The FIFO runs with CONFIG.FIFO_MODE = 1 (a full FIFO drops new data): after an overflow the
//! oldest frames in the FIFO are still aligned and contiguous with what was read before, so
//! they are delivered; the FIFO is then reset and the next sample is flagged
//! (`FIFO_OVERFLOW | GAP_BEFORE`, with the number of samples lost estimated from time). With
//! FIFO_MODE = 0 an overflow overwrites the oldest bytes and misaligns every frame.
//!
//! Register transactions (status, count, configuration) that fail are retried; a FIFO data
//! read that fails is not (the bytes it clocked out are gone), the FIFO is reset instead and
//! the gap flagged. Errors that persist through the retries, or a FIFO that stops filling,
//! re-initialise the device (probe, reset, configure) from [`Mpu9250::read_samples`]; if that
//! fails too, the call returns the error and the next call tries again.
//!
//! Sample times come from the `timing` submodule: reconstructed from the FIFO counts with a
//! continuously measured sample period, anchored to the caller's clock (`CLOCK_MONOTONIC` in
//! production, a virtual clock in tests), then moved back by the configured low-pass filter's
//! delay, so that a sample's time is when the motion it shows happened. The steady-state read
//! loop allocates nothing: frames are read into a buffer inside the driver and decoded into
//! the caller's slice.
//!
//! Start-up follows the Linux driver (drivers/iio/imu/inv_mpu6050/): WHO_AM_I accepts the
//! MPU-6500, MPU-9250 and MPU-9255; after H_RESET the driver waits the start-up time; after
//! configuring the gyros it lets them settle ([`reg::GYRO_SETTLE_NS`], inv_mpu_core.c
//! `inv_mpu6050_set_power_itg` / `inv_mpu6050_switch_engine` sleep for the start-up time) and
//! drops the first FIFO sample with gyro data (inv_mpu_ring.c `inv_mpu6050_read_fifo` skips
//! `st->skip_samples`); the FIFO is reset with its channels disabled first (inv_mpu_ring.c
//! `inv_reset_fifo`: FIFO_EN = 0, USER_CTRL without FIFO_EN, FIFO_RST, FIFO_EN, channels).
//!
//! The driver speaks embedded-hal's `I2c`; over SPI it runs on [`crate::spi::SpiRegisters`],
//! which maps the same register transactions to SPI frames. It knows what its bus can carry
//! ([`BusKind`]) and refuses a configuration whose FIFO data the bus cannot move.

mod bus;
mod config;
mod duplicates;
mod error;
mod timing;

pub use bus::{BusKind, MAX_DATA_SHARE};
pub use config::{Config, Dlpf, OutputMode};
use duplicates::Pairing;
pub use error::Error;

use embedded_hal::i2c::{Error as _, ErrorKind, I2c, NoAcknowledgeSource};
use ipc_types::RawImuSample;
use ipc_types::raw_flags;
use ipc_types::stream::range;
use ipc_types::units::{AccelRange, GyroRange, is_saturated, temp_c_from_counts};

use crate::clock::Clock;
use crate::registers as reg;
use timing::SampleTimer;

/// Counters of what the driver saw and did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DriverStats {
    /// Samples delivered.
    pub samples: u64,
    /// Calls of [`Mpu9250::read_samples`] that reached the FIFO.
    pub reads: u64,
    /// FIFO overflows seen (INT_STATUS.FIFO_OFLOW_INT).
    pub overflows: u64,
    /// Short reads: a FIFO count that is not a whole number of frames (bytes lost, frames
    /// misaligned), or a FIFO data read that failed part-way.
    pub short_reads: u64,
    /// Gaps flagged on delivered samples.
    pub gaps: u64,
    /// Samples estimated lost in those gaps.
    pub lost_samples: u64,
    /// Failed transactions (each attempt counts).
    pub bus_errors: u64,
    /// Transactions retried after a failure.
    pub retries: u64,
    /// FIFO resets after an overflow, a short read or a failed FIFO read.
    pub fifo_resets: u64,
    /// Times the FIFO stopped filling for longer than the stall timeout.
    pub stalls: u64,
    /// Re-initialisations (successful or not) after persistent errors or stalls.
    pub reinits: u64,
    /// The largest FIFO_COUNT read, bytes (512 is a full FIFO): how close the reads came to an
    /// overflow.
    pub max_fifo_bytes: u64,
    /// Repeated frames recognised and not delivered (4 kHz accelerometer mode).
    pub duplicates: u64,
    /// Frames that should have repeated the one before and did not (corrupt or misaligned;
    /// the FIFO is reset and the gap flagged).
    pub pair_mismatches: u64,
    /// Frames dropped after a FIFO start because the gyros were still settling.
    pub settling_discarded: u64,
}

/// Attempts per register transaction (the first plus retries).
const ATTEMPTS: u32 = 3;
/// A FIFO_COUNT read that took longer than this, ns (about 120 us of bus time at 400 kHz),
/// was delayed by the host (preemption, bus contention): its observation of the sample phase
/// is not used for timing.
const COUNT_READ_MAX_NS: u64 = 1_000_000;
/// FIFO_COUNT reads tried for a prompt observation when the one the sample times would be
/// anchored on was delayed.
const ANCHOR_COUNT_ATTEMPTS: u32 = 3;
/// The FIFO must receive data within this many output periods (and at least
/// [`STALL_MIN_NS`]) of the last sample, or the device is considered stopped.
const STALL_PERIODS: f64 = 50.0;
/// Lower bound of the stall timeout, ns.
const STALL_MIN_NS: f64 = 50e6;

/// What one poll's FIFO_COUNT read said: when it was read (ns, before and after), the whole
/// frames counted, and whether the FIFO was full.
#[derive(Clone, Copy)]
struct FifoCount {
    t_before: u64,
    t_after: u64,
    available: usize,
    full: bool,
}

/// The outcome of reading a poll's frames: samples delivered, the poll going on to check for
/// an overflow; or delivered before the FIFO was reset, which ends the poll.
enum FramesRead {
    Delivered(usize),
    FifoReset(usize),
}

/// An MPU-9250 on an I2C bus (or on SPI through [`crate::spi::SpiRegisters`]).
pub struct Mpu9250<I2C: I2c> {
    i2c: I2C,
    bus: String,
    bus_kind: BusKind,
    address: u8,
    part: Option<&'static str>,
    pairing: Pairing,
    /// FIFO frames still to drop after a FIFO start (gyro settling).
    skip_frames: usize,
    config: Option<Config>,
    needs_init: bool,
    buf: [u8; reg::FIFO_SIZE],
    timer: SampleTimer,
    /// Flags and lost count for the next delivered sample.
    pending_flags: u16,
    /// Samples known to be lost (discarded by the driver) before the next delivered sample.
    pending_discarded: u64,
    seq: u64,
    temp_counts: Option<i16>,
    next_temp_ns: u64,
    last_data_ns: Option<u64>,
    stats: DriverStats,
}

impl<I2C: I2c> Mpu9250<I2C> {
    /// A driver for the device at `address` on `i2c`; `bus` names the bus in errors (e.g.
    /// "/dev/i2c-1" or "sim"). Nothing is sent until [`Mpu9250::probe`] or [`Mpu9250::init`].
    pub fn new(i2c: I2C, bus: impl Into<String>, address: u8) -> Self {
        Self {
            i2c,
            bus: bus.into(),
            bus_kind: BusKind::I2C_FAST_MODE,
            address,
            part: None,
            pairing: Pairing::default(),
            skip_frames: 0,
            config: None,
            needs_init: true,
            buf: [0; reg::FIFO_SIZE],
            timer: SampleTimer::new(1e9 / reg::ACCEL_BYPASS_RATE_HZ),
            pending_flags: 0,
            pending_discarded: 0,
            seq: 0,
            temp_counts: None,
            next_temp_ns: 0,
            last_data_ns: None,
            stats: DriverStats::default(),
        }
    }

    /// Declares the bus the driver talks over (default: I2C at 400 kHz); [`Mpu9250::init`]
    /// refuses configurations it cannot carry, and on SPI the I2C interface is disabled.
    pub fn with_bus_kind(mut self, kind: BusKind) -> Self {
        self.bus_kind = kind;
        self
    }

    /// The bus the driver talks over.
    pub fn bus_kind(&self) -> BusKind {
        self.bus_kind
    }

    /// The part WHO_AM_I identified ("MPU-9250", "MPU-9255" or "MPU-6500"), once probed.
    pub fn part(&self) -> Option<&'static str> {
        self.part
    }

    /// The bus label given to [`Mpu9250::new`].
    pub fn bus_label(&self) -> &str {
        &self.bus
    }

    /// The device address.
    pub fn address(&self) -> u8 {
        self.address
    }

    /// Counters.
    pub fn stats(&self) -> DriverStats {
        self.stats
    }

    /// The configuration last applied by [`Mpu9250::init`].
    pub fn config(&self) -> Option<Config> {
        self.config
    }

    /// The full-scale ranges the device is set to, read back from its registers: GYRO_CONFIG
    /// (27) and ACCEL_CONFIG (28) bits `[4:3]`, `GYRO_FS_SEL` and `ACCEL_FS_SEL` (register map
    /// RM-MPU-9250A-00 rev 1.6, sections 4.6-4.7: +-250/500/1000/2000 deg/s, +-2/4/8/16 g; the
    /// Linux driver drivers/iio/imu/inv_mpu6050/inv_mpu_core.c reads the same bits into its
    /// `gyro_fs`/`accl_fs`). An axis at the end of these is clipped
    /// (`ipc_types::stream::range`).
    pub fn ranges(&mut self) -> Result<range::Ranges, Error<I2C::Error>> {
        let mut config = [0u8; 2];
        self.read_registers(
            reg::GYRO_CONFIG,
            &mut config,
            "reading the full-scale ranges",
        )?;
        let gyro = GyroRange::from_bits(config[0] >> reg::GYRO_FS_SEL_SHIFT);
        let accel = AccelRange::from_bits(config[1] >> reg::ACCEL_FS_SEL_SHIFT);
        // The largest count over the sensitivity: +-32768 counts span the range.
        Ok(range::Ranges {
            accel_g: range::Range::given(Some(32768.0 / accel.lsb_per_g())),
            gyro_dps: range::Range::given(Some(32768.0 / gyro.lsb_per_dps())),
        })
    }

    /// The bus (for inspection, e.g. the simulated device's statistics).
    pub fn i2c(&self) -> &I2C {
        &self.i2c
    }

    /// The bus, e.g. to reach a simulated device's controls.
    pub fn bus_mut(&mut self) -> &mut I2C {
        &mut self.i2c
    }

    /// Gives the bus back.
    pub fn release(self) -> I2C {
        self.i2c
    }

    /// Checks that an MPU-9250 answers: reads WHO_AM_I and accepts the parts of
    /// [`reg::WHO_AM_I_PARTS`].
    pub fn probe(&mut self) -> Result<(), Error<I2C::Error>> {
        let mut who = [0u8; 1];
        let address = self.address;
        let read = attempt(
            &mut self.i2c,
            &mut self.stats,
            |_| true,
            |i2c| i2c.write_read(address, &[reg::WHO_AM_I], &mut who),
        );
        match read {
            Err(error) if is_address_nack(error.kind()) => Err(Error::Absent {
                bus: self.bus.clone(),
                address,
                error,
            }),
            Err(error) => Err(self.bus_error("reading WHO_AM_I", error)),
            Ok(()) => match reg::WHO_AM_I_PARTS.iter().find(|(id, _)| *id == who[0]) {
                Some((_, part)) => {
                    self.part = Some(part);
                    Ok(())
                }
                None => Err(Error::WrongDevice {
                    bus: self.bus.clone(),
                    address,
                    found: who[0],
                }),
            },
        }
    }

    /// Resets every register to its default (PWR_MGMT_1.H_RESET) and waits the maximum
    /// start-up time (100 ms) on `clock`.
    pub fn reset(&mut self, clock: &impl Clock) -> Result<(), Error<I2C::Error>> {
        self.write_register(reg::PWR_MGMT_1, reg::PWR_MGMT_1_H_RESET, "resetting")?;
        clock.sleep_ns(reg::STARTUP_MAX_NS);
        Ok(())
    }

    /// Probes, resets and configures the device, then starts the FIFO. Sample times start
    /// afresh (the first sample after this is not flagged; later re-initialisations flag a gap).
    pub fn init(&mut self, config: Config, clock: &impl Clock) -> Result<(), Error<I2C::Error>> {
        self.bus_kind
            .check(&config)
            .map_err(|message| Error::Infeasible {
                bus: self.bus.clone(),
                message,
            })?;
        self.probe()?;
        self.reset(clock)?;
        self.probe()?;
        self.configure(config, clock)?;
        self.config = Some(config);
        self.needs_init = false;
        Ok(())
    }

    /// Writes and verifies the configuration registers, lets the gyros settle, then starts
    /// the FIFO (its first gyro sample is dropped).
    fn configure(&mut self, config: Config, clock: &impl Clock) -> Result<(), Error<I2C::Error>> {
        let values = config.register_values();
        for (register, value) in values {
            self.write_register(register, value, "configuring")?;
        }
        if config.gyros_on() {
            clock.sleep_ns(reg::GYRO_SETTLE_NS);
        }
        self.start_fifo(config)?;
        let fifo = [
            (reg::FIFO_EN, config.fifo_channels()),
            (reg::USER_CTRL, self.user_ctrl() | reg::USER_CTRL_FIFO_EN),
        ];
        for (register, expected) in values.into_iter().chain(fifo) {
            let mut read = [0u8; 1];
            self.read_registers(register, &mut read, "verifying the configuration")?;
            if read[0] != expected {
                return Err(Error::Verify {
                    bus: self.bus.clone(),
                    address: self.address,
                    register,
                    wrote: expected,
                    read: read[0],
                });
            }
        }
        self.timer.set_period(1e9 / config.fifo_rate_hz());
        self.temp_counts = None;
        self.next_temp_ns = clock.now_ns();
        self.last_data_ns = Some(clock.now_ns());
        Ok(())
    }

    /// USER_CTRL's bits besides the FIFO's: I2C_IF_DIS on SPI.
    fn user_ctrl(&self) -> u8 {
        if self.bus_kind.is_spi() {
            reg::USER_CTRL_I2C_IF_DIS
        } else {
            0
        }
    }

    /// Empties and (re)starts the FIFO in the Linux driver's order (inv_mpu_ring.c
    /// `inv_reset_fifo`): channels off (FIFO_EN = 0), FIFO off, FIFO_RST, FIFO on, channels on.
    /// The register map does not say what a reset does to a frame being written; with the
    /// channels off none is. The first frame after a start with the gyros on is dropped
    /// (settling).
    fn start_fifo(&mut self, config: Config) -> Result<(), Error<I2C::Error>> {
        let base = self.user_ctrl();
        let steps = [
            (reg::FIFO_EN, 0),
            (reg::USER_CTRL, base),
            (reg::USER_CTRL, base | reg::USER_CTRL_FIFO_RST),
            (reg::USER_CTRL, base | reg::USER_CTRL_FIFO_EN),
            (reg::FIFO_EN, config.fifo_channels()),
        ];
        for (register, value) in steps {
            self.write_register(register, value, "resetting the FIFO")?;
        }
        self.pairing.reset();
        self.skip_frames = if config.gyros_on() { 1 } else { 0 };
        Ok(())
    }

    /// Reads the die temperature (TEMP_OUT_H/L in one transaction), degC.
    pub fn read_temperature(&mut self) -> Result<f64, Error<I2C::Error>> {
        Ok(temp_c_from_counts(self.read_temp_counts()?))
    }

    fn read_temp_counts(&mut self) -> Result<i16, Error<I2C::Error>> {
        let mut b = [0u8; 2];
        self.read_registers(reg::TEMP_OUT_H, &mut b, "reading TEMP_OUT")?;
        Ok(i16::from_be_bytes(b))
    }

    /// Reads the samples waiting in the FIFO into `out` (at most `out.len()`), oldest first,
    /// and returns how many. `clock` must be the clock the sample times are wanted on.
    ///
    /// Persistent bus errors or a stalled FIFO re-initialise the device here (the next sample
    /// is flagged `GAP_BEFORE`); the error is returned only if re-initialisation fails, and the
    /// next call tries again.
    pub fn read_samples(
        &mut self,
        clock: &impl Clock,
        out: &mut [RawImuSample],
    ) -> Result<usize, Error<I2C::Error>> {
        let config = self.config.ok_or_else(|| Error::NotInitialised {
            bus: self.bus.clone(),
            address: self.address,
        })?;
        if self.needs_init {
            self.reinit(config, clock)?;
        }
        match self.poll(config, clock, out) {
            Ok(Some(n)) => Ok(n),
            Ok(None) => {
                self.stats.stalls += 1;
                self.reinit(config, clock).map(|()| 0)
            }
            Err(_) => self.reinit(config, clock).map(|()| 0),
        }
    }

    /// Re-initialises after a failure; the next sample is flagged as following a gap.
    fn reinit(&mut self, config: Config, clock: &impl Clock) -> Result<(), Error<I2C::Error>> {
        self.stats.reinits += 1;
        self.needs_init = true;
        self.pending_flags |= raw_flags::GAP_BEFORE;
        self.timer.resync();
        self.init(config, clock)
    }

    /// One FIFO read. `Ok(None)` means the FIFO has stalled.
    fn poll(
        &mut self,
        config: Config,
        clock: &impl Clock,
        out: &mut [RawImuSample],
    ) -> Result<Option<usize>, Error<I2C::Error>> {
        self.stats.reads += 1;
        let frame = config.frame_len();
        if config.mode == OutputMode::Accel4kHz
            && config.temp_interval_ns > 0
            && clock.now_ns() >= self.next_temp_ns
        {
            self.temp_counts = Some(self.read_temp_counts()?);
            self.next_temp_ns = clock.now_ns() + config.temp_interval_ns;
        }
        let mut count_bytes = [0u8; 2];
        let t_before = clock.now_ns();
        self.read_registers(reg::FIFO_COUNTH, &mut count_bytes, "reading FIFO_COUNT")?;
        let t_after = clock.now_ns();
        let count = usize::from(u16::from_be_bytes(count_bytes) & 0x1FFF).min(reg::FIFO_SIZE);
        // A full FIFO has overflowed (neither frame size divides 512, so a full FIFO ends in
        // part of a frame): with FIFO_MODE = 1 its oldest whole frames are intact and are
        // delivered, then it is reset.
        let full = count == reg::FIFO_SIZE;
        self.stats.max_fifo_bytes = self.stats.max_fifo_bytes.max(count as u64);
        let available = count / frame;
        let short = count % frame != 0;

        if available == 0 && !full && !short {
            let period = self.timer.period_ns();
            let stalled = self.last_data_ns.is_some_and(|last| {
                (t_after.saturating_sub(last)) as f64 > (STALL_PERIODS * period).max(STALL_MIN_NS)
            });
            return Ok(if stalled { None } else { Some(0) });
        }
        self.last_data_ns = Some(t_after);

        // A count that is not whole frames means bytes were lost: the frames may be misaligned,
        // so nothing in the FIFO is trusted (unless the FIFO is full, where with FIFO_MODE = 1
        // only the tail is incomplete).
        let take = if short && !full {
            0
        } else {
            available.min(out.len())
        };
        let mut delivered = 0;
        if take > 0 {
            let count = FifoCount {
                t_before,
                t_after,
                available,
                full,
            };
            match self.read_frames(config, clock, count, take, out)? {
                FramesRead::Delivered(n) => delivered = n,
                FramesRead::FifoReset(n) => return Ok(Some(n)),
            }
        }
        self.check_overflow(config, full, short, available)?;
        Ok(Some(delivered))
    }

    /// Reads `take` whole frames (of `count.available`) and decodes them into `out`, numbered
    /// and timed; a failed read or a mismatched pair resets the FIFO (the frames from there
    /// on cannot be trusted).
    fn read_frames(
        &mut self,
        config: Config,
        clock: &impl Clock,
        count: FifoCount,
        take: usize,
        out: &mut [RawImuSample],
    ) -> Result<FramesRead, Error<I2C::Error>> {
        let frame = config.frame_len();
        let FifoCount {
            t_before,
            t_after,
            available,
            full,
        } = count;
        // The observation for the times: this poll's count, or, when that was delayed and
        // the times are to be anchored on it, a prompt count taken before any frame is read.
        let mut obs = (t_before, available);
        let mut reliable = !full && t_after - t_before <= COUNT_READ_MAX_NS;
        if !reliable
            && !full
            && self.timer.anchoring()
            && let Some(again) = self.observe_count(clock, frame)?
        {
            (obs, reliable) = (again, true);
        }
        let bytes = take * frame;
        // Only an address NACK is retried: after any other failure, the bytes clocked out
        // before it are gone from the FIFO and the frames can no longer be trusted.
        let address = self.address;
        let buf = &mut self.buf[..bytes];
        let fifo_read = attempt(&mut self.i2c, &mut self.stats, is_address_nack, |i2c| {
            i2c.write_read(address, &[reg::FIFO_R_W], buf)
        });
        match fifo_read {
            Err(e) if is_address_nack(e.kind()) => {
                return Err(self.persistent("reading the FIFO", e));
            }
            Err(_) => {
                self.stats.short_reads += 1;
                let lost = available / config.frames_per_sample();
                self.reset_fifo(config, lost as u64)?;
                return Ok(FramesRead::FifoReset(0));
            }
            Ok(()) => {}
        }
        // The newest sample was produced within one period before the count was latched.
        let newest_obs = obs.0 as f64 - self.timer.period_ns() / 2.0;
        let a = self.timer.assign(take, obs.1, newest_obs, reliable);
        let fps = config.frames_per_sample() as u64;
        let (n, skipped, mismatch) = self.decode_frames(&config, take, &a, out);
        for sample in &mut out[..n] {
            sample.seq = self.seq;
            self.seq += 1;
        }
        self.mark_gap(&mut out[..n], a.lost, skipped, fps);
        self.stats.samples += n as u64;
        if let Some(bad) = mismatch {
            // The frames from the mismatch on cannot be trusted: drop them and what is
            // left in the FIFO.
            self.stats.pair_mismatches += 1;
            let dropped = (available - bad) as u64 / fps;
            self.reset_fifo(config, dropped)?;
            return Ok(FramesRead::FifoReset(n));
        }
        Ok(FramesRead::Delivered(n))
    }

    /// INT_STATUS after the data: FIFO_OFLOW_INT covers the time since the last poll read it.
    /// An overflow before this poll's count left the FIFO full (nothing was read since); one
    /// after it, while this poll ran, left a partial frame behind the frames just read, which
    /// would misalign every later frame: the rest of the FIFO is dropped. So is a FIFO whose
    /// count was not whole frames (`short`; `available` whole frames counted).
    fn check_overflow(
        &mut self,
        config: Config,
        full: bool,
        short: bool,
        available: usize,
    ) -> Result<(), Error<I2C::Error>> {
        let mut status = [0u8; 1];
        self.read_registers(reg::INT_STATUS, &mut status, "reading INT_STATUS")?;
        let overflow = full || status[0] & reg::INT_STATUS_FIFO_OFLOW != 0;
        let fps = config.frames_per_sample();
        if overflow {
            self.stats.overflows += 1;
            self.pending_flags |= raw_flags::FIFO_OVERFLOW | raw_flags::GAP_BEFORE;
            self.reset_fifo(config, 0)?;
        } else if short {
            self.stats.short_reads += 1;
            self.reset_fifo(config, (available / fps) as u64)?;
        }
        Ok(())
    }

    /// Flags the first of the `delivered` samples with the gap before it, if any: its size is
    /// what the times say (`frames_lost` frames), at least what the driver discarded (settling
    /// frames dropped after a FIFO reset, `skipped`, are part of a gap), and at least one
    /// sample whenever a gap is known to have happened. With nothing delivered (a settling or
    /// repeated frame only) the gap is carried to the next sample. `fps`: frames per sample.
    fn mark_gap(
        &mut self,
        delivered: &mut [RawImuSample],
        frames_lost: u64,
        skipped: usize,
        fps: u64,
    ) {
        let gap = self.pending_flags & raw_flags::GAP_BEFORE != 0;
        let dropped = if gap { skipped as u64 } else { 0 };
        let mut lost = ((frames_lost + dropped) as f64 / fps as f64).round() as u64;
        lost = lost.max(self.pending_discarded);
        if gap {
            lost = lost.max(1);
        }
        let Some(first) = delivered.first_mut() else {
            self.pending_discarded = lost;
            return;
        };
        if lost > 0 {
            first.flags |= self.pending_flags | raw_flags::GAP_BEFORE;
            first.lost_before = u32::try_from(lost).unwrap_or(u32::MAX);
            self.stats.gaps += 1;
            self.stats.lost_samples += lost;
        }
        self.pending_flags = 0;
        self.pending_discarded = 0;
    }

    /// Reads FIFO_COUNT again for an observation to anchor the sample times on, when the read
    /// that counted the frames just taken was delayed (the times of a whole stream follow
    /// from its anchor, and one taken late would start them early and later show a gap that
    /// never happened). Returns the count's time and the whole frames it found, from the
    /// first of [`ANCHOR_COUNT_ATTEMPTS`] reads that was prompt and found neither a full FIFO
    /// nor a partial frame; `None` if none was. FIFO_COUNT is the number of bytes the FIFO
    /// holds (RM-MPU-9250A-00 registers 114-115), so until frames are read it only grows, and
    /// the frames counted first are still the oldest.
    fn observe_count(
        &mut self,
        clock: &impl Clock,
        frame: usize,
    ) -> Result<Option<(u64, usize)>, Error<I2C::Error>> {
        let mut count_bytes = [0u8; 2];
        for _ in 0..ANCHOR_COUNT_ATTEMPTS {
            let t_before = clock.now_ns();
            self.read_registers(reg::FIFO_COUNTH, &mut count_bytes, "reading FIFO_COUNT")?;
            let t_after = clock.now_ns();
            let count = usize::from(u16::from_be_bytes(count_bytes) & 0x1FFF);
            if t_after - t_before <= COUNT_READ_MAX_NS
                && count < reg::FIFO_SIZE
                && count % frame == 0
            {
                return Ok(Some((t_before, count / frame)));
            }
        }
        Ok(None)
    }

    /// Decodes the first `take` frames of the read buffer into `out`, timed by `a` and moved
    /// back by the filter delay: drops the frames still settling, and in the 4 kHz mode the
    /// repeated ones. Returns the samples written, the settling frames dropped and, if a
    /// repeated frame did not match, its index.
    fn decode_frames(
        &mut self,
        config: &Config,
        take: usize,
        a: &timing::Assignment,
        out: &mut [RawImuSample],
    ) -> (usize, usize, Option<usize>) {
        let frame = config.frame_len();
        let skip = self.skip_frames.min(take);
        self.skip_frames -= skip;
        self.stats.settling_discarded += skip as u64;
        let delay = config.filter_delay_ns() as f64;
        let temp = self.temp_counts;
        let buf = &self.buf[..take * frame];
        let mut n = 0;
        // Frame `i`, stamped `back` frames earlier (a lone second copy: its first copy was
        // written one frame before).
        let mut emit = |i: usize, back: usize| {
            let t = a.first_ns + (i as f64 - back as f64) * a.step_ns - delay;
            out[n] = decode(config, &buf[i * frame..(i + 1) * frame], t, temp);
            n += 1;
        };
        let mismatch = if config.frames_per_sample() == 2 {
            let mut kept = 0u64;
            let bad = self.pairing.select(&buf[skip * frame..], |i, lone| {
                kept += 1;
                emit(skip + i, usize::from(lone));
            });
            let looked_at = bad.unwrap_or(take - skip) as u64;
            self.stats.duplicates += looked_at - kept;
            bad.map(|i| skip + i)
        } else {
            (skip..take).for_each(|i| emit(i, 0));
            None
        };
        (n, skip, mismatch)
    }

    /// Empties the FIFO (keeping it enabled) and clears a stale overflow flag (a full FIFO keeps
    /// raising it until the reset); `discarded` samples are known lost with it. The next sample
    /// is flagged as following a gap and re-anchors the sample times.
    fn reset_fifo(&mut self, config: Config, discarded: u64) -> Result<(), Error<I2C::Error>> {
        self.start_fifo(config)?;
        let mut status = [0u8; 1];
        self.read_registers(reg::INT_STATUS, &mut status, "clearing INT_STATUS")?;
        self.stats.fifo_resets += 1;
        self.pending_flags |= raw_flags::GAP_BEFORE;
        self.pending_discarded += discarded;
        self.timer.resync();
        Ok(())
    }

    /// Writes one register (retried).
    fn write_register(
        &mut self,
        register: u8,
        value: u8,
        during: &'static str,
    ) -> Result<(), Error<I2C::Error>> {
        let address = self.address;
        let r = attempt(
            &mut self.i2c,
            &mut self.stats,
            |_| true,
            |i2c| i2c.write(address, &[register, value]),
        );
        r.map_err(|e| self.persistent(during, e))
    }

    /// Reads consecutive registers from `register` in one transaction (retried).
    fn read_registers(
        &mut self,
        register: u8,
        buf: &mut [u8],
        during: &'static str,
    ) -> Result<(), Error<I2C::Error>> {
        let address = self.address;
        let r = attempt(
            &mut self.i2c,
            &mut self.stats,
            |_| true,
            |i2c| i2c.write_read(address, &[register], buf),
        );
        r.map_err(|e| self.persistent(during, e))
    }

    /// A failure that survived the retries: the device needs re-initialising.
    fn persistent(&mut self, during: &'static str, error: I2C::Error) -> Error<I2C::Error> {
        self.needs_init = true;
        self.bus_error(during, error)
    }

    fn bus_error(&self, during: &'static str, error: I2C::Error) -> Error<I2C::Error> {
        Error::Bus {
            bus: self.bus.clone(),
            address: self.address,
            during,
            error,
        }
    }
}

/// Builds a sample (without `seq`) from one FIFO frame taken at `t_ns`; in accelerometer-only
/// mode `temp_counts` is the latest TEMP_OUT read, if any.
fn decode(config: &Config, frame: &[u8], t_ns: f64, temp_counts: Option<i16>) -> RawImuSample {
    let be = |i: usize| i16::from_be_bytes([frame[2 * i], frame[2 * i + 1]]);
    let mut s = RawImuSample::default();
    s.stamps.sample_ns = t_ns.max(0.0).round() as u64;
    s.accel_counts = [be(0), be(1), be(2)];
    s.accel_g = s
        .accel_counts
        .map(|c| f64::from(c) / config.accel_range.lsb_per_g());
    let mut saturated = s.accel_counts.iter().any(|&c| is_saturated(c));
    let temp = match config.mode {
        OutputMode::Imu { .. } => {
            s.gyro_counts = [be(4), be(5), be(6)];
            s.gyro_dps = s
                .gyro_counts
                .map(|c| f64::from(c) / config.gyro_range.lsb_per_dps());
            saturated |= s.gyro_counts.iter().any(|&c| is_saturated(c));
            s.flags |= raw_flags::GYRO_VALID;
            Some(be(3))
        }
        OutputMode::Accel4kHz => temp_counts,
    };
    if let Some(t) = temp {
        s.temp_counts = t;
        s.temp_c = temp_c_from_counts(t);
        s.flags |= raw_flags::TEMP_VALID;
    }
    if saturated {
        // Which axes: an output at -32768 or +32767 counts is the end of the range
        // `ACCEL_FS_SEL`/`GYRO_FS_SEL` set (register map RM-MPU-9250A-00 rev 1.6, registers
        // 27-28; Linux drivers/iio/imu/inv_mpu6050 scales the same 16-bit words).
        let clipped = range::clipped_axes_from_counts(&s);
        range::mark_clipped(&mut s, clipped);
    }
    s
}

/// Whether an error is the address not being acknowledged: nothing was transferred, so any
/// transaction (even a FIFO read) can be repeated safely.
fn is_address_nack(kind: ErrorKind) -> bool {
    kind == ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address)
}

/// Runs the transaction `f` up to [`ATTEMPTS`] times while it fails with an error that
/// `retryable` accepts; counts failures and retries in `stats`. Returns the last error.
fn attempt<I2C: I2c>(
    i2c: &mut I2C,
    stats: &mut DriverStats,
    retryable: impl Fn(ErrorKind) -> bool,
    mut f: impl FnMut(&mut I2C) -> Result<(), I2C::Error>,
) -> Result<(), I2C::Error> {
    let mut tries = 1;
    loop {
        match f(i2c) {
            Ok(()) => return Ok(()),
            Err(e) => {
                stats.bus_errors += 1;
                if tries == ATTEMPTS || !retryable(e.kind()) {
                    return Err(e);
                }
                stats.retries += 1;
                tries += 1;
            }
        }
    }
}
