//! The DLPF model against independent computations: the register-map bandwidth and delay of
//! every setting from the closed-form response, the time-domain recursion against that
//! response (sines), the statistics of filtered white noise against their closed forms, and
//! the filter in the sensor path (noise level, correlation and delay of simulated samples).

use std::f64::consts::PI;

use mems_sim::dlpf::{
    ACCEL_BYPASS, ACCEL_DLPF, Coefficients, DlpfConfig, GYRO_BYPASS_3600, GYRO_BYPASS_8800,
    GYRO_DLPF, Setting, TriadFilter, cfg_for_rate,
};
use mems_sim::model::{SensorModel, TriadModel};
use mems_sim::scenario::{PoseParams, PoseSession, Scenario};
use mems_sim::vibration::VibrationModel;
use mems_sim::{DlpfGrid, SimSensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Every setting of both tables.
fn all_settings() -> Vec<Setting> {
    let mut v: Vec<Setting> = GYRO_DLPF.iter().chain(ACCEL_DLPF.iter()).copied().collect();
    v.extend([GYRO_BYPASS_8800, GYRO_BYPASS_3600, ACCEL_BYPASS]);
    v
}

/// Magnitude and phase (rad) of a complex number given as (re, im).
fn polar((re, im): (f64, f64)) -> (f64, f64) {
    (re.hypot(im), im.atan2(re))
}

#[test]
fn every_setting_has_the_register_map_bandwidth_and_delay() {
    for s in all_settings() {
        let c = Coefficients::new(&s);
        let fs = s.internal_rate_hz;
        // -3 dB at the bandwidth: |H|^2 = 1/2.
        let (mag, _) = polar(c.response(s.bandwidth_hz, fs));
        assert!(
            (mag * mag - 0.5).abs() < 1e-12,
            "{s:?}: |H(B)|^2 = {}",
            mag * mag
        );
        // Unity gain at DC, and the low-frequency group delay -dphi/dw (central difference of
        // the closed-form phase) is the table's delay.
        assert!((polar(c.response(0.0, fs)).0 - 1.0).abs() < 1e-12);
        let df = s.bandwidth_hz * 1e-4;
        let (_, p1) = polar(c.response(df, fs));
        let (_, p0) = polar(c.response(-df, fs));
        let delay = -(p1 - p0) / (2.0 * 2.0 * PI * df);
        assert!(
            (delay - s.delay_s).abs() < 1e-6 * s.delay_s.max(1e-3),
            "{s:?}: group delay {delay} s"
        );
        // The magnitude is the first-order section's alone (all-pass and delay add none).
        for f in [0.3, 1.0, 2.5].map(|x| x * s.bandwidth_hz) {
            if f >= fs / 2.0 {
                continue;
            }
            let omega = (PI * f / fs).tan();
            let want = 1.0 / (1.0 + (omega / c.k).powi(2));
            let (mag, _) = polar(c.response(f, fs));
            assert!((mag * mag - want).abs() < 1e-12, "{s:?} at {f} Hz");
        }
    }
}

/// Least-squares amplitude and phase of `y[n] = A cos(w n + phi)` (w in rad/sample).
fn fit_sine(y: &[f64], w: f64, n0: usize) -> (f64, f64) {
    let (mut cc, mut ss, mut cs, mut yc, mut ys) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, v) in y.iter().enumerate() {
        let a = w * (n0 + i) as f64;
        let (s, c) = a.sin_cos();
        cc += c * c;
        ss += s * s;
        cs += c * s;
        yc += v * c;
        ys += v * s;
    }
    // Solve [cc cs; cs ss] [p; q] = [yc; ys] for y = p cos + q sin.
    let det = cc * ss - cs * cs;
    let p = (yc * ss - ys * cs) / det;
    let q = (ys * cc - yc * cs) / det;
    // p cos + q sin = A cos(wn + phi) with A cos phi = p, -A sin phi = q.
    (p.hypot(q), (-q).atan2(p))
}

#[test]
fn the_recursion_matches_the_closed_form_response_to_sines() {
    for s in all_settings() {
        let c = Coefficients::new(&s);
        let fs = s.internal_rate_hz;
        for f in [0.05, 0.5, 1.0, 1.7].map(|x| x * s.bandwidth_hz) {
            if f >= 0.45 * fs {
                continue;
            }
            let w = 2.0 * PI * f / fs;
            let mut filter = TriadFilter::new(&s);
            // Settle for 20 time constants of the pole, then fit over many periods.
            let settle = (20.0 / (1.0 - c.pole().abs()).max(1e-3)) as usize + 64;
            let n = settle + (40.0 * fs / f) as usize + 1000;
            let mut out = Vec::with_capacity(n - settle);
            for i in 0..n {
                let x = (w * i as f64).cos();
                let y = filter.step([x, 2.0 * x, -x]);
                assert!((y[1] - 2.0 * y[0]).abs() < 1e-9 && (y[2] + y[0]).abs() < 1e-9);
                if i >= settle {
                    out.push(y[0]);
                }
            }
            let (amp, phase) = fit_sine(&out, w, settle);
            let (want_amp, want_phase) = polar(c.response(f, fs));
            let dphi = (phase - want_phase + PI).rem_euclid(2.0 * PI) - PI;
            assert!(
                (amp - want_amp).abs() < 1e-6,
                "{s:?} at {f} Hz: amplitude {amp} vs {want_amp}"
            );
            assert!(dphi.abs() < 1e-6, "{s:?} at {f} Hz: phase off by {dphi}");
        }
    }
}

#[test]
fn constant_input_passes_unchanged_from_the_first_sample() {
    for s in all_settings() {
        let mut filter = TriadFilter::new(&s);
        for _ in 0..100 {
            let y = filter.step([1.0, -0.25, 9.5]);
            for (a, b) in y.iter().zip([1.0, -0.25, 9.5]) {
                assert!((a - b).abs() < 1e-12, "{s:?}: {y:?}");
            }
        }
    }
}

#[test]
fn filtered_white_noise_has_the_closed_form_variance_and_autocorrelation() {
    let n = 400_000;
    for s in [
        GYRO_DLPF[1],
        GYRO_DLPF[4],
        GYRO_DLPF[6],
        ACCEL_DLPF[3],
        ACCEL_BYPASS,
    ] {
        let c = Coefficients::new(&s);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut filter = TriadFilter::new(&s);
        filter.step([0.0; 3]);
        let y: Vec<f64> = (0..n)
            .map(|_| filter.step([StandardNormal.sample(&mut rng), 0.0, 0.0])[0])
            .collect();
        let var = y.iter().map(|v| v * v).sum::<f64>() / n as f64;
        let rho = |lag: usize| {
            y.windows(lag + 1).map(|w| w[0] * w[lag]).sum::<f64>() / ((n - lag) as f64 * var)
        };
        // The sample variance of a correlated series: its standard error grows with the
        // correlation time, about sqrt(2 (1 + p) / (1 - p) / n) relative.
        let p = c.pole();
        let rel_se = (2.0 * (1.0 + p.abs()) / (1.0 - p.abs()) / n as f64).sqrt();
        let want = c.noise_variance_ratio();
        assert!(
            (var / want - 1.0).abs() < 5.0 * rel_se,
            "{s:?}: variance {var} vs {want}"
        );
        for lag in [1, 2, 5] {
            let se = (2.0 * (1.0 + p.abs()) / (1.0 - p.abs()) / n as f64).sqrt();
            let (got, want) = (rho(lag), c.autocorrelation(lag as u32));
            assert!(
                (got - want).abs() < 5.0 * se,
                "{s:?} lag {lag}: {got} vs {want} +- {}",
                5.0 * se
            );
        }
    }
}

/// The low-frequency density of decimated filtered noise (a frequency-domain sum over the
/// aliases) against the time domain: the sum over lags of the kept samples' autocovariance,
/// `m K / (1 + K) (1 + 2 sum_l rho(l m))` in units of the input density squared, from the
/// closed-form autocorrelation (tested against the recursion above).
#[test]
fn decimation_folds_the_passed_noise_as_the_autocorrelation_says() {
    for s in all_settings() {
        let c = Coefficients::new(&s);
        for m in [1u32, 2, 4, 5, 10, 20] {
            let tail: f64 = (1..20_000).map(|l| c.autocorrelation(l * m)).sum();
            let want = (f64::from(m) * c.noise_variance_ratio() * (1.0 + 2.0 * tail)).sqrt();
            let got = c.aliased_density_ratio(m);
            assert!(
                (got - want).abs() < 1e-9 * want,
                "{s:?} kept every {m}: {got} vs {want}"
            );
        }
        assert!((c.aliased_density_ratio(1) - 1.0).abs() < 1e-12);
    }
    // The 184 Hz filters at 200 Hz (every fifth 1 kHz sample) fold 1.41x (gyro) and 1.50x
    // (accelerometer, 218.1 Hz) the density in; 20 Hz next to none.
    let at_200 = |s: &Setting| Coefficients::new(s).aliased_density_ratio(5);
    assert!((at_200(&GYRO_DLPF[1]) - 1.407).abs() < 1e-3);
    assert!((at_200(&ACCEL_DLPF[1]) - 1.500).abs() < 1e-3);
    assert!((at_200(&GYRO_DLPF[4]) - 1.008).abs() < 1e-3);
}

/// A level, still sensor with only white noise (and a gyro bias), measured through `dlpf` at
/// `rate_hz` for `n` samples; returns the gyro x and accel x series.
fn noisy_static(dlpf: Option<DlpfConfig>, rate_hz: f64, n: usize) -> (Vec<f64>, Vec<f64>) {
    let model = SensorModel {
        accel: TriadModel {
            noise_density: [300e-6; 3],
            ..TriadModel::ideal()
        },
        gyro: TriadModel {
            bias: [0.5, 0.0, 0.0],
            noise_density: [0.01; 3],
            ..TriadModel::ideal()
        },
        ..SensorModel::ideal()
    };
    let g = ipc_types::units::STANDARD_GRAVITY_MPS2;
    let s = PoseSession::static_pose(Default::default(), 1e6, g).unwrap();
    let mut sim = SimSensor::new(s, &model, &VibrationModel::moderate(0.0), 3).unwrap();
    sim.set_dlpf(dlpf.map(DlpfGrid::from_power_on));
    let mut gx = Vec::with_capacity(n);
    let mut ax = Vec::with_capacity(n);
    for k in 0..n {
        let (a, _) = sim.sample_with_truth(k as f64 / rate_hz, rate_hz);
        gx.push(a.gyro_dps[0]);
        ax.push(a.accel_g[0]);
    }
    (gx, ax)
}

/// Mean, variance and lag-1 autocorrelation.
fn stats(x: &[f64]) -> (f64, f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let r1 = x
        .windows(2)
        .map(|w| (w[0] - mean) * (w[1] - mean))
        .sum::<f64>()
        / ((n - 1.0) * var);
    (mean, var, r1)
}

#[test]
fn sensor_samples_are_the_filtered_internal_noise_decimated_to_the_output_rate() {
    let n = 100_000;
    // DLPF_CFG = A_DLPF_CFG = 4 (gyro 20 Hz, accel 21.2 Hz), internal 1 kHz, output 1 kHz and
    // 100 Hz (SMPLRT_DIV = 9).
    let config = DlpfConfig::both(4);
    for (rate, lag) in [(1000.0, 1u32), (100.0, 10)] {
        let (gx, ax) = noisy_static(Some(config), rate, n);
        for (name, x, setting, density) in [
            ("gyro", &gx, config.gyro, 0.01),
            ("accel", &ax, config.accel, 300e-6),
        ] {
            let c = Coefficients::new(&setting);
            let (mean, var, r1) = stats(x);
            let want_var = density * density * 1000.0 * c.noise_variance_ratio();
            let want_r1 = c.autocorrelation(lag);
            let p = c.pole().powi(lag as i32);
            let se = (2.0 * (1.0 + p) / (1.0 - p) / n as f64).sqrt();
            assert!(
                (var / want_var - 1.0).abs() < 5.0 * se,
                "{name} at {rate} Hz: variance {var} vs {want_var}"
            );
            assert!(
                (r1 - want_r1).abs() < 5.0 * se,
                "{name} at {rate} Hz: lag-1 autocorrelation {r1} vs {want_r1}"
            );
            if name == "gyro" {
                assert!((mean - 0.5).abs() < 0.01, "gyro mean {mean}");
            }
        }
    }
    // Without the filter the same source is white at the output rate, as before.
    let (gx, _) = noisy_static(None, 1000.0, n);
    let (_, var, r1) = stats(&gx);
    assert!((var / (0.01f64.powi(2) * 1000.0) - 1.0).abs() < 5.0 * (2.0 / n as f64).sqrt());
    assert!(r1.abs() < 5.0 / (n as f64).sqrt(), "white lag-1 {r1}");
}

#[test]
fn sensor_output_lags_the_truth_by_the_register_map_delay() {
    // An ideal sensor rotated slowly between poses (20 s raised-cosine rotations): through the
    // 5 Hz gyro DLPF (33.48 ms delay) the output follows the truth delayed by that much, and
    // a delay 1 ms shorter or longer fits several times worse.
    let params = PoseParams {
        rotate_s: 20.0,
        ..PoseParams::new(2.0)
    };
    let s = PoseSession::six_position(&params, 9).unwrap();
    let duration = s.duration_s();
    let mut sim = SimSensor::new(
        s.clone(),
        &SensorModel::ideal(),
        &VibrationModel::moderate(0.0),
        1,
    )
    .unwrap();
    let config = DlpfConfig::both(6);
    sim.set_dlpf(Some(DlpfGrid::from_power_on(config)));
    let rate = 1000.0;
    let delays = [-1e-3, 0.0, 1e-3].map(|d| config.gyro.delay_s + d);
    let (mut err, mut peak) = ([0.0f64; 3], 0.0f64);
    for k in 1000..(duration * rate) as usize {
        let t = k as f64 / rate;
        let (a, _) = sim.sample_with_truth(t, rate);
        for (e, d) in err.iter_mut().zip(delays) {
            let delayed = s.truth(t - d);
            for i in 0..3 {
                let w = delayed.angular_rate_rps[i].to_degrees();
                peak = peak.max(w.abs());
                *e = e.max((a.gyro_dps[i] - w).abs());
            }
        }
    }
    assert!(peak > 10.0, "peak rate {peak} deg/s");
    assert!(
        err[1] < 0.25 * err[0].min(err[2]),
        "max error against the truth delayed by the table's delay -1 ms, +0, +1 ms: {err:?} \
         deg/s (peak {peak})"
    );
}

#[test]
fn the_driver_rule_keeps_the_folded_noise_small_at_every_divided_rate() {
    // At every output rate 1000/n Hz down to 10 Hz (where the narrowest setting, 5 Hz, is
    // half the rate) the rule's setting keeps the gyro bandwidth at most half the rate
    // (Nyquist, the reason Linux's driver gives) and, for both triads, the noise density
    // folded in by keeping every n-th filter output below 1.31x (a first-order section with
    // its bandwidth at exactly half the rate folds 1.30x). The old fixed choice (DLPF_CFG = 1
    // at every rate) folds 1.41x at 200 Hz, so this fails on it.
    for n in 1..=100u32 {
        let rate = 1000.0 / f64::from(n);
        let config = DlpfConfig::driver(rate);
        let cfg = cfg_for_rate(rate);
        assert_eq!(config, DlpfConfig::both(cfg));
        let bandwidth = GYRO_DLPF[usize::from(cfg)].bandwidth_hz;
        assert!(bandwidth <= rate / 2.0, "{rate} Hz: DLPF_CFG {cfg}");
        for s in [config.gyro, config.accel] {
            let fold = Coefficients::new(&s).aliased_density_ratio(n);
            assert!(fold < 1.31, "{rate} Hz: {s:?} folds {fold}");
        }
    }
    assert_eq!(cfg_for_rate(1000.0), 1);
    assert_eq!(cfg_for_rate(200.0), 2);
    assert!(Coefficients::new(&GYRO_DLPF[1]).aliased_density_ratio(5) > 1.31);
}
