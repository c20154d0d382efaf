//! The MPU-9250 driver against the simulated device: probe, configuration as the register map
//! says, lossless FIFO acquisition at 4 kHz over a 400 kHz bus, sample timing, FIFO overflow,
//! bus errors, re-initialisation, stalls, temperature.

mod common;

use acquire::clock::{Clock, SimClock};
use acquire::driver::{Config, Dlpf, Error, Mpu9250, OutputMode};
use acquire::registers as reg;
use acquire::sim::{Fault, ProducedSample, SimConfig, SimMpu9250};
use common::{NoisySource, noisy_sim};
use ipc_types::RawImuSample;
use ipc_types::raw_flags;
use ipc_types::units::{AccelRange, GyroRange, TEMP_LSB_PER_DEGC};

type SimDriver = Mpu9250<SimMpu9250<NoisySource>>;

const A: u8 = reg::ADDRESS_AD0_LOW;

fn accel_4k() -> Config {
    Config::default()
}

fn imu_1k() -> Config {
    Config {
        mode: OutputMode::Imu {
            dlpf: Dlpf::Hz184,
            divider: 0,
        },
        ..Config::default()
    }
}

/// A driver on a fresh simulated device (keeping `history` samples), initialised with `config`.
fn started(seed: u64, history: usize, config: Config) -> (SimDriver, SimClock) {
    let sim = noisy_sim(seed, history);
    let clock = sim.clock().clone();
    let mut drv = Mpu9250::new(sim, "sim", A);
    drv.init(config, &clock).expect("init");
    (drv, clock)
}

/// Reads every `every_ns` on a fixed schedule for `duration_ns`; returns all samples delivered.
fn read_for(
    drv: &mut SimDriver,
    clock: &SimClock,
    duration_ns: u64,
    every_ns: u64,
) -> Vec<RawImuSample> {
    let mut buf = [RawImuSample::default(); 128];
    let mut out = Vec::new();
    let end = clock.now_ns() + duration_ns;
    let mut next = clock.now_ns();
    while clock.now_ns() < end {
        next += every_ns;
        clock.sleep_until(next);
        let n = drv.read_samples(clock, &mut buf).expect("read_samples");
        out.extend_from_slice(&buf[..n]);
    }
    out
}

/// Whether a delivered sample holds exactly the counts of a produced one (gyro and temperature
/// only where the sample says they are valid).
fn same(s: &RawImuSample, p: &ProducedSample) -> bool {
    s.accel_counts == p.accel
        && (s.flags & raw_flags::GYRO_VALID == 0 || s.gyro_counts == p.gyro)
        && (s.flags & raw_flags::TEMP_VALID == 0 || s.temp_counts == p.temp)
}

/// The history index of each delivered sample, matching them in order (each search starts
/// after the previous match). Panics if a sample matches no produced sample.
fn locate(drv: &mut SimDriver, samples: &[RawImuSample]) -> Vec<u64> {
    let history = drv.bus_mut().history();
    let mut pos = 0;
    samples
        .iter()
        .map(|s| {
            let offset = history
                .range(pos..)
                .position(|p| same(s, p))
                .unwrap_or_else(|| {
                    panic!("sample seq {} matches no produced sample (torn?)", s.seq)
                });
            pos += offset + 1;
            history[pos - 1].index
        })
        .collect()
}

/// True time of produced sample `index`.
fn true_time(drv: &mut SimDriver, index: u64) -> u64 {
    common::produced(drv.bus_mut().history(), index).t_ns
}

#[test]
fn probe_accepts_an_mpu9250() {
    let sim = noisy_sim(1, 0);
    let mut drv = Mpu9250::new(sim, "sim", A);
    drv.probe().unwrap();
    assert_eq!(drv.stats().bus_errors, 0);
}

#[test]
fn probe_names_bus_address_and_value_of_a_wrong_part() {
    let config = SimConfig {
        who_am_i: 0x73, // an MPU-9255
        ..SimConfig::default()
    };
    let sim = SimMpu9250::new(NoisySource::new(1), SimClock::new_virtual(0), config);
    let mut drv = Mpu9250::new(sim, "/dev/i2c-7", A);
    let err = drv.probe().unwrap_err();
    assert!(
        matches!(
            err,
            Error::WrongDevice {
                found: 0x73,
                address: 0x68,
                ..
            }
        ),
        "{err:?}"
    );
    let text = err.to_string();
    for needle in ["/dev/i2c-7", "0x68", "0x73", "0x71", "WHO_AM_I"] {
        assert!(text.contains(needle), "{needle:?} missing from: {text}");
    }
}

#[test]
fn probe_names_bus_and_address_of_an_absent_part() {
    let mut sim = noisy_sim(1, 0);
    sim.set_present(false);
    let mut drv = Mpu9250::new(sim, "sim", A);
    let err = drv.probe().unwrap_err();
    assert!(
        matches!(err, Error::Absent { address: 0x68, .. }),
        "{err:?}"
    );
    assert!(
        err.to_string().contains("sim") && err.to_string().contains("0x68"),
        "{err}"
    );

    // A device at 0x68 probed at 0x69 is absent at 0x69.
    let mut drv = Mpu9250::new(noisy_sim(1, 0), "sim", reg::ADDRESS_AD0_HIGH);
    let err = drv.probe().unwrap_err();
    assert!(err.to_string().contains("0x69"), "{err}");
    assert_eq!(drv.stats().bus_errors, 3, "probe tries three times");
}

#[test]
fn read_before_init_is_an_error() {
    let sim = noisy_sim(1, 0);
    let clock = sim.clock().clone();
    let mut drv = Mpu9250::new(sim, "sim", A);
    let mut buf = [RawImuSample::default(); 4];
    let err = drv.read_samples(&clock, &mut buf).unwrap_err();
    assert!(matches!(err, Error::NotInitialised { .. }), "{err}");
}

#[test]
fn configuration_registers_are_written_as_the_register_map_says() {
    let mut sim = noisy_sim(2, 0);
    let clock = sim.clock().clone();
    // Something a reset must clear: INT_ENABLE (register 56).
    common::write_reg(&mut sim, A, 0x38, 0x55);
    let mut drv = Mpu9250::new(sim, "sim", A);
    let config = Config {
        accel_range: AccelRange::G8,
        gyro_range: GyroRange::Dps1000,
        mode: OutputMode::Imu {
            dlpf: Dlpf::Hz41,
            divider: 4,
        },
        temp_interval_ns: 0,
    };
    drv.init(config, &clock).unwrap();
    let sim = drv.bus_mut();
    let expected = [
        (0x38, 0x00, "INT_ENABLE cleared by H_RESET"),
        (0x6B, 0x01, "PWR_MGMT_1: awake, CLKSEL = 1"),
        (0x6C, 0x00, "PWR_MGMT_2: all axes on"),
        (0x1A, 0x43, "CONFIG: FIFO_MODE (bit 6), DLPF_CFG = 3"),
        (0x19, 0x04, "SMPLRT_DIV = 4"),
        (
            0x1B,
            0x10,
            "GYRO_CONFIG: GYRO_FS_SEL = 2 in bits [4:3], FCHOICE_B = 0",
        ),
        (0x1C, 0x10, "ACCEL_CONFIG: ACCEL_FS_SEL = 2 in bits [4:3]"),
        (
            0x1D,
            0x03,
            "ACCEL_CONFIG2: accel_fchoice_b = 0, A_DLPF_CFG = 3",
        ),
        (0x23, 0xF8, "FIFO_EN: TEMP, GYRO X/Y/Z, ACCEL (bits 7-3)"),
        (0x6A, 0x40, "USER_CTRL: FIFO_EN (bit 6)"),
    ];
    for (register, value, what) in expected {
        assert_eq!(sim.peek(register), value, "{what}");
    }
    assert_eq!(sim.output_rate_hz(), Some(200.0));
    assert_eq!(config.output_rate_hz(), 200.0);

    let config = Config {
        accel_range: AccelRange::G4,
        ..Config::default()
    };
    drv.init(config, &clock).unwrap();
    let sim = drv.bus_mut();
    let expected = [
        (0x6C, 0x07, "PWR_MGMT_2: gyros in standby"),
        (0x1A, 0x41, "CONFIG: FIFO_MODE, DLPF_CFG = 1"),
        (0x1C, 0x08, "ACCEL_CONFIG: ACCEL_FS_SEL = 1"),
        (
            0x1D,
            0x08,
            "ACCEL_CONFIG2: accel_fchoice_b (bit 3): DLPF bypassed",
        ),
        (0x23, 0x08, "FIFO_EN: ACCEL only"),
        (0x6A, 0x40, "USER_CTRL: FIFO_EN"),
    ];
    for (register, value, what) in expected {
        assert_eq!(sim.peek(register), value, "{what}");
    }
    assert_eq!(sim.output_rate_hz(), Some(4000.0));
}

/// Checks a lossless run: every produced sample delivered once, in order, with consecutive
/// sequence numbers, no flags but the validity bits, and times that follow the true sample
/// times at the configured period.
fn assert_lossless_and_on_time(drv: &mut SimDriver, samples: &[RawImuSample], period_ns: f64) {
    let idx = locate(drv, samples);
    for (w, s) in idx.windows(2).zip(samples.windows(2)) {
        assert_eq!(
            w[1],
            w[0] + 1,
            "sample after seq {} skipped produced samples",
            s[0].seq
        );
        assert_eq!(s[1].seq, s[0].seq + 1);
        assert!(
            s[1].stamps.sample_ns > s[0].stamps.sample_ns,
            "time went backwards at seq {}",
            s[1].seq
        );
    }
    let valid = raw_flags::GYRO_VALID | raw_flags::TEMP_VALID;
    assert!(
        samples
            .iter()
            .all(|s| s.flags & !valid == 0 && s.lost_before == 0)
    );
    // After the loop has settled (the first second), every time is within half a period of the
    // truth and every spacing within 10 % of the period.
    let settle = (1e9 / period_ns) as usize;
    let (mut worst_err, mut worst_step) = (0.0f64, 0.0f64);
    for (i, s) in samples.iter().enumerate().skip(settle) {
        let truth = true_time(drv, idx[i]) as f64;
        let err = s.stamps.sample_ns as f64 - truth;
        assert!(
            err.abs() < period_ns / 2.0,
            "seq {}: time error {err} ns",
            s.seq
        );
        let step = (s.stamps.sample_ns - samples[i - 1].stamps.sample_ns) as f64;
        assert!(
            (step - period_ns).abs() < 0.1 * period_ns,
            "seq {}: step {step} ns",
            s.seq
        );
        worst_err = worst_err.max(err.abs());
        worst_step = worst_step.max((step - period_ns).abs());
    }
    println!(
        "period {period_ns:.0} ns: worst time error {worst_err:.0} ns, worst spacing deviation \
         {worst_step:.0} ns after the first second"
    );
}

#[test]
fn accel_4khz_is_sustained_over_a_400khz_bus_without_loss() {
    let (mut drv, clock) = started(3, 100_000, accel_4k());
    let samples = read_for(&mut drv, &clock, 10_000_000_000, 5_000_000);
    assert!(
        (samples.len() as f64 - 40_000.0).abs() < 40.0,
        "{} samples in 10 s",
        samples.len()
    );
    assert_lossless_and_on_time(&mut drv, &samples, 250_000.0);
    let stats = drv.stats();
    assert_eq!(
        (stats.overflows, stats.gaps, stats.bus_errors, stats.reinits),
        (0, 0, 0, 0)
    );
    let utilisation = drv.bus_mut().bus_utilisation();
    // 6 bytes of FIFO data per sample at 9 SCL periods each: 54 x 2.5 us x 4000/s = 54 %,
    // plus per-read overhead.
    assert!(
        utilisation > 0.54 && utilisation < 0.65,
        "bus utilisation {utilisation}"
    );
    println!(
        "4 kHz accel-only, reads every 5 ms: bus utilisation {:.1} %",
        100.0 * utilisation
    );
}

#[test]
fn imu_1khz_is_lossless_and_never_torn() {
    let (mut drv, clock) = started(4, 40_000, imu_1k());
    // Irregular reading: 1 to 12 ms between reads.
    let mut buf = [RawImuSample::default(); 32];
    let mut samples = Vec::new();
    for i in 0..1500u64 {
        clock.advance(1_000_000 + (i * 7_919_000) % 11_000_000);
        let n = drv.read_samples(&clock, &mut buf).unwrap();
        samples.extend_from_slice(&buf[..n]);
    }
    assert!(samples.len() > 8_000);
    assert!(
        samples
            .iter()
            .all(|s| s.flags & raw_flags::GYRO_VALID != 0 && s.flags & raw_flags::TEMP_VALID != 0)
    );
    // Every sample is exactly one produced sample, all seven values from the same instant.
    assert_lossless_and_on_time(&mut drv, &samples, 1_000_000.0);
    let s = samples[100];
    assert_eq!(s.accel_g[2], f64::from(s.accel_counts[2]) / 16384.0);
    assert_eq!(s.gyro_dps[2], f64::from(s.gyro_counts[2]) / 131.0);
    assert!((s.temp_c - 30.0).abs() <= 0.5 / TEMP_LSB_PER_DEGC);
}

#[test]
fn sample_times_follow_a_device_clock_half_a_percent_fast() {
    let config = SimConfig {
        rate_error_ppm: 5_000.0,
        history_len: 50_000,
        ..SimConfig::default()
    };
    let clock = SimClock::new_virtual(0);
    let sim = SimMpu9250::new(NoisySource::new(5), clock.clone(), config);
    let mut drv = Mpu9250::new(sim, "sim", A);
    drv.init(accel_4k(), &clock).unwrap();
    let samples = read_for(&mut drv, &clock, 8_000_000_000, 4_000_000);
    assert_lossless_and_on_time(&mut drv, &samples, 250_000.0 / 1.005);
}

#[test]
fn fifo_overflow_is_detected_flagged_and_recovered() {
    let (mut drv, clock) = started(6, 100_000, accel_4k());
    let before = read_for(&mut drv, &clock, 200_000_000, 5_000_000);
    clock.advance(100_000_000); // the reader stalls: 400 samples, the FIFO holds 85
    let after = read_for(&mut drv, &clock, 200_000_000, 5_000_000);
    assert_eq!(drv.stats().overflows, 1);
    assert_eq!(drv.stats().fifo_resets, 1);

    let all: Vec<RawImuSample> = before.iter().chain(&after).copied().collect();
    let idx = locate(&mut drv, &all);
    let flagged: Vec<usize> = (0..all.len())
        .filter(|&i| all[i].flags & raw_flags::GAP_BEFORE != 0)
        .collect();
    assert_eq!(flagged.len(), 1, "one gap");
    let g = flagged[0];
    // FIFO_MODE = 1 kept the oldest 85 frames: they follow the last sample read before the
    // stall without a gap, and are delivered before the flagged sample.
    assert_eq!(g, before.len() + 85);
    assert!(idx[..g].windows(2).all(|w| w[1] == w[0] + 1));
    let s = all[g];
    assert_ne!(s.flags & raw_flags::FIFO_OVERFLOW, 0);
    let true_lost = idx[g] - idx[g - 1] - 1;
    assert!(true_lost > 300);
    assert!(
        u64::from(s.lost_before).abs_diff(true_lost) <= 1,
        "lost_before {} vs {true_lost}",
        s.lost_before
    );
    assert_eq!(drv.stats().lost_samples, u64::from(s.lost_before));
    // Times stay monotonic across the gap, and the first sample after it is on time.
    assert!(
        all.windows(2)
            .all(|w| w[1].stamps.sample_ns > w[0].stamps.sample_ns)
    );
    let err = s.stamps.sample_ns as f64 - true_time(&mut drv, idx[g]) as f64;
    assert!(err.abs() < 250_000.0, "time error after the gap {err} ns");
    // Everything after the gap is contiguous again.
    assert!(idx[g..].windows(2).all(|w| w[1] == w[0] + 1));
}

#[test]
fn transient_nacks_are_retried_without_loss() {
    let (mut drv, clock) = started(7, 100_000, accel_4k());
    let first = drv.bus_mut().stats().transactions;
    // Every fifth transaction for a while, whatever it is (status, count, FIFO data), fails
    // once with an address NACK.
    for k in 0..60 {
        drv.bus_mut()
            .fail_transaction(first + 10 + 5 * k, Fault::ADDRESS_NACK);
    }
    let samples = read_for(&mut drv, &clock, 2_000_000_000, 5_000_000);
    let stats = drv.stats();
    assert_eq!(stats.retries, 60);
    assert_eq!(stats.bus_errors, 60);
    assert_eq!((stats.gaps, stats.reinits, stats.fifo_resets), (0, 0, 0));
    assert_lossless_and_on_time(&mut drv, &samples, 250_000.0);
}

#[test]
fn a_fifo_read_failing_part_way_resets_the_fifo_and_flags_the_gap() {
    let (mut drv, clock) = started(8, 100_000, accel_4k());
    let mut samples = read_for(&mut drv, &clock, 100_000_000, 5_000_000);
    // A bus error after 10 payload bytes hits only a transaction that long: of the next four
    // (at most one read cycle: temperature, status, count, FIFO data), only the FIFO read.
    let next = drv.bus_mut().stats().transactions;
    for k in 0..4 {
        drv.bus_mut()
            .fail_transaction(next + k, Fault::bus_error(10));
    }
    samples.extend(read_for(&mut drv, &clock, 100_000_000, 5_000_000));
    let stats = drv.stats();
    assert_eq!(
        (
            stats.short_reads,
            stats.fifo_resets,
            stats.gaps,
            stats.reinits
        ),
        (1, 1, 1, 0)
    );
    let idx = locate(&mut drv, &samples);
    let g = samples
        .iter()
        .position(|s| s.flags & raw_flags::GAP_BEFORE != 0)
        .unwrap();
    assert_eq!(samples[g].flags & raw_flags::FIFO_OVERFLOW, 0);
    let true_lost = idx[g] - idx[g - 1] - 1;
    assert!(
        true_lost >= 20,
        "a read's worth of samples is lost, got {true_lost}"
    );
    assert!(
        u64::from(samples[g].lost_before).abs_diff(true_lost) <= 1,
        "lost_before {} vs {true_lost}",
        samples[g].lost_before
    );
}

#[test]
fn persistent_errors_reinitialise_the_device_without_dying() {
    let (mut drv, clock) = started(9, 100_000, accel_4k());
    let before = read_for(&mut drv, &clock, 100_000_000, 5_000_000);
    drv.bus_mut().set_present(false);
    let mut buf = [RawImuSample::default(); 128];
    for _ in 0..5 {
        clock.advance(5_000_000);
        let err = drv.read_samples(&clock, &mut buf).unwrap_err();
        assert!(matches!(err, Error::Absent { .. }), "{err}");
        assert!(err.to_string().contains("sim") && err.to_string().contains("0x68"));
    }
    drv.bus_mut().set_present(true);
    let after = read_for(&mut drv, &clock, 300_000_000, 5_000_000);
    assert!(drv.stats().reinits >= 5);
    let all: Vec<RawImuSample> = before.iter().chain(&after).copied().collect();
    let idx = locate(&mut drv, &all);
    let g = before.len();
    assert_ne!(all[g].flags & raw_flags::GAP_BEFORE, 0);
    assert!(
        all.iter()
            .filter(|s| s.flags & raw_flags::GAP_BEFORE != 0)
            .count()
            == 1
    );
    // The gap is measured in output periods of elapsed time (the device produced nothing while
    // resetting, so time, not the device's sample count, says how long the gap was).
    let dt = true_time(&mut drv, idx[g]) - true_time(&mut drv, idx[g - 1]);
    let expected = (dt as f64 / 250_000.0).round() as u64 - 1;
    assert!(
        u64::from(all[g].lost_before).abs_diff(expected) <= 1,
        "lost_before {} vs {expected}",
        all[g].lost_before
    );
    assert!(idx[g + 1..].windows(2).all(|w| w[1] == w[0] + 1));
    assert!(
        all.windows(2)
            .all(|w| w[1].stamps.sample_ns > w[0].stamps.sample_ns)
    );
}

#[test]
fn a_stalled_fifo_reinitialises_the_device() {
    let (mut drv, clock) = started(10, 100_000, accel_4k());
    let before = read_for(&mut drv, &clock, 100_000_000, 5_000_000);
    // Something puts the device to sleep behind the driver's back (e.g. a brown-out reset).
    common::write_reg(drv.bus_mut(), A, reg::PWR_MGMT_1, reg::PWR_MGMT_1_SLEEP);
    let after = read_for(&mut drv, &clock, 300_000_000, 5_000_000);
    let stats = drv.stats();
    assert_eq!((stats.stalls, stats.reinits, stats.gaps), (1, 1, 1));
    assert!(after.len() > 500);
    let all: Vec<RawImuSample> = before.iter().chain(&after).copied().collect();
    let idx = locate(&mut drv, &all);
    // The samples produced before the device fell asleep come first, unflagged; the first one
    // after the re-initialisation carries the gap: at least the 50 ms stall timeout plus the
    // 100 ms reset wait, and what elapsed time says.
    let g = all
        .iter()
        .position(|s| s.flags & raw_flags::GAP_BEFORE != 0)
        .unwrap();
    assert!(g >= before.len());
    assert!(idx[..g].windows(2).all(|w| w[1] == w[0] + 1));
    let lost = u64::from(all[g].lost_before);
    assert!(lost >= 600, "{lost}");
    let dt = true_time(&mut drv, idx[g]) - true_time(&mut drv, idx[g - 1]);
    let expected = (dt as f64 / 250_000.0).round() as u64 - 1;
    assert!(
        lost.abs_diff(expected) <= 1,
        "lost_before {lost} vs {expected}"
    );
    assert!(
        all.windows(2)
            .all(|w| w[1].stamps.sample_ns > w[0].stamps.sample_ns)
    );
}

#[test]
fn temperature_is_read_and_attached_in_accel_only_mode() {
    let (mut drv, clock) = started(11, 0, accel_4k());
    let t = drv.read_temperature().unwrap();
    assert!((t - 30.0).abs() <= 0.5 / TEMP_LSB_PER_DEGC, "{t} degC");
    let samples = read_for(&mut drv, &clock, 50_000_000, 5_000_000);
    assert!(
        samples
            .iter()
            .all(|s| s.flags & raw_flags::TEMP_VALID != 0 && s.temp_c == t)
    );
    assert!(samples.iter().all(|s| s.flags & raw_flags::GYRO_VALID == 0));

    let (mut drv, clock) = started(
        11,
        0,
        Config {
            temp_interval_ns: 0,
            ..accel_4k()
        },
    );
    let samples = read_for(&mut drv, &clock, 50_000_000, 5_000_000);
    assert!(samples.iter().all(|s| s.flags & raw_flags::TEMP_VALID == 0));
}

#[test]
fn saturated_samples_are_flagged() {
    let mut source = NoisySource::new(12);
    source.accel_g = [0.0, 0.0, 2.0]; // at the end of ±2 g: about half the samples saturate
    let clock = SimClock::new_virtual(0);
    let sim = SimMpu9250::new(source, clock.clone(), SimConfig::default());
    let mut drv = Mpu9250::new(sim, "sim", A);
    drv.init(accel_4k(), &clock).unwrap();
    let samples = read_for(&mut drv, &clock, 20_000_000, 5_000_000);
    assert!(!samples.is_empty());
    for s in &samples {
        assert_eq!(
            s.flags & raw_flags::SATURATED != 0,
            s.accel_counts.contains(&i16::MAX),
            "{:?}",
            s.accel_counts
        );
    }
    let saturated = samples
        .iter()
        .filter(|s| s.flags & raw_flags::SATURATED != 0)
        .count();
    assert!(
        saturated > 0 && saturated < samples.len(),
        "{saturated} of {}",
        samples.len()
    );
}

/// A bus that silently ignores writes to one register (a stuck register on a faulty part).
struct IgnoresWritesTo<B> {
    inner: B,
    register: u8,
}

impl<B: embedded_hal::i2c::ErrorType> embedded_hal::i2c::ErrorType for IgnoresWritesTo<B> {
    type Error = B::Error;
}

impl<B: embedded_hal::i2c::I2c> embedded_hal::i2c::I2c for IgnoresWritesTo<B> {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [embedded_hal::i2c::Operation<'_>],
    ) -> Result<(), Self::Error> {
        use embedded_hal::i2c::Operation;
        let is_ignored_write =
            matches!(operations, [Operation::Write([r, _, ..])] if *r == self.register);
        if is_ignored_write {
            return Ok(());
        }
        self.inner.transaction(address, operations)
    }
}

#[test]
fn a_register_that_does_not_read_back_fails_init_with_a_clear_error() {
    let sim = noisy_sim(13, 0);
    let clock = sim.clock().clone();
    let bus = IgnoresWritesTo {
        inner: sim,
        register: reg::ACCEL_CONFIG,
    };
    let mut drv = Mpu9250::new(bus, "sim", A);
    let config = Config {
        accel_range: AccelRange::G8,
        ..Config::default()
    };
    let err = drv.init(config, &clock).unwrap_err();
    assert!(
        matches!(
            err,
            Error::Verify {
                register: 0x1C,
                wrote: 0x10,
                read: 0x00,
                ..
            }
        ),
        "{err:?}"
    );
    let text = err.to_string();
    for needle in ["sim", "0x68", "0x1c", "0x10", "0x00"] {
        assert!(text.contains(needle), "{needle:?} missing from: {text}");
    }
}
