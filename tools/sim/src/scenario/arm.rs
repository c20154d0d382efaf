//! An industrial arm carrying the sensor: a rest at the start, then moves between random
//! waypoints of its workspace with short pauses between them, back to where it started.

use nalgebra::{Unit, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use recording::Truth;

use super::{Kinematics, Scenario, ScenarioError, check_positive, check_range, ramp};
use crate::{stream_rng, streams};

/// Parameters of an arm's path. Randomised quantities are drawn uniformly from `[min, max]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmParams {
    /// Moves between waypoints; the last one returns to the start (>= 2).
    pub moves: usize,
    /// Rest at the start, s (>= 0).
    pub initial_rest_s: f64,
    /// Pause after each move, s.
    pub pause_s: [f64; 2],
    /// Length of each move, s.
    pub move_s: [f64; 2],
    /// Half-width of the workspace around the start, m: waypoints are uniform in a box of
    /// `+-reach` horizontally and `+-reach / 2` vertically.
    pub reach_m: f64,
    /// Largest angle between a waypoint's attitude and the start's (level), degrees: each is
    /// the start turned about a uniformly random axis by a uniform angle up to it.
    pub max_turn_deg: f64,
    /// Local gravity, m/s^2.
    pub gravity_mps2: f64,
}

impl ArmParams {
    /// `moves` moves of 0.8-2 s with pauses of 0.1-0.65 s (the arm recordings of issue 28's
    /// measurements), 1.6 s of rest first, a 0.5 m reach, turns up to 90 deg, standard gravity.
    pub fn new(moves: usize) -> Self {
        Self {
            moves,
            initial_rest_s: 1.6,
            pause_s: [0.1, 0.65],
            move_s: [0.8, 2.0],
            reach_m: 0.5,
            max_turn_deg: 90.0,
            gravity_mps2: ipc_types::units::STANDARD_GRAVITY_MPS2,
        }
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        if self.moves < 2 {
            return Err(ScenarioError {
                field: "moves".into(),
                reason: format!("needs at least 2 (out and back), got {}", self.moves),
            });
        }
        let r0 = self.initial_rest_s;
        if !(r0.is_finite() && r0 >= 0.0) {
            return Err(ScenarioError {
                field: "initial_rest_s".into(),
                reason: format!("must be finite and >= 0, got {r0}"),
            });
        }
        check_range("pause_s", self.pause_s)?;
        check_range("move_s", self.move_s)?;
        check_positive("reach_m", self.reach_m)?;
        let turn = self.max_turn_deg;
        if !(turn.is_finite() && (0.0..=180.0).contains(&turn)) {
            return Err(ScenarioError {
                field: "max_turn_deg".into(),
                reason: format!("must be in [0, 180], got {turn}"),
            });
        }
        check_positive("gravity_mps2", self.gravity_mps2)
    }
}

/// One move: from `p0`, `q0` by `dp` and a turn of `angle` about the navigation-frame `axis`,
/// over `[start_s, start_s + duration_s)`, then a pause until `end_s`.
#[derive(Debug, Clone)]
struct Move {
    start_s: f64,
    duration_s: f64,
    end_s: f64,
    p0: Vector3<f64>,
    dp: Vector3<f64>,
    q0: UnitQuaternion<f64>,
    axis: Unit<Vector3<f64>>,
    angle: f64,
}

/// An arm's path, generated from a seed: position and attitude follow the squared
/// raised-cosine ramp of every scenario from one waypoint to the next (a straight line and a
/// turn about a fixed axis), so velocity, acceleration and rate are continuous.
#[derive(Debug, Clone)]
pub struct Arm {
    moves: Vec<Move>,
    params: ArmParams,
}

/// A uniform draw from `[lo, hi]` (exactly `lo` when the range is empty).
fn uniform(rng: &mut ChaCha8Rng, [lo, hi]: [f64; 2]) -> f64 {
    if hi > lo {
        rng.random_range(lo..=hi)
    } else {
        lo
    }
}

/// A waypoint: a position in the workspace and an attitude turned from level.
fn waypoint(rng: &mut ChaCha8Rng, p: &ArmParams) -> (Vector3<f64>, UnitQuaternion<f64>) {
    let r = p.reach_m;
    let pos = Vector3::new(
        uniform(rng, [-r, r]),
        uniform(rng, [-r, r]),
        uniform(rng, [-r / 2.0, r / 2.0]),
    );
    let axis = Vector3::new(
        uniform(rng, [-1.0, 1.0]),
        uniform(rng, [-1.0, 1.0]),
        uniform(rng, [-1.0, 1.0]),
    );
    let angle = uniform(rng, [0.0, p.max_turn_deg.to_radians()]);
    let q = Unit::try_new(axis, 1e-9).map_or(UnitQuaternion::identity(), |a| {
        UnitQuaternion::from_axis_angle(&a, angle)
    });
    (pos, q)
}

impl Arm {
    /// Generates a path from `params` and `seed`.
    pub fn new(params: &ArmParams, seed: u64) -> Result<Self, ScenarioError> {
        params.validate()?;
        let mut rng = stream_rng(seed, streams::ARM_PLAN);
        let start = (Vector3::zeros(), UnitQuaternion::identity());
        let mut points: Vec<_> = (1..params.moves)
            .map(|_| waypoint(&mut rng, params))
            .collect();
        points.insert(0, start);
        points.push(start);
        let mut t = params.initial_rest_s;
        let mut moves = Vec::with_capacity(params.moves);
        for w in points.windows(2) {
            let ((p0, q0), (p1, q1)) = (w[0], w[1]);
            let (axis, angle) = (q1 * q0.inverse())
                .axis_angle()
                .unwrap_or((Vector3::z_axis(), 0.0));
            let duration_s = uniform(&mut rng, params.move_s);
            let end_s = t + duration_s + uniform(&mut rng, params.pause_s);
            moves.push(Move {
                start_s: t,
                duration_s,
                end_s,
                p0,
                dp: p1 - p0,
                q0,
                axis,
                angle,
            });
            t = end_s;
        }
        Ok(Self {
            moves,
            params: params.clone(),
        })
    }

    /// The intervals `[start, end)` s of the moves (the pauses and rests are between them).
    pub fn move_intervals_s(&self) -> Vec<(f64, f64)> {
        self.moves
            .iter()
            .map(|m| (m.start_s, m.start_s + m.duration_s))
            .collect()
    }
}

/// The ramp's second derivative `P''(x) = (8 pi / 3) sin(2 pi x) - (4 pi / 3) sin(4 pi x)` on
/// [0, 1], 0 outside (see [`ramp`]).
fn ramp_rate(x: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    if x <= 0.0 || x >= 1.0 {
        return 0.0;
    }
    8.0 * PI / 3.0 * (TAU * x).sin() - 4.0 * PI / 3.0 * (2.0 * TAU * x).sin()
}

impl Scenario for Arm {
    fn truth(&self, t_s: f64) -> Truth {
        assert!(t_s.is_finite() && t_s >= 0.0, "truth at {t_s} s");
        let i = self.moves.partition_point(|m| m.start_s <= t_s);
        let kinematics = if i == 0 {
            // The rest at the start.
            let m = &self.moves[0];
            Kinematics {
                position: m.p0,
                velocity: Vector3::zeros(),
                accel: Vector3::zeros(),
                attitude: m.q0,
                rate: Vector3::zeros(),
                at_rest: true,
            }
        } else {
            let m = &self.moves[i - 1];
            let x = (t_s - m.start_s) / m.duration_s;
            let (p, dp) = ramp(x);
            let t = m.duration_s;
            Kinematics {
                position: m.p0 + m.dp * p,
                velocity: m.dp * (dp / t),
                accel: m.dp * (ramp_rate(x) / (t * t)),
                attitude: UnitQuaternion::from_axis_angle(&m.axis, m.angle * p) * m.q0,
                rate: m.axis.into_inner() * (m.angle * dp / t),
                at_rest: dp == 0.0,
            }
        };
        kinematics.truth(t_s, self.params.gravity_mps2)
    }

    fn duration_s(&self) -> f64 {
        self.moves.last().map_or(0.0, |m| m.end_s)
    }

    fn wheel_speed_mps(&self, _t_s: f64) -> f64 {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_rate_is_the_derivative_of_the_ramps_rate() {
        for x in [0.1, 0.25, 0.4, 0.5, 0.77, 0.9] {
            let h = 1e-6;
            let numeric = (ramp(x + h).1 - ramp(x - h).1) / (2.0 * h);
            assert!((ramp_rate(x) - numeric).abs() < 1e-6, "x {x}");
        }
    }

    #[test]
    fn the_path_returns_to_its_start_and_rests_in_its_pauses() {
        let arm = Arm::new(&ArmParams::new(6), 3).unwrap();
        let end = arm.truth(arm.duration_s());
        assert!(Vector3::from(end.position_m).norm() < 1e-12);
        assert!(end.at_rest);
        let moves = arm.move_intervals_s();
        assert_eq!(moves.len(), 6);
        for w in moves.windows(2) {
            let pause = w[1].0 - w[0].1;
            assert!((0.1..=0.65).contains(&pause), "pause {pause} s");
            let mid = arm.truth(0.5 * (w[0].1 + w[1].0));
            assert!(mid.at_rest && Vector3::from(mid.velocity_mps).norm() == 0.0);
        }
        // Velocity is the derivative of position mid-move.
        let (a, b) = moves[2];
        let t = 0.5 * (a + b);
        let h = 1e-5;
        let (p1, p0) = (arm.truth(t + h).position_m, arm.truth(t - h).position_m);
        let v = arm.truth(t).velocity_mps;
        for k in 0..3 {
            assert!(((p1[k] - p0[k]) / (2.0 * h) - v[k]).abs() < 1e-6);
        }
    }

    #[test]
    fn bad_parameters_are_named() {
        let e = Arm::new(
            &ArmParams {
                moves: 1,
                ..ArmParams::new(1)
            },
            0,
        )
        .unwrap_err();
        assert_eq!(e.field, "moves");
        let e = Arm::new(
            &ArmParams {
                max_turn_deg: 200.0,
                ..ArmParams::new(4)
            },
            0,
        )
        .unwrap_err();
        assert_eq!(e.field, "max_turn_deg");
    }
}
