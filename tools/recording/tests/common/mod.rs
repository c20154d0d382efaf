//! Helpers shared by the integration tests.
#![allow(dead_code)] // Each test binary uses a different subset.

use std::path::{Path, PathBuf};

use ipc_types::units::{self, AccelRange, GyroRange};
use ipc_types::{RawImuSample, Stamps, raw_flags};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use recording::Truth;

/// A fresh path for a test file (the directory is cargo's per-target scratch space).
pub fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("recording-tests");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    let _ = std::fs::remove_file(&path);
    path
}

/// The thesis data folder beside the repository (`../shared/data/capstone`), or `None` with a
/// message when it is absent.
pub fn capstone_dir() -> Option<PathBuf> {
    test_support::shared_data("data/capstone")
}

/// Samples as a live sensor would produce them: random counts, values = counts / sensitivity,
/// times from 2^60 ns (beyond f64's exact integers) with random increments.
pub fn live_samples(n: usize, seed: u64) -> Vec<RawImuSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut t_ns = 1u64 << 60;
    (0..n)
        .map(|i| {
            t_ns += rng.random_range(1..20_000_000);
            let accel_counts: [i16; 3] = rng.random();
            let gyro_counts: [i16; 3] = rng.random();
            let temp_counts: i16 = rng.random_range(-8000..8000);
            let extra = [0, raw_flags::GAP_BEFORE, raw_flags::REPAIRED][i % 3];
            RawImuSample {
                stamps: Stamps {
                    sample_ns: t_ns,
                    ..Stamps::default()
                },
                seq: i as u64,
                accel_g: accel_counts.map(|c| f64::from(c) / AccelRange::G2.lsb_per_g()),
                gyro_dps: gyro_counts.map(|c| f64::from(c) / GyroRange::Dps250.lsb_per_dps()),
                temp_c: units::temp_c_from_counts(temp_counts),
                accel_counts,
                gyro_counts,
                temp_counts,
                flags: raw_flags::GYRO_VALID | raw_flags::TEMP_VALID | extra,
                lost_before: if extra == raw_flags::GAP_BEFORE {
                    rng.random_range(1..1000)
                } else {
                    0
                },
                undelivered: 0,
            }
        })
        .collect()
}

/// A random finite `f64` drawn from all bit patterns (subnormals, huge values, -0.0 included).
pub fn any_finite(rng: &mut ChaCha8Rng) -> f64 {
    loop {
        let v = f64::from_bits(rng.random());
        if v.is_finite() {
            return v;
        }
    }
}

/// An arbitrary bit pattern that is finite and at most `limit` in magnitude (about half of
/// all patterns are within 20).
pub fn any_within(rng: &mut ChaCha8Rng, limit: f64) -> f64 {
    loop {
        let v = any_finite(rng);
        if v.abs() <= limit {
            return v;
        }
    }
}

/// Truth records at the samples' times with arbitrary finite values.
pub fn any_truth(samples: &[RawImuSample], seed: u64) -> Vec<Truth> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    samples
        .iter()
        .map(|s| Truth {
            t_ns: s.stamps.sample_ns,
            position_m: [
                any_finite(&mut rng),
                any_finite(&mut rng),
                any_finite(&mut rng),
            ],
            velocity_mps: [
                any_finite(&mut rng),
                any_finite(&mut rng),
                any_finite(&mut rng),
            ],
            attitude_wxyz: [0.0; 4].map(|_| any_finite(&mut rng)),
            specific_force_mps2: [0.0; 3].map(|_| any_finite(&mut rng)),
            angular_rate_rps: [0.0; 3].map(|_| any_finite(&mut rng)),
            at_rest: rng.random(),
        })
        .collect()
}

/// Every `f64` of a sample as bits, so that comparisons distinguish -0.0 from 0.0.
pub fn sample_bits(s: &RawImuSample) -> Vec<u64> {
    s.accel_g
        .iter()
        .chain(&s.gyro_dps)
        .chain([&s.temp_c])
        .map(|v| v.to_bits())
        .collect()
}

/// Every `f64` of a truth record as bits.
pub fn truth_bits(t: &Truth) -> Vec<u64> {
    t.position_m
        .iter()
        .chain(&t.velocity_mps)
        .chain(&t.attitude_wxyz)
        .chain(&t.specific_force_mps2)
        .chain(&t.angular_rate_rps)
        .map(|v| v.to_bits())
        .collect()
}
