//! The error model against independent computations: the measurement equation term by term,
//! and the statistics of its random terms within their expected sampling error.

// Index loops over axes mirror the equations they check.
#![allow(clippy::needless_range_loop)]

use ipc_types::raw_flags;
use ipc_types::units::{AccelRange, GyroRange};
use mems_sim::AnalogSample;
use mems_sim::adc::quantize_sample;
use mems_sim::model::{Sensor, SensorModel, ThermalModel, TriadModel};

/// Mean and (n - 1) standard deviation.
fn mean_std(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

/// Runs `model` powered on with `seed` for `n` samples at `rate_hz` with constant inputs,
/// returning the samples.
fn run(
    model: &SensorModel,
    seed: u64,
    rate_hz: f64,
    n: usize,
    accel_g: [f64; 3],
) -> Vec<AnalogSample> {
    let mut sensor = Sensor::power_on(model, seed).unwrap();
    (0..n)
        .map(|k| sensor.measure(k as f64 / rate_hz, rate_hz, accel_g, [0.0; 3]))
        .collect()
}

#[test]
fn ideal_sensor_passes_inputs_through() {
    let mut sensor = Sensor::power_on(&SensorModel::ideal(), 7).unwrap();
    let s = sensor.measure(0.5, 1000.0, [0.1, -0.2, 0.97], [3.0, -4.0, 5.5]);
    assert_eq!(s.accel_g, [0.1, -0.2, 0.97]);
    assert_eq!(s.gyro_dps, [3.0, -4.0, 5.5]);
    assert_eq!(s.temp_c, 25.0);
}

#[test]
fn deterministic_terms_follow_the_measurement_equation() {
    let accel = TriadModel {
        bias: [0.01, -0.02, 0.03],
        scale: [0.02, -0.01, 0.005],
        misalignment: [[0.0, 0.01, -0.02], [0.015, 0.0, 0.005], [-0.01, 0.02, 0.0]],
        nonlinearity: [0.003, -0.002, 0.001],
        bias_temp_coeff: [1e-3, -2e-3, 0.5e-3],
        scale_temp_coeff: [2e-4, 1e-4, -3e-4],
        warmup_bias: [0.004, 0.0, -0.006],
        warmup_time_constant_s: 20.0,
        ..TriadModel::ideal()
    };
    let thermal = ThermalModel {
        ambient_c: 22.0,
        ambient_drift_c_per_s: 0.01,
        self_heating_c: 3.0,
        self_heating_time_constant_s: 50.0,
        reference_c: 25.0,
    };
    let model = SensorModel {
        accel: accel.clone(),
        gyro: TriadModel {
            bias: [1.0, 2.0, -3.0],
            scale: [0.01, 0.02, 0.03],
            ..TriadModel::ideal()
        },
        thermal,
    };
    let mut sensor = Sensor::power_on(&model, 1).unwrap();
    let inputs = [[0.3, -0.5, 0.8], [1.5, 0.2, -1.1], [-0.7, 1.9, 0.05]];
    for (k, u) in inputs.iter().enumerate() {
        let t = 10.0 + 40.0 * k as f64;
        let s = sensor.measure(t, 100.0, *u, [10.0, -20.0, 30.0]);
        let temp = 22.0 + 0.01 * t + 3.0 * (1.0 - (-t / 50.0f64).exp());
        assert!((s.temp_c - temp).abs() < 1e-12, "temperature at {t} s");
        let dt = temp - 25.0;
        for i in 0..3 {
            // y_i = sum_j (delta_ij (1 + s_i + c_s,i dT) + M_ij) q_j + b_i + c_b,i dT + warm-up.
            let mut y = 0.0;
            for j in 0..3 {
                let q = u[j] + accel.nonlinearity[j] * u[j] * u[j];
                let m = if i == j {
                    1.0 + accel.scale[i] + accel.scale_temp_coeff[i] * dt
                } else {
                    accel.misalignment[i][j]
                };
                y += m * q;
            }
            y += accel.bias[i]
                + accel.bias_temp_coeff[i] * dt
                + accel.warmup_bias[i] * (-t / 20.0f64).exp();
            assert!(
                (s.accel_g[i] - y).abs() < 1e-14,
                "accel axis {i} at {t} s: {} vs {y}",
                s.accel_g[i]
            );
        }
        let g_expected = [10.0 * 1.01 + 1.0, -20.0 * 1.02 + 2.0, 30.0 * 1.03 - 3.0];
        for i in 0..3 {
            assert!((s.gyro_dps[i] - g_expected[i]).abs() < 1e-12);
        }
    }
}

#[test]
fn white_noise_std_is_density_times_sqrt_rate() {
    let mut model = SensorModel::ideal();
    model.accel.noise_density = [300e-6, 150e-6, 600e-6];
    let n = 40_000;
    for rate in [1000.0, 100.0] {
        let samples = run(&model, 3, rate, n, [0.0, 0.0, 1.0]);
        for axis in 0..3 {
            let x: Vec<f64> = samples.iter().map(|s| s.accel_g[axis]).collect();
            let (mean, std) = mean_std(&x);
            let sigma = model.accel.noise_density[axis] * f64::sqrt(rate);
            let truth = if axis == 2 { 1.0 } else { 0.0 };
            // Sampling errors: mean sigma / sqrt(n), std sigma / sqrt(2 (n - 1)); 4-sigma bounds.
            assert!(
                (mean - truth).abs() < 4.0 * sigma / (n as f64).sqrt(),
                "axis {axis} mean {mean}"
            );
            let se = sigma / (2.0 * (n as f64 - 1.0)).sqrt();
            assert!(
                (std - sigma).abs() < 4.0 * se,
                "axis {axis} at {rate} Hz: std {std} vs {sigma}"
            );
        }
        // Axes are independent: sample correlation within 4 / sqrt(n) of zero.
        let (x, y): (Vec<f64>, Vec<f64>) =
            samples.iter().map(|s| (s.accel_g[0], s.accel_g[1])).unzip();
        let (mx, sx) = mean_std(&x);
        let (my, sy) = mean_std(&y);
        let cov = x
            .iter()
            .zip(&y)
            .map(|(a, b)| (a - mx) * (b - my))
            .sum::<f64>()
            / (n as f64 - 1.0);
        assert!((cov / (sx * sy)).abs() < 4.0 / (n as f64).sqrt());
    }
}

#[test]
fn gyro_white_noise_matches_its_density() {
    let mut model = SensorModel::ideal();
    model.gyro.noise_density = [0.01; 3];
    let n = 40_000;
    let rate = 1000.0;
    let mut sensor = Sensor::power_on(&model, 11).unwrap();
    let samples: Vec<AnalogSample> = (0..n)
        .map(|k| sensor.measure(k as f64 / rate, rate, [0.0; 3], [1.0, 2.0, 3.0]))
        .collect();
    let sigma = 0.01 * f64::sqrt(rate);
    for axis in 0..3 {
        let x: Vec<f64> = samples.iter().map(|s| s.gyro_dps[axis]).collect();
        let (mean, std) = mean_std(&x);
        assert!((mean - (axis as f64 + 1.0)).abs() < 4.0 * sigma / (n as f64).sqrt());
        assert!((std - sigma).abs() < 4.0 * sigma / (2.0 * (n as f64 - 1.0)).sqrt());
    }
}

#[test]
fn turn_on_bias_is_drawn_per_power_on_with_the_configured_std() {
    let mut model = SensorModel::ideal();
    let std = [4.5e-3 / 9.80665, 2.5e-3 / 9.80665, 6.1e-3 / 9.80665];
    model.accel.turn_on_bias_std = std;
    model.gyro.turn_on_bias_std = [0.5; 3];
    let seeds = 3000u64;
    let draws: Vec<([f64; 3], [f64; 3])> = (0..seeds)
        .map(|s| Sensor::power_on(&model, s).unwrap().turn_on_bias())
        .collect();
    for axis in 0..3 {
        let x: Vec<f64> = draws.iter().map(|d| d.0[axis]).collect();
        let (mean, sd) = mean_std(&x);
        let n = seeds as f64;
        assert!(
            mean.abs() < 4.0 * std[axis] / n.sqrt(),
            "axis {axis} mean {mean}"
        );
        assert!(
            (sd - std[axis]).abs() < 4.0 * std[axis] / (2.0 * (n - 1.0)).sqrt(),
            "axis {axis} std {sd}"
        );
        let g: Vec<f64> = draws.iter().map(|d| d.1[axis]).collect();
        let (_, gsd) = mean_std(&g);
        assert!((gsd - 0.5).abs() < 4.0 * 0.5 / (2.0 * (n - 1.0)).sqrt());
    }
    // The bias is constant within a power-on and what the output shows.
    let mut sensor = Sensor::power_on(&model, 42).unwrap();
    let (b, _) = sensor.turn_on_bias();
    for k in 0..5 {
        let s = sensor.measure(k as f64, 1.0, [0.0; 3], [0.0; 3]);
        assert_eq!(s.accel_g, b);
    }
    // Same seed, same part; another seed, another bias.
    assert_eq!(Sensor::power_on(&model, 42).unwrap().turn_on_bias().0, b);
    assert_ne!(Sensor::power_on(&model, 43).unwrap().turn_on_bias().0, b);
}

#[test]
fn random_walk_increments_have_variance_k2_dt() {
    let mut model = SensorModel::ideal();
    let k = [2e-3, 1e-3, 4e-3];
    model.accel.bias_random_walk = k;
    let rate = 100.0;
    let n = 40_001;
    let samples = run(&model, 5, rate, n, [0.0; 3]);
    for lag in [1usize, 10] {
        let dt = lag as f64 / rate;
        for axis in 0..3 {
            // Non-overlapping increments are independent N(0, K^2 dt).
            let inc: Vec<f64> = (0..(n - 1) / lag)
                .map(|i| samples[(i + 1) * lag].accel_g[axis] - samples[i * lag].accel_g[axis])
                .collect();
            let m = inc.len() as f64;
            let var = inc.iter().map(|x| x * x).sum::<f64>() / m;
            let want = k[axis] * k[axis] * dt;
            // The variance of a mean of m chi-square(1) terms: relative std sqrt(2 / m).
            assert!(
                (var / want - 1.0).abs() < 4.0 * (2.0 / m).sqrt(),
                "lag {lag} axis {axis}: {var} vs {want}"
            );
        }
    }
    // It starts at zero at power-on.
    assert_eq!(samples[0].accel_g, [0.0; 3]);
}

/// Non-overlapping Allan variance of `x` sampled at `rate_hz` at cluster size `m`, and the
/// number of cluster differences it averages.
fn allan_variance(x: &[f64], m: usize) -> (f64, usize) {
    let means: Vec<f64> = x
        .chunks_exact(m)
        .map(|c| c.iter().sum::<f64>() / m as f64)
        .collect();
    let d = means.len() - 1;
    let avar = means.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (2.0 * d as f64);
    (avar, d)
}

#[test]
fn bias_instability_has_the_flicker_allan_floor() {
    let b = 2e-4;
    let mut model = SensorModel::ideal();
    model.accel.bias_instability = [b; 3];
    model.accel.bias_instability_corr_s = [0.05, 50.0];
    // The model's theory curve is flat at the flicker floor 2 B^2 ln 2 / pi (IEEE 952) within
    // 5% between 30 times the shortest and a tenth of the longest correlation time.
    let floor = 2.0 * b * b * std::f64::consts::LN_2 / std::f64::consts::PI;
    for tau in [1.5, 2.0, 3.0, 5.0] {
        let theory = model.accel.allan_variance(0, tau);
        assert!(
            (theory / floor - 1.0).abs() < 0.05,
            "tau {tau}: {theory} vs floor {floor}"
        );
    }
    // A simulated record has the theoretical Allan variance within its sampling error. Three
    // independent axes pool their cluster differences.
    let rate = 100.0;
    let n = 80_000;
    let samples = run(&model, 9, rate, n, [0.0; 3]);
    for tau in [0.5, 2.0] {
        let m = (tau * rate) as usize;
        let mut pooled = 0.0;
        let mut count = 0;
        for axis in 0..3 {
            let x: Vec<f64> = samples.iter().map(|s| s.accel_g[axis]).collect();
            let (avar, d) = allan_variance(&x, m);
            pooled += avar * d as f64;
            count += d;
        }
        let avar = pooled / count as f64;
        let theory = model.accel.allan_variance(0, tau);
        // Relative std of an Allan variance from d cluster differences is about sqrt(2 / d)
        // (chi-square with d degrees of freedom); neighbouring differences of flicker noise
        // are correlated, so allow 5 of these rather than 4.
        let rel = (2.0 / count as f64).sqrt();
        assert!(
            (avar / theory - 1.0).abs() < 5.0 * rel,
            "tau {tau}: simulated {avar} vs theory {theory} (rel se {rel})"
        );
    }
}

#[test]
fn allan_theory_of_white_noise_and_random_walk() {
    let mut triad = TriadModel::ideal();
    triad.noise_density = [0.01, 0.0, 0.0];
    triad.bias_random_walk = [0.0, 1e-4, 0.0];
    // N^2 / tau and K^2 tau / 3 (IEEE 952 Annex C).
    assert!((triad.allan_variance(0, 4.0) - 1e-4 / 4.0).abs() < 1e-18);
    assert!((triad.allan_variance(1, 30.0) - 1e-8 * 30.0 / 3.0).abs() < 1e-20);
    assert_eq!(triad.allan_variance(2, 1.0), 0.0);
}

#[test]
fn random_terms_use_independent_streams() {
    // Adding a turn-on bias leaves the noise realisation unchanged: the difference of the two
    // outputs is exactly the drawn bias.
    let mut noisy = SensorModel::ideal();
    noisy.accel.noise_density = [300e-6; 3];
    let mut biased = noisy.clone();
    biased.accel.turn_on_bias_std = [0.01; 3];
    biased.accel.bias_random_walk = [1e-3; 3];
    let a = run(&noisy, 77, 100.0, 1, [0.0; 3]);
    let mut sensor = Sensor::power_on(&biased, 77).unwrap();
    let (b, _) = sensor.turn_on_bias();
    let s = sensor.measure(0.0, 100.0, [0.0; 3], [0.0; 3]);
    for i in 0..3 {
        assert!((s.accel_g[i] - a[0].accel_g[i] - b[i]).abs() < 1e-15);
    }
}

#[test]
fn the_same_seed_gives_the_same_samples() {
    let model = SensorModel::mpu9250_datasheet();
    let a = run(&model, 123, 500.0, 200, [0.0, 0.0, 1.0]);
    let b = run(&model, 123, 500.0, 200, [0.0, 0.0, 1.0]);
    let c = run(&model, 124, 500.0, 200, [0.0, 0.0, 1.0]);
    assert_eq!(a, b);
    assert_ne!(a, c);
}

#[test]
fn presets_validate_and_ideal_is_all_zero() {
    for model in [
        SensorModel::ideal(),
        SensorModel::mpu9250_datasheet(),
        SensorModel::mpu9250_calibrated(),
    ] {
        model.validate().unwrap();
    }
    // The datasheet preset's errors are within the datasheet's tolerances.
    let ds = SensorModel::mpu9250_datasheet();
    assert!(
        ds.accel.bias[0].abs() <= 0.060
            && ds.accel.bias[1].abs() <= 0.060
            && ds.accel.bias[2].abs() <= 0.080
    );
    assert!(ds.accel.scale.iter().all(|s| s.abs() <= 0.03));
    assert!(
        ds.accel
            .misalignment
            .iter()
            .flatten()
            .all(|m| m.abs() <= 0.02)
    );
    assert!(ds.accel.bias_temp_coeff.iter().all(|c| c.abs() <= 1.5e-3));
    assert!(ds.gyro.bias.iter().all(|b| b.abs() <= 5.0));
}

#[test]
fn invalid_parameters_name_their_field() {
    let mut m = SensorModel::ideal();
    m.accel.noise_density[1] = -1.0;
    let e = m.validate().unwrap_err();
    assert_eq!(e.field, "accel.noise_density[1]");

    let mut m = SensorModel::ideal();
    m.gyro.misalignment[2][2] = 0.01;
    assert_eq!(m.validate().unwrap_err().field, "gyro.misalignment[2][2]");

    let mut m = SensorModel::ideal();
    m.accel.warmup_bias[0] = 0.01;
    assert_eq!(
        m.validate().unwrap_err().field,
        "accel.warmup_time_constant_s"
    );

    let mut m = SensorModel::ideal();
    m.gyro.bias_instability[0] = 0.01;
    m.gyro.bias_instability_corr_s = [1.0, 5.0];
    assert_eq!(
        m.validate().unwrap_err().field,
        "gyro.bias_instability_corr_s"
    );

    let mut m = SensorModel::ideal();
    m.thermal.self_heating_c = 2.0;
    let e = m.validate().unwrap_err();
    assert_eq!(e.field, "thermal.self_heating_time_constant_s");
    assert!(
        e.to_string()
            .contains("thermal.self_heating_time_constant_s")
    );
    assert!(Sensor::power_on(&m, 0).is_err());
}

#[test]
fn quantization_rounds_scales_and_flags_saturation() {
    let analog = AnalogSample {
        accel_g: [0.123_456, -1.999, 2.5],
        gyro_dps: [100.004, -300.0, 0.0],
        temp_c: 30.0,
    };
    let raw = quantize_sample(&analog, AccelRange::G2, GyroRange::Dps250, 5_000, 9);
    assert_eq!(
        raw.accel_counts,
        [(0.123_456f64 * 16384.0).round() as i16, -32752, i16::MAX]
    );
    assert_eq!(raw.gyro_counts, [13101, i16::MIN, 0]);
    assert_eq!(raw.accel_g[0], f64::from(raw.accel_counts[0]) / 16384.0);
    assert_eq!(raw.gyro_dps[0], 13101.0 / 131.0);
    assert_eq!(raw.temp_counts, (9.0f64 * 333.87).round() as i16);
    assert!((raw.temp_c - 30.0).abs() <= 0.5 / 333.87);
    assert_eq!(raw.stamps.sample_ns, 5_000);
    assert_eq!(raw.seq, 9);
    assert_ne!(raw.flags & raw_flags::SATURATED, 0);
    assert_ne!(raw.flags & raw_flags::GYRO_VALID, 0);

    // A wider range: nothing saturates, and the resolution is coarser.
    let raw = quantize_sample(&analog, AccelRange::G4, GyroRange::Dps500, 0, 0);
    assert_eq!(raw.flags & raw_flags::SATURATED, 0);
    assert_eq!(raw.accel_counts[2], 20480);
    assert_eq!(raw.gyro_counts[1], -19650);
}

/// One nanosecond reached by two float sums a few 1e-17 s apart is one instant; an earlier
/// time beyond that is still a caller bug.
#[test]
fn the_same_nanosecond_rounded_twice_is_not_time_going_backwards() {
    let mut sensor = Sensor::power_on(&SensorModel::mpu9250_datasheet(), 3).unwrap();
    sensor.measure(0.228_659_896_000_000_03, 4000.0, [0.0, 0.0, 1.0], [0.0; 3]);
    sensor.measure(0.228_659_896, 4000.0, [0.0, 0.0, 1.0], [0.0; 3]);
    let earlier = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        sensor.measure(0.228_659_895, 4000.0, [0.0, 0.0, 1.0], [0.0; 3]);
    }));
    assert!(earlier.is_err(), "1 ns earlier must still panic");
}
