//! Pose sessions: the sensor held still in a sequence of attitudes, rotated in place between
//! them (six-position calibration, N-orientation sessions, long static runs).

use std::f64::consts::PI;

use nalgebra::{Unit, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use recording::Truth;

use super::{Kinematics, Scenario, ScenarioError, check_positive, ramp};
use crate::{stream_rng, streams};

/// Timing and environment of a pose session.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseParams {
    /// How long each pose is held still, s.
    pub hold_s: f64,
    /// How long each rotation between consecutive poses takes, s.
    pub rotate_s: f64,
    /// Local gravity, m/s^2.
    pub gravity_mps2: f64,
    /// 1-sigma of a random tilt of each placement about a random horizontal axis, degrees (0:
    /// every pose exactly as nominal, e.g. a perfectly level table).
    pub placement_tilt_std_deg: f64,
}

impl PoseParams {
    /// Poses held `hold_s` seconds, rotations of 4 s, standard gravity, exact placement.
    pub fn new(hold_s: f64) -> Self {
        Self {
            hold_s,
            rotate_s: 4.0,
            gravity_mps2: ipc_types::units::STANDARD_GRAVITY_MPS2,
            placement_tilt_std_deg: 0.0,
        }
    }

    fn validate(&self) -> Result<(), ScenarioError> {
        check_positive("hold_s", self.hold_s)?;
        check_positive("rotate_s", self.rotate_s)?;
        check_positive("gravity_mps2", self.gravity_mps2)?;
        let tilt = self.placement_tilt_std_deg;
        if !(tilt.is_finite() && tilt >= 0.0) {
            return Err(ScenarioError {
                field: "placement_tilt_std_deg".into(),
                reason: format!("must be finite and >= 0, got {tilt}"),
            });
        }
        Ok(())
    }
}

/// The sensor held in a sequence of attitudes, `hold_s` each, rotating in place (about its own
/// origin: position and velocity stay zero) between consecutive poses about the fixed axis of
/// the shortest rotation, with a squared raised-cosine angular-rate profile.
///
/// Timeline: pose 0 held over `[0, hold_s)`, rotation to pose 1 over `[hold_s, hold_s +
/// rotate_s)`, pose 1 held, and so on; the last pose is held for ever after.
#[derive(Debug, Clone)]
pub struct PoseSession {
    poses: Vec<UnitQuaternion<f64>>,
    /// Axis (navigation frame) and angle of each rotation between consecutive poses; `None`
    /// when two consecutive poses are equal.
    rotations: Vec<Option<(Unit<Vector3<f64>>, f64)>>,
    hold_s: f64,
    rotate_s: f64,
    gravity_mps2: f64,
}

/// The attitude that points the sensor-frame direction `up` (unit) along the navigation z axis,
/// then turns it by `heading_rad` about the navigation z axis.
fn attitude_with_up(up: Vector3<f64>, heading_rad: f64) -> UnitQuaternion<f64> {
    let level = UnitQuaternion::rotation_between(&up, &Vector3::z())
        // Antiparallel (sensor -z up): any half turn about a horizontal axis will do.
        .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI));
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), heading_rad) * level
}

impl PoseSession {
    /// A session through the given attitudes (each rotating sensor-frame vectors into the
    /// navigation frame).
    pub fn from_poses(
        poses: Vec<UnitQuaternion<f64>>,
        params: &PoseParams,
    ) -> Result<Self, ScenarioError> {
        params.validate()?;
        if poses.is_empty() {
            return Err(ScenarioError {
                field: "poses".into(),
                reason: "a pose session needs at least one pose".into(),
            });
        }
        let rotations = poses
            .windows(2)
            .map(|w| (w[1] * w[0].inverse()).axis_angle())
            .collect();
        Ok(Self {
            poses,
            rotations,
            hold_s: params.hold_s,
            rotate_s: params.rotate_s,
            gravity_mps2: params.gravity_mps2,
        })
    }

    /// The thesis's six-position session: sensor +z, -z, +y, -y, +x, -x pointing up in that
    /// order, each placed at a random heading (and tilted by `placement_tilt_std_deg`) drawn
    /// from `seed`.
    pub fn six_position(params: &PoseParams, seed: u64) -> Result<Self, ScenarioError> {
        let ups = [
            Vector3::z(),
            -Vector3::z(),
            Vector3::y(),
            -Vector3::y(),
            Vector3::x(),
            -Vector3::x(),
        ];
        Self::placed(&ups, params, seed)
    }

    /// `n` well-spread orientations: the sensor-frame "up" directions are a Fibonacci lattice
    /// on the sphere (near-uniform for any `n`) turned by a random rotation, each pose at a
    /// random heading, all drawn from `seed`.
    pub fn orientations(n: usize, params: &PoseParams, seed: u64) -> Result<Self, ScenarioError> {
        if n == 0 {
            return Err(ScenarioError {
                field: "n".into(),
                reason: "the number of orientations must be >= 1".into(),
            });
        }
        let mut rng = stream_rng(seed, streams::POSE_SPREAD);
        // A uniformly random rotation: a normalised 4-D standard normal vector.
        let q: [f64; 4] = std::array::from_fn(|_| rng.sample(StandardNormal));
        let spin =
            UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]));
        let golden_angle = PI * (3.0 - 5f64.sqrt());
        let ups: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden_angle * i as f64;
                spin * Vector3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect();
        Self::placed(&ups, params, seed)
    }

    /// A single pose held for `duration_s`.
    pub fn static_pose(
        attitude: UnitQuaternion<f64>,
        duration_s: f64,
        gravity_mps2: f64,
    ) -> Result<Self, ScenarioError> {
        check_positive("duration_s", duration_s)?;
        let params = PoseParams {
            gravity_mps2,
            ..PoseParams::new(duration_s)
        };
        Self::from_poses(vec![attitude], &params)
    }

    /// Poses with the given sensor-frame up directions, at random headings and placement tilts.
    fn placed(ups: &[Vector3<f64>], params: &PoseParams, seed: u64) -> Result<Self, ScenarioError> {
        params.validate()?;
        let mut rng = stream_rng(seed, streams::POSE_PLACEMENT);
        let tilt_std = params.placement_tilt_std_deg.to_radians();
        let poses = ups
            .iter()
            .map(|up| {
                let heading = rng.random_range(-PI..PI);
                let tilt_axis_angle = rng.random_range(-PI..PI);
                let tilt = tilt_std * rng.sample::<f64, _>(StandardNormal);
                let axis = Unit::new_normalize(Vector3::new(
                    tilt_axis_angle.cos(),
                    tilt_axis_angle.sin(),
                    0.0,
                ));
                UnitQuaternion::from_axis_angle(&axis, tilt) * attitude_with_up(*up, heading)
            })
            .collect();
        Self::from_poses(poses, params)
    }

    /// The attitudes of the session, in order.
    pub fn poses(&self) -> &[UnitQuaternion<f64>] {
        &self.poses
    }

    /// The time interval `[start, end)` s during which pose `i` is held.
    ///
    /// # Panics
    /// If `i` is not a pose index.
    pub fn hold_interval_s(&self, i: usize) -> (f64, f64) {
        assert!(i < self.poses.len(), "pose {i} of {}", self.poses.len());
        let start = i as f64 * (self.hold_s + self.rotate_s);
        (start, start + self.hold_s)
    }
}

impl Scenario for PoseSession {
    fn truth(&self, t_s: f64) -> Truth {
        assert!(t_s.is_finite() && t_s >= 0.0, "truth at {t_s} s");
        let cycle = self.hold_s + self.rotate_s;
        let last = self.poses.len() - 1;
        let i = ((t_s / cycle).floor() as usize).min(last);
        let into = t_s - i as f64 * cycle;
        let rotation = if i < last && into >= self.hold_s {
            self.rotations[i]
        } else {
            None
        };
        let (attitude, rate, at_rest) = match rotation {
            // Holding a pose, or "rotating" between two equal poses.
            None => (self.poses[i], Vector3::zeros(), true),
            Some((axis, angle)) => {
                let (p, dp) = ramp((into - self.hold_s) / self.rotate_s);
                let turned = UnitQuaternion::from_axis_angle(&axis, angle * p);
                (
                    turned * self.poses[i],
                    axis.into_inner() * (angle * dp / self.rotate_s),
                    // Still at the instant the rotation starts.
                    dp == 0.0,
                )
            }
        };
        Kinematics {
            position: Vector3::zeros(),
            velocity: Vector3::zeros(),
            accel: Vector3::zeros(),
            attitude,
            rate,
            at_rest,
        }
        .truth(t_s, self.gravity_mps2)
    }

    fn duration_s(&self) -> f64 {
        self.poses.len() as f64 * self.hold_s + (self.poses.len() - 1) as f64 * self.rotate_s
    }

    fn wheel_speed_mps(&self, _t_s: f64) -> f64 {
        0.0
    }
}
