//! The simulated MPU-9250 driven with raw I2C transactions through its register map (no driver):
//! FIFO statistics against the sensor model through the DLPF the registers select, torn reads, FIFO overflow in both modes, reset,
//! addressing, the bus timing model and fault injection.

mod common;

use acquire::clock::{Clock, SimClock};
use acquire::registers as reg;
use acquire::sim::{BusTiming, Fault, SimConfig, SimMpu9250};
use acquire::spi::SpiRegisters;
use common::{be16, noisy_sim, produced, read_regs, write_reg};
use embedded_hal::i2c::{ErrorKind, I2c, NoAcknowledgeSource};
use ipc_types::units::{TEMP_LSB_PER_DEGC, temp_c_from_counts, temp_counts_from_c};
use mems_sim::SampleSource;
use mems_sim::SimSensor;
use mems_sim::dlpf::{self, Coefficients, Setting};
use mems_sim::model::{SensorModel, ThermalModel, TriadModel};
use mems_sim::scenario::PoseSession;
use mems_sim::vibration::VibrationModel;
use nalgebra::UnitQuaternion;

const A: u8 = reg::ADDRESS_AD0_LOW;

/// Starts the FIFO with raw register writes: reset, wake, the given rate/filter registers and
/// FIFO contents, FIFO_MODE as given. The sample rate (and FIFO rate) is 1 kHz, also with the
/// accelerometer at 4 kHz (accel_fchoice_b): then every fourth accelerometer sample reaches
/// the FIFO.
fn start_fifo<B: I2c>(
    bus: &mut B,
    clock: &SimClock,
    accel_config2: u8,
    fifo_en: u8,
    fifo_mode: u8,
) {
    write_reg(bus, A, reg::PWR_MGMT_1, reg::PWR_MGMT_1_H_RESET);
    clock.advance(reg::STARTUP_MAX_NS);
    write_reg(bus, A, reg::PWR_MGMT_1, reg::CLKSEL_AUTO);
    write_reg(bus, A, reg::CONFIG, fifo_mode | 1); // DLPF_CFG = 1: 1 kHz internal rate
    write_reg(bus, A, reg::SMPLRT_DIV, 0);
    write_reg(bus, A, reg::ACCEL_CONFIG2, accel_config2);
    write_reg(bus, A, reg::FIFO_EN, fifo_en);
    write_reg(
        bus,
        A,
        reg::USER_CTRL,
        reg::USER_CTRL_FIFO_EN | reg::USER_CTRL_FIFO_RST,
    );
}

/// Reads whole frames from the FIFO (count in one transaction, frames in another) every
/// `every_ns` until `n` frames are collected; returns them and the virtual time spent.
fn collect_frames<B: I2c>(
    bus: &mut B,
    clock: &SimClock,
    frame: usize,
    n: usize,
    every_ns: u64,
) -> (Vec<Vec<u8>>, u64) {
    let t0 = clock.now_ns();
    let mut frames = Vec::with_capacity(n);
    let mut buf = [0u8; reg::FIFO_SIZE];
    while frames.len() < n {
        clock.advance(every_ns);
        let mut count = [0u8; 2];
        read_regs(bus, A, reg::FIFO_COUNTH, &mut count);
        let bytes = usize::from(u16::from_be_bytes(count)) / frame * frame;
        assert!(bytes < reg::FIFO_SIZE, "FIFO filled up: read too slowly");
        read_regs(bus, A, reg::FIFO_R_W, &mut buf[..bytes]);
        frames.extend(buf[..bytes].chunks(frame).map(<[u8]>::to_vec));
    }
    frames.truncate(n);
    (frames, clock.now_ns() - t0)
}

/// Mean and (n-1) standard deviation.
fn mean_std(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

/// Checks the sample mean and standard deviation of `counts` against a model mean and the
/// noise the part outputs: white noise of standard deviation `sigma_in` (counts) per internal
/// sample through the DLPF `setting`, read at every internal sample, then quantized to
/// integers. The filtered noise has standard deviation `sigma_in sqrt(K / (1 + K))` and the
/// lag-k autocorrelation of `mems_sim::dlpf::Coefficients` (closed forms tested in mems-sim);
/// the tolerances are 5 standard errors of each estimator for correlated samples:
/// `sigma sqrt(sum_k rho_k / n)` for the mean and `sigma sqrt(sum_k rho_k^2 / (2 n))` for the
/// standard deviation (sums over all lags, negative ones included; the quantization noise,
/// variance 1/12, is white).
fn assert_matches_model(
    name: &str,
    counts: &[f64],
    model_mean: f64,
    sigma_in: f64,
    setting: &Setting,
) {
    let c = Coefficients::new(setting);
    let filtered_var = sigma_in * sigma_in * c.noise_variance_ratio();
    let expected_var = filtered_var + 1.0 / 12.0;
    let expected_std = expected_var.sqrt();
    // Correlation of the quantized samples: the filtered part's scaled by its share.
    let rho = |k: u32| c.autocorrelation(k) * filtered_var / expected_var;
    let (mut sum_rho, mut sum_rho2) = (1.0, 1.0);
    for k in 1..10_000 {
        sum_rho += 2.0 * rho(k);
        sum_rho2 += 2.0 * rho(k).powi(2);
    }
    let n = counts.len() as f64;
    let (mean, std) = mean_std(counts);
    let mean_tol = 5.0 * expected_std * (sum_rho / n).sqrt();
    let std_tol = 5.0 * expected_std * (sum_rho2 / (2.0 * (n - 1.0))).sqrt();
    assert!(
        (mean - model_mean).abs() < mean_tol,
        "{name}: mean {mean:.3} counts, model {model_mean:.3} +- {mean_tol:.3}"
    );
    assert!(
        (std - expected_std).abs() < std_tol,
        "{name}: std {std:.3} counts, model {expected_std:.3} +- {std_tol:.3}"
    );
}

/// A level, still sensor with constant biases, white noise at the datasheet densities and a
/// constant 30 degC die (the `mems-sim` error model, every other term off).
fn static_sensor() -> (SimSensor<PoseSession>, [f64; 3], [f64; 3]) {
    let accel_bias = [0.010, -0.020, 0.030];
    let gyro_bias = [1.0, -2.0, 0.5];
    let model = SensorModel {
        accel: TriadModel {
            bias: accel_bias,
            noise_density: [300e-6; 3],
            ..TriadModel::ideal()
        },
        gyro: TriadModel {
            bias: gyro_bias,
            noise_density: [0.01; 3],
            ..TriadModel::ideal()
        },
        thermal: ThermalModel {
            ambient_c: 30.0,
            reference_c: 30.0,
            ..ThermalModel::constant_25c()
        },
    };
    let g = ipc_types::units::STANDARD_GRAVITY_MPS2;
    let scenario = PoseSession::static_pose(UnitQuaternion::identity(), 1000.0, g).unwrap();
    let sensor = SimSensor::new(scenario, &model, &VibrationModel::moderate(0.0), 11).unwrap();
    // Level, z up: the true specific force is +1 g on z, the true rate zero.
    let accel_mean = [accel_bias[0], accel_bias[1], 1.0 + accel_bias[2]];
    (sensor, accel_mean, gyro_bias)
}

#[test]
fn fifo_data_match_the_sensor_model_at_1khz_accel_temp_gyro() {
    let (sensor, accel_mean_g, gyro_mean_dps) = static_sensor();
    let clock = SimClock::new_virtual(0);
    let mut dev = SimMpu9250::new(sensor, clock.clone(), SimConfig::default());
    let all = reg::FIFO_EN_ACCEL
        | reg::FIFO_EN_TEMP
        | reg::FIFO_EN_GYRO_X
        | reg::FIFO_EN_GYRO_Y
        | reg::FIFO_EN_GYRO_Z;
    start_fifo(&mut dev, &clock, 1, all, reg::CONFIG_FIFO_MODE); // ±2 g, ±250 deg/s (reset values)
    let n = 20_000;
    let (frames, elapsed) = collect_frames(&mut dev, &clock, 14, n, 10_000_000);
    // 1 kHz: n frames take n ms (plus less than one read interval).
    let rate = n as f64 / (elapsed as f64 * 1e-9);
    assert!((rate - 1000.0).abs() < 1000.0 * 0.01, "rate {rate} Hz");

    // The noise is drawn per internal sample (1 kHz, the output rate here) and filtered by
    // DLPF_CFG = A_DLPF_CFG = 1 (gyro 184 Hz, accel 218.1 Hz).
    let per_sample = |density: f64| density * 1000f64.sqrt(); // mems-sim: N sqrt(rate)
    for axis in 0..3 {
        let a: Vec<f64> = frames
            .iter()
            .map(|f| f64::from(be16(f, 2 * axis)))
            .collect();
        assert_matches_model(
            &format!("accel {axis}"),
            &a,
            accel_mean_g[axis] * 16384.0,
            per_sample(300e-6) * 16384.0,
            &dlpf::ACCEL_DLPF[1],
        );
        let g: Vec<f64> = frames
            .iter()
            .map(|f| f64::from(be16(f, 8 + 2 * axis)))
            .collect();
        assert_matches_model(
            &format!("gyro {axis}"),
            &g,
            gyro_mean_dps[axis] * 131.0,
            per_sample(0.01) * 131.0,
            &dlpf::GYRO_DLPF[1],
        );
    }
    // The die is at a constant 30 degC: every TEMP_OUT is the datasheet formula's value.
    let expected_counts = ((30.0 - 21.0) * TEMP_LSB_PER_DEGC).round() as i16;
    assert!(frames.iter().all(|f| be16(f, 6) == expected_counts));
    let t = temp_c_from_counts(expected_counts);
    assert!(
        (t - 30.0).abs() <= 0.5 / TEMP_LSB_PER_DEGC,
        "temperature {t} degC"
    );
}

#[test]
fn fifo_data_match_the_sensor_model_at_4khz_accel_only() {
    let (sensor, accel_mean_g, _) = static_sensor();
    let clock = SimClock::new_virtual(0);
    let sim = SimMpu9250::new(sensor, clock.clone(), SimConfig::default());
    // 48 kB/s of FIFO data: over SPI (a 400 kHz I2C bus cannot carry them).
    let mut dev = SpiRegisters::new(sim);
    start_fifo(
        &mut dev,
        &clock,
        reg::ACCEL_FCHOICE_B,
        reg::FIFO_EN_ACCEL,
        reg::CONFIG_FIFO_MODE,
    );
    // DLPF_CFG = 0: an 8 kHz sample rate, so every 4 kHz accelerometer sample reaches the FIFO,
    // each twice in a row.
    write_reg(&mut dev, A, reg::CONFIG, reg::CONFIG_FIFO_MODE);
    write_reg(
        &mut dev,
        A,
        reg::USER_CTRL,
        reg::USER_CTRL_FIFO_EN | reg::USER_CTRL_FIFO_RST,
    );
    let n = 80_000;
    let (all, elapsed) = collect_frames(&mut dev, &clock, 6, n, 5_000_000);
    let rate = n as f64 / (elapsed as f64 * 1e-9);
    assert!((rate - 8000.0).abs() < 8000.0 * 0.01, "FIFO rate {rate} Hz");
    let phase = usize::from(all[0] != all[1]);
    let frames: Vec<Vec<u8>> = all[phase..]
        .chunks_exact(2)
        .map(|pair| {
            assert_eq!(pair[0], pair[1], "every sample is written twice");
            pair[0].clone()
        })
        .collect();
    assert!(frames.windows(2).filter(|w| w[0] == w[1]).count() < 10);
    assert_eq!(dev.inner().stats().spi_overspeed, 0);
    // Every 4 kHz accelerometer sample, through the bypassed accelerometer's filter.
    let sigma = 300e-6 * 4000f64.sqrt() * 16384.0;
    for (axis, mean_g) in accel_mean_g.iter().enumerate() {
        let a: Vec<f64> = frames
            .iter()
            .map(|f| f64::from(be16(f, 2 * axis)))
            .collect();
        assert_matches_model(
            &format!("accel {axis}"),
            &a,
            mean_g * 16384.0,
            sigma,
            &dlpf::ACCEL_BYPASS,
        );
    }
}

/// Reads ACCEL_XOUT 2000 times, either high and low byte in two transactions or both in one,
/// with a varying pause before each read; returns how many values match none of the samples
/// the data registers held during the read.
fn torn_reads(split: bool) -> usize {
    let mut dev = noisy_sim(3, 100_000);
    let clock = dev.clock().clone();
    write_reg(&mut dev, A, reg::ACCEL_CONFIG2, reg::ACCEL_FCHOICE_B); // 4 kHz
    clock.advance(1_000_000);
    let mut torn = 0;
    for i in 0..2000u64 {
        clock.advance(37_000 * (i % 7));
        let mut b = [0u8; 2];
        if split {
            read_regs(&mut dev, A, reg::ACCEL_XOUT_H, &mut b[..1]);
            let first = dev.samples_produced() - 1;
            read_regs(&mut dev, A, reg::ACCEL_XOUT_H + 1, &mut b[1..]);
            let last = dev.samples_produced() - 1;
            let value = i16::from_be_bytes(b);
            let consistent = (first..=last).any(|k| produced(dev.history(), k).accel[0] == value);
            torn += usize::from(!consistent);
        } else {
            read_regs(&mut dev, A, reg::ACCEL_XOUT_H, &mut b);
            let current = produced(dev.history(), dev.samples_produced() - 1);
            torn += usize::from(current.accel[0] != i16::from_be_bytes(b));
        }
    }
    torn
}

#[test]
fn separate_transactions_tear_and_burst_reads_never_do() {
    let split = torn_reads(true);
    // The two reads straddle a sample update about half of the time, and the high bytes of
    // consecutive samples (300 counts of noise) differ often: hundreds of torn values.
    assert!(
        split > 200,
        "only {split} torn values out of 2000 split reads"
    );
    assert_eq!(torn_reads(false), 0);
}

#[test]
fn overwrite_mode_keeps_the_newest_bytes_and_misaligns_frames() {
    let mut dev = noisy_sim(5, 10_000);
    let clock = dev.clock().clone();
    start_fifo(
        &mut dev,
        &clock,
        reg::ACCEL_FCHOICE_B,
        reg::FIFO_EN_ACCEL,
        0,
    );
    let first_index = dev.samples_produced();
    clock.advance(200_000_000); // 200 samples of 6 bytes: 1200 bytes into 512
    // Stop FIFO writes (samples due so far are written first), keeping the contents.
    write_reg(&mut dev, A, reg::USER_CTRL, 0);
    let last = dev.samples_produced() - 1;
    let mut status = [0u8; 1];
    read_regs(&mut dev, A, reg::INT_STATUS, &mut status);
    assert_ne!(status[0] & reg::INT_STATUS_FIFO_OFLOW, 0);
    read_regs(&mut dev, A, reg::INT_STATUS, &mut status);
    assert_eq!(
        status[0] & reg::INT_STATUS_FIFO_OFLOW,
        0,
        "INT_STATUS clears on read"
    );
    let mut count = [0u8; 2];
    read_regs(&mut dev, A, reg::FIFO_COUNTH, &mut count);
    assert_eq!(usize::from(u16::from_be_bytes(count)), reg::FIFO_SIZE);
    let mut fifo = [0u8; reg::FIFO_SIZE];
    read_regs(&mut dev, A, reg::FIFO_R_W, &mut fifo);
    assert!(last - first_index >= 199);
    // 512 = 85 * 6 + 2: the FIFO starts with the last two bytes of an older frame, then the
    // newest 85 whole frames.
    for (i, frame) in fifo[2..].chunks(6).enumerate() {
        let s = produced(dev.history(), last - 84 + i as u64);
        assert_eq!(
            [be16(frame, 0), be16(frame, 2), be16(frame, 4)],
            s.accel,
            "frame {i}"
        );
    }
    let older = produced(dev.history(), last - 85);
    assert_eq!(be16(&fifo, 0), older.accel[2]);
    assert_eq!(
        dev.stats().fifo_bytes_lost,
        6 * (last - first_index + 1) - 512
    );
}

#[test]
fn drop_mode_keeps_the_oldest_bytes() {
    let mut dev = noisy_sim(6, 10_000);
    let clock = dev.clock().clone();
    start_fifo(
        &mut dev,
        &clock,
        reg::ACCEL_FCHOICE_B,
        reg::FIFO_EN_ACCEL,
        reg::CONFIG_FIFO_MODE,
    );
    let first_index = dev.samples_produced();
    clock.advance(100_000_000); // 100 samples of 6 bytes into 512
    let mut fifo = [0u8; reg::FIFO_SIZE + 3];
    read_regs(&mut dev, A, reg::FIFO_R_W, &mut fifo);
    for (i, frame) in fifo[..510].chunks(6).enumerate() {
        assert_eq!(
            [be16(frame, 0), be16(frame, 2), be16(frame, 4)],
            produced(dev.history(), first_index + i as u64).accel
        );
    }
    // The 86th frame got in partially (its X axis), the rest was dropped.
    assert_eq!(
        be16(&fifo, 510),
        produced(dev.history(), first_index + 85).accel[0]
    );
    // Reading past the end repeats the last byte.
    assert_eq!(&fifo[reg::FIFO_SIZE..], &[fifo[reg::FIFO_SIZE - 1]; 3]);
    let mut status = [0u8; 1];
    read_regs(&mut dev, A, reg::INT_STATUS, &mut status);
    assert_ne!(status[0] & reg::INT_STATUS_FIFO_OFLOW, 0);
}

#[test]
fn fifo_count_low_byte_is_latched_by_the_high_byte() {
    let mut dev = noisy_sim(7, 0);
    let clock = dev.clock().clone();
    start_fifo(
        &mut dev,
        &clock,
        reg::ACCEL_FCHOICE_B,
        reg::FIFO_EN_ACCEL,
        reg::CONFIG_FIFO_MODE,
    );
    clock.advance(40_000_000); // 40 samples, 240 bytes
    let mut c = [0u8; 2];
    read_regs(&mut dev, A, reg::FIFO_COUNTH, &mut c);
    let latched = u16::from_be_bytes(c);
    assert_eq!(usize::from(latched), dev.fifo_len());
    clock.advance(40_000_000); // 40 more samples
    read_regs(&mut dev, A, reg::FIFO_COUNTL, &mut c[1..]);
    assert_eq!(
        c[1], latched as u8,
        "FIFO_COUNTL alone returns the latched count"
    );
    read_regs(&mut dev, A, reg::FIFO_COUNTH, &mut c);
    assert_eq!(usize::from(u16::from_be_bytes(c)), dev.fifo_len());
    assert!(dev.fifo_len() > usize::from(latched));
}

#[test]
fn output_rate_follows_the_rate_registers() {
    let mut dev = noisy_sim(8, 0);
    let clock = dev.clock().clone();
    let rate_over_one_second = |dev: &mut SimMpu9250<common::NoisySource>| {
        let mut b = [0u8; 1];
        read_regs(dev, A, reg::WHO_AM_I, &mut b); // catch up
        let before = dev.samples_produced();
        clock.advance(1_000_000_000);
        read_regs(dev, A, reg::WHO_AM_I, &mut b);
        dev.samples_produced() - before
    };
    // Reset values: DLPF_CFG = 0 runs the gyro path at 8 kHz.
    assert_eq!(rate_over_one_second(&mut dev), 8000);
    write_reg(&mut dev, A, reg::CONFIG, 3); // DLPF on: 1 kHz internal
    write_reg(&mut dev, A, reg::SMPLRT_DIV, 4); // / 5
    assert_eq!(rate_over_one_second(&mut dev), 200);
    assert_eq!(dev.output_rate_hz(), Some(200.0));
    // The accelerometer at 4 kHz: the FIFO and data registers still update at the sample
    // rate, each time with a new accelerometer sample (every 20th).
    write_reg(&mut dev, A, reg::ACCEL_CONFIG2, reg::ACCEL_FCHOICE_B);
    assert_eq!(rate_over_one_second(&mut dev), 200);
    assert_eq!(dev.output_rate_hz(), Some(200.0));
    // At the 8 kHz sample rate every accelerometer sample is written twice: 8000 ticks, 4000
    // distinct samples.
    write_reg(&mut dev, A, reg::CONFIG, 0);
    let ticks = dev.sample_ticks();
    // (A one-second window catches 8000 or 8001 ticks of the restarted grid.)
    assert!((4000..=4001).contains(&rate_over_one_second(&mut dev)));
    assert!((8000..=8001).contains(&(dev.sample_ticks() - ticks)));
    write_reg(&mut dev, A, reg::PWR_MGMT_1, reg::PWR_MGMT_1_SLEEP);
    assert_eq!(rate_over_one_second(&mut dev), 0);
    assert_eq!(dev.output_rate_hz(), None);

    // A device whose clock runs 1 % fast.
    let clock = SimClock::new_virtual(0);
    let config = SimConfig {
        rate_error_ppm: 10_000.0,
        ..common::white_config()
    };
    let mut fast = SimMpu9250::new(common::NoisySource::new(1), clock.clone(), config);
    write_reg(&mut fast, A, reg::ACCEL_CONFIG2, reg::ACCEL_FCHOICE_B);
    let before = fast.samples_produced();
    clock.advance(1_000_000_000);
    write_reg(&mut fast, A, reg::SMPLRT_DIV, 0);
    assert_eq!(fast.samples_produced() - before, 4040);
    // And one 8 % slow, as the internal oscillator may be.
    let clock = SimClock::new_virtual(0);
    let config = SimConfig {
        rate_error_ppm: -80_000.0,
        ..common::white_config()
    };
    let mut slow = SimMpu9250::new(common::NoisySource::new(1), clock.clone(), config);
    write_reg(&mut slow, A, reg::CONFIG, 1);
    let before = slow.samples_produced();
    clock.advance(1_000_000_000);
    write_reg(&mut slow, A, reg::SMPLRT_DIV, 0);
    assert_eq!(slow.samples_produced() - before, 920);
}

#[test]
fn h_reset_restores_defaults_after_the_startup_time() {
    let mut dev = noisy_sim(9, 0);
    let clock = dev.clock().clone();
    start_fifo(
        &mut dev,
        &clock,
        reg::ACCEL_FCHOICE_B,
        reg::FIFO_EN_ACCEL,
        reg::CONFIG_FIFO_MODE,
    );
    write_reg(&mut dev, A, reg::ACCEL_CONFIG, 3 << reg::ACCEL_FS_SEL_SHIFT);
    clock.advance(5_000_000);
    dev.update();
    assert!(dev.fifo_len() > 0);
    write_reg(&mut dev, A, reg::PWR_MGMT_1, reg::PWR_MGMT_1_H_RESET);
    let mut b = [0u8; 1];
    assert_eq!(
        dev.write_read(A, &[reg::WHO_AM_I], &mut b),
        Err(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address)),
        "the device ignores its address during start-up"
    );
    clock.advance(reg::STARTUP_TYPICAL_NS);
    let mut regs = [0u8; 3];
    read_regs(&mut dev, A, reg::USER_CTRL, &mut regs);
    assert_eq!(regs, [0, reg::PWR_MGMT_1_RESET_VALUE, 0]);
    for r in [
        reg::SMPLRT_DIV,
        reg::CONFIG,
        reg::GYRO_CONFIG,
        reg::ACCEL_CONFIG,
        reg::ACCEL_CONFIG2,
        reg::FIFO_EN,
    ] {
        read_regs(&mut dev, A, r, &mut b);
        assert_eq!(b[0], 0, "register {r:#04x} after H_RESET");
    }
    read_regs(&mut dev, A, reg::WHO_AM_I, &mut b);
    assert_eq!(b[0], 0x71);
    assert_eq!(dev.fifo_len(), 0);
}

#[test]
fn data_registers_are_big_endian_counts_of_the_configured_range() {
    let mut dev = noisy_sim(10, 10);
    write_reg(&mut dev, A, reg::ACCEL_CONFIG, 2 << reg::ACCEL_FS_SEL_SHIFT); // ±8 g
    write_reg(&mut dev, A, reg::GYRO_CONFIG, 1 << reg::GYRO_FS_SEL_SHIFT); // ±500 deg/s
    dev.clock().advance(1_000_000);
    let mut b = [0u8; 14];
    read_regs(&mut dev, A, reg::ACCEL_XOUT_H, &mut b);
    let s = *dev.history().back().unwrap();
    assert_eq!([be16(&b, 0), be16(&b, 2), be16(&b, 4)], s.accel);
    assert_eq!(be16(&b, 6), s.temp);
    assert_eq!([be16(&b, 8), be16(&b, 10), be16(&b, 12)], s.gyro);
    // z reads about 1 g = 4096 counts at ±8 g (noise 0.02 g = 82 counts), yaw rate 10 deg/s =
    // 655 counts at 65.5 LSB/(deg/s) (noise 1 deg/s = 66 counts).
    assert!(
        (f64::from(s.accel[2]) - 4096.0).abs() < 6.0 * 82.0,
        "{:?}",
        s.accel
    );
    assert!(
        (f64::from(s.gyro[2]) - 655.0).abs() < 6.0 * 66.0,
        "{:?}",
        s.gyro
    );
    assert_eq!(s.temp, temp_counts_from_c(30.0));
}

#[test]
fn full_scale_saturates() {
    struct Huge;
    impl SampleSource for Huge {
        fn sample(&mut self, _: f64, _: f64) -> mems_sim::AnalogSample {
            mems_sim::AnalogSample {
                accel_g: [3.0, -3.0, 0.5],
                gyro_dps: [300.0, -300.0, 0.0],
                temp_c: 25.0,
            }
        }

        /// A constant input leaves the DLPF unchanged (unit gain at DC, started in its steady
        /// state), so the filter the registers select needs no modelling here.
        fn set_dlpf(&mut self, _grid: Option<mems_sim::DlpfGrid>) {}
    }
    let clock = SimClock::new_virtual(0);
    let mut dev = SimMpu9250::new(Huge, clock.clone(), SimConfig::default());
    clock.advance(1_000_000);
    let mut b = [0u8; 14];
    read_regs(&mut dev, A, reg::ACCEL_XOUT_H, &mut b);
    assert_eq!(
        [be16(&b, 0), be16(&b, 2), be16(&b, 4)],
        [i16::MAX, i16::MIN, 8192]
    );
    assert_eq!([be16(&b, 8), be16(&b, 10)], [i16::MAX, i16::MIN]);
}

#[test]
fn only_the_configured_address_answers() {
    let clock = SimClock::new_virtual(0);
    let config = SimConfig {
        address: reg::ADDRESS_AD0_HIGH,
        who_am_i: 0x70,
        ..common::white_config()
    };
    let mut dev = SimMpu9250::new(common::NoisySource::new(1), clock, config);
    let mut b = [0u8; 1];
    let nack = Err(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address));
    assert_eq!(dev.write_read(0x68, &[reg::WHO_AM_I], &mut b), nack);
    dev.write_read(0x69, &[reg::WHO_AM_I], &mut b).unwrap();
    assert_eq!(b[0], 0x70, "the configured (wrong) WHO_AM_I");
    dev.set_present(false);
    assert_eq!(dev.write_read(0x69, &[reg::WHO_AM_I], &mut b), nack);
    assert_eq!(dev.stats().errors, 2);
}

#[test]
fn transactions_take_their_i2c_time_and_count_towards_utilisation() {
    let mut dev = noisy_sim(12, 0);
    let clock = dev.clock().clone();
    let bit_ns = 2_500; // 400 kHz
    let t0 = clock.now_ns();
    // START, address+W, register, repeated START, address+R, 6 bytes, STOP = 30 + 54 periods.
    let mut b = [0u8; 6];
    read_regs(&mut dev, A, reg::ACCEL_XOUT_H, &mut b);
    assert_eq!(clock.now_ns() - t0, 84 * bit_ns + 1_300);
    assert_eq!(BusTiming::register_read_periods(6), 84);
    // START, address+W, register, value, STOP = 29 periods.
    let t1 = clock.now_ns();
    write_reg(&mut dev, A, reg::SMPLRT_DIV, 1);
    assert_eq!(clock.now_ns() - t1, 29 * bit_ns + 1_300);
    // A NACKed address: START, address, STOP.
    let t2 = clock.now_ns();
    assert!(dev.write(0x42, &[0]).is_err());
    assert_eq!(clock.now_ns() - t2, 11 * bit_ns + 1_300);
    let busy = (84 + 29 + 11) * bit_ns + 3 * 1_300;
    assert_eq!(dev.stats().busy_ns, busy);
    clock.advance(busy); // idle as long as busy: half the time
    assert!((dev.bus_utilisation() - 0.5).abs() < 1e-9);
}

#[test]
fn real_time_pacing_sleeps_for_the_transaction() {
    let clock = SimClock::real_time();
    let mut dev = SimMpu9250::new(
        common::NoisySource::new(1),
        clock.clone(),
        common::white_config(),
    );
    let mut buf = [0u8; 400];
    let t0 = clock.now_ns();
    read_regs(&mut dev, A, reg::FIFO_R_W, &mut buf);
    let expected = BusTiming::FAST_MODE.duration_ns(BusTiming::register_read_periods(400));
    assert!(
        clock.now_ns() - t0 >= expected,
        "took {} ns, bus time {expected} ns",
        clock.now_ns() - t0
    );
}

#[test]
fn scheduled_faults_fail_the_chosen_transactions_with_their_side_effects() {
    let mut dev = noisy_sim(13, 0);
    let clock = dev.clock().clone();
    start_fifo(
        &mut dev,
        &clock,
        reg::ACCEL_FCHOICE_B,
        reg::FIFO_EN_ACCEL,
        reg::CONFIG_FIFO_MODE,
    );
    clock.advance(5_000_000); // 20 samples, 120 bytes
    write_reg(&mut dev, A, reg::USER_CTRL, 0); // freeze the FIFO contents
    let before = dev.fifo_len();
    let next = dev.stats().transactions;
    dev.fail_transaction(next, Fault::ADDRESS_NACK);
    dev.fail_transaction(next + 1, Fault::bus_error(5));
    let mut buf = [0u8; 60];
    assert_eq!(
        dev.write_read(A, &[reg::FIFO_R_W], &mut buf),
        Err(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address))
    );
    assert_eq!(dev.fifo_len(), before, "an address NACK has no effect");
    assert_eq!(
        dev.write_read(A, &[reg::FIFO_R_W], &mut buf),
        Err(ErrorKind::Bus)
    );
    // The register pointer and 4 data bytes went through before the bus error.
    assert_eq!(dev.fifo_len(), before - 4);
    dev.write_read(A, &[reg::FIFO_R_W], &mut buf).unwrap();
    assert_eq!(dev.stats().errors, 2);
}

#[test]
fn random_faults_are_seeded_and_occur_at_the_set_probability() {
    let pattern = |seed: u64| {
        let mut dev = noisy_sim(14, 0);
        dev.fail_randomly(0.2, Fault::bus_error(1), seed);
        let mut b = [0u8; 1];
        (0..5000)
            .map(|_| dev.write_read(A, &[reg::WHO_AM_I], &mut b).is_err())
            .collect::<Vec<bool>>()
    };
    let a = pattern(42);
    assert_eq!(a, pattern(42), "same seed, same faults");
    assert_ne!(a, pattern(43));
    let failures = a.iter().filter(|f| **f).count() as f64;
    // Binomial(5000, 0.2): mean 1000, std 28.3.
    assert!(
        (failures - 1000.0).abs() < 5.0 * 28.3,
        "{failures} failures"
    );
}
