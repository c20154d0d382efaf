//! The forward axis from the path the filter integrates while its velocity is still well
//! known: a wheeled robot that does not skid moves along its forward axis, so in the sensor
//! frame its velocity points along that axis whatever it turns (`v_s = R_bs^T (v, 0, 0)`),
//! and the sensor-frame displacement of a motion, `sum q^-1 v dt`, points along it too, signed
//! by the speed hints' distance over the same samples (a robot may reverse). From a rest the filter knows its velocity to a few centimetres per second for a second or
//! two; the displacement's direction is then known within degrees.
//!
//! The speed-change fit ([`crate::cruise::ForwardAxis`]) needs the accelerations to stand
//! out of what the floor's slope and the body's tilt leave in the horizontal specific force;
//! at a small robot's 0.1-0.2 m/s they do not (the corpus's TurtleBot, docs/hints.md), while
//! the path's direction is known within degrees a couple of seconds after a start. Both feed
//! one mounting: the first trusted gives it, and each later speed-change fit is fused with the
//! path's estimate ([`fuse`]).
//!
//! A displacement, not the velocity at each hint: a body rocking on its wheels or suspension
//! moves the velocity's direction by its swing's speed over the robot's (on a simulated robot
//! at 0.2 m/s rocking at 1.2 Hz, 20 degrees) but the displacement only by its amplitude, a
//! few millimetres, over the distance driven.
//!
//! Frames: sensor frame (the IMU's axes), navigation frame z up. Units: m, m/s, rad.

use nalgebra::{UnitQuaternion, Vector3};

use crate::cruise::{FORWARD_MAX_SIGMA_RAD, MIN_SPEED_MPS};
use crate::hints::{ForwardFit, mounting_from};

/// The least distance the speed hints must count in a motion before its direction is
/// trusted, m: a second at the slowest speed the cruise logic counts as motion
/// ([`MIN_SPEED_MPS`]). A body rocking on its wheels moves the IMU by millimetres about its
/// path, a few degrees of 0.1 m at most.
pub const MIN_DISTANCE_M: f64 = MIN_SPEED_MPS * 1.0;

/// How far the filter's horizontal distance may lie from the hints', in their combined
/// 1-sigmas, for the motion to count: beyond it the filter's path is not the robot's (a
/// skid, a velocity that drifted, hints with a wrong gain), and its direction says nothing
/// of the mounting.
pub const AGREEMENT_SIGMAS: f64 = 3.0;

/// The current motion's sensor-frame displacement against the speed hints' distance (see the
/// module documentation). Its direction's 1-sigma is the displacement's over the distance
/// (small angles), the displacement's taken as the sum of the filter's horizontal velocity
/// 1-sigma times each sample's interval: the velocity's error drifts, one error over the
/// motion, so the 1-sigmas add rather than add in quadrature.
#[derive(Debug, Clone, Copy, Default)]
pub struct VelocityAxis {
    /// Sensor-frame displacement since the motion began, m.
    displacement: Vector3<f64>,
    /// Its 1-sigma per horizontal axis, m.
    displacement_sigma: f64,
    /// The speed hints' signed distance over the same samples, m, and its 1-sigma, m (their
    /// speed 1-sigmas times the intervals, added likewise).
    distance: f64,
    distance_sigma: f64,
}

impl VelocityAxis {
    /// A rest, a stale hint or an unknown velocity: the next motion starts anew.
    pub fn restart(&mut self) {
        *self = Self::default();
    }

    /// Adds a sample of `dt` s: the filter's velocity `v_s` (sensor frame, m/s) with its
    /// horizontal 1-sigma per axis `v_sigma` (m/s), and the fresh speed hint's `speed` with
    /// its 1-sigma `speed_sigma` (m/s).
    pub fn step(
        &mut self,
        v_s: &Vector3<f64>,
        v_sigma: f64,
        speed: f64,
        speed_sigma: f64,
        dt: f64,
    ) {
        self.displacement += v_s * dt;
        self.displacement_sigma += v_sigma * dt;
        self.distance += speed * dt;
        self.distance_sigma += speed_sigma * dt;
    }

    /// The mounting and its yaw 1-sigma (rad) with `up_s` the filter's up in the sensor frame,
    /// once trusted: at least [`MIN_DISTANCE_M`] counted, the filter's and the hints'
    /// distances agreeing within [`AGREEMENT_SIGMAS`], the 1-sigma at most `max_sigma_rad`.
    pub fn mounting(
        &self,
        up_s: &Vector3<f64>,
        max_sigma_rad: f64,
    ) -> Option<(UnitQuaternion<f64>, f64)> {
        let horizontal = self.displacement - up_s * up_s.dot(&self.displacement);
        let (ours, hinted) = (horizontal.norm(), self.distance.abs());
        let combined = self.displacement_sigma.hypot(self.distance_sigma);
        if hinted < MIN_DISTANCE_M || (ours - hinted).abs() > AGREEMENT_SIGMAS * combined {
            return None;
        }
        let sigma = self.displacement_sigma / ours.min(hinted);
        if sigma > max_sigma_rad {
            return None;
        }
        Some((
            mounting_from(&(horizontal * self.distance.signum()), up_s)?,
            sigma,
        ))
    }
}

/// The largest 1-sigma of a coarse path axis ([`PathAxis`]), rad: 20 degrees.
pub const COARSE_MAX_SIGMA_RAD: f64 = 0.35;

/// How far the speed hints must count after the first coarse path axis before it is taken,
/// m: the speed-change fit's least excitation
/// ([`crate::cruise::FORWARD_MIN_INTERVALS`] intervals of [`crate::cruise::FORWARD_INTERVAL_S`], 3 s) at a third of a metre per second, a small robot's top speed.
pub const COARSE_WAIT_M: f64 = 1.0;

/// The forward axis from the path over the motions before a mounting is known: each
/// motion's [`VelocityAxis`], taken once its 1-sigma is at most [`FORWARD_MAX_SIGMA_RAD`];
/// else the coarse estimate with the least 1-sigma (at most [`COARSE_MAX_SIGMA_RAD`]), held
/// back until the speed hints have counted [`COARSE_WAIT_M`] since the first one.
///
/// A coarse estimate's 1-sigma is honest (within 1.8 of its 1-sigmas of the truth at its first
/// trust on eleven simulated TurtleBot starts and on the corpus's TurtleBot, docs/hints.md), but
/// a mounting 10-20 degrees off turns the whole track by that much, and the speed-change fit
/// fused with it later ([`fuse`]) leaves much of that error: the fit, when it comes, is the
/// better start. A robot whose fit never comes (the corpus's TurtleBot) takes the coarse axis
/// rather than none.
#[derive(Debug, Clone, Copy, Default)]
pub struct PathAxis {
    /// The current motion's path.
    motion: VelocityAxis,
    /// The coarse estimate with the least 1-sigma so far: the mounting and its yaw 1-sigma, rad.
    coarse: Option<(UnitQuaternion<f64>, f64)>,
    /// The speed hints' unsigned distance since the first coarse estimate, m.
    since_coarse_m: f64,
}

impl PathAxis {
    /// A rest, a stale hint or an unknown velocity: the next motion starts anew (a coarse
    /// estimate is kept).
    pub fn restart(&mut self) {
        self.motion.restart();
    }

    /// [`VelocityAxis::step`], and the distance since a coarse estimate.
    pub fn step(
        &mut self,
        v_s: &Vector3<f64>,
        v_sigma: f64,
        speed: f64,
        speed_sigma: f64,
        dt: f64,
    ) {
        self.motion.step(v_s, v_sigma, speed, speed_sigma, dt);
        if self.coarse.is_some() {
            self.since_coarse_m += speed.abs() * dt;
        }
    }

    /// The mounting and its yaw 1-sigma (rad) with `up_s` the filter's up in the sensor frame:
    /// the motion's once trusted, else the coarse one once waited for (see [`PathAxis`]).
    pub fn mounting(&mut self, up_s: &Vector3<f64>) -> Option<(UnitQuaternion<f64>, f64)> {
        let found = self.motion.mounting(up_s, COARSE_MAX_SIGMA_RAD);
        if let Some((q, sigma)) = found {
            if sigma <= FORWARD_MAX_SIGMA_RAD {
                return found;
            }
            if self.coarse.is_none_or(|(_, s)| sigma < s) {
                self.coarse = Some((q, sigma));
            }
        }
        if self.since_coarse_m >= COARSE_WAIT_M {
            return self.coarse;
        }
        None
    }
}

/// Two independent estimates of one forward axis fused: the speed-change fit `turns` and the
/// path's `path` ([`VelocityAxis`]), their yaws about `turns`'s up averaged with the inverse
/// variances of their whole 1-sigmas ([`ForwardFit::systematic_sigma_rad`]), the 1-sigma
/// the inverse of the summed inverse variances; the speed scale is the fit's (the path tells
/// none). Small angles: both are trusted within [`COARSE_MAX_SIGMA_RAD`].
pub fn fuse(turns: &ForwardFit, path: &ForwardFit) -> ForwardFit {
    let (w_t, w_p) = (
        turns.systematic_sigma_rad().powi(-2),
        path.systematic_sigma_rad().powi(-2),
    );
    let up = turns.mounting.inverse_transform_vector(&Vector3::z());
    let f_t = turns.mounting.inverse_transform_vector(&Vector3::x());
    let f_p = path.mounting.inverse_transform_vector(&Vector3::x());
    let delta = f_t.cross(&f_p).dot(&up).atan2(f_t.dot(&f_p));
    let turn = UnitQuaternion::from_axis_angle(
        &nalgebra::Unit::new_normalize(up),
        delta * w_p / (w_t + w_p),
    );
    let mounting = mounting_from(&(turn * f_t), &up).unwrap_or(turns.mounting);
    ForwardFit {
        mounting,
        sigma_rad: (w_t + w_p).sqrt().recip(),
        bias_sigma_rad: 0.0,
        ..*turns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A robot whose forward axis is the sensor's -y (z up) driving `steps` samples of 0.02 s
    /// at `speed` m/s (negative: reversing), the filter's velocity `err` off (m/s, sensor
    /// frame) with 1-sigma `sigma`.
    fn drive(steps: u32, speed: f64, err: Vector3<f64>, sigma: f64) -> VelocityAxis {
        let mut axis = VelocityAxis::default();
        let forward = Vector3::new(0.0, -1.0, 0.0);
        for _ in 0..steps {
            axis.step(&(forward * speed + err), sigma, speed, 0.01, 0.02);
        }
        axis
    }

    fn forward_of(q: &UnitQuaternion<f64>) -> Vector3<f64> {
        // The mounting turns the sensor frame into the body's: forward is body x.
        q.inverse_transform_vector(&Vector3::x())
    }

    #[test]
    fn the_path_gives_the_axis_and_its_sign() {
        let up = Vector3::z();
        // 0.2 m/s for 0.4 s: 0.08 m, short of the least distance.
        assert!(
            drive(20, 0.2, Vector3::zeros(), 0.01)
                .mounting(&up, FORWARD_MAX_SIGMA_RAD)
                .is_none()
        );
        // 0.01 m/s across 0.2 m/s for 2 s: 2.9 degrees; 1-sigma 0.02 m / 0.4 m.
        let err = Vector3::new(0.01, 0.0, 0.0);
        let (q, sigma) = drive(100, 0.2, err, 0.01)
            .mounting(&up, FORWARD_MAX_SIGMA_RAD)
            .expect("trusted");
        let expected = (Vector3::new(0.0, -1.0, 0.0) + err / 0.2).normalize();
        assert!((forward_of(&q) - expected).norm() < 1e-9, "{q:?}");
        assert!((sigma - 0.05).abs() < 1e-9, "{sigma}");
        // Reversing: the path runs along +y, the wheels say backwards, the axis is -y.
        let back = drive(100, -0.2, Vector3::zeros(), 0.01);
        let f = forward_of(
            &back
                .mounting(&up, FORWARD_MAX_SIGMA_RAD)
                .expect("trusted")
                .0,
        );
        assert!((f - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-9, "{f}");
    }

    #[test]
    fn an_uncertain_or_disagreeing_path_is_not_trusted() {
        let up = Vector3::z();
        // 1-sigma 0.05 m/s at 0.2 m/s: 14 degrees, above the bound.
        assert!(
            drive(200, 0.2, Vector3::zeros(), 0.05)
                .mounting(&up, FORWARD_MAX_SIGMA_RAD)
                .is_none()
        );
        // The filter drives 0.5 m/s where the wheels say 0.2: not the robot's path.
        let err = Vector3::new(0.0, -0.3, 0.0);
        assert!(
            drive(200, 0.2, err, 0.01)
                .mounting(&up, FORWARD_MAX_SIGMA_RAD)
                .is_none()
        );
        let mut axis = drive(200, 0.2, Vector3::zeros(), 0.01);
        assert!(axis.mounting(&up, FORWARD_MAX_SIGMA_RAD).is_some());
        axis.restart();
        assert!(axis.mounting(&up, FORWARD_MAX_SIGMA_RAD).is_none());
    }

    #[test]
    fn a_coarse_path_waits_for_the_speed_change_fit() {
        let up = Vector3::z();
        let forward = Vector3::new(0.0, -1.0, 0.0);
        // 0.2 m/s with 1-sigma 0.03 m/s per axis: 0.03 / 0.2 rad, 8.6 degrees; with 0.05 m/s,
        // 0.25 rad, 14.3 degrees, coarse.
        let drive = |axis: &mut PathAxis, steps: u32, sigma: f64| {
            for _ in 0..steps {
                axis.step(&(forward * 0.2), sigma, 0.2, 0.01, 0.02);
            }
        };
        let mut fine = PathAxis::default();
        drive(&mut fine, 50, 0.03);
        let (_, sigma) = fine.mounting(&up).expect("trusted at once");
        assert!((sigma - 0.15).abs() < 1e-9, "{sigma}");
        let mut coarse = PathAxis::default();
        drive(&mut coarse, 50, 0.05);
        assert!(coarse.mounting(&up).is_none());
        // A rest: the coarse estimate is kept, the hints' distance counted on.
        coarse.restart();
        drive(&mut coarse, 240, 0.5);
        assert!(
            coarse.mounting(&up).is_none(),
            "0.96 m since the coarse one"
        );
        drive(&mut coarse, 20, 0.5);
        let (q, sigma) = coarse.mounting(&up).expect("1.04 m since the coarse one");
        assert!((sigma - 0.25).abs() < 1e-9, "{sigma}");
        assert!((forward_of(&q) - forward).norm() < 1e-9, "{q:?}");
        // Beyond the coarse bound: never.
        let mut poor = PathAxis::default();
        drive(&mut poor, 300, 0.1);
        assert!(poor.mounting(&up).is_none());
    }

    #[test]
    fn two_estimates_are_fused_by_their_variances() {
        let up = Vector3::z();
        let at = |yaw_deg: f64| {
            let f = Vector3::new(yaw_deg.to_radians().cos(), yaw_deg.to_radians().sin(), 0.0);
            mounting_from(&f, &up).unwrap()
        };
        let fit = |yaw_deg: f64, sigma_deg: f64, bias_deg: f64| ForwardFit {
            mounting: at(yaw_deg),
            sigma_rad: sigma_deg.to_radians(),
            bias_sigma_rad: bias_deg.to_radians(),
            scale: Some(0.1),
            scale_sigma: 0.02,
        };
        // Whole 1-sigmas 2 (the fit's noise and bias share, 1.2 and 1.6 deg) and 1 deg: weights
        // 1/4 and 1, the mean 4/5 of the way from the fit to the path, 1-sigma 1/sqrt(1.25).
        let fused = fuse(&fit(-90.0, 1.2, 1.6), &fit(-85.0, 1.0, 0.0));
        let f = forward_of(&fused.mounting);
        let yaw = f.y.atan2(f.x).to_degrees();
        assert!((yaw + 86.0).abs() < 1e-9, "{yaw}");
        assert!((fused.systematic_sigma_rad().to_degrees() - 1.25f64.sqrt().recip()).abs() < 1e-9);
        assert_eq!((fused.scale, fused.scale_sigma), (Some(0.1), 0.02));
    }
}
