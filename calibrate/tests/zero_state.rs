//! The zero-state detectors on synthetic sessions (white noise of known level, exact
//! disturbances) and on a short simulated drive with ground truth.

use calibrate::zero_state::{
    BATCH_LEN, DetectorConfig, DetectorKind, LearnRejection, NoiseFloor, Verdict, ZeroStateDetector,
};
use mems_sim::dlpf::DlpfConfig;
use mems_sim::scenario::{Drive, DriveParams, ns_from_s};
use mems_sim::vibration::VibrationModel;
use mems_sim::{DlpfGrid, SimSensor, adc};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const G: f64 = 9.80665;
const RATE_HZ: f64 = 1000.0;
/// Per-sample noise of the synthetic sensor: the MPU-9250's densities at 1 kHz.
const ACCEL_SIGMA: f64 = 300e-6 * 31.622_776_601_683_793 * G;
const GYRO_SIGMA: f64 = 0.01 * 31.622_776_601_683_793 * std::f64::consts::PI / 180.0;
/// Gyroscope bias of the synthetic sensor, rad/s.
const GYRO_BIAS: [f64; 3] = [0.004, -0.002, 0.006];

/// A synthetic sensor lying level: gravity's reaction plus `extra_accel` (m/s^2), the bias
/// plus `rate` (rad/s), white noise scaled by `noise_scale`.
struct Synth {
    rng: ChaCha8Rng,
    k: u64,
}

impl Synth {
    fn new(seed: u64) -> Self {
        Self {
            rng: ChaCha8Rng::seed_from_u64(seed),
            k: 0,
        }
    }

    fn sample(
        &mut self,
        extra_accel: [f64; 3],
        rate: [f64; 3],
        noise_scale: f64,
    ) -> (u64, [f64; 3], [f64; 3]) {
        let na = Normal::new(0.0, ACCEL_SIGMA * noise_scale).unwrap();
        let ng = Normal::new(0.0, GYRO_SIGMA * noise_scale).unwrap();
        let up = [0.0, 0.0, G];
        let a = std::array::from_fn(|i| up[i] + extra_accel[i] + na.sample(&mut self.rng));
        let w = std::array::from_fn(|i| GYRO_BIAS[i] + rate[i] + ng.sample(&mut self.rng));
        let t = ns_from_s(self.k as f64 / RATE_HZ);
        self.k += 1;
        (t, a, w)
    }

    /// Feeds `seconds` of samples to `det`; returns the verdicts.
    fn feed(
        &mut self,
        det: &mut ZeroStateDetector,
        seconds: f64,
        extra_accel: [f64; 3],
        rate: [f64; 3],
        noise_scale: f64,
    ) -> Vec<Verdict> {
        let n = (seconds * RATE_HZ).round() as usize;
        (0..n)
            .filter_map(|_| {
                let (t, a, w) = self.sample(extra_accel, rate, noise_scale);
                det.push(t, a, w)
            })
            .collect()
    }
}

/// The detector's default settings (5 s of learning).
fn config(kind: DetectorKind) -> DetectorConfig {
    DetectorConfig::new(kind, G)
}

fn detector(kind: DetectorKind) -> ZeroStateDetector {
    ZeroStateDetector::new(config(kind))
}

fn rest_fraction(v: &[Verdict]) -> f64 {
    v.iter().filter(|v| v.rest).count() as f64 / v.len() as f64
}

/// Learns for 5 s of rest; returns the detector (ready) and the generator.
fn learned(kind: DetectorKind, seed: u64) -> (ZeroStateDetector, Synth) {
    let mut det = detector(kind);
    let mut synth = Synth::new(seed);
    let v = synth.feed(&mut det, 5.0, [0.0; 3], [0.0; 3], 1.0);
    assert!(det.is_ready(), "{kind:?} not ready after 5 s");
    assert!(v[..v.len() - 1].iter().all(|v| !v.ready && !v.rest));
    assert!(v.last().unwrap().ready && v.last().unwrap().learned.is_some());
    (det, synth)
}

#[test]
fn thresholds_are_learned_from_the_start_up_rest() {
    for kind in [DetectorKind::Yu, DetectorKind::Glrt] {
        let mut det = detector(kind);
        let mut synth = Synth::new(1);
        let verdicts = synth.feed(&mut det, 5.0, [0.0; 3], [0.0; 3], 1.0);
        // 5 s at 1 kHz = 250 batches; learning completes with the last one.
        assert_eq!(verdicts.len(), 5000 / BATCH_LEN);
        let r = verdicts.last().unwrap().learned.expect("learned");
        assert_eq!(r.batches, 250);
        assert!((r.duration_s - 5.0).abs() < 1e-9, "{}", r.duration_s);
        // Pooled std of 250 x 19 dof: relative error about 1/sqrt(2 * 4750) = 1%.
        for i in 0..3 {
            assert!(
                (r.accel_sigma_mps2[i] / ACCEL_SIGMA - 1.0).abs() < 0.04,
                "{r:?}"
            );
            assert!(
                (r.gyro_sigma_rps[i] / GYRO_SIGMA - 1.0).abs() < 0.04,
                "{r:?}"
            );
            // Means to a few sigma / sqrt(5000).
            let up = [0.0, 0.0, G][i];
            assert!((r.accel_mean_mps2[i] - up).abs() < 4.0 * ACCEL_SIGMA / 5000f64.sqrt());
            assert!((r.gyro_mean_rps[i] - GYRO_BIAS[i]).abs() < 4.0 * GYRO_SIGMA / 5000f64.sqrt());
            // White noise: batch means scatter as sigma / sqrt(20) (ratio 1 +- 0.1).
            assert!(r.accel_correlation[i] < 1.35 && r.gyro_correlation[i] < 1.35);
        }
        assert!((r.magnitude_mps2 - G).abs() < 0.01);
        let expect = ACCEL_SIGMA / (BATCH_LEN as f64).sqrt();
        assert!((r.magnitude_std_mps2 / expect - 1.0).abs() < 0.15, "{r:?}");
    }
}

#[test]
fn rest_is_detected_after_learning() {
    for kind in [DetectorKind::Yu, DetectorKind::Glrt] {
        let (mut det, mut synth) = learned(kind, 2);
        let v = synth.feed(&mut det, 20.0, [0.0; 3], [0.0; 3], 1.0);
        // The GLRT's window starts full of the learned rest: rest holds from the first batch on,
        // at the false-alarm rate.
        assert!(v.iter().all(|v| v.ready));
        let f = rest_fraction(&v);
        assert!(f > 0.97, "{kind:?}: rest fraction {f}");
    }
}

#[test]
fn glrt_false_alarm_rate_at_rest_matches_its_chi_squared_quantile() {
    for alpha in [1e-2, 1e-1] {
        let mut config = config(DetectorKind::Glrt);
        config.glrt.false_alarm = alpha;
        let mut det = ZeroStateDetector::new(config);
        let mut synth = Synth::new(3);
        synth.feed(&mut det, 5.0, [0.0; 3], [0.0; 3], 1.0);
        let v = synth.feed(&mut det, 200.0, [0.0; 3], [0.0; 3], 1.0);
        let missed = 1.0 - rest_fraction(&v);
        // Overlapping windows are correlated, so the count is noisier than binomial; the
        // quantiles allow for the learned levels' error (F, not chi-squared) and the gravity
        // reference's own uncertainty, which makes the test a little conservative.
        assert!(
            missed > 0.1 * alpha && missed < 2.0 * alpha,
            "alpha {alpha}: missed {missed}"
        );
    }
}

#[test]
fn vertical_acceleration_and_vibration_are_motion_for_both() {
    for kind in [DetectorKind::Yu, DetectorKind::Glrt] {
        let (mut det, mut synth) = learned(kind, 4);
        let bump = synth.feed(&mut det, 1.0, [0.0, 0.0, 0.3], [0.0; 3], 1.0);
        assert!(rest_fraction(&bump) < 0.02, "{kind:?} vertical");
        synth.feed(&mut det, 2.0, [0.0; 3], [0.0; 3], 1.0);
        let shaking = synth.feed(&mut det, 1.0, [0.0; 3], [0.0; 3], 2.0);
        assert!(rest_fraction(&shaking) < 0.02, "{kind:?} vibration");
    }
}

#[test]
fn only_the_glrt_sees_horizontal_acceleration_and_in_place_spins() {
    // Yu's magnitude test: 0.3 m/s^2 across gravity changes |a| by 4.6 mm/s^2, well inside
    // its tolerance; an in-place spin does not touch the accelerometer at all.
    let steady = [0.3, 0.0, 0.0];
    let spin = [0.0, 0.0, 30f64.to_radians()];
    let (mut yu, mut synth) = learned(DetectorKind::Yu, 5);
    assert!(rest_fraction(&synth.feed(&mut yu, 2.0, steady, [0.0; 3], 1.0)) > 0.95);
    assert!(rest_fraction(&synth.feed(&mut yu, 2.0, [0.0; 3], spin, 1.0)) > 0.95);
    // The GLRT: motion from the second batch on (the first one's window still holds 24 of rest).
    let (mut glrt, mut synth) = learned(DetectorKind::Glrt, 5);
    assert_eq!(
        rest_fraction(&synth.feed(&mut glrt, 2.0, steady, [0.0; 3], 1.0)[1..]),
        0.0
    );
    assert_eq!(
        rest_fraction(&synth.feed(&mut glrt, 2.0, [0.0; 3], spin, 1.0)[1..]),
        0.0
    );
    // A slow drift of the gyroscope bias (0.02 deg/s, e.g. temperature) is followed at rest.
    let drift = [0.0, 0.0, 0.02f64.to_radians()];
    let v = synth.feed(&mut glrt, 30.0, [0.0; 3], drift, 1.0);
    let f = rest_fraction(&v[v.len() / 2..]);
    assert!(f > 0.95, "{f} {:?}", glrt.references());
    let (_, bias) = glrt.references().unwrap();
    assert!(
        (bias[2] - GYRO_BIAS[2] - drift[2]).abs() < 0.1 * drift[2],
        "{bias:?}"
    );
}

#[test]
fn learning_slides_past_an_interval_where_the_sensor_moves() {
    for kind in [DetectorKind::Yu, DetectorKind::Glrt] {
        let mut det = detector(kind);
        let mut synth = Synth::new(6);
        // 2 s still, 1 s of turning (the batch means wander), then still.
        synth.feed(&mut det, 2.0, [0.0; 3], [0.0; 3], 1.0);
        synth.feed(&mut det, 1.0, [0.0; 3], [0.0, 0.0, 0.5], 1.0);
        synth.feed(&mut det, 3.0, [0.0; 3], [0.0; 3], 1.0);
        assert!(!det.is_ready(), "{kind:?} learned from a moving interval");
        // Every 5 s window that holds the turn is refused (one per batch from 5 s on), the
        // last for the one batch of the turn it still holds.
        let (refused, why) = det.learn_rejections();
        assert_eq!(refused, 51);
        assert!(
            matches!(why, Some(LearnRejection::Outlier { channel: 5, .. })),
            "{why:?}"
        );
        // Learned from the first 5 s without the turn: 3 s to 8 s.
        synth.feed(&mut det, 1.98, [0.0; 3], [0.0; 3], 1.0);
        assert!(!det.is_ready());
        synth.feed(&mut det, 0.02, [0.0; 3], [0.0; 3], 1.0);
        assert!(det.is_ready());
        let (_, bias) = det.references().unwrap();
        assert!((bias[2] - GYRO_BIAS[2]).abs() < 4.0 * GYRO_SIGMA / 5000f64.sqrt());
    }
    // Not gravity (6 % off: an uncalibrated or wrongly scaled accelerometer) where the
    // calibration file says the part is calibrated: refused, naming the figure and the flag.
    let mut det = detector(DetectorKind::Glrt);
    let mut synth = Synth::new(7);
    synth.feed(&mut det, 5.0, [0.0, 0.0, 0.6], [0.0; 3], 1.0);
    let why = det.learn_rejections().1;
    assert!(
        matches!(why, Some(LearnRejection::Gravity { .. })),
        "{why:?}"
    );
    let message = why.unwrap().to_string();
    assert!(
        message.contains("+6.1 % off") && message.contains("--max-gravity-error"),
        "{message}"
    );
    // Without a fitted calibration (the identity file) the gate is an uncalibrated part's
    // (`learn::UNCALIBRATED_GRAVITY_ERROR`, 39 %): the same rest is learned.
    let identity = calibrate::calibfile::CalibrationFile::identity(G);
    let mut det = ZeroStateDetector::new(config(DetectorKind::Glrt).for_file(&identity));
    let mut synth = Synth::new(7);
    synth.feed(&mut det, 6.0, [0.0, 0.0, 0.6], [0.0; 3], 1.0);
    assert!(det.is_ready(), "{:?}", det.learn_rejections());
    // A cheap part at the allowance's sizing: 4 % sensitivity along gravity and 0.2 g on every
    // axis, reading gravity 27 % high (beyond an allowance of 0.2 g on one axis, 24 %): learned.
    let (g, off) = (G, 0.2 * G);
    let mut det = ZeroStateDetector::new(config(DetectorKind::Glrt).for_file(&identity));
    let mut synth = Synth::new(7);
    synth.feed(&mut det, 6.0, [off, off, 0.04 * g + off], [0.0; 3], 1.0);
    assert!(det.is_ready(), "{:?}", det.learn_rejections());
}

/// A rest noisier than 1.5 times the calibration file's measured noise (a vehicle cruising
/// with its vibration) is not learned from; the reason names the channel and the ratio.
#[test]
fn a_window_much_noisier_than_the_measured_noise_is_not_learned() {
    let mut config = config(DetectorKind::Glrt);
    config.noise = Some(NoiseFloor::from_params(&noise_params(0.5, RATE_HZ), G));
    let mut det = ZeroStateDetector::new(config);
    let mut synth = Synth::new(10);
    synth.feed(&mut det, 8.0, [0.0; 3], [0.0; 3], 1.0);
    assert!(!det.is_ready());
    let (refused, why) = det.learn_rejections();
    assert_eq!(refused, 151, "one per batch from 5 s on");
    match why {
        Some(LearnRejection::TooNoisy { ratio, limit, .. }) => {
            assert!((ratio - 2.0).abs() < 0.1 && limit == 1.5, "{ratio} {limit}")
        }
        other => panic!("{other:?}"),
    }
}

/// A sensor that turns steadily about gravity from its first sample (a robot driving off in a
/// curve) looks still to every steadiness test; at 40 deg/s, beyond any MEMS gyroscope's
/// zero-rate offset, it is refused as a turn, naming its rate (the bias, 0.34 deg/s, with it)
/// and the flag, and the rest
/// after it is learned, with its own bias. Widened past the turn, the turn is learned as bias.
#[test]
fn a_steady_turn_faster_than_a_zero_rate_offset_is_not_learned() {
    let turn = [0.0, 0.0, 40f64.to_radians()];
    let mut det = detector(DetectorKind::Glrt);
    let mut synth = Synth::new(11);
    synth.feed(&mut det, 6.0, [0.0; 3], turn, 1.0);
    assert!(!det.is_ready());
    let why = det.learn_rejections().1.unwrap();
    assert!(
        matches!(why, LearnRejection::Turning { channel: 2, .. }),
        "{why:?}"
    );
    let message = why.to_string();
    assert!(
        message.contains("+40.3 deg/s") && message.contains("--max-gyro-offset-dps"),
        "{message}"
    );
    synth.feed(&mut det, 5.5, [0.0; 3], [0.0; 3], 1.0);
    assert!(det.is_ready());
    let (_, bias) = det.references().unwrap();
    assert!((bias[2] - GYRO_BIAS[2]).abs() < 4.0 * GYRO_SIGMA / 5000f64.sqrt());
    let mut config = config(DetectorKind::Glrt);
    config.learn.max_gyro_offset_rps = 45f64.to_radians();
    let mut det = ZeroStateDetector::new(config);
    Synth::new(11).feed(&mut det, 5.5, [0.0; 3], turn, 1.0);
    let (_, bias) = det.references().unwrap();
    assert!((bias[2] - GYRO_BIAS[2] - turn[2]).abs() < 1e-3, "{bias:?}");
}

#[test]
fn a_gap_empties_the_glrt_window_but_keeps_what_was_learned() {
    let (mut det, mut synth) = learned(DetectorKind::Glrt, 8);
    synth.feed(&mut det, 1.0, [0.0; 3], [0.0; 3], 1.0);
    // Half a batch, then a gap: the partial batch gives no verdict.
    assert!(
        synth
            .feed(&mut det, 0.01, [0.0; 3], [0.0; 3], 1.0)
            .is_empty()
    );
    det.interrupt();
    let v = synth.feed(&mut det, 5.0, [0.0; 3], [0.0; 3], 1.0);
    assert!(det.is_ready());
    assert!(v[..24].iter().all(|v| v.ready && !v.rest));
    let f = rest_fraction(&v[24..]);
    assert!(f > 0.95, "{f}");
}

/// A 3-minute simulated drive with turns and in-place turns at moderate vibration, measured by
/// the calibrated MPU-9250 model through the DLPF our driver configures at 1 kHz (correlated
/// samples, as the part gives them): the GLRT finds the rests and does not call turning or moving
/// at speed rest.
#[test]
fn glrt_on_a_simulated_drive() {
    let mut params = DriveParams::new(180.0);
    params.turns = true;
    params.in_place_turns = true;
    let drive = Drive::new(&params, 11).unwrap();
    let model = mems_sim::model::SensorModel::mpu9250_calibrated();
    let mut sim = SimSensor::new(drive, &model, &VibrationModel::moderate(1.0), 11).unwrap();
    sim.set_dlpf(Some(DlpfGrid::from_power_on(DlpfConfig::driver(RATE_HZ))));
    let mut det = detector(DetectorKind::Glrt);
    let mut truths = Vec::with_capacity(BATCH_LEN);
    let (mut rest, mut rest_hit, mut moving_fast, mut moving_fast_hit) = (0, 0, 0, 0);
    for k in 0..(180.0 * RATE_HZ) as u64 {
        let t = k as f64 / RATE_HZ;
        let (analog, truth) = sim.sample_with_truth(t, RATE_HZ);
        let raw = adc::quantize_sample(
            &analog,
            ipc_types::units::AccelRange::G2,
            ipc_types::units::GyroRange::Dps250,
            ns_from_s(t),
            k,
        );
        truths.push(truth);
        let a = raw.accel_g.map(|x| x * G);
        let w = raw.gyro_dps.map(f64::to_radians);
        if let Some(v) = det.push(raw.stamps.sample_ns, a, w) {
            for tr in truths.drain(..) {
                let speed = tr.velocity_mps[0].hypot(tr.velocity_mps[1]);
                let turning = tr.angular_rate_rps[2].abs() > 2f64.to_radians();
                if tr.at_rest && v.ready {
                    rest += 1;
                    rest_hit += usize::from(v.rest);
                }
                if speed > 0.1 || turning {
                    moving_fast += 1;
                    moving_fast_hit += usize::from(v.rest);
                }
            }
        }
    }
    let detection = rest_hit as f64 / rest as f64;
    assert!(detection > 0.95, "detection rate {detection}");
    assert!(moving_fast > 30_000, "{moving_fast} moving samples");
    assert_eq!(moving_fast_hit, 0, "rest flagged while moving or turning");
}

/// Noise parameters whose accelerometer and gyro white noise is `scale` times the synthetic
/// sensor's, as measured at `rate_hz` (per-sample sigma = N sqrt(rate)).
fn noise_params(scale: f64, rate_hz: f64) -> calibrate::noise_params::NoiseParams {
    use calibrate::noise_params::{AxisNoise, Estimate, NoiseParams, SensorNoise};
    let axis = |sigma: f64| AxisNoise {
        white_noise_density: Some(Estimate {
            value: scale * sigma / rate_hz.sqrt(),
            sigma: 1e-3 * sigma,
        }),
        ..Default::default()
    };
    let sensor = |unit: &str, sigma: f64| SensorNoise {
        unit: unit.into(),
        x: axis(sigma),
        y: axis(sigma),
        z: axis(sigma),
    };
    NoiseParams {
        source: "static.csv".into(),
        sample_rate_hz: rate_hz,
        record_length_s: 600.0,
        samples: 600_000,
        gravity_mps2: G,
        accel: sensor("m/s^2", ACCEL_SIGMA),
        gyro: Some(sensor("rad/s", GYRO_SIGMA)),
    }
}

/// The calibration file's noise parameters raise learned noise levels that came out lower
/// than the sensor's (here the table says 1.8 times the learned noise): the later rest, at the
/// table's noise, is then called rest, which the learned levels alone call motion. A table
/// measured at another rate, or one a little below the learned levels, changes nothing.
#[test]
fn noise_parameters_are_a_floor_for_the_learned_levels() {
    for kind in [DetectorKind::Yu, DetectorKind::Glrt] {
        let run = |floor: Option<NoiseFloor>| {
            let mut config = config(kind);
            config.noise = floor;
            let mut det = ZeroStateDetector::new(config);
            let mut synth = Synth::new(9);
            let learned = synth.feed(&mut det, 5.0, [0.0; 3], [0.0; 3], 1.0);
            let reference = learned.last().unwrap().learned.expect("learned");
            let rest = synth.feed(&mut det, 10.0, [0.0; 3], [0.0; 3], 1.8);
            (reference, rest_fraction(&rest[25..]))
        };
        let (plain, plain_rest) = run(None);
        let floor = NoiseFloor::from_params(&noise_params(1.8, RATE_HZ), G);
        let (raised, raised_rest) = run(Some(floor));
        for i in 0..3 {
            assert!((raised.accel_sigma_mps2[i] / (1.8 * ACCEL_SIGMA) - 1.0).abs() < 1e-12);
            assert!((raised.gyro_sigma_rps[i] / (1.8 * GYRO_SIGMA) - 1.0).abs() < 1e-12);
            // The scatter of the batch means stays as learned.
            let learned = plain.accel_correlation[i] * plain.accel_sigma_mps2[i].powi(2);
            let kept = raised.accel_correlation[i] * raised.accel_sigma_mps2[i].powi(2);
            assert!(kept >= learned * (1.0 - 1e-12));
            assert_eq!(raised.accel_mean_mps2[i], plain.accel_mean_mps2[i]);
        }
        assert!(
            plain_rest < 0.2,
            "{kind:?}: learned levels only: {plain_rest}"
        );
        assert!(raised_rest > 0.9, "{kind:?}: with the floor: {raised_rest}");

        // Measured at 200 Hz: not applicable to a 1 kHz stream.
        let (other_rate, _) = run(Some(NoiseFloor::from_params(&noise_params(1.8, 200.0), G)));
        assert_eq!(other_rate, plain);
        // Below the learned levels (within the learner's 1.5x noise ceiling): the learned
        // levels stay.
        let (quieter, _) = run(Some(NoiseFloor::from_params(
            &noise_params(0.8, RATE_HZ),
            G,
        )));
        assert_eq!(quieter.accel_sigma_mps2, plain.accel_sigma_mps2);
        assert_eq!(quieter.gyro_sigma_rps, plain.gyro_sigma_rps);
    }
}

/// Feeds `seconds` at `rate_hz` to `det` from sample `*k` on: white noise of the MPU-9250 at
/// 1 kHz, gravity's reaction turned about x by `tilt(t)` rad, rotating about x at `rate(t)`
/// rad/s; returns the verdicts.
fn feed_tilting(
    det: &mut ZeroStateDetector,
    rng: &mut ChaCha8Rng,
    k: &mut u64,
    rate_hz: f64,
    seconds: f64,
    tilt: impl Fn(f64) -> f64,
    rate: impl Fn(f64) -> f64,
) -> Vec<Verdict> {
    feed_biased(det, rng, k, (rate_hz, seconds), tilt, rate, [0.0; 3])
}

/// [`feed_tilting`] (`at`: its rate, Hz, and duration, s) with an accelerometer bias `bias`
/// (m/s^2, sensor frame, added to every sample).
fn feed_biased(
    det: &mut ZeroStateDetector,
    rng: &mut ChaCha8Rng,
    k: &mut u64,
    (rate_hz, seconds): (f64, f64),
    tilt: impl Fn(f64) -> f64,
    rate: impl Fn(f64) -> f64,
    bias: [f64; 3],
) -> Vec<Verdict> {
    let na = Normal::new(0.0, ACCEL_SIGMA).unwrap();
    let ng = Normal::new(0.0, GYRO_SIGMA).unwrap();
    let mut out = Vec::new();
    for _ in 0..(seconds * rate_hz).round() as usize {
        let t = *k as f64 / rate_hz;
        *k += 1;
        let phi = tilt(t);
        let a = [
            bias[0] + na.sample(rng),
            bias[1] + G * phi.sin() + na.sample(rng),
            bias[2] + G * phi.cos() + na.sample(rng),
        ];
        let w = [
            GYRO_BIAS[0] + rate(t) + ng.sample(rng),
            GYRO_BIAS[1] + ng.sample(rng),
            GYRO_BIAS[2] + ng.sample(rng),
        ];
        out.extend(det.push(ns_from_s(t), a, w));
    }
    out
}

#[test]
fn a_half_second_rest_is_enough_to_learn_and_rest_follows_at_once() {
    // Learning from half a second (`--learn-s 0.5`); the GLRT's window starts full of that
    // rest, so the very next batch is decided at rest.
    let mut c = DetectorConfig::new(DetectorKind::Glrt, G);
    c.learn.duration_s = 0.5;
    let mut det = ZeroStateDetector::new(c);
    let mut synth = Synth::new(11);
    let v = synth.feed(&mut det, 0.5, [0.0; 3], [0.0; 3], 1.0);
    assert!(det.is_ready(), "{:?}", det.learn_rejections());
    assert_eq!(v.last().unwrap().learned.unwrap().batches, 25);
    let v = synth.feed(&mut det, 0.5, [0.0; 3], [0.0; 3], 1.0);
    assert!(v[0].rest, "the first batch after learning");
    assert!(rest_fraction(&v) > 0.9, "{}", rest_fraction(&v));
    // Motion is still motion, once the window holds a few of its batches (the thresholds of
    // a half-second learning are wider than a 5 s one's).
    let moving = synth.feed(&mut det, 1.0, [0.3, 0.0, 0.0], [0.0; 3], 1.0);
    assert_eq!(rest_fraction(&moving[3..]), 0.0);
}

/// A robot's detector under a longer learning (`--learn-s 5`) does not wait for a rest that
/// long, which a robot that stops for 2 s never gives: it is ready from its first half second,
/// and learns again from the first 5 s of rest at most half as noisy as that. A first half
/// second learned while the robot drove off (its vibration, 4x a rest's noise) is replaced by
/// the rest that comes later; a rest like the first, or a steady cruise, which passes every
/// learning check but is noisier than the first rest, is not taken over it.
#[test]
fn a_longer_learning_starts_from_its_first_half_second_and_learns_again_at_a_quiet_rest() {
    let mut c = DetectorConfig::robot(G);
    c.learn.duration_s = 5.0;
    let mut det = ZeroStateDetector::new(c);
    let mut synth = Synth::new(21);
    let v = synth.feed(&mut det, 0.5, [0.0; 3], [0.0; 3], 4.0);
    assert!(det.is_ready(), "{:?}", det.learn_rejections());
    assert_eq!(v.last().unwrap().learned.unwrap().batches, 25);
    synth.feed(&mut det, 3.0, [0.3, 0.0, 0.0], [0.0; 3], 4.0);
    let rest = synth.feed(&mut det, 6.0, [0.0; 3], [0.0; 3], 1.0);
    let again = det.relearned().expect("learned again");
    let start_s = again.t_start_ns as f64 * 1e-9;
    assert!((3.5..3.6).contains(&start_s), "{start_s}");
    assert!(again.duration_s >= 5.0, "{}", again.duration_s);
    let sigma = again.accel_sigma_mps2[0];
    assert!((sigma / ACCEL_SIGMA - 1.0).abs() < 0.1, "{sigma}");
    // The verdict of the batch that ends the window is rest, and carries no first learning.
    let last = rest.iter().rposition(|v| v.rest).unwrap();
    assert!(rest[last].learned.is_none());
    assert_eq!(
        det.reference().unwrap().accel_sigma_mps2,
        again.accel_sigma_mps2
    );
    // Without the longer learning nothing is learned again.
    let mut det = ZeroStateDetector::new(DetectorConfig::robot(G));
    let mut synth = Synth::new(21);
    synth.feed(&mut det, 0.5, [0.0; 3], [0.0; 3], 4.0);
    synth.feed(&mut det, 9.0, [0.0; 3], [0.0; 3], 1.0);
    assert!(det.is_ready() && det.relearned().is_none());
    // A rest first, then a long steady cruise: the cruise passes as a window, but is noisier;
    // nor does a longer rest like the first replace it.
    for (seed, later) in [(22, 4.0), (23, 1.0)] {
        let mut det = ZeroStateDetector::new(c);
        let mut synth = Synth::new(seed);
        synth.feed(&mut det, 0.5, [0.0; 3], [0.0; 3], 1.0);
        synth.feed(&mut det, 8.0, [0.0; 3], [0.0; 3], later);
        assert!(det.is_ready() && det.relearned().is_none(), "{later}");
    }
}

#[test]
fn a_rest_after_a_tilt_is_rest_and_a_tilt_the_gyro_did_not_see_is_not() {
    for (seen, what) in [
        (true, "tilted by 20 deg, the gyro saw it"),
        (false, "no rotation seen"),
    ] {
        let mut det = ZeroStateDetector::new(DetectorConfig::new(DetectorKind::Glrt, G));
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let mut k = 0;
        let level = |_t: f64| 0.0;
        feed_tilting(&mut det, &mut rng, &mut k, RATE_HZ, 5.0, level, level);
        assert!(det.is_ready());
        // Tilt by 20 degrees about x over 1 s, from t = 5 s; then rest there.
        let end = 20f64.to_radians();
        let tilt = move |t: f64| end * (t - 5.0).clamp(0.0, 1.0);
        let rate = move |t: f64| {
            if seen && (5.0..6.0).contains(&t) {
                end
            } else {
                0.0
            }
        };
        feed_tilting(&mut det, &mut rng, &mut k, RATE_HZ, 1.0, tilt, rate);
        let rest = feed_tilting(&mut det, &mut rng, &mut k, RATE_HZ, 1.9, tilt, rate);
        // The window needs half a second of the new rest.
        let f = rest_fraction(&rest[25..]);
        if seen {
            assert!(f > 0.9, "{what}: rest fraction {f}");
            assert_eq!(det.gravity_reanchored(), 0, "{what}");
        } else {
            // Gravity moved 20 degrees without a rotation: acceleration, not a rest, until
            // it has been still by every other test for REANCHOR_S.
            assert_eq!(f, 0.0, "{what}");
            assert_eq!(det.gravity_reanchored(), 0, "{what}");
            let waited = until_reanchored(&mut det, &mut rng, &mut k, tilt, rate);
            assert!(waited <= 2.0, "{what}: measured anew {waited} s later");
            let later = feed_tilting(&mut det, &mut rng, &mut k, RATE_HZ, 1.0, tilt, rate);
            let f = rest_fraction(&later);
            assert!(
                f > 0.9,
                "{what}, after the reference was measured anew: {f}"
            );
        }
    }
}

/// A gravity reference the gyroscope carried wrongly (here a 20 % scale error on a tilt of
/// 22.5 deg: 4.5 deg the carrying does not see) is measured anew once the sensor has been
/// still by every other test for `REANCHOR_S`; a steady horizontal acceleration with a
/// vehicle's vibration never is.
#[test]
fn a_lost_gravity_reference_is_measured_anew_but_a_vibrating_acceleration_is_not_rest() {
    use calibrate::zero_state::glrt::REANCHOR_S;
    let (mut det, mut synth) = learned(DetectorKind::Glrt, 14);
    // A steady 0.5 m/s^2 forward acceleration for 10 s, vibrating at three times the noise.
    let v = synth.feed(&mut det, 10.0, [0.5, 0.0, 0.0], [0.0; 3], 3.0);
    assert_eq!(rest_fraction(&v), 0.0);
    assert_eq!(det.gravity_reanchored(), 0);

    let mut det = ZeroStateDetector::new(DetectorConfig::new(DetectorKind::Glrt, G));
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    let mut k = 0;
    let level = |_t: f64| 0.0;
    feed_tilting(&mut det, &mut rng, &mut k, RATE_HZ, 5.0, level, level);
    assert!(det.is_ready());
    // From t = 5 s: a tilt of 22.5 deg about x over 1 s that the gyroscope reads 20 % low, so
    // the carried reference misses 4.5 deg of it; then rest there.
    let end = 22.5f64.to_radians();
    let tilt = move |t: f64| end * (t - 5.0).clamp(0.0, 1.0);
    let rate = move |t: f64| {
        if (5.0..6.0).contains(&t) {
            0.8 * end
        } else {
            0.0
        }
    };
    feed_tilting(&mut det, &mut rng, &mut k, RATE_HZ, 1.0, tilt, rate);
    let before = feed_tilting(&mut det, &mut rng, &mut k, RATE_HZ, REANCHOR_S, tilt, rate);
    assert_eq!(
        rest_fraction(&before),
        0.0,
        "4.5 deg off the carried reference"
    );
    let waited = until_reanchored(&mut det, &mut rng, &mut k, tilt, rate);
    assert!(waited <= 2.0, "measured anew {waited} s later");
    let after = feed_tilting(&mut det, &mut rng, &mut k, RATE_HZ, 1.0, tilt, rate);
    assert!(rest_fraction(&after) > 0.9, "{}", rest_fraction(&after));
}

/// A rest whose specific force reads a magnitude the gravity reference does not hold (an
/// accelerometer bias read at another attitude, or moved by temperature) is a rest once the
/// sensor has been still by the scatter and the gyroscope for `REANCHOR_S`, and for as long as
/// it stays so: a detector whose window is long (here 2 s, whose mean holds gravity's
/// magnitude to 0.2 mm/s^2) otherwise never rests again. The reference's magnitude is not
/// moved by it. A magnitude beyond what a calibrated part's bias reads (10 mg) and a vertical
/// acceleration that vibrates stay motion.
#[test]
fn a_rest_whose_gravity_magnitude_moved_is_rest_after_reanchor_s() {
    use calibrate::zero_state::glrt::REANCHOR_S;
    let mut c = DetectorConfig::new(DetectorKind::Glrt, G);
    c.glrt.window_s = 2.0;
    let mut det = ZeroStateDetector::new(c);
    let mut synth = Synth::new(16);
    synth.feed(&mut det, 5.0, [0.0; 3], [0.0; 3], 1.0);
    assert!(det.is_ready());
    let magnitude = |det: &ZeroStateDetector| {
        let (accel, _) = det.references().unwrap();
        accel.iter().map(|a| a * a).sum::<f64>().sqrt()
    };
    let learned = magnitude(&det);
    // Moving, then at rest with the magnitude 20 mm/s^2 (2 mg) above the learned one.
    let moved = [0.0, 0.0, 0.02];
    synth.feed(&mut det, 2.0, [0.3, 0.0, 0.0], [0.0; 3], 3.0);
    let first = synth.feed(&mut det, 2.0, moved, [0.0; 3], 1.0);
    assert_eq!(rest_fraction(&first), 0.0, "2 mg off the learned magnitude");
    assert_eq!(det.gravity_held(), 0);
    let later = synth.feed(&mut det, REANCHOR_S + 1.0, moved, [0.0; 3], 1.0);
    assert_eq!(det.gravity_held(), 1);
    assert!(rest_fraction(&later) > 0.0);
    let rest = synth.feed(&mut det, 10.0, moved, [0.0; 3], 1.0);
    assert!(rest_fraction(&rest) > 0.95, "{}", rest_fraction(&rest));
    assert_eq!(det.gravity_held(), 1, "one rest, held");
    assert_eq!(det.gravity_reanchored(), 0);
    // The reference keeps its magnitude.
    assert!(
        (magnitude(&det) - learned).abs() < 1e-9,
        "{learned} -> {}",
        magnitude(&det)
    );
    // Beyond a calibrated part's bias bound (63 mm/s^2), a steady vertical acceleration of
    // 0.1 m/s^2 with no vibration and no turn is no rest, however long.
    synth.feed(&mut det, 1.0, [0.3, 0.0, 0.0], [0.0; 3], 3.0);
    let beyond = synth.feed(&mut det, 6.0, [0.0, 0.0, 0.1], [0.0; 3], 1.0);
    assert_eq!(rest_fraction(&beyond), 0.0);
    // A vertical acceleration that vibrates is no rest either.
    let lift = synth.feed(&mut det, 5.0, [0.0, 0.0, 0.03], [0.0; 3], 3.0);
    assert_eq!(rest_fraction(&lift), 0.0);
    assert_eq!(det.gravity_held(), 1);
}

/// An arm whose accelerometer carries a 6 mg bias (as the simulated arm of docs/diagnosis.md)
/// rests at poses up to 90 deg from the start, 3 s each: each pose reads gravity's magnitude
/// up to 50 mm/s^2 off (the bias along gravity there), beyond the 0.5 s window's noise, so it
/// is rest only once held `REANCHOR_S`; and between poses, at the start attitude again, it is
/// rest at once: the poses did not drag the reference's magnitude off.
#[test]
fn an_arms_biased_poses_do_not_move_the_magnitude_reference_off() {
    use calibrate::zero_state::glrt::REANCHOR_S;
    let bias = [0.059, -0.049, 0.0];
    let mut det = ZeroStateDetector::new(DetectorConfig::new(DetectorKind::Glrt, G));
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let mut k = 0;
    let level = |_t: f64| 0.0;
    feed_biased(
        &mut det,
        &mut rng,
        &mut k,
        (RATE_HZ, 5.0),
        level,
        level,
        bias,
    );
    assert!(det.is_ready());
    let magnitude = |det: &ZeroStateDetector| {
        let (accel, _) = det.references().unwrap();
        accel.iter().map(|a| a * a).sum::<f64>().sqrt()
    };
    let learned = magnitude(&det);
    for (i, deg) in [90.0f64, -60.0, 45.0, -90.0].into_iter().enumerate() {
        // Over 1 s to the pose (the gyroscope sees it), 3 s there, over 1 s back, 1 s level.
        let t0 = k as f64 / RATE_HZ;
        let end = deg.to_radians();
        let tilt = move |t: f64| end * ((t - t0).clamp(0.0, 1.0) - (t - t0 - 4.0).clamp(0.0, 1.0));
        let rate = move |t: f64| {
            let s = t - t0;
            if (0.0..1.0).contains(&s) {
                end
            } else if (4.0..5.0).contains(&s) {
                -end
            } else {
                0.0
            }
        };
        let at = |s: f64| (RATE_HZ, s);
        feed_biased(&mut det, &mut rng, &mut k, at(1.0), tilt, rate, bias);
        let pose = feed_biased(&mut det, &mut rng, &mut k, at(3.0), tilt, rate, bias);
        // The window's first 0.5 s, then REANCHOR_S: no rest before, rest after.
        let held = ((0.5 + REANCHOR_S) * RATE_HZ) as usize / BATCH_LEN;
        assert_eq!(rest_fraction(&pose[..held - 2]), 0.0, "pose {deg} deg");
        assert!(rest_fraction(&pose[held + 1..]) > 0.9, "pose {deg} deg");
        assert_eq!(det.gravity_held(), i as u64 + 1, "pose {deg} deg");
        feed_biased(&mut det, &mut rng, &mut k, at(1.0), tilt, rate, bias);
        let back = feed_biased(&mut det, &mut rng, &mut k, at(1.0), tilt, rate, bias);
        let f = rest_fraction(&back[back.len() / 2..]);
        assert!(f > 0.9, "back from {deg} deg: rest fraction {f}");
    }
    let drift = magnitude(&det) - learned;
    assert!(drift.abs() < 2e-3, "the magnitude moved {drift} m/s^2");
    assert_eq!(det.gravity_reanchored(), 0);
}

/// Feeds `tilt` and `rate` in steps of 0.1 s until `det` has measured its gravity reference
/// anew once (at most 3 s); returns the time that took, s.
fn until_reanchored(
    det: &mut ZeroStateDetector,
    rng: &mut ChaCha8Rng,
    k: &mut u64,
    tilt: impl Fn(f64) -> f64 + Copy,
    rate: impl Fn(f64) -> f64 + Copy,
) -> f64 {
    let mut waited = 0.0;
    while det.gravity_reanchored() == 0 && waited < 3.0 {
        feed_tilting(det, rng, k, RATE_HZ, 0.1, tilt, rate);
        waited += 0.1;
    }
    assert_eq!(
        det.gravity_reanchored(),
        1,
        "not measured anew within {waited} s"
    );
    waited
}

#[test]
fn windows_are_seconds_at_any_rate() {
    // At 40 Hz a batch is half a second: the learning takes 10 batches (5 s), the GLRT's
    // 0.5 s window one (25 batches of 20 samples would be 12.5 s), and a rest is called from
    // the first batch after learning.
    let mut det = ZeroStateDetector::new(DetectorConfig::new(DetectorKind::Glrt, G));
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let mut k = 0;
    let level = |_t: f64| 0.0;
    let v = feed_tilting(&mut det, &mut rng, &mut k, 40.0, 5.0, level, level);
    assert_eq!(v.len(), 10);
    assert!(det.is_ready(), "{:?}", det.learn_rejections());
    let v = feed_tilting(&mut det, &mut rng, &mut k, 40.0, 2.0, level, level);
    assert!(v.iter().all(|v| v.rest), "{v:?}");
}

/// A walker turning steadily with the sensor in hand: 0.2 rad/s about z (a 4 m circle at 0.8
/// m/s) and a bounce of 0.7 m/s^2 at 1.7 steps/s along z. Its batch means are steady enough
/// for the white-noise tests, whose scatter the bounce widens, so without a ceiling on the
/// accelerometer's noise the turn is learned as the gyro's bias; with
/// [`REST_ACCEL_SIGMA_MPS2`] it is refused as shaking, and the rest after it is learned.
#[test]
fn a_walkers_steady_turn_is_no_rest_under_the_rest_noise_ceiling() {
    use calibrate::zero_state::learn::REST_ACCEL_SIGMA_MPS2;
    let walk_then_rest = |ceiling: Option<f64>| {
        let mut config = DetectorConfig::robot(G);
        config.learn.max_accel_sigma_mps2 = ceiling;
        let mut det = ZeroStateDetector::new(config);
        let mut synth = Synth::new(21);
        let mut learned = None;
        for k in 0..(3.0 * RATE_HZ) as usize {
            let t_s = k as f64 / RATE_HZ;
            let walking = t_s < 2.0;
            let bounce = 0.7 * (2.0 * std::f64::consts::PI * 1.7 * t_s).sin();
            let (t, a, w) = if walking {
                synth.sample([0.0, 0.0, bounce], [0.0, 0.0, 0.2], 1.0)
            } else {
                synth.sample([0.0; 3], [0.0; 3], 1.0)
            };
            if let Some(v) = det.push(t, a, w) {
                learned = learned.or(v.learned.map(|r| (t_s, r)));
            }
        }
        (learned, det.learn_rejections())
    };
    let (learned, _) = walk_then_rest(None);
    let (t_s, r) = learned.expect("learned without the ceiling");
    assert!(t_s < 2.0, "learned at {t_s} s");
    assert!(
        (r.gyro_mean_rps[2] - 0.2).abs() < 0.01,
        "{:?}",
        r.gyro_mean_rps
    );
    let (learned, (refused, _)) = walk_then_rest(Some(REST_ACCEL_SIGMA_MPS2));
    let (t_s, r) = learned.expect("learned on the rest");
    assert!(t_s > 2.0, "learned at {t_s} s");
    assert!(refused > 10, "{refused}");
    for (learned, bias) in r.gyro_mean_rps.iter().zip(GYRO_BIAS) {
        assert!((learned - bias).abs() < 0.002, "{:?}", r.gyro_mean_rps);
    }
}

/// The ceiling's refusal names the axis and its noise.
#[test]
fn a_shaking_window_is_refused_by_name() {
    let mut config = DetectorConfig::robot(G);
    config.learn.max_accel_sigma_mps2 = Some(0.15);
    let mut det = ZeroStateDetector::new(config);
    let mut synth = Synth::new(22);
    // Four times the MPU-9250's noise at 1 kHz: 0.37 m/s^2 per sample.
    synth.feed(&mut det, 2.0, [0.0; 3], [0.0; 3], 4.0);
    assert!(!det.is_ready());
    match det.learn_rejections().1 {
        Some(why @ LearnRejection::Shaking { sigma_mps2, .. }) => {
            assert!((sigma_mps2 - 4.0 * ACCEL_SIGMA).abs() < 0.05, "{why}");
            assert!(why.to_string().contains("about its mean"), "{why}");
        }
        other => panic!("{other:?}"),
    }
}

/// An uncalibrated part (4 % scale error and a 0.15 g offset on every axis, so its rest reads
/// gravity 19 % off) turned 30 deg about gravity, or pitched by 5 deg, its gyro seeing the
/// turn, rests again. Carrying the reference turns its offset with it: about gravity by
/// `2 sin(15 deg) 0.21 g` = 0.53 m/s^2 across gravity; a pitch moves the offset's share of the
/// magnitude by `sin(5 deg) 0.15 g` = 0.13 m/s^2. The reference's uncertainty must allow both.
/// The same turn without the offset (a calibrated part) keeps the calibrated allowance: a
/// horizontal acceleration of 0.3 m/s^2 after it (five times the gyro's turn error there) is
/// still motion.
#[test]
fn an_uncalibrated_part_rests_again_after_a_turn() {
    let na = Normal::new(0.0, ACCEL_SIGMA).unwrap();
    let ng = Normal::new(0.0, GYRO_SIGMA).unwrap();
    // (offset, g; turn axis; angle, deg; acceleration after it, m/s^2 along x; a rest?)
    let cases = [
        (0.15, 2, 30.0, 0.0, true),
        (0.15, 1, 5.0, 0.0, true),
        (0.0, 2, 30.0, 0.0, true),
        (0.0, 2, 30.0, 0.3, false),
    ];
    for (offset_g, axis, angle_deg, extra, want_rest) in cases {
        let mut c = DetectorConfig::new(DetectorKind::Glrt, G);
        c.learn.max_gravity_error = calibrate::zero_state::learn::UNCALIBRATED_GRAVITY_ERROR;
        let mut det = ZeroStateDetector::new(c);
        let mut rng = ChaCha8Rng::seed_from_u64(15);
        let scale = if offset_g > 0.0 { 1.04 } else { 1.0 };
        let angle = f64::to_radians(angle_deg);
        // The turn takes 1 s from t = 5 s, at `angle` rad/s about `axis`.
        let turned = |t: f64| angle * (t - 5.0).clamp(0.0, 1.0);
        let mut feed = |det: &mut ZeroStateDetector, from_s: f64, seconds: f64, extra: f64| {
            let n = (seconds * RATE_HZ).round() as usize;
            let k0 = (from_s * RATE_HZ).round() as usize;
            let mut out = Vec::new();
            for k in k0..k0 + n {
                let t = k as f64 / RATE_HZ;
                // Gravity's reaction in the sensor frame: unmoved by a turn about z (gravity),
                // turned to (-g sin phi, 0, g cos phi) by a pitch of phi about y.
                let phi = if axis == 1 { turned(t) } else { 0.0 };
                let truth = [extra - G * phi.sin(), 0.0, G * phi.cos()];
                let a =
                    std::array::from_fn(|i| scale * truth[i] + offset_g * G + na.sample(&mut rng));
                let rate = if (5.0..6.0).contains(&t) { angle } else { 0.0 };
                let w = std::array::from_fn(|i| {
                    GYRO_BIAS[i] + if i == axis { rate } else { 0.0 } + ng.sample(&mut rng)
                });
                out.extend(det.push(ns_from_s(t), a, w));
            }
            out
        };
        feed(&mut det, 0.0, 5.0, 0.0);
        assert!(det.is_ready(), "{:?}", det.learn_rejections());
        feed(&mut det, 5.0, 1.0, 0.0);
        let after = feed(&mut det, 6.0, 1.9, extra);
        // The window needs half a second of the new rest.
        let f = rest_fraction(&after[25..]);
        let what = format!(
            "offset {offset_g} g, {angle_deg} deg about axis {axis}, {extra} m/s^2 after it"
        );
        if want_rest {
            assert!(f > 0.9, "{what}: rest fraction {f}");
        } else {
            assert_eq!(f, 0.0, "{what}");
        }
        assert_eq!(det.gravity_reanchored(), 0, "{what}");
    }
}
