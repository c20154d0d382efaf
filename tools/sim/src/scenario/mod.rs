//! Scenarios: motions with their exact ground truth, each a deterministic function of a seed.
//!
//! Frames and signs as in `ipc-types`: navigation frame z-up with gravity (0, 0, -g); the truth
//! attitude rotates sensor-frame vectors into the navigation frame; the truth specific force is
//! `f = R^T (a_nav - g_nav)` in the sensor frame (+g on z when lying level) and the truth
//! angular rate is the sensor's rate relative to the navigation frame, in the sensor frame
//! (the Earth's rotation is neglected). Every motion profile is smooth (raised-cosine
//! acceleration and turn rate), and the truth is evaluated in closed form or by high-order
//! quadrature, so it is exact to rounding error at any time.

mod arm;
mod drive;
mod handheld;
mod pose;
mod walk;

pub use arm::{Arm, ArmParams};
pub use drive::{Drive, DriveParams, DriveSegment};
pub use handheld::{Handheld, HandheldParams};
pub use pose::{PoseParams, PoseSession};
pub use walk::{Walk, WalkParams};

use nalgebra::{UnitQuaternion, Vector3};
use recording::Truth;

/// An invalid scenario parameter: names the parameter and says what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("scenario parameter `{field}`: {reason}")]
pub struct ScenarioError {
    /// The parameter's name, e.g. `rest_s`.
    pub field: String,
    /// What is wrong with it.
    pub reason: String,
}

/// Returns an error for `field` unless `x` is finite and `> 0`.
fn check_positive(field: &str, x: f64) -> Result<(), ScenarioError> {
    if x.is_finite() && x > 0.0 {
        Ok(())
    } else {
        Err(ScenarioError {
            field: field.into(),
            reason: format!("must be finite and > 0, got {x}"),
        })
    }
}

/// Returns an error for `field` unless `lo <= hi` and both are finite and `> 0`.
fn check_range(field: &str, [lo, hi]: [f64; 2]) -> Result<(), ScenarioError> {
    if lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi {
        Ok(())
    } else {
        Err(ScenarioError {
            field: field.into(),
            reason: format!("needs 0 < min <= max, got [{lo}, {hi}]"),
        })
    }
}

/// A motion with its ground truth at any time.
pub trait Scenario {
    /// Ground truth at `t_s` seconds after the start (power-on); after [`Self::duration_s`]
    /// the final state holds (always a rest).
    ///
    /// # Panics
    /// If `t_s` is negative or not finite.
    fn truth(&self, t_s: f64) -> Truth;

    /// The planned length of the scenario, s.
    fn duration_s(&self) -> f64;

    /// Mean ground speed of the driven wheels at `t_s`, m/s: what sets the level of the motor
    /// and wheel vibration (0 when nothing is driven).
    fn wheel_speed_mps(&self, t_s: f64) -> f64;

    /// What the sensor sees at `t_s` beyond the truth's motion (e.g. a walker's tremor):
    /// specific force in m/s^2 and angular rate in deg/s, sensor frame. None by default.
    fn disturbance(&self, _t_s: f64) -> ([f64; 3], [f64; 3]) {
        ([0.0; 3], [0.0; 3])
    }
}

/// Nanoseconds from seconds, rounded (the conversion every sample and truth time uses).
///
/// # Panics
/// If `t_s` is negative or not finite.
pub fn ns_from_s(t_s: f64) -> u64 {
    assert!(
        t_s.is_finite() && t_s >= 0.0,
        "sample time must be finite and >= 0, got {t_s} s"
    );
    (t_s * 1e9).round() as u64
}

/// The normalised ramp every profile follows: its rate is a squared raised cosine,
/// `P'(x) = (8/3) sin^4(pi x) = 1 - (4/3) cos(2 pi x) + (1/3) cos(4 pi x)`, so
/// `P(x) = x - 2 sin(2 pi x) / (3 pi) + sin(4 pi x) / (12 pi)` rises from 0 to 1 on [0, 1]
/// (clamped outside) with its first three derivatives zero at both ends: a speed or heading
/// following it has continuous acceleration, jerk and snap, which keeps the trapezoid rule's
/// error at its smooth-function (Euler-Maclaurin) level. The peak rate is `8/3`. Returns
/// `(P, P')` with the derivative in `x`.
fn ramp(x: f64) -> (f64, f64) {
    use std::f64::consts::{PI, TAU};
    if x <= 0.0 {
        (0.0, 0.0)
    } else if x >= 1.0 {
        (1.0, 0.0)
    } else {
        let (s1, c1) = (TAU * x).sin_cos();
        let (s2, c2) = (2.0 * TAU * x).sin_cos();
        (
            x - 2.0 * s1 / (3.0 * PI) + s2 / (12.0 * PI),
            1.0 - 4.0 / 3.0 * c1 + c2 / 3.0,
        )
    }
}

/// Peak of the ramp's rate `P'`: a change of `d` at a peak rate `r` takes `RAMP_PEAK d / r`.
const RAMP_PEAK: f64 = 8.0 / 3.0;

/// 8-point Gauss-Legendre nodes and weights on [-1, 1] (exact for polynomials of degree 15).
/// Written out because it is eight constants; a test checks them against exact moments.
const GAUSS_LEGENDRE_8: [(f64, f64); 8] = [
    (-0.960_289_856_497_536_3, 0.101_228_536_290_376_3),
    (-0.796_666_477_413_626_7, 0.222_381_034_453_374_5),
    (-0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (-0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.183_434_642_495_649_8, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_5),
    (0.960_289_856_497_536_3, 0.101_228_536_290_376_3),
];

/// Integral of `f` over [a, b] by 8-point Gauss-Legendre quadrature.
fn gauss_legendre<const N: usize>(a: f64, b: f64, f: impl Fn(f64) -> [f64; N]) -> [f64; N] {
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    let mut acc = [0.0; N];
    for (x, w) in GAUSS_LEGENDRE_8 {
        let v = f(mid + half * x);
        for (a, v) in acc.iter_mut().zip(v) {
            *a += w * half * v;
        }
    }
    acc
}

/// Kinematics of the sensor in the navigation frame at one time.
struct Kinematics {
    /// Position, m.
    position: Vector3<f64>,
    /// Velocity, m/s.
    velocity: Vector3<f64>,
    /// Kinematic acceleration, m/s^2.
    accel: Vector3<f64>,
    /// Rotates sensor-frame vectors into the navigation frame.
    attitude: UnitQuaternion<f64>,
    /// Angular rate, rad/s, navigation frame.
    rate: Vector3<f64>,
    /// Whether the scenario is in a rest (zero velocity and angular rate).
    at_rest: bool,
}

impl Kinematics {
    /// The [`Truth`] at `t_s` under gravity `gravity_mps2` (sensor-frame specific force and
    /// rate from the navigation-frame kinematics).
    fn truth(&self, t_s: f64, gravity_mps2: f64) -> Truth {
        let g_nav = Vector3::new(0.0, 0.0, -gravity_mps2);
        let q = &self.attitude;
        Truth {
            t_ns: ns_from_s(t_s),
            position_m: self.position.into(),
            velocity_mps: self.velocity.into(),
            attitude_wxyz: [q.w, q.i, q.j, q.k],
            specific_force_mps2: q.inverse_transform_vector(&(self.accel - g_nav)).into(),
            angular_rate_rps: q.inverse_transform_vector(&self.rate).into(),
            at_rest: self.at_rest,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_constants_integrate_monomials_exactly() {
        // The integral of x^k over [-1, 1] is 2 / (k + 1) for even k and 0 for odd k; an
        // 8-point rule must reproduce it for every k <= 15.
        for k in 0..=15 {
            let [got] = gauss_legendre(-1.0, 1.0, |x| [x.powi(k)]);
            let want = if k % 2 == 0 {
                2.0 / (k as f64 + 1.0)
            } else {
                0.0
            };
            assert!((got - want).abs() < 1e-15, "x^{k}: {got} vs {want}");
        }
        // Degree 16 is not exact: the rule really has 8 points.
        let [got] = gauss_legendre(-1.0, 1.0, |x| [x.powi(16)]);
        assert!((got - 2.0 / 17.0).abs() > 1e-6);
    }

    #[test]
    fn ramp_is_a_squared_raised_cosine_rate() {
        let h = 1e-6;
        for x in [0.05, 0.3, 0.5, 0.77, 0.99] {
            let (p0, d0) = ramp(x);
            let (pp, _) = ramp(x + h);
            let (pm, _) = ramp(x - h);
            assert!(((pp - pm) / (2.0 * h) - d0).abs() < 1e-8);
            assert!((0.0..=1.0).contains(&p0));
        }
        // The rate is (8/3) sin^4(pi x): zero with three zero derivatives at both ends (so it
        // grows like x^4), peak 8/3 at the middle, and the ramp rises by exactly 1.
        for x in [0.01, 0.2, 0.5, 0.9] {
            let want = RAMP_PEAK * (std::f64::consts::PI * x).sin().powi(4);
            assert!((ramp(x).1 - want).abs() < 1e-13);
        }
        assert!((ramp(0.5).1 - RAMP_PEAK).abs() < 1e-15);
        assert_eq!(ramp(0.0), (0.0, 0.0));
        assert_eq!(ramp(1.0), (1.0, 0.0));
        assert!((ramp(1.0 - 1e-12).0 - 1.0).abs() < 1e-12);
    }
}
