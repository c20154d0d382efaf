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
//! The partial sums at the states kept for revision ([`WaitMark`]) give the path at each of
//! them, which the odometry publishes again once `F` is known ([`WaitRevision`]): the states
//! published during the wait had no direction.
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
    /// The last sample's speed, m/s.
    speed: f64,
}

/// The wait path's partial sums at one sample ([`WaitPath::mark`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaitMark {
    /// `sum s R dt` up to the sample, m.
    m: Matrix3<f64>,
    /// `sum s dt` up to the sample, m.
    distance_m: f64,
    /// The speed at the sample, m/s.
    speed: f64,
}

/// The wait path once the forward axis is known ([`WaitPath::revision`]): the position,
/// velocity and their 1-sigmas at each [`WaitMark`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaitRevision {
    /// The filter's position at the wait's first sample, m.
    start: Vector3<f64>,
    /// The forward axis, unit, sensor frame.
    forward_s: Vector3<f64>,
    /// The filter's position after the wait's measurement less the path's end, m: spread
    /// over the path in proportion to the distance driven, so that the revised path ends
    /// where the filter goes on from.
    closing: Vector3<f64>,
    /// The whole wait's distance, m.
    distance_m: f64,
    /// The path's relative 1-sigma per axis (speed scale and yaw in quadrature), fraction.
    relative_sigma: f64,
}

/// A revised state of the wait ([`WaitRevision::at`]): navigation frame, m and m/s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RevisedWait {
    /// Position.
    pub p: Vector3<f64>,
    /// Velocity.
    pub v: Vector3<f64>,
    /// Position 1-sigma per axis.
    pub sigma_p: Vector3<f64>,
    /// Velocity 1-sigma per axis.
    pub sigma_v: Vector3<f64>,
}

impl WaitRevision {
    /// The revised state at the sample of `mark`, whose attitude was `q` (sensor to
    /// navigation): the path up to it, `start + M F` plus the closing's share of its distance;
    /// the velocity `s R F`; 1-sigmas the distance and the speed times the relative one.
    pub fn at(&self, mark: &WaitMark, q: &UnitQuaternion<f64>) -> RevisedWait {
        let share = if self.distance_m > 0.0 {
            mark.distance_m / self.distance_m
        } else {
            1.0
        };
        RevisedWait {
            p: self.start + mark.m * self.forward_s + self.closing * share,
            v: q * self.forward_s * mark.speed,
            sigma_p: Vector3::repeat(mark.distance_m * self.relative_sigma),
            sigma_v: Vector3::repeat(mark.speed.abs() * self.relative_sigma),
        }
    }
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
                self.speed = s;
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

    /// The partial sums so far; `None` when nothing was added or a sample had no speed.
    pub fn mark(&self) -> Option<WaitMark> {
        self.start.filter(|_| !self.broken)?;
        Some(WaitMark {
            m: self.m,
            distance_m: self.distance_m,
            speed: self.speed,
        })
    }

    /// The revision of the path with the forward axis `forward_s` (unit, sensor frame), the
    /// filter's position `p_after` after the wait's position measurement and the path's
    /// relative 1-sigma per axis `relative_sigma`; `None` as for [`Self::displacement`].
    pub fn revision(
        &self,
        forward_s: &Vector3<f64>,
        p_after: &Vector3<f64>,
        relative_sigma: f64,
    ) -> Option<WaitRevision> {
        let (end, distance_m) = self.displacement(forward_s)?;
        Some(WaitRevision {
            start: self.start?,
            forward_s: *forward_s,
            closing: p_after - end,
            distance_m,
            relative_sigma,
        })
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

    /// The same circle: the state revised at the half-way mark lies on the circle at half the
    /// angle, its velocity along the tangent there, and the closing (the filter's position
    /// after the wait less the path's end) takes half its share there.
    #[test]
    fn a_revised_mark_lies_on_the_circle() {
        let (speed, radius, dt) = (2.0, 10.0, 0.001);
        let r_bs = UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0)
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2);
        let forward_s = r_bs.inverse() * Vector3::x();
        let (mut path, mut half) = (WaitPath::default(), None);
        let n = 5000;
        let attitude = |i: u32| {
            let yaw = speed / radius * (f64::from(i) + 0.5) * dt;
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw) * r_bs
        };
        for i in 0..n {
            path.add(&Vector3::zeros(), &attitude(i), Some(speed), dt);
            if i == n / 2 - 1 {
                half = path.mark();
            }
        }
        let (end, _) = path.displacement(&forward_s).unwrap();
        let closing = Vector3::new(0.4, -0.2, 0.0);
        let rev = path.revision(&forward_s, &(end + closing), 0.1).unwrap();
        let got = rev.at(&half.unwrap(), &attitude(n / 2 - 1));
        let angle = speed / radius * f64::from(n / 2) * dt;
        let on_circle = Vector3::new(radius * angle.sin(), radius * (1.0 - angle.cos()), 0.0);
        assert!((got.p - on_circle - closing * 0.5).norm() < 1e-6, "{got:?}");
        let tangent = Vector3::new(angle.cos(), angle.sin(), 0.0) * speed;
        assert!((got.v - tangent).norm() < 1e-3, "{got:?}");
        let distance = speed * f64::from(n / 2) * dt;
        assert!((got.sigma_p.x - 0.1 * distance).abs() < 1e-9, "{got:?}");
    }
}
