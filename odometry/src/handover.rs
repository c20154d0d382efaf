//! The path a robot that starts in motion drives while the speed hints wait for its forward axis
//! (`crate::cruise::ForwardAxis`; mounting not given).
//!
//! A cruise alignment without a mounting starts the velocity at zero for want of a direction
//! (`crate::cruise::initial_velocity`), so the position the IMU integrates meanwhile is the
//! double integral of the specific force from a velocity tens of m/s off: its error grows with
//! the tilt's as `g delta t^2 / 2`. The hints' speeds say how far the robot went and the
//! attitude which way it faced: the displacement over the wait is `sum s_j R_j dt_j F` with
//! `s_j` the speed (the hint's, over `1 + k`), `R_j` the attitude (sensor to navigation) at each
//! sample and `F` the forward axis in the sensor frame, unknown until the fit is trusted. The
//! sum `M = sum s_j R_j dt_j` is a 3 x 3 matrix that does not depend on `F`, so it is gathered
//! sample by sample and multiplied by `F` once the axis is known ([`WaitPath::displacement`]).
//! Frames: navigation z up, heading fixed at alignment; m, s, m/s.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// The sum `M` of the module documentation, from the first sample of the wait on.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WaitPath {
    /// `sum s R dt`, m.
    m: Matrix3<f64>,
    /// The filter's position at the first sample, m (navigation frame).
    start: Option<Vector3<f64>>,
    /// `sum s dt`, m.
    distance_m: f64,
    /// A sample had no speed (no fresh speed hint): the sum misses part of the path.
    broken: bool,
}

impl WaitPath {
    /// Adds a sample of `dt_s` at the filter's position `p` and attitude `q` (sensor to
    /// navigation), with the robot's speed `speed` (m/s; `None` without a fresh speed hint).
    pub fn add(
        &mut self,
        p: &Vector3<f64>,
        q: &UnitQuaternion<f64>,
        speed: Option<f64>,
        dt_s: f64,
    ) {
        self.start.get_or_insert(*p);
        match speed {
            Some(s) => {
                self.m += q.to_rotation_matrix().into_inner() * (s * dt_s);
                self.distance_m += s.abs() * dt_s;
            }
            None => self.broken = true,
        }
    }

    /// The position at the last sample added, from the first sample's position and the
    /// forward axis `forward_s` (unit, sensor frame), and the distance driven (m); `None`
    /// when nothing was added or a sample had no speed.
    pub fn displacement(&self, forward_s: &Vector3<f64>) -> Option<(Vector3<f64>, f64)> {
        let start = self.start.filter(|_| !self.broken)?;
        Some((start + self.m * forward_s, self.distance_m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A robot at 2 m/s on a circle of radius 10 m, its IMU yawed 90 degrees on it (sensor -y
    /// forward) and rolled 180 degrees: the sum ends on the circle's chord, computed directly.
    #[test]
    fn the_path_over_a_turn_is_the_chord_of_the_circle() {
        let (speed, radius, dt) = (2.0, 10.0, 0.001);
        let r_bs = UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0)
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let forward_s = r_bs.inverse() * Vector3::x();
        let mut path = WaitPath::default();
        let p0 = Vector3::new(1.0, -2.0, 0.5);
        let n = 5000;
        for i in 0..n {
            // Heading at the middle of the step (body x along the circle's tangent).
            let yaw = speed / radius * (f64::from(i) + 0.5) * dt;
            let r_nb = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
            path.add(&p0, &(r_nb * r_bs), Some(speed), dt);
        }
        let angle = speed / radius * f64::from(n) * dt;
        let chord = Vector3::new(radius * angle.sin(), radius * (1.0 - angle.cos()), 0.0);
        let (p, d) = path.displacement(&forward_s).unwrap();
        assert!((p - p0 - chord).norm() < 1e-6, "{p} {chord}");
        assert!((d - speed * f64::from(n) * dt).abs() < 1e-9);
        path.add(&p0, &r_bs, None, dt);
        assert!(path.displacement(&forward_s).is_none());
    }
}
