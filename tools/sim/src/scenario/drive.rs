//! A ground robot driving on a flat, level floor, or a vehicle whose stops are on slopes:
//! accelerate, cruise, turn, change speed, brake, rest, repeat.

use nalgebra::{UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use recording::Truth;

use super::{
    Kinematics, RAMP_PEAK, Scenario, ScenarioError, check_positive, check_range, gauss_legendre,
    ramp,
};
use crate::{stream_rng, streams};

/// Spacing of the stored positions inside a moving segment, s: the position at any time is the
/// stored one before it plus one 8-point Gauss-Legendre integral, exact to rounding error for
/// profiles whose shortest time scale (a ramp) is well above this.
const KNOT_S: f64 = 0.25;

/// How many planned motions may overrun the drive's end before planning stops.
const MAX_MISFITS: u32 = 20;

/// Parameters of a drive. Randomised quantities are drawn uniformly from `[min, max]` ranges.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveParams {
    /// Planned length, s; the drive ends with a rest that fills up to it.
    pub duration_s: f64,
    /// Rest at the start (for alignment and the rest detector's thresholds), s (>= 0).
    pub initial_rest_s: f64,
    /// Length of each rest between motions, s.
    pub rest_s: [f64; 2],
    /// Cruise speed of each leg, m/s.
    pub cruise_speed_mps: [f64; 2],
    /// Peak longitudinal acceleration of every speed change, m/s^2 (squared raised-cosine
    /// profile: a change of `dv` takes `8/3 |dv| / peak` seconds).
    pub peak_accel_mps2: f64,
    /// Length of each constant-speed leg, s.
    pub leg_s: [f64; 2],
    /// Each motion has between 1 and this many legs; between legs the robot turns (when
    /// `turns` is on) and changes to the next leg's speed.
    pub max_legs: u32,
    /// Longest motion between two rests, s: the planner drops further legs and shortens the
    /// last one so that acceleration, legs, turns, speed changes and braking fit, so the robot
    /// rests at least this often. Must allow the shortest motion (accelerating to the top
    /// cruise speed, the shortest leg, braking) and, with `in_place_turns`, the widest turn.
    pub max_motion_s: f64,
    /// Whether the robot turns between legs (otherwise it drives along one straight line).
    pub turns: bool,
    /// Magnitude of each turn (random sign), degrees.
    pub turn_angle_deg: [f64; 2],
    /// Peak yaw rate of turns and in-place turns, deg/s (squared raised-cosine profile: a
    /// turn of `a` takes `8/3 |a| / peak` seconds).
    pub peak_yaw_rate_dps: f64,
    /// Whether half of the motions start with an in-place turn followed by a rest.
    pub in_place_turns: bool,
    /// Track width of the differential drive, m (sets the wheel speeds of in-place turns).
    pub track_width_m: f64,
    /// Mounting of the IMU on the robot: rotates sensor-frame vectors into the body frame
    /// (x forward, y left, z up). The IMU sits at the body origin (no lever arm).
    pub mounting: UnitQuaternion<f64>,
    /// Local gravity, m/s^2.
    pub gravity_mps2: f64,
    /// Largest grade of the road where each motion ends, degrees (nose up positive): while it
    /// brakes, the body pitches from the grade it started on to one drawn uniformly from
    /// `[-max, max]` (from a stream of its own), and climbs or descends with it (velocity
    /// along the body's x axis). 0: a flat, level floor.
    pub max_slope_deg: f64,
}

impl DriveParams {
    /// A drive of `duration_s` seconds: 10 s initial rest, rests of 1-30 s, motions of at most
    /// 30 s between them, cruise 0.2-1 m/s at up to 0.5 m/s^2, legs of 2-10 s (up to 3 per
    /// motion), no turns, turns (when switched on) of 30-120 degrees at up to 45 deg/s, no
    /// in-place turns, 0.3 m track, IMU mounted aligned with the body, standard gravity.
    pub fn new(duration_s: f64) -> Self {
        Self {
            duration_s,
            initial_rest_s: 10.0,
            rest_s: [1.0, 30.0],
            cruise_speed_mps: [0.2, 1.0],
            peak_accel_mps2: 0.5,
            leg_s: [2.0, 10.0],
            max_legs: 3,
            max_motion_s: 30.0,
            turns: false,
            turn_angle_deg: [30.0, 120.0],
            peak_yaw_rate_dps: 45.0,
            in_place_turns: false,
            track_width_m: 0.3,
            mounting: UnitQuaternion::identity(),
            gravity_mps2: ipc_types::units::STANDARD_GRAVITY_MPS2,
            max_slope_deg: 0.0,
        }
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        check_positive("duration_s", self.duration_s)?;
        let r0 = self.initial_rest_s;
        if !(r0.is_finite() && r0 >= 0.0 && r0 <= self.duration_s) {
            return Err(ScenarioError {
                field: "initial_rest_s".into(),
                reason: format!("needs 0 <= initial_rest_s <= duration_s, got {r0}"),
            });
        }
        check_range("rest_s", self.rest_s)?;
        check_range("cruise_speed_mps", self.cruise_speed_mps)?;
        check_positive("peak_accel_mps2", self.peak_accel_mps2)?;
        check_range("leg_s", self.leg_s)?;
        if self.max_legs == 0 {
            return Err(ScenarioError {
                field: "max_legs".into(),
                reason: "must be >= 1".into(),
            });
        }
        check_range("turn_angle_deg", self.turn_angle_deg)?;
        check_positive("peak_yaw_rate_dps", self.peak_yaw_rate_dps)?;
        check_positive("max_motion_s", self.max_motion_s)?;
        let shortest =
            2.0 * RAMP_PEAK * self.cruise_speed_mps[1] / self.peak_accel_mps2 + self.leg_s[0];
        if shortest > self.max_motion_s {
            return Err(ScenarioError {
                field: "max_motion_s".into(),
                reason: format!(
                    "{} s is shorter than the shortest motion at the top cruise speed \
                     ({shortest} s: accelerate, shortest leg, brake)",
                    self.max_motion_s
                ),
            });
        }
        let widest_turn = RAMP_PEAK * self.turn_angle_deg[1] / self.peak_yaw_rate_dps;
        if self.in_place_turns && widest_turn > self.max_motion_s {
            return Err(ScenarioError {
                field: "max_motion_s".into(),
                reason: format!(
                    "{} s is shorter than the widest in-place turn ({widest_turn} s)",
                    self.max_motion_s
                ),
            });
        }
        let w = self.track_width_m;
        if !(w.is_finite() && w >= 0.0) {
            return Err(ScenarioError {
                field: "track_width_m".into(),
                reason: format!("must be finite and >= 0, got {w}"),
            });
        }
        let slope = self.max_slope_deg;
        if !(slope.is_finite() && (0.0..45.0).contains(&slope)) {
            return Err(ScenarioError {
                field: "max_slope_deg".into(),
                reason: format!("must be in [0, 45), got {slope}"),
            });
        }
        check_positive("gravity_mps2", self.gravity_mps2)
    }
}

/// One piece of a drive, over `[start_s, start_s + duration_s)`: forward speed and heading each
/// follow a smooth ramp from their start values, `v(t) = v0 + dv P(x)`, `psi(t) = psi0 +
/// dpsi P(x)` with `x = (t - start_s) / duration_s` and `P` the normalised ramp whose rate is
/// a squared raised cosine, `P'(x) = (8/3) sin^4(pi x)`.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveSegment {
    /// Start time, s.
    pub start_s: f64,
    /// Length, s.
    pub duration_s: f64,
    /// Forward speed at the start, m/s.
    pub speed0_mps: f64,
    /// Change of forward speed over the segment, m/s.
    pub speed_change_mps: f64,
    /// Heading at the start (angle of body x from navigation x, counter-clockwise), rad.
    pub heading0_rad: f64,
    /// Change of heading over the segment, rad.
    pub heading_change_rad: f64,
    /// Whether this is a rest (zero speed and yaw rate throughout).
    pub at_rest: bool,
    /// Pitch (grade) at the start, rad, nose up positive.
    pub pitch0_rad: f64,
    /// Change of pitch over the segment, rad (same ramp).
    pub pitch_change_rad: f64,
    /// Position at the start and then every `KNOT_S`, m (navigation x, y, z).
    knots: Vec<[f64; 3]>,
}

impl DriveSegment {
    /// Forward speed (m/s), its rate (m/s^2), heading (rad) and yaw rate (rad/s) at `s`
    /// seconds into the segment.
    fn profile(&self, s: f64) -> (f64, f64, f64, f64) {
        let (p, dp) = ramp(s / self.duration_s);
        (
            self.speed0_mps + self.speed_change_mps * p,
            self.speed_change_mps * dp / self.duration_s,
            self.heading0_rad + self.heading_change_rad * p,
            self.heading_change_rad * dp / self.duration_s,
        )
    }

    /// Pitch (rad) and pitch rate (rad/s) at `s` seconds into the segment.
    fn pitch(&self, s: f64) -> (f64, f64) {
        let (p, dp) = ramp(s / self.duration_s);
        (
            self.pitch0_rad + self.pitch_change_rad * p,
            self.pitch_change_rad * dp / self.duration_s,
        )
    }

    /// Navigation-frame velocity at `s` seconds into the segment, m/s: the forward speed is
    /// the horizontal one, and the body climbs at its grade (`v tan(pitch)`).
    fn velocity(&self, s: f64) -> [f64; 3] {
        let (v, _, psi, _) = self.profile(s);
        let (pitch, _) = self.pitch(s);
        [v * psi.cos(), v * psi.sin(), v * pitch.tan()]
    }

    /// Position at `s` seconds into the segment, m.
    fn position(&self, s: f64) -> [f64; 3] {
        let k = ((s / KNOT_S).floor() as usize).min(self.knots.len() - 1);
        let base = self.knots[k];
        if self.at_rest {
            return base;
        }
        let d = gauss_legendre(k as f64 * KNOT_S, s, |u| self.velocity(u));
        std::array::from_fn(|i| base[i] + d[i])
    }

    /// Fills the stored positions from the start position `p0`.
    fn integrate_knots(&mut self, p0: [f64; 3]) {
        self.knots = vec![p0];
        if self.at_rest {
            return;
        }
        let count = (self.duration_s / KNOT_S).floor() as usize;
        for k in 1..=count {
            let prev = self.knots[k - 1];
            let d = gauss_legendre((k - 1) as f64 * KNOT_S, k as f64 * KNOT_S, |u| {
                self.velocity(u)
            });
            self.knots.push(std::array::from_fn(|i| prev[i] + d[i]));
        }
    }
}

/// A ground robot's drive on a flat, level floor, generated from a seed: an initial rest, then
/// motions separated by rests. A motion optionally starts with an in-place turn and a rest,
/// then accelerates to a cruise speed, drives 1 to `max_legs` legs (turning and changing speed
/// between legs) and brakes to a stop, all within `max_motion_s`. Every speed and heading change follows a squared
/// raised-cosine rate profile, so acceleration and yaw rate are continuous with three
/// continuous derivatives.
#[derive(Debug, Clone)]
pub struct Drive {
    segments: Vec<DriveSegment>,
    params: DriveParams,
}

/// One step of a drive's plan.
#[derive(Debug, Clone, Copy)]
struct Step {
    /// Length, s (> 0: zero-length steps are never planned).
    duration_s: f64,
    /// Forward speed at the end of the step, m/s: the plan carries absolute speeds, so that a
    /// braking step ends at exactly 0 whatever the speed changes before it.
    speed_after_mps: f64,
    /// Change of heading over the step, rad.
    heading_change_rad: f64,
    /// Whether the step is a rest.
    at_rest: bool,
}

impl Step {
    fn rest(duration_s: f64) -> Self {
        Self {
            duration_s,
            speed_after_mps: 0.0,
            heading_change_rad: 0.0,
            at_rest: true,
        }
    }
}

impl Drive {
    /// Generates a drive from `params` and `seed`.
    pub fn new(params: &DriveParams, seed: u64) -> Result<Self, ScenarioError> {
        params.validate()?;
        let mut rng = stream_rng(seed, streams::DRIVE_PLAN);
        let mut steps: Vec<Step> = Vec::new();
        if params.initial_rest_s > 0.0 {
            steps.push(Step::rest(params.initial_rest_s));
        }
        let mut t = params.initial_rest_s;
        // Plan motions (each followed by a rest) while they fit; near the end, a few more
        // draws look for a shorter one that still fits.
        let mut misfits = 0;
        while misfits < MAX_MISFITS {
            let mut motion = Self::plan_motion(params, &mut rng);
            motion.push(Step::rest(uniform(&mut rng, params.rest_s)));
            let length: f64 = motion.iter().map(|s| s.duration_s).sum();
            if t + length > params.duration_s {
                misfits += 1;
                continue;
            }
            t += length;
            steps.extend(motion);
        }
        // The final rest fills up to the planned duration.
        let remaining = params.duration_s - t;
        match steps.last_mut() {
            Some(last) if last.at_rest => last.duration_s += remaining,
            _ => steps.push(Step::rest(remaining)),
        }

        let mut slopes = stream_rng(seed, streams::DRIVE_SLOPES);
        let max_slope = params.max_slope_deg.to_radians();
        let mut segments = Vec::with_capacity(steps.len());
        let (mut start, mut speed, mut heading, mut pos) = (0.0, 0.0, 0.0, [0.0; 3]);
        let mut pitch = 0.0;
        for step in steps {
            // A braking step (to a stop, from a speed) ends on the next stop's grade.
            let braking = !step.at_rest && step.speed_after_mps == 0.0 && speed > 0.0;
            let next_pitch = if braking && max_slope > 0.0 {
                uniform(&mut slopes, [-max_slope, max_slope])
            } else {
                pitch
            };
            let mut seg = DriveSegment {
                start_s: start,
                duration_s: step.duration_s,
                speed0_mps: speed,
                speed_change_mps: step.speed_after_mps - speed,
                heading0_rad: heading,
                heading_change_rad: step.heading_change_rad,
                at_rest: step.at_rest,
                pitch0_rad: pitch,
                pitch_change_rad: next_pitch - pitch,
                knots: Vec::new(),
            };
            seg.integrate_knots(pos);
            pos = seg.position(step.duration_s);
            pitch = next_pitch;
            start += step.duration_s;
            speed = step.speed_after_mps;
            heading += step.heading_change_rad;
            segments.push(seg);
        }
        Ok(Self {
            segments,
            params: params.clone(),
        })
    }

    /// One motion: optional in-place turn and rest, acceleration, legs with turns and speed
    /// changes between them, braking. The part after the optional rest lasts at most
    /// `max_motion_s`: a further leg is added only if it fits with at least the shortest leg
    /// and the braking, and the last leg is shortened to fit.
    fn plan_motion(p: &DriveParams, rng: &mut ChaCha8Rng) -> Vec<Step> {
        let peak_yaw = p.peak_yaw_rate_dps.to_radians();
        let turn = |rng: &mut ChaCha8Rng, speed: f64| {
            let angle = uniform(rng, p.turn_angle_deg).to_radians();
            let signed = if rng.random_bool(0.5) { angle } else { -angle };
            Step {
                duration_s: RAMP_PEAK * angle / peak_yaw,
                speed_after_mps: speed,
                heading_change_rad: signed,
                at_rest: false,
            }
        };
        let change_s = |from: f64, to: f64| RAMP_PEAK * (to - from).abs() / p.peak_accel_mps2;
        let speed_change = |from: f64, to: f64| Step {
            duration_s: change_s(from, to),
            speed_after_mps: to,
            heading_change_rad: 0.0,
            at_rest: false,
        };
        let mut steps = Vec::new();
        if p.in_place_turns && rng.random_bool(0.5) {
            steps.push(turn(rng, 0.0));
            steps.push(Step::rest(uniform(rng, p.rest_s)));
        }
        let mut speed = uniform(rng, p.cruise_speed_mps);
        steps.push(speed_change(0.0, speed));
        let mut used = change_s(0.0, speed);
        let legs = rng.random_range(1..=p.max_legs);
        for leg in 0..legs {
            if leg > 0 {
                let turned = p.turns.then(|| turn(rng, speed));
                let next = uniform(rng, p.cruise_speed_mps);
                let between = turned.map_or(0.0, |s| s.duration_s) + change_s(speed, next);
                if used + between + p.leg_s[0] + change_s(next, 0.0) > p.max_motion_s {
                    break;
                }
                steps.extend(turned);
                // Equal speeds need no change (a zero-length step would divide by zero).
                if next != speed {
                    steps.push(speed_change(speed, next));
                }
                used += between;
                speed = next;
            }
            let room = p.max_motion_s - used - change_s(speed, 0.0);
            let leg_s = uniform(rng, p.leg_s).min(room);
            steps.push(Step {
                duration_s: leg_s,
                speed_after_mps: speed,
                heading_change_rad: 0.0,
                at_rest: false,
            });
            used += leg_s;
        }
        steps.push(speed_change(speed, 0.0));
        steps
    }

    /// The segments of the drive, in time order.
    pub fn segments(&self) -> &[DriveSegment] {
        &self.segments
    }

    /// The parameters the drive was generated from.
    pub fn params(&self) -> &DriveParams {
        &self.params
    }

    /// The segment containing `t_s` and the time into it (clamped to its end after the drive).
    fn locate(&self, t_s: f64) -> (&DriveSegment, f64) {
        assert!(t_s.is_finite() && t_s >= 0.0, "truth at {t_s} s");
        let i = self.segments.partition_point(|s| s.start_s <= t_s) - 1;
        let seg = &self.segments[i];
        (seg, (t_s - seg.start_s).min(seg.duration_s))
    }

    /// The robot's forward speed (m/s, body x) and yaw rate (rad/s, about body z) at `t_s`:
    /// what wheel encoders would report.
    pub fn body_motion(&self, t_s: f64) -> (f64, f64) {
        let (seg, s) = self.locate(t_s);
        let (v, _, _, yaw_rate) = seg.profile(s);
        (v, yaw_rate)
    }
}

/// A uniform draw from `[lo, hi]` (exactly `lo` when the range is empty).
fn uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f64; 2]) -> f64 {
    if hi > lo {
        rng.random_range(lo..=hi)
    } else {
        lo
    }
}

impl Scenario for Drive {
    fn truth(&self, t_s: f64) -> Truth {
        let (seg, s) = self.locate(t_s);
        let (v, dv, psi, dpsi) = seg.profile(s);
        let (pitch, dpitch) = seg.pitch(s);
        let (sin, cos) = psi.sin_cos();
        let tan = pitch.tan();
        let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), psi);
        // Nose up is a negative turn about body y (left) in this z-up frame.
        let body = yaw * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -pitch);
        Kinematics {
            position: Vector3::from(seg.position(s)),
            velocity: Vector3::new(v * cos, v * sin, v * tan),
            // d/dt (v cos psi, v sin psi, v tan pitch).
            accel: Vector3::new(
                dv * cos - v * dpsi * sin,
                dv * sin + v * dpsi * cos,
                dv * tan + v * dpitch / (pitch.cos() * pitch.cos()),
            ),
            attitude: body * self.params.mounting,
            rate: Vector3::new(0.0, 0.0, dpsi) + yaw * Vector3::new(0.0, -dpitch, 0.0),
            // Rest segments (where speed and yaw rate are exactly zero by construction), and
            // the instants where a motion starts or ends.
            at_rest: seg.at_rest || (v == 0.0 && dpsi == 0.0 && dpitch == 0.0),
        }
        .truth(t_s, self.params.gravity_mps2)
    }

    fn duration_s(&self) -> f64 {
        self.params.duration_s
    }

    /// The mean of the two wheels' ground speeds of a differential drive, `(|v + w b / 2| +
    /// |v - w b / 2|) / 2` with forward speed `v`, yaw rate `w` and track width `b`.
    fn wheel_speed_mps(&self, t_s: f64) -> f64 {
        let (v, w) = self.body_motion(t_s);
        let half = 0.5 * w * self.params.track_width_m;
        0.5 * ((v + half).abs() + (v - half).abs())
    }
}
