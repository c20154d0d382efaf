//! Zero-velocity updates on correlated samples: the effective-sample factor that
//! `odometry::rest_noise` estimates from a rest, checked against the scatter of the mean of
//! first-order autoregressive (AR(1)) sequences computed here, and the filter's velocity
//! 1-sigma after a rest's updates against the scatter of its own estimates when the updates'
//! errors are so correlated, and the stage's gyro-bias 1-sigma at alignment against the
//! scatter of a correlated rest's mean. Units: m/s for the velocities, m/s^2 for the
//! accelerometer, rad/s for the gyro.

use ipc_types::{CorrectedImuSample, Stamps, corrected_flags, raw_flags};
use nalgebra::Vector3;
use odometry::config::OdometryConfig;
use odometry::eskf::{Eskf, Imu, NoiseModel, align};
use odometry::rest_noise::RestNoise;
use odometry::stage::OdometryStage;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const G: f64 = 9.80665;

/// `n` samples of an AR(1) sequence with pole `p` and marginal standard deviation `sigma`
/// (lag-k autocorrelation `p^k`), started in its stationary distribution.
fn ar1(p: f64, sigma: f64, n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let start = Normal::new(0.0, sigma).unwrap();
    let e = Normal::new(0.0, sigma * (1.0 - p * p).sqrt()).unwrap();
    let mut y = start.sample(rng);
    (0..n)
        .map(|_| {
            let out = y;
            y = p * y + e.sample(rng);
            out
        })
        .collect()
}

/// `n` samples of white noise through the bilinear transform of a first-order low-pass of
/// bandwidth `b_hz` at `fs_hz` (the simulator's DLPF model without its delay, `mems_sim::dlpf`;
/// written out here from its formula): `y[k] = (K (e[k] + e[k-1]) - (K - 1) y[k-1]) / (1 + K)`,
/// `K = tan(pi b / fs)`, after a start-up of 2000 samples.
fn bilinear(b_hz: f64, fs_hz: f64, n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let k = (std::f64::consts::PI * b_hz / fs_hz).tan();
    let e = Normal::new(0.0, 1.0).unwrap();
    let (mut y, mut e_prev) = (0.0, 0.0);
    (0..n + 2000)
        .map(|_| {
            let e_now = e.sample(rng);
            y = (k * (e_now + e_prev) - (k - 1.0) * y) / (1.0 + k);
            e_prev = e_now;
            y
        })
        .skip(2000)
        .collect()
}

/// The variance of the mean of the `n` samples of each of `runs` independent sequences, in
/// units of the per-sample variance over `n` (1 for white samples): the mean-variance factor,
/// measured.
fn measured_factor(runs: usize, mut sequence: impl FnMut() -> Vec<f64>) -> f64 {
    let (mut mean_sq, mut var, mut n) = (0.0, 0.0, 0);
    for _ in 0..runs {
        let x = sequence();
        n = x.len();
        let m = x.iter().sum::<f64>() / n as f64;
        mean_sq += m * m / runs as f64;
        var += x.iter().map(|v| v * v).sum::<f64>() / n as f64 / runs as f64;
    }
    mean_sq * n as f64 / var
}

/// The median of 50 estimates of the factor, each from one sequence.
fn estimated_factor(mut sequence: impl FnMut() -> Vec<f64>) -> (f64, Vec<f64>) {
    let mut estimates: Vec<f64> = (0..50)
        .map(|_| {
            let mut r = RestNoise::default();
            for x in sequence() {
                r.push(Vector3::new(2e-3 * x, -2e-3 * x, G + 2e-3 * x));
            }
            r.mean_variance_factor().x
        })
        .collect();
    estimates.sort_by(f64::total_cmp);
    (estimates[estimates.len() / 2], estimates)
}

#[test]
fn the_factor_of_one_rest_matches_the_scatter_of_the_mean() {
    // One second at 1 kHz, the rest the stage aligns on. AR(1) with p = 0.88 and 0.5, white
    // samples (p = 0), and the simulated MPU-9250's accelerometer DLPF at 1 kHz with its
    // 44.8 Hz and 21.2 Hz settings (measured factors about 8 and 15.5; the pole alone,
    // `(1 + r1) / (1 - r1)`, would say about 16 and 35). The median of 50 one-second
    // estimates is within 5 % of the measured factor; 90 % of them within 15-30 %.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let n = 1000;
    for p in [0.0, 0.5, 0.88] {
        let want = measured_factor(2000, || ar1(p, 1.0, n, &mut rng));
        let (got, all) = estimated_factor(|| ar1(p, 1.0, n, &mut rng));
        // The measured factor's own sampling spread over 2000 runs is about 3 %.
        assert!(
            (got / want - 1.0).abs() < 0.15,
            "p {p}: estimated {got}, measured {want}"
        );
        if p == 0.0 {
            assert!(all.iter().all(|&f| f == 1.0), "{all:?}");
        }
    }
    for b in [44.8, 21.2] {
        let want = measured_factor(2000, || bilinear(b, 1000.0, n, &mut rng));
        let (got, _) = estimated_factor(|| bilinear(b, 1000.0, n, &mut rng));
        assert!(
            (got / want - 1.0).abs() < 0.15,
            "{b} Hz: estimated {got}, measured {want}"
        );
    }
}

/// A filter aligned level at rest with no process noise and a broad velocity prior (1 m/s;
/// the error state holds position, then velocity).
fn filter() -> Eskf {
    let g_s = Vector3::new(0.0, 0.0, G);
    let (x, mut cov) = align(
        g_s,
        Vector3::zeros(),
        G,
        Vector3::repeat(1e-3),
        Vector3::repeat(1e-4),
    );
    for i in 0..3 {
        cov[(3 + i, 3 + i)] = 1.0;
    }
    let noise = NoiseModel {
        accel_noise_density: 0.0,
        gyro_noise_density: 0.0,
        accel_bias_random_walk: 0.0,
        gyro_bias_random_walk: 0.0,
        vibration_accel_density_per_mps: 0.0,
        vibration_gyro_density_per_mps: 0.0,
    };
    Eskf::new(
        x,
        cov,
        G,
        noise,
        Imu {
            f: g_s,
            w: Vector3::zeros(),
        },
    )
}

/// Runs `n` zero-velocity updates of 1-sigma `sigma` whose measurement errors are `errors`
/// (the update measures `-error` instead of 0: the state is shifted by the error around
/// it), and returns the final x velocity and its variance.
fn updates(errors: &[f64], sigma: f64) -> (f64, f64) {
    let mut kf = filter();
    for e in errors {
        kf.x.v.x += e;
        kf.zero_velocity(sigma);
        kf.x.v.x -= e;
    }
    (kf.x.v.x, kf.velocity_sigma().x.powi(2))
}

#[test]
fn correlated_updates_with_the_factor_report_the_scatter_of_their_estimate() {
    // The truth is zero velocity; the updates' errors are AR(1) with p = 0.88 and 2 mm/s.
    // Counted as independent, 1000 of them claim a variance 1/16 of their estimate's real
    // scatter; with the factor estimated from the same kind of rest, the claim matches it.
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (p, sigma, n, runs) = (0.88, 2e-3, 1000, 600);
    // The factor from a long rest: what is tested here is the updates' information given the
    // factor (one second's estimate scatters by about 15 %, tested above).
    let mut rest = RestNoise::default();
    for x in ar1(p, 1.0, 20_000, &mut rng) {
        rest.push(Vector3::repeat(x));
    }
    let factor = rest.mean_variance_factor().x;
    let (mut scatter, mut plain, mut widened) = (0.0, 0.0, 0.0);
    for _ in 0..runs {
        let errors = ar1(p, sigma, n, &mut rng);
        let (v, var) = updates(&errors, sigma * factor.sqrt());
        scatter += v * v / runs as f64;
        widened = var;
        plain = updates(&errors, sigma).1;
    }
    // The estimate is the mean of the errors either way (equal weights, broad prior).
    let ratio = scatter / widened;
    assert!(
        (ratio - 1.0).abs() < 0.15,
        "scatter/variance {ratio}, factor {factor}"
    );
    assert!(scatter / plain > 10.0, "plain updates: {}", scatter / plain);
}

/// A rest at 1 kHz: the accelerometer reads gravity plus AR(1) noise of pole `p` whose
/// low-frequency density is the same for every `p` (marginal standard deviation
/// `sigma_white sqrt((1 - p) / (1 + p))`), the gyro white noise; every sample flagged rest.
fn rest_samples(p: f64, seconds: f64, seed: u64) -> Vec<CorrectedImuSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = (seconds * 1000.0) as usize;
    let sigma_white = 300e-6 * G * (500.0_f64).sqrt();
    let sigma = sigma_white * ((1.0 - p) / (1.0 + p)).sqrt();
    let axes: Vec<Vec<f64>> = (0..3).map(|_| ar1(p, sigma, n, &mut rng)).collect();
    let gyro = Normal::new(0.0, 0.01_f64.to_radians() * 500.0_f64.sqrt()).unwrap();
    (0..n)
        .map(|k| CorrectedImuSample {
            stamps: Stamps {
                sample_ns: 1_000_000_000 + k as u64 * 1_000_000,
                ..Stamps::default()
            },
            seq: k as u64,
            accel_mps2: [axes[0][k], axes[1][k], G + axes[2][k]],
            gyro_rps: [
                gyro.sample(&mut rng),
                gyro.sample(&mut rng),
                gyro.sample(&mut rng),
            ],
            flags: corrected_flags::ZERO_STATE | corrected_flags::DETECTOR_READY,
            raw_flags: raw_flags::GYRO_VALID,
            ..CorrectedImuSample::default()
        })
        .collect()
}

/// The stage's horizontal velocity 1-sigma at the end of `samples`, m/s.
fn velocity_sigma(samples: &[CorrectedImuSample], effective: bool) -> f64 {
    let cfg = OdometryConfig {
        effective_samples: effective,
        ..OdometryConfig::mpu9250(G)
    };
    let mut stage = OdometryStage::new(cfg);
    let mut last = None;
    for s in samples {
        stage.process(s, &mut |o| last = Some(*o)).unwrap();
    }
    last.expect("states").velocity_sigma_mps[0]
}

#[test]
fn the_stage_widens_its_rest_updates_for_correlated_samples_only() {
    let white = rest_samples(0.0, 6.0, 3);
    let filtered = rest_samples(0.88, 6.0, 3);
    // Counted as independent, the two rests give the same 1-sigma: the covariance does not
    // see the data.
    let (w, f) = (
        velocity_sigma(&white, false),
        velocity_sigma(&filtered, false),
    );
    assert!((f / w - 1.0).abs() < 0.01, "white {w}, filtered {f}");
    // With the factor the white rest moves by its estimate's spread only, and the filtered
    // one's updates, 1/15.7 as informative each, leave a velocity 1-sigma about
    // 15.7^(1/4) = 2.0 times wider (steady state of a random walk under updates of variance
    // r: sqrt(q r)).
    let w_eff = velocity_sigma(&white, true);
    assert!((w_eff / w - 1.0).abs() < 0.05, "white {w} -> {w_eff}");
    let ratio = velocity_sigma(&filtered, true) / w;
    assert!((ratio - 2.0).abs() < 0.3, "filtered/white {ratio}");
}

/// A rest at 1 kHz whose gyro reads the simulated 20 Hz DLPF's correlated noise (x axis) on
/// white-noise y and z axes, the accelerometer gravity plus white noise; every sample flagged
/// rest. `scale` sets the x axis' noise, rad/s per unit of the filtered sequence.
fn correlated_gyro_rest(scale: f64, seconds: f64, rng: &mut ChaCha8Rng) -> Vec<CorrectedImuSample> {
    let n = (seconds * 1000.0) as usize;
    let x = bilinear(20.0, 1000.0, n, rng);
    let white = Normal::new(0.0, 1e-3).unwrap();
    (0..n)
        .map(|k| CorrectedImuSample {
            stamps: Stamps {
                sample_ns: 1_000_000_000 + k as u64 * 1_000_000,
                ..Stamps::default()
            },
            seq: k as u64,
            accel_mps2: [white.sample(rng), white.sample(rng), G + white.sample(rng)],
            gyro_rps: [scale * x[k], white.sample(rng), white.sample(rng)],
            flags: corrected_flags::ZERO_STATE | corrected_flags::DETECTOR_READY,
            raw_flags: raw_flags::GYRO_VALID,
            ..CorrectedImuSample::default()
        })
        .collect()
}

/// The stage's gyro-bias 1-sigma about the sensor's x axis as it aligns (before any
/// zero-rate update), rad/s; the error state holds the gyro bias at 12-14.
fn aligned_gyro_bias_sigma(samples: &[CorrectedImuSample], effective: bool) -> f64 {
    let cfg = OdometryConfig {
        effective_samples: effective,
        ..OdometryConfig::mpu9250(G)
    };
    let mut stage = OdometryStage::new(cfg);
    for s in samples {
        stage.process(s, &mut |_| {}).unwrap();
        if let Some(kf) = stage.filter() {
            return kf.cov[(12, 12)].sqrt();
        }
    }
    panic!("never aligned");
}

#[test]
fn the_alignment_gyro_bias_sigma_is_the_scatter_of_a_correlated_rest_mean() {
    // The alignment averages the first second of rest (`align_s`). Measured here: how much
    // the mean of one second of the 20 Hz DLPF's noise scatters over 400 rests.
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let scale = 1e-3;
    let means: Vec<f64> = (0..400)
        .map(|_| {
            let x = bilinear(20.0, 1000.0, 1001, &mut rng);
            scale * x.iter().sum::<f64>() / x.len() as f64
        })
        .collect();
    let scatter = (means.iter().map(|m| m * m).sum::<f64>() / means.len() as f64).sqrt();
    let rest = correlated_gyro_rest(scale, 2.0, &mut rng);
    let with = aligned_gyro_bias_sigma(&rest, true);
    let without = aligned_gyro_bias_sigma(&rest, false);
    // One second's factor scatters by about 15 % (above), its square root by half that; the
    // measured scatter by 4 % over 400 rests.
    assert!(
        (with / scatter - 1.0).abs() < 0.2,
        "sigma {with}, scatter {scatter}"
    );
    // Counted as independent samples, the bias is claimed about sqrt(15) times too precise.
    assert!(
        scatter / without > 3.0,
        "sigma {without}, scatter {scatter}"
    );
}
