//! The zero-state learner and detectors on noise correlated by a sensor's own low-pass filter
//! (as every real IMU's is), on a slowly moving sensor, and SHOE on a synthetic gait.

use calibrate::zero_state::{DetectorConfig, DetectorKind, LearnRejection, ZeroStateDetector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const G: f64 = 9.80665;
const RATE_HZ: f64 = 1000.0;
const BATCH: usize = calibrate::zero_state::BATCH_LEN;
/// Pole of each of the two cascaded one-pole low-pass sections: each 31 Hz at 1 kHz, together
/// 20 Hz at -3 dB, like the MPU-9250's DLPF_CFG = 4.
const PHI: f64 = 0.823;

/// White noise through two cascaded one-pole sections `x_k = PHI x_k-1 + e_k`, scaled to a
/// stationary standard deviation of `sigma`.
struct Coloured {
    rng: ChaCha8Rng,
    state: [[f64; 2]; 6],
}

impl Coloured {
    fn new(seed: u64) -> Self {
        let mut c = Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            state: [[0.0; 2]; 6],
        };
        for _ in 0..2000 {
            c.next(1.0);
        }
        c
    }

    /// Stationary variance of the cascade for unit input noise: (1 + PHI^2) / (1 - PHI^2)^3.
    fn unit_std() -> f64 {
        ((1.0 + PHI * PHI) / (1.0 - PHI * PHI).powi(3)).sqrt()
    }

    fn next(&mut self, sigma: f64) -> [f64; 6] {
        let e = Normal::new(0.0, 1.0).unwrap();
        std::array::from_fn(|c| {
            let s = &mut self.state[c];
            s[0] = PHI * s[0] + e.sample(&mut self.rng);
            s[1] = PHI * s[1] + s[0];
            s[1] / Self::unit_std() * sigma
        })
    }
}

/// The ratio `var(batch mean) n / E[within-batch variance]` of the cascade, from its
/// autocorrelation `r_k = PHI^k (1 + k (1 - PHI^2) / (1 + PHI^2))` (an independent closed form).
fn expected_ratio(n: usize) -> f64 {
    let nf = n as f64;
    let s: f64 = (1..n)
        .map(|k| {
            let k = k as f64;
            let r = PHI.powf(k) * (1.0 + k * (1.0 - PHI * PHI) / (1.0 + PHI * PHI));
            (1.0 - k / nf) * r
        })
        .sum();
    (1.0 + 2.0 * s) / (1.0 - 2.0 * s / (nf - 1.0))
}

/// Feeds `seconds` at rest (level, coloured noise of `sigma_a` m/s^2 and `sigma_g` rad/s),
/// tilting about x at `tilt_rate` rad/s; returns (verdicts that were rest, verdicts).
fn feed(
    det: &mut ZeroStateDetector,
    noise: &mut Coloured,
    k0: &mut u64,
    seconds: f64,
    tilt_rate: f64,
) -> (usize, usize) {
    let (sigma_a, sigma_g) = (0.02, 0.003);
    let (mut rest, mut total) = (0, 0);
    for _ in 0..(seconds * RATE_HZ) as usize {
        let t = *k0 as f64 / RATE_HZ;
        *k0 += 1;
        let angle = tilt_rate * t;
        let n = noise.next(1.0);
        let a = [
            n[0] * sigma_a,
            G * angle.sin() + n[1] * sigma_a,
            G * angle.cos() + n[2] * sigma_a,
        ];
        let w = [tilt_rate + n[3] * sigma_g, n[4] * sigma_g, n[5] * sigma_g];
        if let Some(v) = det.push((t * 1e9).round() as u64, a, w) {
            total += 1;
            rest += usize::from(v.rest);
        }
    }
    (rest, total)
}

#[test]
fn a_rest_with_filter_correlated_noise_is_learned_and_called_rest() {
    let expected = expected_ratio(BATCH);
    assert!(
        expected > 5.0,
        "the test needs strongly correlated noise: {expected}"
    );
    for seed in 0..3 {
        let mut det = ZeroStateDetector::new(DetectorConfig::new(DetectorKind::Glrt, G));
        let mut noise = Coloured::new(seed);
        let mut k = 0;
        feed(&mut det, &mut noise, &mut k, 5.5, 0.0);
        assert!(det.is_ready(), "seed {seed}: {:?}", det.learn_rejections());
        let (rest, total) = feed(&mut det, &mut noise, &mut k, 20.0, 0.0);
        let fraction = rest as f64 / total as f64;
        assert!(fraction > 0.9, "seed {seed}: rest {fraction}");
    }
}

#[test]
fn the_learned_correlation_matches_the_filters_closed_form() {
    let expected = expected_ratio(BATCH);
    let mut det = ZeroStateDetector::new(DetectorConfig::new(DetectorKind::Glrt, G));
    let mut noise = Coloured::new(7);
    let mut learned = None;
    for k in 0..(6.0 * RATE_HZ) as usize {
        let t = k as f64 / RATE_HZ;
        let n = noise.next(1.0);
        let a = [0.02 * n[0], 0.02 * n[1], G + 0.02 * n[2]];
        let w = [0.003 * n[3], 0.003 * n[4], 0.003 * n[5]];
        if let Some(v) = det.push((t * 1e9).round() as u64, a, w) {
            learned = learned.or(v.learned);
        }
    }
    let r = learned.expect("learned");
    // The learned correlation is the ratio times (1 + 2 r_b), r_b the batch means' lag-1
    // correlation (0.2-0.3 here): within [0.8, 2] of the closed-form ratio.
    for c in r.accel_correlation.iter().chain(&r.gyro_correlation) {
        assert!(
            *c > 0.8 * expected && *c < 2.0 * expected,
            "{c} vs {expected}"
        );
    }
}

#[test]
fn a_slowly_tilting_sensor_is_not_learned() {
    // 0.5 deg/s about x: 2.5 degrees over a learning window, a trend in the y specific force
    // 20 times its noise, with the same correlated noise.
    let mut det = ZeroStateDetector::new(DetectorConfig::new(DetectorKind::Glrt, G));
    let mut noise = Coloured::new(3);
    let mut k = 0;
    feed(&mut det, &mut noise, &mut k, 12.0, 0.5_f64.to_radians());
    assert!(!det.is_ready());
    let (refused, why) = det.learn_rejections();
    assert!(refused > 0);
    assert!(
        matches!(why, Some(LearnRejection::Unsteady { .. })),
        "{why:?}"
    );
    // Still again: learned from the first 5 s of that rest.
    feed(&mut det, &mut noise, &mut k, 5.5, 0.0);
    assert!(det.is_ready(), "{:?}", det.learn_rejections());
}

/// A synthetic gait at 200 Hz: stances of `stance_s` with the foot's angular rate at
/// `stance_rate` rad/s about y (rolling over), swings of 0.7 s at up to 5 rad/s and 3 g;
/// returns the fraction of stance and of swing windows called rest.
fn gait(stance_s: f64, stance_rate: f64) -> (f64, f64) {
    let rate = 200.0;
    let mut det = ZeroStateDetector::new(DetectorConfig::new(DetectorKind::Shoe, G));
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let noise = Normal::new(0.0, 0.05).unwrap();
    let (mut stance, mut swing) = ((0, 0), (0, 0));
    let step = stance_s + 0.7;
    let (mut window_stance, mut window_swing) = (true, true);
    for k in 0..(20.0 * rate) as usize {
        let t = k as f64 / rate;
        let phase = t % step;
        let in_stance = phase < stance_s;
        let s = ((phase - stance_s) / 0.7 * std::f64::consts::PI).sin();
        let (a, w) = if in_stance {
            ([0.0, 0.0, G], [0.0, stance_rate, 0.0])
        } else {
            ([3.0 * G * s, 0.0, G + 2.0 * G * s], [0.0, 5.0 * s, 0.5 * s])
        };
        let a = a.map(|x| x + noise.sample(&mut rng));
        let w = w.map(|x| x + 0.01 * noise.sample(&mut rng));
        window_stance &= in_stance;
        // Swing proper: the foot faster than a third of its peak (its slow ends are as quiet
        // as a rolling stance).
        window_swing &= !in_stance && s > 0.3;
        if let Some(v) = det.push((t * 1e9).round() as u64, a, w) {
            // Windows across a transition count as neither.
            for (whole, counter) in [(window_stance, &mut stance), (window_swing, &mut swing)] {
                if whole {
                    counter.0 += usize::from(v.rest);
                    counter.1 += 1;
                }
            }
            (window_stance, window_swing) = (true, true);
        }
    }
    (
        stance.0 as f64 / stance.1 as f64,
        swing.0 as f64 / swing.1 as f64,
    )
}

#[test]
fn shoe_finds_stances_of_a_slow_and_of_a_brisk_gait() {
    // A still foot (T near the noise): the fixed threshold.
    let (stance, swing) = gait(0.4, 0.0);
    assert!(
        stance > 0.9 && swing < 0.02,
        "still stance {stance}, swing {swing}"
    );
    // A foot rolling over at 25 deg/s during a 0.25 s stance: T about 6e4, above OpenShoe's
    // fixed 3e4; the adaptive threshold (3 x the quietest window of the last 2 s) finds it.
    let (stance, swing) = gait(0.25, 25_f64.to_radians());
    assert!(
        stance > 0.9 && swing < 0.02,
        "brisk stance {stance}, swing {swing}"
    );
}
