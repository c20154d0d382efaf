//! Benchmark of the acquisition loop on the simulated MPU-9250 with the 400 kHz I2C timing
//! model (1 kHz and below) or the SPI model (4 kHz, which I2C cannot carry): a virtual clock
//! runs the device for 60 s of sensor time per configuration while the host measures how much
//! CPU the driver and the loop need.
//!
//! `cargo bench -p acquire --bench acquire_loop`
//!
//! Reported per configuration: samples/s sustained (in sensor time), bus utilisation (busy time
//! over elapsed time under the timing model), host CPU per sample (thread CPU time, so the
//! figure does not depend on what else the machine runs), and drops (samples lost, overflows).

use std::time::Duration;

use acquire::acquisition::{Acquisition, config_for_rate, default_read_interval_ns};
use acquire::clock::{Clock, SimClock};
use acquire::driver::{Config, Mpu9250};
use acquire::registers as reg;
use acquire::sim::{SimConfig, SimMpu9250};
use embedded_hal::i2c::I2c;
use mems_sim::SimSensor;
use mems_sim::model::SensorModel;
use mems_sim::scenario::{Drive, DriveParams};
use mems_sim::vibration::VibrationModel;

fn thread_cpu() -> Duration {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: a valid, writable timespec; CLOCK_THREAD_CPUTIME_ID is supported on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    assert_eq!(rc, 0);
    Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

/// Runs `seconds` of sensor time at `rate_hz`, reading every `read_interval_ms` (default: the
/// loop's default for the rate).
fn run(rate_hz: u32, read_interval_ms: Option<f64>, seconds: u64) {
    let mut params = DriveParams::new(seconds as f64 + 10.0);
    params.turns = true;
    let drive = Drive::new(&params, 7).expect("drive");
    let sensor = SimSensor::new(
        drive,
        &SensorModel::mpu9250_datasheet(),
        &VibrationModel::moderate(1.0),
        7,
    )
    .expect("sensor");
    let clock = SimClock::new_virtual(1_000_000_000);
    let device = SimMpu9250::new(sensor, clock.clone(), SimConfig::default());
    let config = config_for_rate(rate_hz, None).unwrap();
    let interval_ns =
        read_interval_ms.map_or_else(|| default_read_interval_ns(&config), |ms| (ms * 1e6) as u64);
    if rate_hz > 1000 {
        let driver = Mpu9250::new_spi(device, "sim-spi");
        measure(driver, clock, config, interval_ns, seconds, "SPI", |d| {
            d.i2c().inner().bus_utilisation()
        });
    } else {
        let driver = Mpu9250::new(device, "sim", reg::ADDRESS_AD0_LOW);
        measure(driver, clock, config, interval_ns, seconds, "I2C", |d| {
            d.i2c().bus_utilisation()
        });
    }
}

/// Runs the loop on `driver`; `utilisation` reads the simulated bus's utilisation.
fn measure<B: I2c>(
    driver: Mpu9250<B>,
    clock: SimClock,
    config: Config,
    interval_ns: u64,
    seconds: u64,
    bus: &str,
    utilisation: impl Fn(&Mpu9250<B>) -> f64,
) {
    let rate_hz = config.output_rate_hz();
    let mut acq = Acquisition::start(driver, clock.clone(), config, interval_ns).expect("start");
    let t0 = clock.now_ns();
    let cpu0 = thread_cpu();
    let mut publish = |_: &ipc_types::RawImuSample| -> Result<(), ()> { Ok(()) };
    while clock.now_ns() - t0 < seconds * 1_000_000_000 {
        let due = acq.next_read_ns();
        clock.advance(due.saturating_sub(clock.now_ns()));
        acq.read_and_publish(&mut publish).unwrap().expect("read");
    }
    let cpu = thread_cpu() - cpu0;
    let elapsed_s = (clock.now_ns() - t0) as f64 * 1e-9;
    let stats = acq.stats();
    let drv = acq.driver().stats();
    let util = utilisation(acq.driver());
    println!(
        "{rate_hz:>5} Hz over {bus}, read every {:.2} ms: {:.1} samples/s sustained over {elapsed_s:.0} s, \
         bus utilisation {:.1} %, host CPU {:.2} us/sample, lost {}, overflows {}, reads {}",
        interval_ns as f64 * 1e-6,
        stats.published as f64 / elapsed_s,
        100.0 * util,
        cpu.as_secs_f64() * 1e6 / stats.published as f64,
        drv.lost_samples,
        drv.overflows,
        stats.reads,
    );
}

fn main() {
    // `cargo bench` passes --bench; nothing to parse.
    run(4000, None, 60);
    run(4000, Some(5.0), 60);
    run(4000, Some(8.0), 60);
    run(1000, None, 60);
    run(200, Some(20.0), 60);
}
