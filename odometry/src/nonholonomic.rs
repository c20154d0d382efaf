//! The non-holonomic constraint from the IMU alone, for wheeled platforms without speed
//! hints: a wheeled robot or vehicle that does not skid moves along its body x axis, so its
//! lateral and vertical body velocities are zero (Brossard, Barrau, Bonnabel, "AI-IMU
//! Dead-Reckoning", IEEE T-IV 2020, section III: the pseudo-measurements `v_lat = v_up = 0`).
//!
//! Frames as in [`crate::hints`]: body x forward, y left, z up; `R_bs` rotates sensor-frame
//! vectors into it. The mounting is the one given (`--mount`), else estimated from the first
//! drive: body z is the gravity-up direction in the sensor frame, body x the direction of the
//! sensor-frame displacement over the first [`MOUNTING_PATH_M`] of driving (the filter's own
//! velocity, unrevised: the first metres after a rest drift least). Until then only the
//! vertical velocity is constrained, and not even that while the velocity has no direction (a
//! filter aligned in motion, waiting for the speed hints' forward axis): linearized about such
//! a velocity the vertical constraint turns the tilt (docs/odometry.md). Turning, an IMU off
//! the turning axis moves sideways, so a drive that begins in a turn (a car pulling out of a
//! parking space) points that displacement off the forward axis: the displacement over the
//! first [`MOUNTING_PATH_M`] of straight driving ([`LEVER_ARM_BOUND_M`],
//! [`STRAIGHT_ANGLE_RAD`]) replaces it once gathered. The first
//! drive's estimate is kept until then, as platforms that rarely drive straight need the
//! lateral constraint. The constraint says nothing about the sign of the forward axis, so a
//! drive that starts in reverse estimates the same mounting.
//!
//! An estimated mounting is not exact: its yaw is off by what the filter's velocity drifted
//! across the path while it was gathered, and by what a lever arm up to
//! [`LEVER_ARM_BOUND_M`] moved the IMU sideways while the platform turned
//! ([`crate::hints::MountingEstimator::yaw_sigma_rad`]). A yaw error `dm` puts `v dm` of the
//! forward speed sideways, and while the platform turns at `w` the constraint's updates read
//! it as a turn of the velocity at `w dm` that the gyro did not see. So the yaw's error is a
//! state of the filter ([`crate::eskf::MY`], prior that 1-sigma, no process noise: the IMU
//! is fixed to the body), which the constraint's updates estimate with the rest
//! ([`Eskf::point_velocity_update`], [`MountingYaw`]) on straight driving: turning, an IMU off the turning
//! axis moves sideways at `w r`, which a yaw error mimics, so there the yaw's uncertainty is
//! counted as the constraint's noise and its estimate stays. A given mounting, or one followed
//! from the speed hints (their own 1-sigma widens the lateral constraint), is taken as it is.
//!
//! The constraint holds at the rear axle, which the lever arm `r_b` (body frame, m, from the
//! IMU to the axle; [`ImuConstraint::with_lever_arm`], zero by default) locates: the velocity
//! constrained is the axle's, `v_b + omega_b x r_b` ([`Eskf::point_velocity`]). Until the
//! mounting is known the lever arm is not used (its body frame is not).
//!
//! Each update is gated: a residual beyond [`GATE_SIGMA`] standard deviations of its
//! prediction (the filter's velocity 1-sigma and the constraint's, in quadrature) is not
//! applied and the sample is flagged `NONHOLONOMIC_REJECTED`.
//!
//! **What it bounds and what it does not.** The constraint observes the velocity across the
//! forward axis: the lateral and vertical drift, and through them the tilt (a tilt error
//! `delta` shows as a vertical body velocity `v delta`). It does not observe the heading: a
//! rotation of the whole track about gravity changes no body-frame velocity, so its updates
//! carry no gain on the heading or on the gyro bias about up (`Heading::Kept`, as the speed
//! hints' updates: `crate::eskf::Heading`). It says nothing about the speed along the forward axis: between two
//! rests that is the double integral of the specific force along it, whose error grows with
//! the forward axis's pitch error (`g delta_p`: 1 deg is 0.17 m/s^2) and the accelerometer's
//! residual bias along it, neither of which the constraint can tell from an acceleration.
//! The filter's own covariance does not hold that error (its mounting is taken as exact, and
//! the constraint's updates shrink the tilt that would carry it), so [`AlongTrack`] adds it
//! to the published 1-sigma: an along-track acceleration error of 1-sigma `a`, constant over
//! each motion between rests (a systematic error, not a noise: the velocity error grows as
//! `a t`, the position error as `a t^2 / 2`), independent from one motion to the next.
//!
//! `a` is learned from the data: each stop's velocity correction is a measurement of it (the
//! filter's speed when a rest after at least [`MIN_MOTION_S`] of motion begins, over that
//! motion's time), pooled with the prior [`ALONG_TRACK_ACCEL_SIGMA_MPS2`] counted as one stop
//! (`a^2` the mean of the squares). And the velocity share stays within [`SPEED_FACTOR`] times
//! the speed the filter has shown over the motion (its root mean square): the error `e` is
//! the filter's speed less the true one, within the shown speed plus the true speed for a
//! platform that drives forward, so a 1-sigma of about the shown speed (a slow rover at
//! 0.2 m/s does not gain a velocity error of 8 m/s in 260 s: the filter would show it). A rest's zero-velocity update takes the velocity
//! share away; the position share stays (a stop's update does not reveal it: on the simulated
//! car of docs/odometry.md the stop's position correction, through the covariance's
//! position-velocity correlation, moved the track the wrong way by tens of metres). Estimates
//! are unchanged.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::eskf::{Eskf, Heading, MountingYaw};
use crate::hints::{MountingEstimator, mounting_from};

/// Path of driving the mounting estimate gathers before the lateral constraint starts, m.
pub const MOUNTING_PATH_M: f64 = 2.0;
/// Largest distance from the IMU to the rear axle the straight-driving mounting allows for, m:
/// a car's dashboard or roof unit sits 1-2.5 m ahead of it. Turning at `w` rad/s the IMU moves
/// sideways at `w r` (`omega x r`), so a displacement gathered while turning points off the
/// forward axis by `atan(w r / v)`: a car pulling out of a parking space at 1 m/s and
/// 20 deg/s with its IMU on the roof 1.5 m ahead, by 28 deg.
pub const LEVER_ARM_BOUND_M: f64 = 2.0;
/// The straight-driving mounting gathers where that angle stays within this, rad (2 deg).
pub const STRAIGHT_ANGLE_RAD: f64 = 0.035;
/// Largest 1-sigma the mounting-yaw state starts with, rad (11.5 deg): the update's
/// linearization in the yaw error (`sin dm = dm`, `cos dm = 1`) stays within 8 % out to two
/// of them (`cos 0.4 = 0.92`). An estimate the filter's velocity knows worse (a slow rover's
/// first metres) starts there: better than taking it as exact, as the constraint did before
/// it had the state.
pub const MAX_MOUNTING_YAW_SIGMA_RAD: f64 = 0.2;
/// Residuals beyond this many standard deviations are rejected.
pub const GATE_SIGMA: f64 = 5.0;
/// 1-sigma given to the unconstrained forward component, m/s (no information).
const FREE_MPS: f64 = 1e3;
/// 1-sigma of the along-track acceleration error between rests, m/s^2 ([`AlongTrack`]): a
/// 0.1 deg pitch of the estimated forward axis (`g` times 1.7 mrad, 0.017 m/s^2) and a
/// calibrated accelerometer's residual bias along it of 1 mg (the MPU-9250's zero-g offset
/// changes by +-1.5 mg/degC over temperature, datasheet PS-MPU-9250A-01 table 2; 0.01 m/s^2),
/// in quadrature.
pub const ALONG_TRACK_ACCEL_SIGMA_MPS2: f64 = 0.03;
/// Shortest motion whose stop measures the along-track acceleration error, s: below it the
/// stop's residual speed is the detector's timing more than the drift.
pub const MIN_MOTION_S: f64 = 5.0;
/// The along-track velocity share stays within this many times the speed the filter has
/// shown over the motion, root mean square (module documentation).
pub const SPEED_FACTOR: f64 = 1.0;

/// The sideways speed an IMU up to [`LEVER_ARM_BOUND_M`] off the turning axis may have at the
/// filter's rate about up (`up_s`, sensor frame), m/s: `|w_up| r`.
fn sideways_bound(kf: &Eskf, up_s: &Vector3<f64>) -> f64 {
    kf.rate().dot(up_s).abs() * LEVER_ARM_BOUND_M
}

/// Whether a platform at `speed` (m/s) drives straight: the lever arm's sideways speed
/// `sideways` ([`sideways_bound`], m/s) turns its velocity by at most [`STRAIGHT_ANGLE_RAD`].
fn drives_straight(sideways: f64, speed: f64) -> bool {
    sideways <= speed * STRAIGHT_ANGLE_RAD.tan()
}

/// The IMU-only constraint's state.
#[derive(Debug, Clone, Copy)]
pub struct ImuConstraint {
    /// 1-sigma over one second of driving, m/s.
    sigma_mps: f64,
    /// `R_bs`, given or estimated; `None` while estimating.
    r_bs: Option<Matrix3<f64>>,
    /// Whether `r_bs` was given.
    given: bool,
    /// Whether `r_bs` is this constraint's own estimate, whose yaw error the filter carries
    /// ([`Eskf::mounted`]), and the filter's correction to it at the last update, rad.
    estimated: Option<f64>,
    /// 1-sigma of `r_bs`'s yaw when it follows the speed hints' forward axis, rad (0
    /// otherwise): a yaw off by that much puts that fraction of the forward speed sideways.
    yaw_sigma_rad: f64,
    /// The displacement of the first drive, turns included.
    estimator: MountingEstimator,
    /// The displacement of straight driving (where the lever arm cannot turn it,
    /// [`LEVER_ARM_BOUND_M`]), which replaces the first drive's mounting once it has
    /// [`MOUNTING_PATH_M`]; `None` once it has, or once the mounting is given or followed.
    straight: Option<MountingEstimator>,
    /// The along-track drift's share of the published 1-sigma.
    along: AlongTrack,
    /// The stops' along-track acceleration errors: sum of squares (m/s^2)^2 and count.
    stops: [f64; 2],
    /// The lever arm from the IMU to the constrained point, body frame, m.
    lever_arm_m: Vector3<f64>,
    /// Sum of the applied updates' normalized innovations squared and of their degrees of
    /// freedom (for `mems-odometry diagnose`'s lever-arm candidate).
    pub nis_sum: [f64; 2],
    /// Updates applied and rejected.
    pub applied: u64,
    /// Updates rejected by the gate.
    pub rejected: u64,
    /// Velocities reset at a certain stop (`stops::CERTAIN_S`): the filter held the velocity
    /// beyond the rest gate while the platform stood (`navigator::wheeled`).
    pub velocity_resets: u64,
}

/// What one call did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Outcome {
    /// The constraint was applied: its normalized innovation squared and degrees of freedom
    /// (2, or 1 while only the vertical velocity is constrained); NaN NIS when its covariance
    /// was singular.
    Applied {
        /// Normalized innovation squared.
        nis: f64,
        /// Degrees of freedom.
        dof: f64,
    },
    /// The gate rejected it.
    Rejected,
}

impl ImuConstraint {
    /// A constraint of 1-sigma `sigma_mps` (over a second) with the mounting `mounting`
    /// (sensor to body), or estimated when `None`.
    pub fn new(sigma_mps: f64, mounting: Option<UnitQuaternion<f64>>) -> Self {
        Self {
            sigma_mps,
            r_bs: mounting.map(|q| q.to_rotation_matrix().into_inner()),
            given: mounting.is_some(),
            estimated: None,
            yaw_sigma_rad: 0.0,
            estimator: MountingEstimator::default(),
            straight: mounting.is_none().then(MountingEstimator::default),
            along: AlongTrack::default(),
            stops: [0.0; 2],
            lever_arm_m: Vector3::zeros(),
            nis_sum: [0.0; 2],
            applied: 0,
            rejected: 0,
            velocity_resets: 0,
        }
    }

    /// The constraint at the point `r_b` (body frame, m, from the IMU; module documentation).
    pub fn with_lever_arm(mut self, r_b: Vector3<f64>) -> Self {
        self.lever_arm_m = r_b;
        self
    }

    /// The mounting in use (given, followed, or estimated with the filter's correction at
    /// the last update), `None` while estimating.
    pub fn mounting(&self) -> Option<UnitQuaternion<f64>> {
        self.r_bs.map(|r| {
            let q = UnitQuaternion::from_rotation_matrix(
                &nalgebra::Rotation3::from_matrix_unchecked(r),
            );
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.estimated.unwrap_or(0.0)) * q
        })
    }

    /// Takes `mounting` (sensor to body), the speed hints' forward axis
    /// ([`crate::cruise::ForwardAxis`]) as it is refined, with its yaw 1-sigma `yaw_sigma_rad`,
    /// unless a mounting was given. The lateral constraint's 1-sigma then takes the forward
    /// speed times that angle, in quadrature.
    pub fn follow(&mut self, mounting: UnitQuaternion<f64>, yaw_sigma_rad: f64) {
        if !self.given {
            self.r_bs = Some(mounting.to_rotation_matrix().into_inner());
            self.estimated = None;
            self.yaw_sigma_rad = yaw_sigma_rad;
            self.straight = None;
        }
    }

    /// Applies the constraint to `kf` after a covariance propagation spanning `interval_s`;
    /// `dt_s` is the last sample's interval (for the mounting estimate, fed at every call
    /// where `velocity_has_direction`: a filter aligned in motion without a mounting starts
    /// its velocity at zero for want of a direction, and the displacement it integrates then
    /// points nowhere in particular; the speed hints' forward axis is followed instead, and
    /// until the mounting comes the constraint is not applied: `None`).
    pub fn apply(
        &mut self,
        kf: &mut Eskf,
        dt_s: f64,
        interval_s: f64,
        velocity_has_direction: bool,
    ) -> Option<Outcome> {
        let up_s = kf.x.q.inverse_transform_vector(&Vector3::z());
        if velocity_has_direction {
            self.estimate_mounting(kf, &up_s, dt_s);
        }
        if !kf.propagated() || interval_s <= 0.0 {
            return None;
        }
        let sigma = self.sigma_mps * (1.0 / interval_s).sqrt();
        let (r_bs, lateral, vertical, r_b) = match self.r_bs {
            Some(r) if self.estimated.is_some() => (kf.mounted(&r), sigma, sigma, self.lever_arm_m),
            Some(r) => (r, sigma, sigma, self.lever_arm_m),
            // Aligned in motion without a mounting, the velocity has no direction yet:
            // linearized about it, even the vertical constraint turns the tilt (module
            // documentation).
            None if !velocity_has_direction => return None,
            // Without a forward axis the velocity is uncertain across the body (the first
            // metres of a drive): the linearization's left-out variance keeps its error from
            // being read as tilt (docs/odometry.md, "Wheeled without hints: the
            // non-holonomic constraint").
            None => {
                let r = up_only(&up_s)?;
                let second = kf.body_velocity_second_order_variance(&r).z;
                (r, FREE_MPS, sigma.hypot(second.sqrt()), Vector3::zeros())
            }
        };
        let v_b = kf.point_velocity(&r_bs, &r_b);
        let lateral = lateral.hypot(v_b.x * self.yaw_sigma_rad);
        let sigma_v = kf.filter_velocity_sigma().norm();
        let gate = |s: f64| GATE_SIGMA * s.hypot(sigma_v);
        if v_b.z.abs() > gate(vertical) || (lateral < FREE_MPS && v_b.y.abs() > gate(lateral)) {
            self.rejected += 1;
            return Some(Outcome::Rejected);
        }
        let residual = Vector3::new(0.0, -v_b.y, -v_b.z);
        let sigmas = Vector3::new(FREE_MPS, lateral, vertical);
        let yaw = if self.estimated.is_some() {
            // Turning, an IMU off the turning axis moves sideways at `w r`, which a yaw error
            // mimics (`v dm`): the yaw is learned on straight driving alone, as the
            // straight-driving mounting is gathered.
            if drives_straight(sideways_bound(kf, &up_s), v_b.x.abs()) {
                MountingYaw::Learned
            } else {
                MountingYaw::Considered
            }
        } else {
            MountingYaw::Exact
        };
        let nis = kf.point_velocity_update(&r_bs, &r_b, residual, sigmas, Heading::Kept, yaw);
        if self.estimated.is_some() {
            self.estimated = Some(kf.mounting_yaw().0);
        }
        self.applied += 1;
        let dof = if lateral < FREE_MPS { 2.0 } else { 1.0 };
        if let Some(x) = nis.filter(|x| x.is_finite()) {
            self.nis_sum[0] += x;
            self.nis_sum[1] += dof;
        }
        Some(Outcome::Applied {
            nis: nis.unwrap_or(f64::NAN),
            dof,
        })
    }
}

impl ImuConstraint {
    /// Gathers the filter's sensor-frame velocity over `dt_s` into the mounting estimates
    /// (module documentation), `up_s` the filter's up direction in the sensor frame; a new
    /// estimate restarts the filter's mounting-yaw state with its 1-sigma.
    fn estimate_mounting(&mut self, kf: &mut Eskf, up_s: &Vector3<f64>, dt_s: f64) {
        let v_s = kf.x.q.inverse_transform_vector(&kf.x.v);
        // Across the path: the velocity's horizontal 1-sigma (per axis) and the sideways
        // speed of an IMU up to the lever-arm bound off the turning axis.
        let v_sigma = kf.filter_velocity_sigma().xy().norm() * std::f64::consts::FRAC_1_SQRT_2;
        let turn = sideways_bound(kf, up_s);
        let across = v_sigma.hypot(turn);
        let from = |e: &MountingEstimator| {
            (e.path_m() >= MOUNTING_PATH_M)
                .then(|| e.mounting(up_s))
                .flatten()
                .map(|q| (q.to_rotation_matrix().into_inner(), e.yaw_sigma_rad(up_s)))
        };
        let mut estimate = None;
        if self.r_bs.is_none() {
            self.estimator.add(&v_s, across, dt_s);
            estimate = from(&self.estimator);
        }
        if let Some(straight) = self.straight.as_mut()
            && drives_straight(turn, v_s.norm())
        {
            straight.add(&v_s, across, dt_s);
            if let Some(found) = from(straight) {
                estimate = Some(found);
                self.straight = None;
            }
        }
        if let Some((r, sigma)) = estimate {
            self.r_bs = Some(r);
            kf.restart_mounting(sigma.min(MAX_MOUNTING_YAW_SIGMA_RAD));
            self.estimated = Some(0.0);
        }
    }

    /// Adds `dt_s` of motion without speed to the along-track drift ([`AlongTrack`]) and
    /// widens `kf`'s published 1-sigma by what it grew.
    pub fn drift_along_track(&mut self, kf: &mut Eskf, dt_s: f64) {
        let v = kf.x.v.xy();
        let speed = v.norm();
        // The direction of travel; at a standstill, any.
        let h = if speed > 0.0 {
            v / speed
        } else {
            nalgebra::Vector2::repeat(std::f64::consts::FRAC_1_SQRT_2)
        };
        let (dp, dv) = self.along.grow(dt_s, self.along_track_accel(), speed);
        let split = |d: f64| [d * h.x * h.x, d * h.y * h.y];
        kf.widen_reported(split(dp), split(dv));
    }

    /// A rest (or a speed measurement) ended the motion: the along-track drift starts anew.
    pub fn stopped(&mut self) {
        self.along = AlongTrack::default();
    }

    /// A rest begins while the filter's horizontal speed is `speed_mps`: after a motion of
    /// at least [`MIN_MOTION_S`] that speed over the motion's time measures the along-track
    /// acceleration error (module documentation). Called at every rest sample; only the
    /// first after a motion counts (it ends the motion, as [`Self::stopped`] does).
    pub fn stop_seen(&mut self, speed_mps: f64) {
        let t = self.along.t_s;
        if t >= MIN_MOTION_S && speed_mps.is_finite() {
            self.stops[0] += (speed_mps / t).powi(2);
            self.stops[1] += 1.0;
        }
        self.stopped();
    }

    /// 1-sigma of the along-track acceleration error, m/s^2: the prior and the stops'
    /// measurements pooled (module documentation).
    pub fn along_track_accel(&self) -> f64 {
        let [sum_sq, n] = self.stops;
        ((ALONG_TRACK_ACCEL_SIGMA_MPS2.powi(2) + sum_sq) / (1.0 + n)).sqrt()
    }

    /// Stops that measured the along-track acceleration error.
    pub fn stops_measured(&self) -> u64 {
        self.stops[1] as u64
    }
}

/// The along-track error of one motion between rests (see the module documentation): an
/// acceleration error of 1-sigma `a`, constant over the motion, grows the velocity's 1-sigma
/// as `u = a t`, within [`SPEED_FACTOR`] times the speed shown (rms), and the position's
/// as the integral of `u` (`a t^2 / 2` below that bound; accumulated as `u dt`, so a motion
/// that stops and starts again without a rest keeps its time).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AlongTrack {
    /// Time since the motion began, s.
    t_s: f64,
    /// The velocity and position 1-sigma so far, m/s and m.
    u: f64,
    d: f64,
    /// The integral of the squared speed shown in the motion, m^2/s.
    speed_sq_s: f64,
}

impl AlongTrack {
    /// Adds `dt_s` seconds at the acceleration 1-sigma `a` (m/s^2) with the filter showing
    /// the speed `speed_mps`; returns how much the position variance (m^2) and the velocity
    /// variance ((m/s)^2) grew.
    pub fn grow(&mut self, dt_s: f64, a: f64, speed_mps: f64) -> (f64, f64) {
        self.t_s += dt_s;
        self.speed_sq_s += speed_mps * speed_mps * dt_s;
        let rms = (self.speed_sq_s / self.t_s).sqrt();
        let u = (a * self.t_s).min(SPEED_FACTOR * rms).max(self.u);
        let d = self.d + 0.5 * (self.u + u) * dt_s;
        let grown = (d * d - self.d * self.d, u * u - self.u * self.u);
        (self.u, self.d) = (u, d);
        grown
    }
}

/// A mounting whose body z is `up_s` and whose x is any perpendicular axis (for the vertical
/// constraint alone).
fn up_only(up_s: &Vector3<f64>) -> Option<Matrix3<f64>> {
    let i = up_s.iamin();
    let any = Vector3::from_fn(|r, _| if r == i { 1.0 } else { 0.0 });
    mounting_from(&any, up_s).map(|q| q.to_rotation_matrix().into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn along_track_drift_grows_as_a_constant_acceleration_error() {
        let mut along = AlongTrack::default();
        let (mut p, mut v) = (0.0, 0.0);
        for _ in 0..6000 {
            let (dp, dv) = along.grow(0.01, 0.02, 5.0);
            (p, v) = (p + dp, v + dv);
        }
        // After 60 s: 1.2 m/s and 36 m.
        assert!((v.sqrt() - 1.2).abs() < 1e-9, "{}", v.sqrt());
        assert!((p.sqrt() - 36.0).abs() < 1e-3, "{}", p.sqrt());
    }

    #[test]
    fn a_slow_platform_s_velocity_share_stays_near_its_speed() {
        let mut along = AlongTrack::default();
        let (mut p, mut v) = (0.0, 0.0);
        for _ in 0..26000 {
            let (dp, dv) = along.grow(0.01, 0.03, 0.2);
            (p, v) = (p + dp, v + dv);
        }
        // 0.2 m/s from 6.7 s on: 51.3 m after 260 s instead of 1014 m.
        assert!((v.sqrt() - 0.2).abs() < 1e-9, "{}", v.sqrt());
        let t1 = 0.2 / 0.03;
        let expected = 0.03 * t1 * t1 / 2.0 + 0.2 * (260.0 - t1);
        assert!((p.sqrt() - expected).abs() < 0.1, "{} {expected}", p.sqrt());
    }

    #[test]
    fn stops_teach_the_along_track_acceleration() {
        let mut nhc = ImuConstraint::new(0.1, None);
        assert_eq!(nhc.along_track_accel(), ALONG_TRACK_ACCEL_SIGMA_MPS2);
        for _ in 0..1000 {
            nhc.along.grow(0.01, 0.03, 1.0);
        }
        // 10 s of motion, 0.05 m/s at the stop: 0.005 m/s^2, pooled with the prior; the
        // stop's next sample is no new stop.
        nhc.stop_seen(0.05);
        nhc.stop_seen(0.05);
        let expected = ((0.03f64.powi(2) + 0.005f64.powi(2)) / 2.0).sqrt();
        assert!((nhc.along_track_accel() - expected).abs() < 1e-12);
        // A short motion measures nothing.
        nhc.along.grow(1.0, 0.03, 1.0);
        nhc.stop_seen(3.0);
        assert_eq!(nhc.stops_measured(), 1);
    }

    /// The constraint's update takes the lateral and vertical body velocity towards zero but
    /// turns neither the heading nor the gyro bias about up (a body-frame velocity does not
    /// observe them), whatever the covariance couples to them.
    #[test]
    fn the_constraint_keeps_the_heading_and_its_rate() {
        use crate::eskf::{Cov, Imu, Nominal};
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(0.05, -0.03, 0.9));
        let x = Nominal {
            p: Vector3::zeros(),
            v: q * Vector3::new(2.0, 0.3, -0.1),
            q,
            b_a: Vector3::zeros(),
            b_g: Vector3::zeros(),
            k: 0.0,
            m: 0.0,
        };
        let a = Cov::from_fn(|i, j| ((5 * i + 2 * j) as f64).cos());
        let cov = a * a.transpose() * 1e-3 + Cov::identity() * 1e-4;
        let first = Imu {
            f: q.inverse() * Vector3::new(0.0, 0.0, 9.81),
            w: Vector3::zeros(),
        };
        let noise = crate::config::OdometryConfig::mpu9250(9.81).noise;
        let mut kf = Eskf::new(x, cov, 9.81, noise, first);
        let up = q.inverse_transform_vector(&Vector3::z());
        let mut nhc = ImuConstraint::new(0.05, Some(UnitQuaternion::identity()));
        let outcome = nhc.apply(&mut kf, 0.01, 1.0, true);
        assert!(
            matches!(outcome, Some(Outcome::Applied { .. })),
            "{outcome:?}"
        );
        let turn = q.inverse() * kf.x.q;
        assert!(turn.scaled_axis().dot(&up).abs() < 1e-12, "{turn:?}");
        assert!(kf.x.b_g.dot(&up).abs() < 1e-12, "{}", kf.x.b_g);
        // The body's lateral velocity (0.3 m/s before) moves towards zero.
        let lateral = kf.x.q.inverse_transform_vector(&kf.x.v).y;
        assert!(lateral > 0.0 && lateral < 0.25, "{lateral}");
    }

    #[test]
    fn up_only_keeps_body_z_on_up() {
        let up = Vector3::new(0.1, -0.2, 0.97).normalize();
        let r = up_only(&up).unwrap();
        assert!((r * up - Vector3::z()).norm() < 1e-12);
    }

    /// A filter whose velocity is uncertain across the body (a horizontal 1-sigma of 20 m/s
    /// about a mean of 15 m/s) and a vertical velocity of 0.8 m/s: linearized about the mean,
    /// the vertical constraint reads that as a pitch of atan(0.8 / 15), 3 deg, and took 2.1
    /// deg of it; its second-order variance keeps the tilt within 1 deg. With no direction at
    /// all (aligned in motion, no mounting) it is not applied.
    #[test]
    fn an_uncertain_velocity_is_not_read_as_tilt() {
        use crate::eskf::{Cov, Imu, Nominal, TH, V};
        let x = Nominal {
            p: Vector3::zeros(),
            v: Vector3::new(15.0, 0.0, 0.8),
            q: UnitQuaternion::identity(),
            b_a: Vector3::zeros(),
            b_g: Vector3::zeros(),
            k: 0.0,
            m: 0.0,
        };
        let mut cov = Cov::identity() * 1e-6;
        for (i, sigma) in [20.0, 20.0, 0.5].iter().enumerate() {
            cov[(V + i, V + i)] = sigma * sigma;
        }
        for (i, sigma_deg) in [3.0f64, 3.0, 20.0].iter().enumerate() {
            cov[(TH + i, TH + i)] = sigma_deg.to_radians().powi(2);
        }
        let first = Imu {
            f: Vector3::new(0.0, 0.0, 9.81),
            w: Vector3::zeros(),
        };
        let noise = crate::config::OdometryConfig::mpu9250(9.81).noise;
        let mut kf = Eskf::new(x, cov, 9.81, noise, first);
        let mut nhc = ImuConstraint::new(0.02, None);
        let before = kf.x;
        assert_eq!(nhc.apply(&mut kf, 0.01, 1.0, false), None);
        assert_eq!(kf.x.q, before.q);
        let outcome = nhc.apply(&mut kf, 0.01, 1.0, true);
        assert!(
            matches!(outcome, Some(Outcome::Applied { .. })),
            "{outcome:?}"
        );
        let tilt =
            kf.x.q
                .inverse_transform_vector(&Vector3::z())
                .angle(&Vector3::z());
        assert!(tilt.to_degrees() < 1.0, "{}", tilt.to_degrees());
    }
}
