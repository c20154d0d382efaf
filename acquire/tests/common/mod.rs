//! Helpers shared by the integration tests: a small noisy sample source (independent of the
//! `mems-sim` error model) and raw register access to the simulated device.

#![allow(dead_code)] // each test binary uses a different subset

use acquire::clock::SimClock;
use acquire::sim::{ProducedSample, SimConfig, SimMpu9250};
use embedded_hal::i2c::I2c;
use mems_sim::{AnalogSample, SampleSource};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Constant inputs plus white Gaussian noise of a fixed per-sample standard deviation.
pub struct NoisySource {
    rng: ChaCha8Rng,
    pub accel_g: [f64; 3],
    pub gyro_dps: [f64; 3],
    pub temp_c: f64,
    pub accel_std_g: f64,
    pub gyro_std_dps: f64,
}

impl NoisySource {
    /// Level, z up, a slow rotation about z, 30 degC; noise of about 300 counts at +-2 g and
    /// 130 counts at +-250 deg/s, so consecutive samples differ in their high bytes often.
    pub fn new(seed: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            accel_g: [0.02, -0.03, 1.0],
            gyro_dps: [0.5, -1.0, 10.0],
            temp_c: 30.0,
            accel_std_g: 0.02,
            gyro_std_dps: 1.0,
        }
    }
}

impl SampleSource for NoisySource {
    fn sample(&mut self, _t_s: f64, _rate_hz: f64) -> AnalogSample {
        let a = Normal::new(0.0, self.accel_std_g).unwrap();
        let g = Normal::new(0.0, self.gyro_std_dps).unwrap();
        AnalogSample {
            accel_g: self.accel_g.map(|x| x + a.sample(&mut self.rng)),
            gyro_dps: self.gyro_dps.map(|x| x + g.sample(&mut self.rng)),
            temp_c: self.temp_c,
        }
    }
}

/// The simulated device's configuration for a [`NoisySource`]: the source's white noise per
/// output sample is not passed through the DLPF (`model_dlpf: false`; the source models no
/// filter). The tests that use it check the bus, the FIFO, the registers and the sample
/// times, which the filter does not change; `sim_dlpf.rs` and the tests with `SimSensor`
/// check the filtered samples.
pub fn white_config() -> SimConfig {
    SimConfig {
        model_dlpf: false,
        ..SimConfig::default()
    }
}

/// A simulated device at 0x68 on a virtual clock starting at 1 s, keeping `history` samples.
pub fn noisy_sim(seed: u64, history: usize) -> SimMpu9250<NoisySource> {
    SimMpu9250::new(
        NoisySource::new(seed),
        SimClock::new_virtual(1_000_000_000),
        SimConfig {
            history_len: history,
            ..white_config()
        },
    )
}

/// Writes one register (one transaction).
pub fn write_reg<B: I2c>(bus: &mut B, address: u8, register: u8, value: u8) {
    bus.write(address, &[register, value])
        .expect("register write");
}

/// Reads `buf.len()` registers from `register` in one transaction.
pub fn read_regs<B: I2c>(bus: &mut B, address: u8, register: u8, buf: &mut [u8]) {
    bus.write_read(address, &[register], buf)
        .expect("register read");
}

/// Big-endian i16 at byte `i` of `b`.
pub fn be16(b: &[u8], i: usize) -> i16 {
    i16::from_be_bytes([b[i], b[i + 1]])
}

/// The produced sample with index `index`, from the device's history.
pub fn produced(
    history: &std::collections::VecDeque<ProducedSample>,
    index: u64,
) -> ProducedSample {
    let first = history.front().expect("history is empty").index;
    history[(index - first) as usize]
}
