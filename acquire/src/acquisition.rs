//! The acquisition loop without I/O of its own: read the FIFO when a read is due, number the
//! samples, stamp their publication time, and hand them to a publish callback. The
//! `mems-acquire` binary wraps it with iceoryx2; tests drive it with a virtual clock.

use embedded_hal::i2c::I2c;
use hdrhistogram::Histogram;
use ipc_types::{RawImuSample, raw_flags};

use crate::clock::Clock;
use crate::driver::{self, Mpu9250};
use crate::registers as reg;
use crate::session::{Resume, Session};

/// Samples one FIFO read can return at most: a full FIFO of the smallest frame (6 bytes).
pub const READ_BUFFER: usize = reg::FIFO_SIZE / 6 + 1;

/// Where the samples come from, as given on the command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SourceSpec {
    /// The simulated MPU-9250 on a simulated 400 kHz I2C bus, paced in real time.
    Sim,
    /// The simulated MPU-9250 on simulated SPI (1 MHz registers, 20 MHz data).
    SimSpi,
    /// A real MPU-9250 on a Linux spidev device.
    Spi {
        /// Device, e.g. `/dev/spidev0.0`.
        device: String,
    },
    /// A real MPU-9250 on a Linux I2C bus.
    I2c {
        /// Bus device, e.g. `/dev/i2c-1`.
        device: String,
        /// 7-bit address (0x68 or 0x69).
        address: u8,
    },
}

impl SourceSpec {
    /// The bus this source's part is read over.
    pub fn bus_kind(&self) -> driver::BusKind {
        match self {
            Self::Sim | Self::I2c { .. } => driver::BusKind::I2C_FAST_MODE,
            Self::SimSpi | Self::Spi { .. } => driver::BusKind::SPI_20MHZ,
        }
    }

    /// Checks that `rate_hz` is a supported rate and that this source's bus can carry it;
    /// the error says why not (with the bus arithmetic) and what to use instead.
    pub fn check_rate(&self, rate_hz: u32) -> Result<driver::Config, String> {
        let config = config_for_rate(rate_hz, None)?;
        self.bus_kind().check(&config)?;
        Ok(config)
    }
}

impl std::str::FromStr for SourceSpec {
    type Err = String;

    /// Parses `sim`, `sim-spi`, `spi:/dev/spidevB.C` or `i2c:/dev/i2c-N[@0xNN]` (address
    /// default 0x68).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "sim" => return Ok(Self::Sim),
            "sim-spi" => return Ok(Self::SimSpi),
            _ => {}
        }
        if let Some(device) = s.strip_prefix("spi:") {
            if device.is_empty() {
                return Err(format!("no SPI device in {s:?}"));
            }
            return Ok(Self::Spi {
                device: device.to_string(),
            });
        }
        let Some(rest) = s.strip_prefix("i2c:") else {
            return Err(format!(
                "unknown source {s:?}: expected `sim`, `sim-spi`, `spi:/dev/spidevB.C` or \
                 `i2c:/dev/i2c-N[@0x68]`"
            ));
        };
        let (device, address) = match rest.split_once('@') {
            Some((device, addr)) => {
                let hex = addr.trim_start_matches("0x").trim_start_matches("0X");
                let address = u8::from_str_radix(hex, 16)
                    .map_err(|e| format!("bad I2C address {addr:?} in {s:?}: {e}"))?;
                (device, address)
            }
            None => (rest, reg::ADDRESS_AD0_LOW),
        };
        if device.is_empty() {
            return Err(format!("no I2C device in {s:?}"));
        }
        if address > 0x7F {
            return Err(format!("I2C address {address:#04x} in {s:?} is not 7-bit"));
        }
        Ok(Self::I2c {
            device: device.to_string(),
            address,
        })
    }
}

/// The driver configuration for an output rate: 4000 Hz is accelerometer-only with the DLPF
/// bypassed; 1000 Hz / n (n = 1..=256) is accelerometer, gyro and temperature through the
/// DLPF with SMPLRT_DIV = n - 1, the setting [`driver::Dlpf::for_rate`] picks for the rate
/// unless `dlpf` overrides it (ignored at 4000 Hz, where the accelerometer bypasses it).
pub fn config_for_rate(rate_hz: u32, dlpf: Option<driver::Dlpf>) -> Result<driver::Config, String> {
    let mode = if rate_hz == 4000 {
        driver::OutputMode::Accel4kHz
    } else if rate_hz > 0 && 1000 % rate_hz == 0 && 1000 / rate_hz <= 256 {
        driver::OutputMode::Imu {
            dlpf: dlpf.unwrap_or_else(|| driver::Dlpf::for_rate(f64::from(rate_hz))),
            divider: (1000 / rate_hz - 1) as u8,
        }
    } else {
        return Err(format!(
            "unsupported rate {rate_hz} Hz: use 4000 (accelerometer only) or 1000/n Hz \
             (1000, 500, 250, 200, ...)"
        ));
    };
    Ok(driver::Config {
        mode,
        ..driver::Config::default()
    })
}

/// The default time between FIFO reads for `config`, ns: an eighth of the time the FIFO takes
/// to fill (1.3 ms at 4 kHz accelerometer-only, whose FIFO fills with 8000 frames/s; 4.5 ms
/// at 1 kHz with 14-byte frames). A read that starts up to seven eighths of the fill time late
/// still finds room in the FIFO, while each read still moves several frames (the fixed cost of
/// a read, INT_STATUS and FIFO_COUNT, is about 0.2 ms of bus time at 400 kHz I2C).
pub fn default_read_interval_ns(config: &driver::Config) -> u64 {
    fifo_fill_ns(config) / 8
}

/// The time the 512-byte FIFO takes to fill from empty for `config`, ns (10.6 ms at 4 kHz
/// accelerometer-only, 36 ms at 1 kHz): the longest the acquisition loop may be away from the
/// sensor, waiting on anything, before samples are lost.
pub fn fifo_fill_ns(config: &driver::Config) -> u64 {
    let frames = reg::FIFO_SIZE / config.frame_len();
    (frames as f64 / config.fifo_rate_hz() * 1e9) as u64
}

/// Counters of the acquisition loop.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LoopStats {
    /// Samples published.
    pub published: u64,
    /// FIFO reads made.
    pub reads: u64,
    /// Reads that returned an error (the driver re-initialises and the loop carries on).
    pub failed_reads: u64,
    /// The latest any read started after its due time, ns (see [`Acquisition::lateness`]).
    pub max_late_ns: u64,
    /// How far the sample times strayed from the acquisition clock, ns: over all reads, the
    /// most the newest sample's FIFO time (sample time plus filter delay) was after its
    /// acquisition time, and the most it was before the read's start minus one FIFO period.
    /// The newest sample was written within one period before the FIFO count was read, which
    /// happens between those two instants (however long the host takes), so both are at most
    /// 0 for correct times; positive values are timing errors. Reads that found the FIFO
    /// overflowed are left out (its newest frames were dropped, so its newest sample is old).
    /// `None` before the first sample.
    pub sample_time_excursion_ns: Option<(i64, i64)>,
    /// When this process continued a sensor session: the first sequence number it published
    /// (the next of the session) and the samples not read while no process ran (its first
    /// sample's `lost_before`).
    pub resumed: Option<(u64, u64)>,
}

/// The acquisition loop's state: the driver, the clock, and a buffer allocated once.
pub struct Acquisition<I2C: I2c, C: Clock> {
    driver: Mpu9250<I2C>,
    clock: C,
    buffer: Vec<RawImuSample>,
    next_seq: u64,
    session: Session,
    /// Where the continued session stood, until the first sample places this process in it.
    resume: Option<Resume>,
    read_interval_ns: u64,
    next_read_ns: u64,
    stats: LoopStats,
    lateness: Histogram<u64>,
}

impl<I2C: I2c, C: Clock> Acquisition<I2C, C> {
    /// Probes and configures the device and prepares the loop; reads are `read_interval_ns`
    /// apart (it must leave the FIFO room: 512 bytes last 10.6 ms at 4 kHz accelerometer-only,
    /// whose FIFO takes 8000 frames/s, and 36 ms at 1 kHz;
    /// see [`default_read_interval_ns`]).
    pub fn start(
        mut driver: Mpu9250<I2C>,
        clock: C,
        config: driver::Config,
        read_interval_ns: u64,
    ) -> Result<Self, driver::Error<I2C::Error>> {
        driver.probe()?;
        driver.init(config, &clock)?;
        let next_read_ns = clock.now_ns() + read_interval_ns;
        let session = Session::transient(clock.now_ns());
        Ok(Self {
            driver,
            clock,
            buffer: vec![RawImuSample::default(); READ_BUFFER],
            next_seq: 0,
            session,
            resume: None,
            read_interval_ns,
            next_read_ns,
            stats: LoopStats::default(),
            // 1 ns to 100 s at 2 significant digits: allocated here, never resized.
            lateness: Histogram::new_with_bounds(1, 100_000_000_000, 2)
                .expect("valid histogram bounds"),
        })
    }

    /// Publishes in `session` (see [`crate::session`]): numbered from where it stands, when it
    /// is continued, else from 0.
    pub fn in_session(mut self, session: Session) -> Self {
        self.resume = session.resume();
        self.session = session;
        self
    }

    /// The time the next read is due, ns on the loop's clock.
    pub fn next_read_ns(&self) -> u64 {
        self.next_read_ns
    }

    /// The loop's clock.
    pub fn clock(&self) -> &C {
        &self.clock
    }

    /// The driver (for its statistics).
    pub fn driver(&self) -> &Mpu9250<I2C> {
        &self.driver
    }

    /// Loop counters.
    pub fn stats(&self) -> LoopStats {
        self.stats
    }

    /// How late each read started after its due time, ns (recorded from 1 ns): the wake-up
    /// latency of the loop, the figure that decides whether the FIFO overflows.
    pub fn lateness(&self) -> &Histogram<u64> {
        &self.lateness
    }

    /// Reads the FIFO now and publishes every sample it held through `publish`, with `seq`
    /// consecutive from 0 and `stamps.acquired_ns` set just before publication. A read error is
    /// counted and returned after the driver has tried to re-initialise; the loop may carry on.
    /// Allocates nothing.
    pub fn read_and_publish<E>(
        &mut self,
        publish: &mut impl FnMut(&RawImuSample) -> Result<(), E>,
    ) -> Result<Result<usize, driver::Error<I2C::Error>>, E> {
        self.stats.reads += 1;
        let due = self.next_read_ns;
        let now = self.clock.now_ns();
        let late = now.saturating_sub(due);
        self.lateness.saturating_record(late.max(1));
        self.stats.max_late_ns = self.stats.max_late_ns.max(late);
        // Keep the read grid; after a long stall, start again from now rather than bursting.
        self.next_read_ns = (due + self.read_interval_ns).max(now);
        let overflows = self.driver.stats().overflows;
        let n = match self.driver.read_samples(&self.clock, &mut self.buffer) {
            Ok(n) => n,
            Err(e) => {
                self.stats.failed_reads += 1;
                return Ok(Err(e));
            }
        };
        let (delay, period) = self.driver.config().map_or((0, 0), |c| {
            (c.filter_delay_ns(), (1e9 / c.fifo_rate_hz()) as i64)
        });
        self.number(n);
        for sample in &mut self.buffer[..n] {
            sample.stamps.acquired_ns = self.clock.now_ns();
            publish(sample)?;
            self.stats.published += 1;
        }
        let newest = self.buffer[..n].last();
        if let Some(newest) = newest.filter(|_| self.driver.stats().overflows == overflows) {
            let written = (newest.stamps.sample_ns + delay) as i64;
            let ahead = written - newest.stamps.acquired_ns as i64;
            let behind = now as i64 - period - written;
            let (a, b) = self
                .stats
                .sample_time_excursion_ns
                .unwrap_or((i64::MIN, i64::MIN));
            self.stats.sample_time_excursion_ns = Some((a.max(ahead), b.max(behind)));
        }
        Ok(Ok(n))
    }

    /// Numbers the first `n` samples of the buffer in the session and notes them in its file
    /// before they are published (a process killed after the note skips numbers, never
    /// reuses one). The first sample of a continued session follows the hole since the
    /// killed process's newest sample: `lost_before` counts the sample periods in it.
    fn number(&mut self, n: usize) {
        let Some(newest_ns) = self.buffer[..n].last().map(|s| s.stamps.sample_ns) else {
            return;
        };
        if let Some(resume) = self.resume.take() {
            let first = &mut self.buffer[0];
            let period_ns = self
                .driver
                .config()
                .map_or(1e6, |c| 1e9 / c.output_rate_hz());
            let hole_ns = first.stamps.sample_ns.saturating_sub(resume.last_sample_ns);
            let lost = ((hole_ns as f64 / period_ns).round() as u64).saturating_sub(1);
            let lost_before = u64::from(first.lost_before) + lost;
            first.lost_before = u32::try_from(lost_before).unwrap_or(u32::MAX);
            first.flags |= raw_flags::GAP_BEFORE | raw_flags::RESUMED;
            self.next_seq = resume.next_seq;
            self.stats.resumed = Some((self.next_seq, lost_before));
        }
        for sample in &mut self.buffer[..n] {
            sample.seq = self.next_seq;
            self.next_seq += 1;
        }
        if let Err(e) = self.session.note(self.next_seq, newest_ns) {
            tracing::warn!("{e}: a restart will not continue this sensor session");
            self.session = Session::transient(self.session.origin_ns());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::SimClock;
    use crate::sim::{SimConfig, SimMpu9250};
    use mems_sim::{AnalogSample, SampleSource};

    /// A part lying still, level.
    struct Still;

    impl SampleSource for Still {
        fn sample(&mut self, _t_s: f64, _rate_hz: f64) -> AnalogSample {
            AnalogSample {
                accel_g: [0.0, 0.0, 1.0],
                ..AnalogSample::default()
            }
        }

        /// A constant input leaves the DLPF unchanged (unit gain at DC, started in its steady
        /// state), so the filter the registers select needs no modelling here.
        fn set_dlpf(&mut self, _grid: Option<mems_sim::DlpfGrid>) {}
    }

    /// Runs 400 reads at 4 kHz over simulated SPI with the default interval on a virtual
    /// clock, the 200th one starting `late_ns` after its due time; returns the loop and driver
    /// counters.
    fn run_with_one_late_read(late_ns: u64) -> (LoopStats, driver::DriverStats, u64) {
        let clock = SimClock::new_virtual(1_000_000_000);
        let device = SimMpu9250::new(Still, clock.clone(), SimConfig::default());
        let drv = Mpu9250::new_spi(device, "sim-spi");
        let config = config_for_rate(4000, None).unwrap();
        let interval = default_read_interval_ns(&config);
        let mut acq = Acquisition::start(drv, clock.clone(), config, interval).unwrap();
        let mut publish = |_: &RawImuSample| Ok::<(), ()>(());
        for k in 0..400 {
            let late = if k == 200 { late_ns } else { 0 };
            clock.sleep_until(acq.next_read_ns() + late);
            acq.read_and_publish(&mut publish).unwrap().unwrap();
        }
        (acq.stats(), acq.driver().stats(), acq.lateness().len())
    }

    #[test]
    fn the_default_interval_leaves_seven_eighths_of_the_fifo_for_lateness() {
        // 512 bytes of 6-byte frames: 85 frames, 10.6 ms at the 8 kHz sample rate; an eighth
        // is 1.33 ms.
        let fill_ns = 85.0 * 125_000.0;
        let config = config_for_rate(4000, None).unwrap();
        assert_eq!(default_read_interval_ns(&config), (fill_ns / 8.0) as u64);
        // 1 kHz, 14-byte frames: 36 samples, 36 ms; an eighth is 4.5 ms.
        assert_eq!(
            default_read_interval_ns(&config_for_rate(1000, None).unwrap()),
            4_500_000
        );
        // A read a quarter millisecond short of 7/8 of the fill time late finds room ...
        let late = (fill_ns * 7.0 / 8.0) as u64 - 250_000;
        let (stats, drv, recorded) = run_with_one_late_read(late);
        assert_eq!((drv.overflows, drv.lost_samples), (0, 0));
        assert!(drv.max_fifo_bytes > 480, "{} bytes", drv.max_fifo_bytes);
        assert_eq!(stats.max_late_ns, late);
        assert_eq!(recorded, 400, "every read's lateness is recorded");
        // ... one a whole fill time late overflows, and the loss is counted and flagged.
        let (_, drv, _) = run_with_one_late_read(fill_ns as u64);
        assert_eq!(drv.overflows, 1);
        assert!(drv.lost_samples > 0);
        assert_eq!(drv.max_fifo_bytes, 512);
    }

    #[test]
    fn accel_4khz_is_refused_over_i2c_with_the_bus_arithmetic() {
        let clock = SimClock::new_virtual(0);
        let device = SimMpu9250::new(Still, clock.clone(), SimConfig::default());
        let drv = Mpu9250::new(device, "sim", reg::ADDRESS_AD0_LOW);
        let config = config_for_rate(4000, None).unwrap();
        let Err(err) = Acquisition::start(drv, clock.clone(), config, 1_000_000) else {
            panic!("4 kHz over I2C was accepted");
        };
        let text = err.to_string();
        for needle in [
            "sim",
            "400 kHz I2C",
            "8000 frames/s",
            "432 kHz",
            "108 %",
            "SPI",
        ] {
            assert!(text.contains(needle), "{needle:?} missing from: {text}");
        }
        // Nothing was sent to the part.
        let device = SimMpu9250::new(Still, clock.clone(), SimConfig::default());
        let mut drv = Mpu9250::new(device, "sim", reg::ADDRESS_AD0_LOW);
        assert!(drv.init(config, &clock).is_err());
        assert_eq!(drv.bus_mut().stats().transactions, 0);
        // 1 kHz with gyro over I2C: 14 B x 9 clocks x 1000/s = 31.5 % of the bus.
        let share =
            driver::BusKind::I2C_FAST_MODE.data_share(&config_for_rate(1000, None).unwrap());
        assert!((share - 0.315).abs() < 1e-12, "{share}");
        assert!(
            drv.init(config_for_rate(1000, None).unwrap(), &clock)
                .is_ok()
        );
    }

    #[test]
    fn parses_sources() {
        assert_eq!("sim".parse(), Ok(SourceSpec::Sim));
        assert_eq!(
            "i2c:/dev/i2c-1".parse(),
            Ok(SourceSpec::I2c {
                device: "/dev/i2c-1".into(),
                address: 0x68
            })
        );
        assert_eq!(
            "i2c:/dev/i2c-3@0x69".parse(),
            Ok(SourceSpec::I2c {
                device: "/dev/i2c-3".into(),
                address: 0x69
            })
        );
        assert_eq!("sim-spi".parse(), Ok(SourceSpec::SimSpi));
        assert_eq!(
            "spi:/dev/spidev0.0".parse(),
            Ok(SourceSpec::Spi {
                device: "/dev/spidev0.0".into()
            })
        );
        for bad in [
            "spi:",
            "sim2",
            "i2c:",
            "i2c:/dev/i2c-1@zz",
            "i2c:/dev/i2c-1@0x80",
        ] {
            assert!(bad.parse::<SourceSpec>().is_err(), "{bad}");
        }
    }

    #[test]
    fn rates_map_to_modes() {
        assert_eq!(
            config_for_rate(4000, None).unwrap().mode,
            driver::OutputMode::Accel4kHz
        );
        assert_eq!(config_for_rate(200, None).unwrap().output_rate_hz(), 200.0);
        assert_eq!(
            config_for_rate(1000, None).unwrap().output_rate_hz(),
            1000.0
        );
        assert!(config_for_rate(3000, None).is_err());
        assert!(config_for_rate(0, None).is_err());
        // The DLPF follows the rate (Linux's rule) unless overridden.
        let imu = |dlpf, divider| driver::OutputMode::Imu { dlpf, divider };
        let mode = |rate, dlpf| config_for_rate(rate, dlpf).unwrap().mode;
        assert_eq!(mode(1000, None), imu(driver::Dlpf::Hz184, 0));
        assert_eq!(mode(200, None), imu(driver::Dlpf::Hz92, 4));
        assert_eq!(mode(100, None), imu(driver::Dlpf::Hz41, 9));
        assert_eq!(mode(50, None), imu(driver::Dlpf::Hz20, 19));
        assert_eq!(
            mode(200, Some(driver::Dlpf::Hz184)),
            imu(driver::Dlpf::Hz184, 4)
        );
        assert_eq!("41".parse::<driver::Dlpf>(), Ok(driver::Dlpf::Hz41));
        assert!("40".parse::<driver::Dlpf>().is_err());
    }
}
