//! The drive planner's guarantees and the vibration's lack of DC, against independent
//! computations on the sampled truth: motions end in a rest at least every `max_motion_s`,
//! rests are exact (speed and rate exactly zero, flagged on every sample), equal consecutive
//! speeds give finite truth that still integrates, and the vibration's time integral stays
//! bounded (no power at zero frequency) with a mean within its standard error of zero.

use std::f64::consts::TAU;

use mems_sim::SimSensor;
use mems_sim::model::{G_MPS2, SensorModel};
use mems_sim::scenario::{Drive, DriveParams, DriveSegment, Scenario};
use mems_sim::vibration::{Vibration, VibrationModel};
use nalgebra::Vector3;
use recording::Truth;

fn truths(s: &impl Scenario, rate_hz: f64) -> Vec<Truth> {
    let n = (s.duration_s() * rate_hz).floor() as usize;
    (0..=n).map(|k| s.truth(k as f64 / rate_hz)).collect()
}

/// Lengths of the runs of consecutive samples not flagged at rest, s (sample count / rate).
fn motion_runs(tr: &[Truth], rate_hz: f64) -> Vec<f64> {
    let mut runs = Vec::new();
    let mut n = 0usize;
    for t in tr {
        if t.at_rest {
            if n > 0 {
                runs.push(n as f64 / rate_hz);
            }
            n = 0;
        } else {
            n += 1;
        }
    }
    runs
}

#[test]
fn the_robot_rests_at_least_every_max_motion_s() {
    let rate = 20.0;
    let mut longest = 0.0f64;
    for seed in 0..12 {
        for (turns, in_place) in [(false, false), (true, true)] {
            let params = DriveParams {
                turns,
                in_place_turns: in_place,
                ..DriveParams::new(600.0)
            };
            assert_eq!(params.max_motion_s, 30.0);
            let tr = truths(&Drive::new(&params, seed).unwrap(), rate);
            let runs = motion_runs(&tr, rate);
            assert!(runs.len() >= 8, "seed {seed}: only {} motions", runs.len());
            for run in &runs {
                // A run of n moving samples spans at most n / rate of a motion's open interval.
                assert!(
                    *run <= 30.0,
                    "seed {seed}, turns {turns}: motion of {run} s"
                );
            }
            longest = longest.max(runs.iter().copied().fold(0.0, f64::max));
        }
    }
    // The bound is active: without it, 3 legs of up to 10 s plus turns and speed changes run
    // past 30 s, so some motions are cut to just under it.
    assert!(longest > 25.0, "longest motion {longest} s");

    // A tighter bound is honoured too.
    let params = DriveParams {
        turns: true,
        max_motion_s: 15.0,
        ..DriveParams::new(600.0)
    };
    let tr = truths(&Drive::new(&params, 3).unwrap(), rate);
    let runs = motion_runs(&tr, rate);
    assert!(runs.iter().all(|r| *r <= 15.0), "{runs:?}");
    assert!(runs.iter().any(|r| *r > 12.0), "{runs:?}");
}

#[test]
fn a_max_motion_shorter_than_the_shortest_motion_is_rejected() {
    // Accelerating to 1 m/s and braking at 0.5 m/s^2 take 8/3 * 2 s each, plus a 2 s leg.
    let e = Drive::new(
        &DriveParams {
            max_motion_s: 12.0,
            ..DriveParams::new(60.0)
        },
        0,
    )
    .unwrap_err();
    assert_eq!(e.field, "max_motion_s");
    assert!(e.to_string().contains("12.66"), "{e}");
    // A 120 degree in-place turn at 45 deg/s takes 8/3 * 120 / 45 = 7.1 s.
    let e = Drive::new(
        &DriveParams {
            max_motion_s: 7.0,
            cruise_speed_mps: [0.1, 0.2],
            leg_s: [1.0, 2.0],
            in_place_turns: true,
            ..DriveParams::new(60.0)
        },
        0,
    )
    .unwrap_err();
    assert_eq!(e.field, "max_motion_s");
    assert!(e.to_string().contains("in-place turn"), "{e}");
}

#[test]
fn every_sample_of_a_rest_is_flagged_with_exactly_zero_motion() {
    let rate = 100.0;
    let mut rests = 0;
    for seed in 0..10 {
        let params = DriveParams {
            turns: true,
            in_place_turns: true,
            ..DriveParams::new(300.0)
        };
        let drive = Drive::new(&params, seed).unwrap();
        for seg in drive.segments().iter().filter(|s| s.at_rest) {
            rests += 1;
            let first = (seg.start_s * rate).ceil() as usize;
            let end = seg.start_s + seg.duration_s;
            let mut k = first;
            while (k as f64) / rate < end {
                let t = drive.truth(k as f64 / rate);
                assert!(
                    t.at_rest,
                    "seed {seed}: rest sample at {} s not flagged",
                    k as f64 / rate
                );
                assert_eq!(
                    t.velocity_mps,
                    [0.0; 3],
                    "seed {seed} at {} s",
                    k as f64 / rate
                );
                assert_eq!(t.angular_rate_rps, [0.0; 3]);
                assert_eq!(drive.wheel_speed_mps(k as f64 / rate), 0.0);
                k += 1;
            }
        }
    }
    assert!(rests > 50, "{rests} rests");
}

/// Largest difference between the truth positions and the composite-Simpson integral of the
/// truth velocities at step `h`, m, and whether every truth value was finite.
fn position_vs_velocity_integral(drive: &Drive, h: f64) -> (f64, bool) {
    let mut finite = true;
    let mut v = |t: f64| {
        let tr = drive.truth(t);
        finite &= tr
            .velocity_mps
            .iter()
            .chain(&tr.position_m)
            .chain(&tr.specific_force_mps2)
            .all(|x| x.is_finite());
        Vector3::from(tr.velocity_mps)
    };
    let mut p = Vector3::zeros();
    let mut worst = 0.0f64;
    let steps = (drive.duration_s() / (2.0 * h)) as usize;
    for k in 0..steps {
        let t0 = 2.0 * h * k as f64;
        p += h / 3.0 * (v(t0) + 4.0 * v(t0 + h) + v(t0 + 2.0 * h));
        worst = worst.max((p - Vector3::from(drive.truth(t0 + 2.0 * h).position_m)).norm());
    }
    (worst, finite)
}

#[test]
fn equal_consecutive_speeds_give_finite_truth_that_integrates() {
    for turns in [false, true] {
        let params = DriveParams {
            cruise_speed_mps: [0.5, 0.5],
            max_legs: 3,
            turns,
            ..DriveParams::new(200.0)
        };
        let drive = Drive::new(&params, 4).unwrap();
        // Some motion has several legs, i.e. two legs at the same speed follow each other
        // (directly, or around a turn).
        let is_leg = |s: &DriveSegment| {
            !s.at_rest && s.speed_change_mps == 0.0 && s.heading_change_rad == 0.0
        };
        let segs = drive.segments();
        let multi_leg = segs.windows(2).any(|w| is_leg(&w[0]) && is_leg(&w[1]))
            || segs
                .windows(3)
                .any(|w| is_leg(&w[0]) && w[1].heading_change_rad != 0.0 && is_leg(&w[2]));
        assert!(multi_leg, "turns {turns}: no consecutive legs");
        assert!(drive.segments().iter().all(|s| s.duration_s > 0.0));
        let (worst, finite) = position_vs_velocity_integral(&drive, 1e-3);
        assert!(finite, "turns {turns}: non-finite truth");
        assert!(
            worst < 1e-8,
            "turns {turns}: position off its integral by {worst} m"
        );
        // Independently: the speed is 0.5 m/s whenever the robot cruises, so the distance is
        // at least 0.5 m/s times the time spent at exactly that speed.
        let tr = truths(&drive, 100.0);
        let cruising = tr
            .iter()
            .filter(|t| (Vector3::from(t.velocity_mps).norm() - 0.5).abs() < 1e-12)
            .count() as f64
            / 100.0;
        let end = Vector3::from(tr.last().unwrap().position_m);
        let path: f64 = tr
            .windows(2)
            .map(|w| (Vector3::from(w[1].position_m) - Vector3::from(w[0].position_m)).norm())
            .sum();
        assert!(
            path >= 0.5 * cruising - 0.01 && cruising > 20.0,
            "{path} m, {cruising} s"
        );
        if !turns {
            // A straight line: the end point is the path length away.
            assert!((end.norm() - path).abs() < 1e-6, "{end:?} vs {path}");
        }
    }
}

/// Integrates the vibration of `model` at a constant wheel speed of 1 m/s for `seconds` at
/// `rate_hz` (rectangle rule: the sum of samples times the step) and returns, per channel
/// (accel x, y, z in m/s, gyro x, y, z in deg), the largest magnitude of the running integral,
/// and the mean square of the samples.
fn integrate_constant_speed(
    model: &VibrationModel,
    seconds: f64,
    rate_hz: f64,
) -> ([f64; 6], [f64; 6]) {
    let mut vib = Vibration::new(model, 31).unwrap();
    let n = (seconds * rate_hz) as usize;
    let dt = 1.0 / rate_hz;
    let (mut sum, mut peak, mut sq) = ([0.0; 6], [0.0f64; 6], [0.0; 6]);
    for k in 1..=n {
        let (a, g) = vib.step(k as f64 * dt, rate_hz, 1.0);
        for (ch, x) in a.into_iter().chain(g).enumerate() {
            sum[ch] += x * dt;
            peak[ch] = peak[ch].max(sum[ch].abs());
            sq[ch] += x * x / n as f64;
        }
    }
    (peak, sq)
}

#[test]
fn vibration_has_no_power_at_zero_frequency() {
    // A vibration moves the sensor about its pose: the integral of the disturbance (velocity,
    // angle) stays bounded. Bound per channel of RMS level L at 1 m/s, wheel radius r, gear
    // ratio G, resonance w0 = 2 pi f0:
    // - wheel and motor sinusoids, sqrt(2 * 0.3) L v sin(k (theta - theta0) +- pi/2) with
    //   theta' = v / r: integral (r / k) sqrt(0.6) L |sin(k (theta - theta0))|, at most
    //   sqrt(0.6) L r (1 + 1 / G) (2% margin for the rectangle rule);
    // - chassis band-pass 2 z w0 s / (s^2 + 2 z w0 s + w0^2) of RMS sqrt(0.4) L: its integral
    //   is the low-pass resonance scaled by 2 z / w0, whose RMS is exactly the band-pass RMS
    //   divided by w0; starting from 0, its magnitude stays below 2 x 5 RMS.
    // A signal with power at DC instead random-walks: the earlier low-pass resonance (density
    // 0.4 L^2 4 z / w0 at DC) reached 0.1 m/s RMS after 1000 s at L = 0.1 m/s^2.
    let model = VibrationModel::moderate(1.0);
    let w0 = TAU * model.chassis_hz;
    let r = model.wheel_radius_m;
    for rate in [200.0, 1000.0, 4000.0] {
        let (peak, sq) = integrate_constant_speed(&model, 1000.0, rate);
        for ch in 0..6 {
            let level = if ch < 3 {
                model.accel_rms_mps2
            } else {
                model.gyro_rms_dps
            };
            let bound = 1.02 * 0.6f64.sqrt() * level * r * (1.0 + 1.0 / model.gear_ratio)
                + 10.0 * 0.4f64.sqrt() * level / w0;
            eprintln!(
                "{rate} Hz ch {ch}: peak integral {:e}, bound {bound:e}",
                peak[ch]
            );
            assert!(
                peak[ch] <= bound,
                "{rate} Hz channel {ch}: {} > {bound}",
                peak[ch]
            );
            // And the level is still the configured RMS at every rate (the resonator's unit
            // variance holds at any sample rate): 3100 independent chassis values per
            // channel give about 1% sampling error on the total.
            let ratio = sq[ch] / (level * level);
            assert!(
                (ratio - 1.0).abs() < 0.05,
                "{rate} Hz channel {ch}: {ratio}"
            );
        }
    }
}

#[test]
fn vibration_mean_over_a_long_drive_is_zero_within_its_standard_error() {
    // 20 minutes with turns at 500 Hz, ideal sensor: the disturbance is the measurement minus
    // the truth. The standard error of each channel's mean over the moving samples comes from
    // means of 2 s batches (much longer than the 64 ms correlation of the resonance and the
    // wheel period at cruise speed), so it does not assume independent samples.
    let params = DriveParams {
        turns: true,
        in_place_turns: true,
        ..DriveParams::new(1200.0)
    };
    let drive = Drive::new(&params, 21).unwrap();
    let model = VibrationModel::moderate(1.0);
    let mut sim = SimSensor::new(drive, &SensorModel::ideal(), &model, 21).unwrap();
    let rate = 500.0;
    let batch = 1000usize;
    let mut batches: Vec<[f64; 6]> = Vec::new();
    let (mut acc, mut count) = ([0.0; 6], 0usize);
    for k in 0..(1200.0 * rate) as usize {
        let (a, truth) = sim.sample_with_truth(k as f64 / rate, rate);
        if truth.at_rest {
            continue;
        }
        for i in 0..3 {
            acc[i] += a.accel_g[i] * G_MPS2 - truth.specific_force_mps2[i];
            acc[3 + i] += a.gyro_dps[i] - truth.angular_rate_rps[i].to_degrees();
        }
        count += 1;
        if count == batch {
            batches.push(acc.map(|s| s / batch as f64));
            (acc, count) = ([0.0; 6], 0);
        }
    }
    let nb = batches.len() as f64;
    assert!(nb > 150.0, "{nb} batches of moving samples");
    for ch in 0..6 {
        let mean = batches.iter().map(|b| b[ch]).sum::<f64>() / nb;
        let var = batches.iter().map(|b| (b[ch] - mean).powi(2)).sum::<f64>() / (nb - 1.0);
        let se = (var / nb).sqrt();
        let level = if ch < 3 {
            model.accel_rms_mps2
        } else {
            model.gyro_rms_dps
        };
        eprintln!("channel {ch}: mean {mean:e}, standard error {se:e}");
        assert!(
            mean.abs() < 3.0 * se,
            "channel {ch}: mean {mean} vs se {se}"
        );
        // The batch means are far below the per-sample level (no slow content).
        assert!(se < 0.01 * level, "channel {ch}: se {se}");
    }
}

#[test]
fn an_idling_engine_shakes_the_gyroscope_at_its_stops_about_zero() {
    // Engine off in motion (moderate(0)), 0.45 deg/s RMS per gyroscope axis at 23 Hz and 46
    // Hz at the stops after the first motion, none before it. Over a 30 s stop at 100 Hz the
    // sample RMS is the configured one (the sinusoids' samples, 690 and 1380 periods, average
    // their squares to a half within 1 %), the mean is zero (no bias: within 0.005 deg/s) and
    // the angle, the running sum of rate times dt, stays bounded: a sum of samples
    // `a sin(k w dt + p)` stays within `a dt / sin(w dt / 2)` in magnitude (the geometric sum
    // of the phasors), with amplitudes `a` of sqrt(2 * 0.7) and sqrt(2 * 0.3) times the RMS.
    let rms = 0.45;
    let model = VibrationModel::moderate(0.0)
        .with_engine_idle(0.3, 23.0, 0.0)
        .with_engine_idle_gyro(rms);
    let mut vib = Vibration::new(&model, 7).unwrap();
    let rate = 100.0;
    let (_, before) = vib.step(0.0, rate, 0.0);
    assert_eq!(before, [0.0; 3], "before the first motion");
    vib.step(0.01, rate, 1.0);
    let n = 3000;
    let (mut sum, mut sq, mut peak) = ([0.0; 3], [0.0; 3], [0.0f64; 3]);
    for k in 0..n {
        let (_, g) = vib.step(0.02 + k as f64 / rate, rate, 0.0);
        for i in 0..3 {
            sum[i] += g[i] / rate;
            sq[i] += g[i] * g[i] / n as f64;
            peak[i] = peak[i].max(sum[i].abs());
        }
    }
    let dt = 1.0 / rate;
    let bound: f64 = [(1.4f64, 23.0), (0.6, 46.0)]
        .iter()
        .map(|(p, hz)| p.sqrt() * rms * dt / (TAU * hz * dt / 2.0).sin())
        .sum();
    for i in 0..3 {
        let mean = sum[i] / (n as f64 / rate);
        eprintln!(
            "axis {i}: rms {}, mean {mean:e}, peak angle {} deg",
            sq[i].sqrt(),
            peak[i]
        );
        assert!(
            (sq[i].sqrt() / rms - 1.0).abs() < 0.01,
            "axis {i}: rms {}",
            sq[i].sqrt()
        );
        assert!(mean.abs() < 0.005, "axis {i}: mean {mean} deg/s");
        assert!(
            peak[i] <= 1.05 * bound,
            "axis {i}: angle {} > {bound} deg",
            peak[i]
        );
    }
}
