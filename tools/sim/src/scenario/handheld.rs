//! A walker carrying the sensor in the hand, held in front as a phone is for texting (its
//! `+y` forward, its top raised by a tilt, its screen toward the walker), walking laps of a
//! circle on a level floor between a rest at the start and one at the end.
//!
//! The hand follows the walker's trunk, which, as an inverted pendulum, rises and falls once
//! per step and sways sideways once per stride (two steps), surging forward and back once per
//! step (W. Zijlstra, A. L. Hof, "Assessment of spatio-temporal gait parameters from trunk
//! accelerations during human walking", Gait & Posture 18(2), 2003, 1-10): here a sinusoid of
//! [`HandheldParams::bounce_m`] vertically and [`HandheldParams::surge_m`] forward at the step
//! frequency, [`HandheldParams::sway_m`] sideways at half of it, and the hand pitching the
//! sensor by [`HandheldParams::pitch_wobble_deg`] at the step frequency. The oscillations scale
//! with the walking speed over its cruise value, so they start and stop with the walk. The
//! speed rises from rest and falls back to it along the drives' raised-cosine ramp over
//! [`RAMP_S`]; the walk ends where it started, with its starting heading. The numbers are not
//! fitted to gait recordings: 1-1.5 cm of hand bounce at 1.5-2 steps/s gives the 0.7-1.8 m/s^2
//! peak-to-peak specific-force bounce of the Tyrex phones held for texting
//! (docs/real-data.md).

use std::f64::consts::{FRAC_PI_2, PI, TAU};

use nalgebra::{UnitQuaternion, Vector3};
use recording::Truth;

use super::{Kinematics, Scenario, ScenarioError, check_positive, ramp};

/// Speed ramps at the start and end of the walk, s.
pub const RAMP_S: f64 = 1.0;

/// Parameters of a hand-held walk.
#[derive(Debug, Clone, PartialEq)]
pub struct HandheldParams {
    /// Laps of the circle (> 0, fractions allowed).
    pub laps: f64,
    /// Radius of the circle, m (walked counter-clockwise from the origin, first along x).
    pub radius_m: f64,
    /// Cruise walking speed, m/s.
    pub speed_mps: f64,
    /// Steps per second.
    pub step_hz: f64,
    /// Rest at the start and at the end, s (>= 0).
    pub rest_s: f64,
    /// Amplitudes of the hand's vertical bounce, forward surge and lateral sway, m.
    pub bounce_m: f64,
    /// See `bounce_m`.
    pub surge_m: f64,
    /// See `bounce_m`.
    pub sway_m: f64,
    /// The sensor's tilt (top raised from level), degrees.
    pub tilt_deg: f64,
    /// Amplitude of the hand's pitching at each step, degrees.
    pub pitch_wobble_deg: f64,
    /// Local gravity, m/s^2.
    pub gravity_mps2: f64,
}

impl HandheldParams {
    /// `laps` of a 4 m circle at 0.8 m/s and 1.7 steps/s, 2 s of rest at both ends, 1.2 cm
    /// of bounce, 0.6 cm of surge, 1.5 cm of sway, held 30 degrees from level pitching by 3,
    /// standard gravity.
    pub fn new(laps: f64) -> Self {
        Self {
            laps,
            radius_m: 4.0,
            speed_mps: 0.8,
            step_hz: 1.7,
            rest_s: 2.0,
            bounce_m: 0.012,
            surge_m: 0.006,
            sway_m: 0.015,
            tilt_deg: 30.0,
            pitch_wobble_deg: 3.0,
            gravity_mps2: ipc_types::units::STANDARD_GRAVITY_MPS2,
        }
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        check_positive("laps", self.laps)?;
        check_positive("radius_m", self.radius_m)?;
        check_positive("speed_mps", self.speed_mps)?;
        check_positive("step_hz", self.step_hz)?;
        check_positive("gravity_mps2", self.gravity_mps2)?;
        for (field, x) in [
            ("rest_s", self.rest_s),
            ("bounce_m", self.bounce_m),
            ("surge_m", self.surge_m),
            ("sway_m", self.sway_m),
            ("pitch_wobble_deg", self.pitch_wobble_deg),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return Err(ScenarioError {
                    field: field.into(),
                    reason: format!("must be finite and >= 0, got {x}"),
                });
            }
        }
        if !(self.tilt_deg.is_finite() && self.tilt_deg.abs() < 90.0) {
            return Err(ScenarioError {
                field: "tilt_deg".into(),
                reason: format!("must be within +-90 degrees, got {}", self.tilt_deg),
            });
        }
        Ok(())
    }
}

/// The hand-held walk (module documentation).
#[derive(Debug, Clone)]
pub struct Handheld {
    p: HandheldParams,
    /// Cruise time, s.
    cruise_s: f64,
}

/// A scalar and its first two time derivatives.
type Jet = (f64, f64, f64);

/// `P''` of the ramp ([`ramp`]), per unit of its argument squared.
fn ramp_second(x: f64) -> f64 {
    if x <= 0.0 || x >= 1.0 {
        return 0.0;
    }
    8.0 * PI / 3.0 * (TAU * x).sin() - 4.0 * PI / 3.0 * (2.0 * TAU * x).sin()
}

/// `integral_0^x P`: the distance a ramp covers, in its own units.
fn ramp_integral(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x / 2.0 + ((TAU * x).cos() - 1.0) / (3.0 * PI * PI)
        - ((2.0 * TAU * x).cos() - 1.0) / (48.0 * PI * PI)
}

/// `a b` with its derivatives.
fn product(a: Jet, b: Jet) -> Jet {
    (
        a.0 * b.0,
        a.1 * b.0 + a.0 * b.1,
        a.2 * b.0 + 2.0 * a.1 * b.1 + a.0 * b.2,
    )
}

/// `amp sin(w t + phase)` with its derivatives.
fn sine(amp: f64, w: f64, t: f64, phase: f64) -> Jet {
    let (s, c) = (w * t + phase).sin_cos();
    (amp * s, amp * w * c, -amp * w * w * s)
}

impl Handheld {
    /// The walk with `params`.
    pub fn new(params: &HandheldParams) -> Result<Self, ScenarioError> {
        params.validate()?;
        let length_m = params.laps * TAU * params.radius_m;
        // The two ramps cover half their time at cruise speed each.
        let cruise_s = (length_m / params.speed_mps - RAMP_S).max(0.0);
        Ok(Self {
            p: params.clone(),
            cruise_s,
        })
    }

    /// Its parameters.
    pub fn params(&self) -> &HandheldParams {
        &self.p
    }

    /// Time the walk starts and ends (the speed leaves and returns to zero), s.
    pub fn walking_s(&self) -> (f64, f64) {
        let t0 = self.p.rest_s;
        (t0, t0 + 2.0 * RAMP_S + self.cruise_s)
    }

    /// Distance along the circle (m), speed (m/s) and tangential acceleration (m/s^2).
    fn along(&self, t: f64) -> Jet {
        let v = self.p.speed_mps;
        let (t0, t_end) = self.walking_s();
        let t1 = t0 + RAMP_S;
        let t2 = t1 + self.cruise_s;
        if t <= t0 {
            (0.0, 0.0, 0.0)
        } else if t < t1 {
            let u = (t - t0) / RAMP_S;
            let (p, dp) = ramp(u);
            (v * RAMP_S * ramp_integral(u), v * p, v * dp / RAMP_S)
        } else if t < t2 {
            (v * RAMP_S / 2.0 + v * (t - t1), v, 0.0)
        } else if t < t_end {
            let u = (t - t2) / RAMP_S;
            let (p, dp) = ramp(u);
            let s = v * RAMP_S / 2.0 + v * self.cruise_s + v * RAMP_S * (u - ramp_integral(u));
            (s, v * (1.0 - p), -v * dp / RAMP_S)
        } else {
            (v * (RAMP_S + self.cruise_s), 0.0, 0.0)
        }
    }

    /// The gait's envelope (speed over cruise speed) with its derivatives.
    fn envelope(&self, t: f64) -> Jet {
        let (t0, t_end) = self.walking_s();
        let t2 = t0 + RAMP_S + self.cruise_s;
        let (_, v, a) = self.along(t);
        let v0 = self.p.speed_mps;
        let jerk = if t > t0 && t < t0 + RAMP_S {
            v0 * ramp_second((t - t0) / RAMP_S) / (RAMP_S * RAMP_S)
        } else if t > t2 && t < t_end {
            -v0 * ramp_second((t - t2) / RAMP_S) / (RAMP_S * RAMP_S)
        } else {
            0.0
        };
        (v / v0, a / v0, jerk / v0)
    }

    fn kinematics(&self, t: f64) -> Kinematics {
        let p = &self.p;
        let (s, v, a) = self.along(t);
        let r = p.radius_m;
        let psi = s / r;
        let (dpsi, ddpsi) = (v / r, a / r);
        let fwd = Vector3::new(psi.cos(), psi.sin(), 0.0);
        let left = Vector3::new(-psi.sin(), psi.cos(), 0.0);
        let centre = Vector3::new(r * psi.sin(), r * (1.0 - psi.cos()), 0.0);
        let e = self.envelope(t);
        let w = TAU * p.step_hz;
        let f = product(e, sine(p.surge_m, w, t, 0.0));
        let l = product(e, sine(p.sway_m, w / 2.0, t, 0.0));
        let z = product(e, sine(p.bounce_m, w, t, FRAC_PI_2));
        // The offset `f fwd + l left + z up` in a frame turning at `dpsi` about up.
        let df = f.1 - l.0 * dpsi;
        let dl = l.1 + f.0 * dpsi;
        let ddf = f.2 - l.1 * dpsi - l.0 * ddpsi - dl * dpsi;
        let ddl = l.2 + f.1 * dpsi + f.0 * ddpsi + df * dpsi;
        let up = Vector3::z();
        let pitch = product(e, sine(p.pitch_wobble_deg.to_radians(), w, t, 0.0));
        let yaw = psi - FRAC_PI_2;
        let attitude = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
            * UnitQuaternion::from_axis_angle(
                &Vector3::x_axis(),
                p.tilt_deg.to_radians() + pitch.0,
            );
        let pitch_axis = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
        Kinematics {
            position: centre + f.0 * fwd + l.0 * left + z.0 * up,
            velocity: v * fwd + df * fwd + dl * left + z.1 * up,
            accel: a * fwd + v * dpsi * left + ddf * fwd + ddl * left + z.2 * up,
            attitude,
            rate: dpsi * up + pitch.1 * pitch_axis,
            at_rest: v == 0.0,
        }
    }
}

impl Scenario for Handheld {
    fn truth(&self, t_s: f64) -> Truth {
        assert!(
            t_s.is_finite() && t_s >= 0.0,
            "scenario time must be finite and >= 0, got {t_s} s"
        );
        self.kinematics(t_s).truth(t_s, self.p.gravity_mps2)
    }

    fn duration_s(&self) -> f64 {
        self.walking_s().1 + self.p.rest_s
    }

    fn wheel_speed_mps(&self, _t_s: f64) -> f64 {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The truth's velocity and acceleration are the derivatives of its position (central
    /// differences), through the ramps and the cruise, and the walk closes.
    #[test]
    fn the_truth_is_consistent_and_the_walk_closes() {
        let walk = Handheld::new(&HandheldParams::new(1.5)).unwrap();
        let (t0, t_end) = walk.walking_s();
        let h = 1e-4;
        for t in [t0 + 0.3, t0 + 0.9, t0 + 7.3, t_end - 0.5, t_end - 0.1] {
            let k = |t| walk.kinematics(t);
            let (a, b, c) = (k(t - h), k(t), k(t + h));
            let dv = (c.position - a.position) / (2.0 * h) - b.velocity;
            let da = (c.velocity - a.velocity) / (2.0 * h) - b.accel;
            assert!(dv.norm() < 1e-6 && da.norm() < 1e-4, "t {t}: {dv:?} {da:?}");
            // The attitude's rate, from the quaternions.
            let dq = a.attitude.inverse() * c.attitude;
            let rate = a.attitude * dq.scaled_axis() / (2.0 * h);
            assert!(
                (rate - b.rate).norm() < 1e-4,
                "t {t}: {rate:?} {:?}",
                b.rate
            );
        }
        let end = walk.kinematics(walk.duration_s());
        // 1.5 laps end across the circle, 8 m from the start.
        assert!((end.position - Vector3::new(0.0, 8.0, 0.0)).norm() < 1e-9);
        assert!(end.at_rest && walk.kinematics(1.0).at_rest);
        let closed = Handheld::new(&HandheldParams::new(2.0)).unwrap();
        assert!(closed.kinematics(closed.duration_s()).position.norm() < 1e-9);
    }
}
