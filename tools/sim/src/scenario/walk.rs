//! A pedestrian with the IMU on a foot (the OpenShoe setting: J.-O. Nilsson, I. Skog, P.
//! Händel, K. V. S. Hari, "Foot-mounted INS for everybody - an open-source embedded
//! implementation", IEEE/ION PLANS 2012; stance detection as in I. Skog, P. Händel, J.-O.
//! Nilsson, J. Rantakokko, "Zero-velocity detection - an algorithm evaluation", IEEE Trans.
//! Biomed. Eng. 57(11), 2010), walking laps of a rectangle on a level floor.
//!
//! One foot's gait cycle, as those papers describe the signal a foot-mounted IMU sees:
//! - stance: the foot flat and still on the floor for 0.2-0.5 s (truth: zero velocity and
//!   rate, `at_rest`); the sensor sees a small physiological tremor (8-12 Hz), a measurement
//!   disturbance, not motion ([`Scenario::disturbance`]);
//! - toe-off and swing: the foot leaves the floor and travels one stride (1.0-1.6 m) to the
//!   next footprint along a smooth profile whose peak speed is 4-5 m/s (`8/3` times the mean
//!   swing speed), lifting by a clearance and pitching toe-down (plantar flexion, tens of
//!   degrees) early and toe-up (dorsiflexion) before heel strike, turning at the corners;
//!   a short vibration burst (truth motion of under a millimetre, about 1 g) marks toe-off;
//! - heel strike: a 50 ms burst (about 3 g and 100 deg/s, truth motion of under a millimetre
//!   and a degree) as the foot lands, then the next stance.
//!
//! The numbers are the ranges of our issue; the shapes are smooth analytic profiles (the
//! drives' raised-cosine ramp along the stride and the heading, `sin^4` envelopes for the
//! lift, the pitch and the bursts, so acceleration and jerk are continuous), not fitted to
//! gait recordings. The IMU sits at the foot's pitch axis (no lever arm). Every stride of a side
//! has the same length (the side divided evenly); stance times and peak speeds are drawn per
//! step from the seed. The walk ends at its starting footprint with its starting heading, so
//! the loop closes exactly.

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use recording::Truth;

use super::{Kinematics, Scenario, ScenarioError, check_positive, check_range, ramp};
use crate::{stream_rng, streams};

/// Length of the heel-strike burst, s.
const IMPACT_S: f64 = 0.05;
/// Frequency of the heel-strike burst, Hz.
const IMPACT_HZ: f64 = 30.0;
/// Length of the toe-off burst at the start of a swing, s.
const TOE_OFF_S: f64 = 0.05;
/// Frequency of the toe-off burst, Hz.
const TOE_OFF_HZ: f64 = 40.0;
/// Shortest swing, s: the final pivot on the start footprint (no stride) lasts this long.
const PIVOT_S: f64 = 0.5;

/// Parameters of a walk. Randomised quantities are drawn uniformly from `[min, max]` ranges.
#[derive(Debug, Clone, PartialEq)]
pub struct WalkParams {
    /// Laps of the rectangle (>= 1).
    pub laps: u32,
    /// Sides of the rectangle, m (walked counter-clockwise from a corner, first along x).
    pub rectangle_m: [f64; 2],
    /// Stride length range, m: each side is divided into the number of equal strides closest
    /// to a length drawn from this range (and within it).
    pub stride_m: [f64; 2],
    /// Still part of each stance, s (after the heel-strike burst).
    pub stance_s: [f64; 2],
    /// Peak foot speed of each swing, m/s (the swing lasts `8/3 stride / peak`).
    pub peak_speed_mps: [f64; 2],
    /// Peak foot clearance, m.
    pub clearance_m: f64,
    /// About the largest toe-down pitch after toe-off, degrees.
    pub toe_off_pitch_deg: f64,
    /// About the largest toe-up pitch before heel strike, degrees.
    pub heel_strike_pitch_deg: f64,
    /// Peak vertical acceleration of the heel-strike burst, m/s^2 (toe-off: a third of it).
    pub impact_mps2: f64,
    /// Peak pitch rate of the heel-strike burst, deg/s.
    pub impact_rate_dps: f64,
    /// Standing still at the start, s (>= 0).
    pub initial_rest_s: f64,
    /// Standing still at the end, s (>= 0).
    pub final_rest_s: f64,
    /// Tremor level during stances (1: about 0.05 m/s^2 and 0.3 deg/s per axis; 0: none).
    pub tremor: f64,
    /// Local gravity, m/s^2.
    pub gravity_mps2: f64,
}

impl WalkParams {
    /// `laps` laps of a 12 m x 6 m rectangle: strides 1.0-1.6 m, stances 0.2-0.5 s, peak foot
    /// speed 4-5 m/s, 0.12 m clearance, 30 degrees toe-down and 15 degrees toe-up, a 3 g,
    /// 100 deg/s heel strike, 10 s standing at the start, 2 s at the end, tremor 1, standard
    /// gravity.
    pub fn new(laps: u32) -> Self {
        Self {
            laps,
            rectangle_m: [12.0, 6.0],
            stride_m: [1.0, 1.6],
            stance_s: [0.2, 0.5],
            peak_speed_mps: [4.0, 5.0],
            clearance_m: 0.12,
            toe_off_pitch_deg: 30.0,
            heel_strike_pitch_deg: 15.0,
            impact_mps2: 3.0 * ipc_types::units::STANDARD_GRAVITY_MPS2,
            impact_rate_dps: 100.0,
            initial_rest_s: 10.0,
            final_rest_s: 2.0,
            tremor: 1.0,
            gravity_mps2: ipc_types::units::STANDARD_GRAVITY_MPS2,
        }
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        if self.laps == 0 {
            return Err(ScenarioError {
                field: "laps".into(),
                reason: "must be >= 1".into(),
            });
        }
        for side in self.rectangle_m {
            check_positive("rectangle_m", side)?;
        }
        check_range("stride_m", self.stride_m)?;
        check_range("stance_s", self.stance_s)?;
        check_range("peak_speed_mps", self.peak_speed_mps)?;
        for side in self.rectangle_m {
            if strides_on(side, self.stride_m[0], self.stride_m).is_none() {
                return Err(ScenarioError {
                    field: "stride_m".into(),
                    reason: format!(
                        "no whole number of strides in [{}, {}] m covers a {side} m side",
                        self.stride_m[0], self.stride_m[1]
                    ),
                });
            }
        }
        for (field, x) in [
            ("clearance_m", self.clearance_m),
            ("toe_off_pitch_deg", self.toe_off_pitch_deg),
            ("heel_strike_pitch_deg", self.heel_strike_pitch_deg),
            ("impact_mps2", self.impact_mps2),
            ("impact_rate_dps", self.impact_rate_dps),
            ("initial_rest_s", self.initial_rest_s),
            ("final_rest_s", self.final_rest_s),
            ("tremor", self.tremor),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return Err(ScenarioError {
                    field: field.into(),
                    reason: format!("must be finite and >= 0, got {x}"),
                });
            }
        }
        check_positive("gravity_mps2", self.gravity_mps2)
    }
}

/// The number of equal strides on a side of `side_m` closest to strides of `want_m`, with the
/// stride inside `range`; `None` if none is.
fn strides_on(side_m: f64, want_m: f64, range: [f64; 2]) -> Option<u32> {
    let n = (side_m / want_m).round().max(1.0) as u32;
    [n, n + 1, n.saturating_sub(1).max(1)]
        .into_iter()
        .find(|&n| (range[0] - 1e-9..=range[1] + 1e-9).contains(&(side_m / n as f64)))
}

/// One step: a swing from one footprint to the next, the heel-strike burst, a still stance.
#[derive(Debug, Clone, PartialEq)]
struct Step {
    /// Start of the swing, s.
    start_s: f64,
    /// Length of the swing, s.
    swing_s: f64,
    /// Still part of the stance after the burst, s.
    stance_s: f64,
    from: [f64; 2],
    to: [f64; 2],
    heading_from: f64,
    heading_to: f64,
}

/// A smooth burst `sin^4(pi u / T) sin(2 pi f u) / (2 pi f)^2` on `[0, T]` (so that its
/// second derivative's oscillation has unit amplitude): value, first and second derivatives
/// at `u`. Zero with three zero derivatives at both ends, like every profile of the walk, so
/// that acceleration and jerk are continuous.
fn burst(u: f64, len_s: f64, hz: f64) -> (f64, f64, f64) {
    if !(0.0..len_s).contains(&u) {
        return (0.0, 0.0, 0.0);
    }
    let w = TAU * hz;
    let k = PI / len_s;
    let (s, c) = (k * u).sin_cos();
    let e = s.powi(4);
    let de = 4.0 * k * s.powi(3) * c;
    let dde = 4.0 * k * k * (3.0 * s * s * c * c - s.powi(4));
    let (sw, cw) = (w * u).sin_cos();
    let scale = 1.0 / (w * w);
    (
        scale * e * sw,
        scale * (de * sw + e * w * cw),
        scale * (dde * sw + 2.0 * de * w * cw - e * w * w * sw),
    )
}

/// A walk: laps of a rectangle with a foot-mounted IMU, generated from a seed.
#[derive(Debug, Clone)]
pub struct Walk {
    steps: Vec<Step>,
    params: WalkParams,
    duration_s: f64,
    /// Tremor: per axis (accel x, y, z, gyro x, y, z) three (frequency Hz, phase rad).
    tremor: [[(f64, f64); 3]; 6],
}

impl Walk {
    /// Generates a walk from `params` and `seed`.
    pub fn new(params: &WalkParams, seed: u64) -> Result<Self, ScenarioError> {
        params.validate()?;
        let mut rng = stream_rng(seed, streams::WALK_PLAN);
        let footprints = Self::footprints(params, &mut rng);
        let mut steps = Vec::with_capacity(footprints.len());
        let mut t = params.initial_rest_s;
        for w in footprints.windows(2) {
            let (from, heading_from) = w[0];
            let (to, heading_to) = w[1];
            let stride = (to[0] - from[0]).hypot(to[1] - from[1]);
            let peak = uniform(&mut rng, params.peak_speed_mps);
            let step = Step {
                start_s: t,
                swing_s: (super::RAMP_PEAK * stride / peak).max(PIVOT_S),
                stance_s: uniform(&mut rng, params.stance_s),
                from,
                to,
                heading_from,
                heading_to,
            };
            t += step.swing_s + IMPACT_S + step.stance_s;
            steps.push(step);
        }
        let mut trng = stream_rng(seed, streams::WALK_TREMOR);
        let tremor = std::array::from_fn(|_| {
            std::array::from_fn(|_| (trng.random_range(8.0..12.0), trng.random_range(0.0..TAU)))
        });
        Ok(Self {
            steps,
            params: params.clone(),
            duration_s: t + params.final_rest_s,
            tremor,
        })
    }

    /// The footprints (position, heading) of the whole walk in order, from the start corner
    /// back to it: each side divided into equal strides, the heading that of the side the
    /// footprint is reached on.
    fn footprints(p: &WalkParams, rng: &mut ChaCha8Rng) -> Vec<([f64; 2], f64)> {
        let [a, b] = p.rectangle_m;
        let corners = [[0.0, 0.0], [a, 0.0], [a, b], [0.0, b]];
        let mut out = vec![([0.0, 0.0], 0.0)];
        let mut heading = 0.0;
        for _ in 0..p.laps {
            for side in 0..4 {
                let (c0, c1) = (corners[side], corners[(side + 1) % 4]);
                let len = (c1[0] - c0[0]).hypot(c1[1] - c0[1]);
                let want = uniform(rng, p.stride_m);
                let n = strides_on(len, want, p.stride_m).expect("validated");
                for k in 1..=n {
                    let f = k as f64 / n as f64;
                    let pos = [c0[0] + f * (c1[0] - c0[0]), c0[1] + f * (c1[1] - c0[1])];
                    out.push((pos, heading));
                }
                heading += FRAC_PI_2;
            }
        }
        // The first stride of each side turns the foot to the side's heading during its
        // swing: the footprint reached on a side carries that side's heading. A last pivot
        // on the start footprint turns the foot back to its starting heading (plus whole
        // turns), so that the loop closes in attitude too.
        out.push(([0.0, 0.0], heading));
        out
    }

    /// The walk's parameters.
    pub fn params(&self) -> &WalkParams {
        &self.params
    }

    /// Start, swing length and still-stance length of every step, s.
    pub fn step_times(&self) -> Vec<(f64, f64, f64)> {
        self.steps
            .iter()
            .map(|s| (s.start_s, s.swing_s, s.stance_s))
            .collect()
    }

    /// Length of the heel-strike burst that follows every swing, s.
    pub fn impact_s(&self) -> f64 {
        IMPACT_S
    }

    /// The foot still on footprint `pos` with `heading`, plus a burst (pitch and vertical)
    /// scaled by `vertical` m/s^2 and `pitch` rad/s at `u` seconds into it.
    fn on_floor(&self, pos: [f64; 2], heading: f64, u: f64) -> Kinematics {
        let (b, db, ddb) = burst(u, IMPACT_S, IMPACT_HZ);
        let vertical = self.params.impact_mps2;
        // The pitch burst's rate amplitude is `impact_rate_dps`: scale the unit-second-
        // derivative burst by rate * w (its first derivative then peaks near the rate).
        let w = TAU * IMPACT_HZ;
        let pitch_scale = self.params.impact_rate_dps.to_radians() * w;
        let (phi, dphi) = (pitch_scale * b, pitch_scale * db);
        let moving = u < IMPACT_S;
        Kinematics {
            position: Vector3::new(pos[0], pos[1], vertical * b),
            velocity: Vector3::new(0.0, 0.0, vertical * db),
            accel: Vector3::new(0.0, 0.0, vertical * ddb),
            attitude: attitude(heading, phi),
            rate: pitch_axis(heading) * dphi,
            at_rest: !moving,
        }
    }

    /// The foot in the swing of `step`, `u` seconds into it.
    fn swing(&self, step: &Step, u: f64) -> Kinematics {
        let p = &self.params;
        let s = step.swing_s;
        let x = u / s;
        let (r, dr) = ramp(x);
        // Second derivative of the ramp: d/dx (8/3) sin^4(pi x).
        let (sn, cs) = (PI * x).sin_cos();
        let ddr = super::RAMP_PEAK * 4.0 * PI * sn.powi(3) * cs;
        let d = [step.to[0] - step.from[0], step.to[1] - step.from[1]];
        // Lift: h sin^4(pi x).
        let h = p.clearance_m;
        let z = h * sn.powi(4);
        let dz = h * 4.0 * PI * sn.powi(3) * cs / s;
        let ddz = h * 4.0 * PI * PI * (3.0 * sn * sn * cs * cs - sn.powi(4)) / (s * s);
        // Toe-off burst on the vertical.
        let (b, db, ddb) = burst(u, TOE_OFF_S, TOE_OFF_HZ);
        let kick = p.impact_mps2 / 3.0;
        // Pitch: sin^4(pi x) (alpha cos(pi x) + beta), toe_off at x = 1/4 and -heel_strike
        // at x = 3/4.
        let (t_off, t_hs) = (
            p.toe_off_pitch_deg.to_radians(),
            p.heel_strike_pitch_deg.to_radians(),
        );
        let alpha = 2.0 * std::f64::consts::SQRT_2 * (t_off + t_hs);
        let beta = 2.0 * (t_off - t_hs);
        let g = sn.powi(4);
        let dg = 4.0 * PI * sn.powi(3) * cs;
        let phi = g * (alpha * cs + beta);
        let dphi = (dg * (alpha * cs + beta) - g * alpha * PI * sn) / s;
        let dpsi = step.heading_to - step.heading_from;
        let psi = step.heading_from + dpsi * r;
        let rate = Vector3::z() * (dpsi * dr / s) + pitch_axis(psi) * dphi;
        Kinematics {
            position: Vector3::new(
                step.from[0] + d[0] * r,
                step.from[1] + d[1] * r,
                z + kick * b,
            ),
            velocity: Vector3::new(d[0] * dr / s, d[1] * dr / s, dz + kick * db),
            accel: Vector3::new(d[0] * ddr / (s * s), d[1] * ddr / (s * s), ddz + kick * ddb),
            attitude: attitude(psi, phi),
            rate,
            at_rest: false,
        }
    }
}

/// The foot's attitude: heading `psi` about the navigation z axis, then pitch `phi` about the
/// foot's lateral (sensor y) axis, positive toe-down.
fn attitude(psi: f64, phi: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), psi)
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), phi)
}

/// The foot's lateral axis in the navigation frame at heading `psi`.
fn pitch_axis(psi: f64) -> Vector3<f64> {
    Vector3::new(-psi.sin(), psi.cos(), 0.0)
}

/// A uniform draw from `[lo, hi]` (the low end when equal).
fn uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f64; 2]) -> f64 {
    if hi > lo {
        rng.random_range(lo..hi)
    } else {
        lo
    }
}

impl Scenario for Walk {
    fn truth(&self, t_s: f64) -> Truth {
        assert!(t_s.is_finite() && t_s >= 0.0, "truth at {t_s} s");
        let i = self.steps.partition_point(|s| s.start_s <= t_s);
        let k = match i.checked_sub(1).map(|i| &self.steps[i]) {
            None => {
                let heading = self.steps.first().map_or(0.0, |s| s.heading_from);
                self.on_floor([0.0, 0.0], heading, f64::INFINITY)
            }
            Some(step) => {
                let u = t_s - step.start_s;
                if u < step.swing_s {
                    self.swing(step, u)
                } else {
                    self.on_floor(step.to, step.heading_to, u - step.swing_s)
                }
            }
        };
        k.truth(t_s, self.params.gravity_mps2)
    }

    fn duration_s(&self) -> f64 {
        self.duration_s
    }

    fn wheel_speed_mps(&self, _t_s: f64) -> f64 {
        0.0
    }

    fn disturbance(&self, t_s: f64) -> ([f64; 3], [f64; 3]) {
        let level = self.params.tremor;
        if level == 0.0 || !self.truth(t_s).at_rest {
            return ([0.0; 3], [0.0; 3]);
        }
        // Three sines per axis of equal amplitude: about 0.05 m/s^2 and 0.3 deg/s RMS.
        let axis = |i: usize, rms: f64| {
            let amp = rms * level * (2.0f64 / 3.0).sqrt();
            self.tremor[i]
                .iter()
                .map(|(f, ph)| amp * (TAU * f * t_s + ph).sin())
                .sum::<f64>()
        };
        (
            std::array::from_fn(|i| axis(i, 0.05)),
            std::array::from_fn(|i| axis(3 + i, 0.3)),
        )
    }
}
