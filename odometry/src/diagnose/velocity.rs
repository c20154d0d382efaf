//! Velocity rows: what a motion from one rest to the next leaves of the velocity, where an
//! accelerometer lag behind the gyro shows and no rest does.
//!
//! Over a motion (from the middle of rest `a` to the middle of rest `b`, as the tilt rows),
//! the specific force rotated into the sensor frame at the start by the gyro's carried
//! attitude `R(t)`, minus gravity as rest `a` measured it (`f_a`), integrates to the velocity
//! change, which is zero from rest to rest: `dv = int (R f - f_a) dt` (m/s, sensor frame at
//! the start; trapezoidal in the samples). `R` is tied to the second rest: the rotation that
//! takes the carried gravity direction at the end onto rest `b`'s measured one (the tilt the
//! tilt rows measure) is applied in proportion to the angle turned so far (to time where the
//! motion barely turns), as a gyro scale error's tilt grows; what the gyro's errors leak into
//! the rows is then small and no stand-in for a lag.
//!
//! **Accelerometer lag** `d` (s; the sample stamped `t` holds the specific force at `t - d`):
//! corrected, `f(t + d) ~ f + d f'` (`f'` the central difference of the samples), which adds
//! `d int R f' dt = d ([R f] - int R (omega x f) dt)`: the first term is the tilt between the
//! two rests (small), the second the gravity the gyro turned through during the motion, so
//! the lag shows as the derivative of the gyro-rotated gravity, greatest at motion onsets and
//! ends, and grows with the angle turned (about `g d` per radian). A lever arm does not
//! show here: the velocity of a point `r` from the rotation centre differs by `omega x r`,
//! zero at both rests, so it needs a constraint that holds at another point (a wheeled
//! robot's non-holonomic constraint at its rear axle) and is not a candidate of this loop.
//!
//! Every candidate acts on these rows (the accelerometer's bias, scale and temperature bias
//! through the corrected samples and `f_a`, the gyro's through `R`): `-J p`, `J` the numerical
//! derivative of `dv` in the candidate's parameters, as for the tilt rows.
//!
//! **Noise** per axis: the accelerometer's white noise integrated over the motion
//! (`N_a^2 T`), the gyro's angle random walk leaking gravity, tied at both ends (`g^2 N_g^2
//! T^3 / 12`), the noise of `f_a` (`var(f_a) T^2`) and of the tie (both rests' gravity
//! directions, `(var(f_a) + var(f_b)) T^2 / 4`). What the odometry carries is added to it
//! (and the rows' `floor` left zero): the accelerometer bias turned with the motion (`b theta
//! T`) and what the tie leaves of a carried gyro error, `CARRIED_SHARE` of the gyro
//! correction's 1-sigma times the angle turned (`g k s theta T`). An uncalibrated gyro's 1 %
//! scale leaks as much gravity as a lag of some milliseconds would without the tie, and the
//! fit must not take one for the other.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::evidence::{Evidence, Interval};
use super::rows::{Candidate, GYRO_STEP, Kind, Row};
use crate::config::OdometryConfig;

/// Steps of the numerical derivatives: accelerometer bias (m/s^2), its scale and temperature
/// bias (fraction, m/s^2/degC), the lag (s).
const BIAS_STEP_MPS2: f64 = 1e-2;
const SCALE_STEP: f64 = 1e-3;
const TEMP_STEP: f64 = 1e-3;
const LAG_STEP_S: f64 = 1e-3;
/// What the tie to the second rest leaves of a carried gyro error's tilt, as a share of its
/// 1-sigma times the angle turned, on average over the motion: on the simulated clean arm run
/// (docs/diagnosis.md) the uncalibrated gyro's 1 % scale leaves the rows at about a third of
/// the 1-sigma this gives.
const CARRIED_SHARE: f64 = 0.05;

/// A correction of the samples: the gyro's `I + n` and the accelerometer's candidate.
struct Correction<'a> {
    n: Matrix3<f64>,
    accel: &'a dyn Fn(usize) -> Vector3<f64>,
}

/// The velocity change over `interval` with the samples corrected by `c` (module
/// documentation), m/s, sensor frame at the start, with the carried attitude tied to the
/// second rest's gravity.
fn velocity_change(ev: &Evidence, interval: &Interval, c: &Correction) -> Vector3<f64> {
    let s = &ev.samples;
    let mean =
        |r: &std::ops::Range<usize>| r.clone().map(c.accel).sum::<Vector3<f64>>() / r.len() as f64;
    let f_a = mean(&ev.rests[interval.from].samples);
    let u_b = mean(&ev.rests[interval.from + 1].samples).normalize();
    let scale = Matrix3::identity() + c.n;
    let range = interval.samples.start + 1..interval.samples.end;
    let step = |i: usize| {
        let w = scale * ((s[i].gyro_rps + s[i - 1].gyro_rps) / 2.0 - ev.gyro_bias_rps);
        w * (s[i].t_s - s[i - 1].t_s)
    };
    // The carried rotation and the angle turned, to tie the attitude to the second rest.
    let (mut q_end, mut turned) = (UnitQuaternion::identity(), 0.0);
    for i in range.clone() {
        let d = step(i);
        q_end *= UnitQuaternion::from_scaled_axis(d);
        turned += d.norm();
    }
    let tie = (q_end * u_b).cross(&f_a.normalize());
    let duration = s[interval.samples.end - 1].t_s - s[interval.samples.start].t_s;
    let mut q = UnitQuaternion::identity();
    let (mut v, mut done) = (Vector3::zeros(), 0.0);
    let mut before = (c.accel)(interval.samples.start);
    for i in range {
        let d = step(i);
        let next = q * UnitQuaternion::from_scaled_axis(d);
        // The share of the tie applied grows with the angle turned (a scale error's tilt
        // does), with time when the motion barely turns.
        let share = |done: f64, t: f64| {
            if turned > 1e-3 {
                done / turned
            } else {
                (t - s[interval.samples.start].t_s) / duration
            }
        };
        let tied = |q: UnitQuaternion<f64>, done: f64, t: f64| {
            UnitQuaternion::from_scaled_axis(tie * share(done, t)) * q
        };
        let f = (c.accel)(i);
        let a = tied(q, done, s[i - 1].t_s) * before;
        let b = tied(next, done + d.norm(), s[i].t_s) * f;
        v += ((a + b) / 2.0 - f_a) * (s[i].t_s - s[i - 1].t_s);
        (q, before, done) = (next, f, done + d.norm());
    }
    v
}

/// The derivative of the specific force at sample `i`, m/s^3 (central difference; one-sided
/// at the run's ends).
fn derivative(ev: &Evidence, i: usize) -> Vector3<f64> {
    let s = &ev.samples;
    let (a, b) = (i.saturating_sub(1), (i + 1).min(s.len() - 1));
    let dt = s[b].t_s - s[a].t_s;
    if dt > 0.0 {
        (s[b].accel_mps2 - s[a].accel_mps2) / dt
    } else {
        Vector3::zeros()
    }
}

/// The velocity change with the candidate `c` applied at parameters `p`.
fn with(
    ev: &Evidence,
    interval: &Interval,
    c: Candidate,
    p: &Vector3<f64>,
    t_ref_c: f64,
) -> Vector3<f64> {
    let s = &ev.samples;
    let temp = |i: usize| {
        let dt = s[i].temp_c - t_ref_c;
        if dt.is_finite() { dt } else { 0.0 }
    };
    let accel: Box<dyn Fn(usize) -> Vector3<f64>> = match c {
        Candidate::AccelBias => Box::new(|i| s[i].accel_mps2 - p),
        Candidate::AccelScale => Box::new(|i| s[i].accel_mps2 - s[i].accel_mps2.component_mul(p)),
        Candidate::AccelTempBias => Box::new(move |i| s[i].accel_mps2 - p * temp(i)),
        Candidate::AccelLag => Box::new(|i| s[i].accel_mps2 + derivative(ev, i) * p.x),
        _ => Box::new(|i| s[i].accel_mps2),
    };
    let n = c.gyro_perturbation(p);
    velocity_change(ev, interval, &Correction { n, accel: &*accel })
}

/// The velocity rows of `ev`, three per motion without a clip (a clip hid part of the
/// motion from the integration), grouped by motion after the rests' and tilts' groups;
/// `t_ref_c` is the temperature candidate's reference.
pub fn all(ev: &Evidence, config: &OdometryConfig, t_ref_c: f64) -> Vec<Row> {
    let first = ev.rests.len() + ev.intervals.len();
    ev.intervals
        .iter()
        .enumerate()
        .filter(|(_, i)| i.samples.len() >= 3 && i.gyro_clipped + i.accel_clipped == 0)
        .flat_map(|(j, i)| rows(ev, config, i, first + j, t_ref_c))
        .collect()
}

/// The three velocity rows of `interval` (group `group`); `t_ref_c` is the temperature
/// candidate's reference.
fn rows(
    ev: &Evidence,
    config: &OdometryConfig,
    interval: &Interval,
    group: usize,
    t_ref_c: f64,
) -> [Row; 3] {
    let zero = Vector3::zeros();
    let v0 = with(ev, interval, Candidate::AccelBias, &zero, t_ref_c);
    let unit = |i: usize, step: f64| Vector3::from_fn(|j, _| if i == j { step } else { 0.0 });
    let derivative = Candidate::ALL.map(|c| {
        let step = match c {
            Candidate::AccelBias => BIAS_STEP_MPS2,
            Candidate::AccelScale => SCALE_STEP,
            Candidate::AccelTempBias => TEMP_STEP,
            Candidate::AccelLag => LAG_STEP_S,
            Candidate::GyroSaturation => return [zero; 3],
            _ => GYRO_STEP,
        };
        std::array::from_fn(|i| {
            if i >= c.params() {
                return zero;
            }
            (with(ev, interval, c, &unit(i, step), t_ref_c) - v0) / step
        })
    });
    let sigma = noise(ev, config, interval);
    std::array::from_fn(|axis| Row {
        kind: Kind::Velocity,
        group,
        r: v0[axis],
        sigma,
        floor: 0.0,
        design: derivative.map(|d| Vector3::from_fn(|i, _| -d[i][axis])),
    })
}

/// The 1-sigma of each velocity row of `interval`: noise and what the model carries (module
/// documentation), m/s.
fn noise(ev: &Evidence, config: &OdometryConfig, interval: &Interval) -> f64 {
    let g = config.gravity_mps2;
    let s = &ev.samples;
    let t = s[interval.samples.end - 1].t_s - s[interval.samples.start].t_s;
    let angle = ev
        .carried(interval, &Matrix3::zeros(), &Vector3::zeros())
        .angle();
    let rest = &ev.rests[interval.from];
    let n = &config.noise;
    let c = &config.gyro_correction_sigma;
    let scale_sigma = c[(0, 0)].max(c[(1, 1)]).max(c[(2, 2)]);
    let bias = config
        .accel_bias_sigma_mps2
        .iter()
        .fold(0.0f64, |m, b| m.max(*b));
    let b = &ev.rests[interval.from + 1];
    let var = n.accel_noise_density.powi(2) * t
        + (g * n.gyro_noise_density).powi(2) * t.powi(3) / 12.0
        + rest.accel_mean_var.max() * t * t
        + (rest.accel_mean_var.max() + b.accel_mean_var.max()) * t * t / 4.0
        + (g * CARRIED_SHARE * scale_sigma * angle * t).powi(2)
        + (bias * angle * t).powi(2);
    var.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::evidence::{Rest, Sample};

    const RATE_HZ: f64 = 200.0;
    const G: f64 = 9.80665;

    /// A sensor turning about its x axis through 1.2 rad (a raised cosine over 1 s) between
    /// two 1 s rests, at the rotation centre (no linear acceleration), its accelerometer
    /// `lag_s` behind its gyro: the evidence and its one motion.
    fn turn(lag_s: f64) -> Evidence {
        let angle = |t: f64| {
            let x = ((t - 1.0) / 1.0).clamp(0.0, 1.0);
            1.2 * (1.0 - (std::f64::consts::PI * x).cos()) / 2.0
        };
        let rate = |t: f64| {
            let x = (t - 1.0) / 1.0;
            if (0.0..=1.0).contains(&x) {
                1.2 * std::f64::consts::PI / 2.0 * (std::f64::consts::PI * x).sin()
            } else {
                0.0
            }
        };
        // Gravity's reading in the sensor frame after turning by `a` about x.
        let force = |a: f64| Vector3::new(0.0, G * a.sin(), G * a.cos());
        let samples: Vec<Sample> = (0..(3.0 * RATE_HZ) as usize + 1)
            .map(|k| {
                let t = k as f64 / RATE_HZ;
                Sample {
                    t_s: t,
                    accel_mps2: force(angle(t - lag_s)),
                    gyro_rps: Vector3::new(rate(t), 0.0, 0.0),
                    temp_c: f64::NAN,
                    raw_flags: 0,
                }
            })
            .collect();
        let rest = |range: std::ops::Range<usize>| Rest {
            t_s: 0.0,
            accel_mps2: range
                .clone()
                .map(|i| samples[i].accel_mps2)
                .sum::<Vector3<f64>>()
                / range.len() as f64,
            accel_mean_var: Vector3::repeat(1e-8),
            gyro_rps: Vector3::zeros(),
            gyro_mean_var: Vector3::repeat(1e-12),
            temp_c: f64::NAN,
            samples: range,
        };
        let rests = vec![rest(20..180), rest(420..580)];
        Evidence {
            intervals: vec![Interval {
                from: 0,
                samples: 100..500,
                gyro_clipped: 0,
                accel_clipped: 0,
            }],
            samples,
            rests,
            innovations_mps: Vec::new(),
            gyro_bias_rps: Vector3::zeros(),
            gyro_bias_var: Vector3::repeat(1e-12),
        }
    }

    fn lag_slot() -> usize {
        Candidate::ALL
            .iter()
            .position(|c| *c == Candidate::AccelLag)
            .unwrap()
    }

    #[test]
    fn a_lag_leaves_what_its_design_predicts_and_none_without_it() {
        let config = OdometryConfig::mpu9250(G);
        let clean = turn(0.0);
        let rows = super::rows(&clean, &config, &clean.intervals[0], 0, f64::NAN);
        for r in &rows {
            assert!(r.r.abs() < 2e-3, "clean velocity row {}", r.r);
            assert!(r.kind == Kind::Velocity && r.floor == 0.0);
        }
        let lag = 0.02;
        let late = turn(lag);
        let rows = super::rows(&late, &config, &late.intervals[0], 0, f64::NAN);
        // About g lag per radian turned, across the turn's axis (y and z, not x).
        let r = Vector3::from_fn(|i, _| rows[i].r);
        assert!(r.x.abs() < 2e-3, "{r}");
        assert!(r.norm() > 0.5 * G * lag, "{r}");
        for row in &rows {
            let predicted = row.design[lag_slot()].x * lag;
            assert!(
                (row.r - predicted).abs() < 0.1 * r.norm(),
                "{} against {predicted}",
                row.r
            );
        }
    }
}
