//! A 16-state error-state Kalman filter for strapdown inertial navigation with zero-velocity
//! (ZUPT) and zero-angular-rate (ZARU) updates, and body-frame velocity updates from a robot's
//! wheel speed (with the wheel speed's scale error as a state).
//!
//! Frames and conventions:
//! - navigation frame `n`: z up, gravity `(0, 0, -g)`; origin and heading fixed at alignment;
//! - sensor frame `s`: the accelerometer's axes;
//! - `q` rotates sensor-frame vectors into the navigation frame (`v_n = q * v_s`);
//! - the accelerometer measures specific force `f = q^-1 (a_n - g_n) + b_a + noise`;
//! - the gyro measures `w = w_true + b_g + noise` (rad/s), after any scale/misalignment
//!   correction;
//! - the attitude error is local: `q_true = q * Exp(dtheta)`.
//!
//! Error state, in this order: `dp` (m), `dv` (m/s), `dtheta` (rad), `db_a` (m/s^2),
//! `db_g` (rad/s), `dk` (the wheel-speed scale error, a fraction: a speed source reads
//! `(1 + k)` times the true forward speed). `k` is constant (no process noise) and only
//! speed updates touch it; without them it keeps its prior. Propagation is first order (Sola, "Quaternion kinematics for the error-state
//! Kalman filter", 2017, section 5.3 and 7); the nominal state integrates with the trapezoid rule.
//! The nominal state integrates every sample; the covariance and the consider sensitivity are
//! propagated from the transition and noise accumulated over the samples of an interval
//! ([`Eskf::with_propagation_interval`], module `increment`), at its end or before any update,
//! the same to rounding as one propagation per sample. Between propagations the covariance
//! is that of the last propagation, at most one interval old; the reported 1-sigma adds the
//! process noise accumulated since ([`Eskf::position_sigma`]).
//! Everything lives on the stack (nalgebra static matrices): no allocation per sample.
//!
//! Systematic errors the filter does not estimate, the residual scale and misalignment of the
//! gyro and the accelerometer, are carried as *consider* parameters (Schmidt's consider
//! covariance; Gelb, "Applied Optimal Estimation", 1974, section 7.2, sensitivity of a filter
//! to unmodelled errors): the filter's gain ignores them, so the estimate is the same, but the
//! error state's sensitivity `M = d(dx)/d(e)` to them is propagated with the same transition
//! and the same gains, and the reported 1-sigma is that of `P + M diag(sigma_e^2) M^T`. A
//! foot or a turning robot rotates through hundreds of degrees, and a 1 % gyro scale error is
//! 1 % of every turn in heading: white noise alone says nothing of it.
//!
//! Written here rather than taken from a crate: no maintained Rust crate provides an ESKF with
//! ZUPT for a strapdown IMU; nalgebra does the linear algebra.

mod increment;
mod lever;
mod refinement;
mod reported;

use increment::{Increment, Sensitivity, Step};
pub use lever::MountingYaw;
use nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};
pub use refinement::{Refinement, RefinementMean};
use reported::Reported;

/// Error-state dimension.
pub const N: usize = 17;
/// Error-state covariance.
pub type Cov = SMatrix<f64, N, N>;
type VecN = SVector<f64, N>;
/// Number of consider parameters: the 9 entries of the gyro's residual error matrix, then the
/// 9 of the accelerometer's, row-major.
pub const NC: usize = 18;

/// Index of the (navigation-frame) position error in the error state.
pub const P: usize = 0;
/// Index of the (navigation-frame) velocity error in the error state.
pub const V: usize = 3;
/// Index of the attitude error (navigation frame: its z is the heading's) in the error state.
pub const TH: usize = 6;
/// Index of the accelerometer bias error (sensor frame) in the error state.
pub const BA: usize = 9;
/// Index of the gyro bias error (sensor frame) in the error state.
pub const BG: usize = 12;
/// Index of the wheel-speed scale error in the error state.
pub const KS: usize = 15;
/// Index of the estimated mounting's yaw error in the error state, rad about body up: the
/// error of a mounting the non-holonomic constraint estimated from the drive
/// (`crate::nonholonomic`), whose prior that estimate sets ([`Eskf::restart_mounting`]); zero
/// variance, and no effect, otherwise.
pub const MY: usize = 16;

/// Whether a velocity update may turn the heading (and its rate, the gyro bias about up).
///
/// A rotation of the whole trajectory about gravity changes no body-frame velocity and no
/// specific force: from body-frame velocities (wheel speeds, the non-holonomic constraint) the
/// heading is unobservable, and only the gyro (its bias at rests) carries it. A linearized
/// filter whose Jacobians are evaluated at changing estimates gains spurious information
/// along such a direction (G. P. Huang, A. I. Mourikis and S. I. Roumeliotis, "Observability-
/// based rules for designing consistent EKF SLAM estimators", IJRR 29(5), 2010), and with a
/// velocity integrated from vibrating samples it takes the speed updates' disagreements out
/// on the heading (docs/real-data.md, the F1TENTH car).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Heading {
    /// The optimal gain: every state the update's Jacobian reaches, the heading included.
    Corrected,
    /// The heading's share of the gain removed (see [`Eskf::body_velocity_update`]).
    Kept,
}

/// Noise model of the filter, SI units throughout.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseModel {
    /// Accelerometer white-noise density (velocity random walk), m/s^2/sqrt(Hz).
    pub accel_noise_density: f64,
    /// Gyro white-noise density (angle random walk), rad/s/sqrt(Hz).
    pub gyro_noise_density: f64,
    /// Accelerometer bias random-walk density, m/s^3/sqrt(Hz).
    pub accel_bias_random_walk: f64,
    /// Gyro bias random-walk density, rad/s^2/sqrt(Hz).
    pub gyro_bias_random_walk: f64,
    /// Low-frequency density of the vehicle's vibration as the accelerometer sees it, per m/s
    /// of speed: m/s^2/sqrt(Hz) per m/s. Added (in quadrature) to the white noise while moving.
    pub vibration_accel_density_per_mps: f64,
    /// The same for the gyro: rad/s/sqrt(Hz) per m/s.
    pub vibration_gyro_density_per_mps: f64,
}

/// The systematic sensor errors the filter reports but does not estimate (see the module
/// documentation): 1-sigma of each entry of the residual error matrix `E`, a fraction, with
/// row the corrected axis and column the raw axis. The gyro's corrected rate is `(I + E_g)`
/// times the true rate; the accelerometer's specific force is `(I + E_a)` times the true one.
/// At alignment `E_a` reads as an accelerometer bias, which the alignment's bias sigma already
/// holds, so only its effect on the change of specific force since alignment is added here.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConsiderModel {
    /// 1-sigma of each entry of `E_g`, fraction.
    pub gyro: Matrix3<f64>,
    /// 1-sigma of each entry of `E_a`, fraction.
    pub accel: Matrix3<f64>,
}

/// What the platform can do while samples are missing ([`Eskf::missed`]): 1-sigma figures of
/// a manoeuvre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Manoeuvre {
    /// Acceleration, m/s^2, each axis.
    pub accel: f64,
    /// Rotation rate, rad/s.
    pub rate: f64,
    /// Largest change of tilt (roll, pitch), rad.
    pub tilt: f64,
    /// Duration of the quickest manoeuvre, s.
    pub duration_s: f64,
}

impl Manoeuvre {
    /// Longest unobserved interval (a gap or a hole in the time line) the odometry bridges,
    /// s: `pi / rate`. Across an interval `t` with no accelerometer or gyro the platform may
    /// have done anything within its envelope ([`Eskf::missed`]): its velocity is known to
    /// `accel t`, its position to `accel t^2 / 2` (1-sigma, each axis), and its heading to
    /// `rate t`. Once `rate t` reaches pi the heading is wholly unknown: the track after the
    /// interval can no longer be placed in the frame of the track before it (any direction is
    /// as likely), so a position that went on across it would be a number without meaning.
    /// A ground robot's default (0.5 rad/s) bridges 6.3 s; then the position's 1-sigma has
    /// grown by about 20 m, the velocity's by 6 m/s.
    pub fn bridge_limit_s(&self) -> f64 {
        std::f64::consts::PI / self.rate
    }
}

/// The variances an unobserved interval of `t` seconds adds ([`Eskf::missed`]): position and
/// velocity (each axis), tilt and heading; each grows with `t`.
fn envelope(t: f64, m: &Manoeuvre) -> [f64; 4] {
    let share = (t / m.duration_s).min(1.0);
    let a = m.accel * share;
    let turn = m.rate * share * t;
    [
        (a * t * t / 2.0).powi(2),
        (a * t).powi(2),
        turn.min(m.tilt).powi(2),
        turn.min(std::f64::consts::PI).powi(2),
    ]
}

/// The nominal state `x0` advanced by `dt` seconds from the measurement `last` to `m` with the
/// trapezoid rule, and half the interval's rotation (the attitude at its midpoint is
/// `x0.q * half`, the geodesic between the two ends).
fn advance(
    x0: &Nominal,
    last: &Imu,
    m: &Imu,
    dt: f64,
    g_n: &Vector3<f64>,
) -> (Nominal, UnitQuaternion<f64>) {
    let w_mid = 0.5 * ((last.w - x0.b_g) + (m.w - x0.b_g));
    let half = UnitQuaternion::from_scaled_axis(w_mid * (0.5 * dt));
    let q1 = x0.q * half * half;
    let a0 = x0.q * (last.f - x0.b_a) + g_n;
    let a1 = q1 * (m.f - x0.b_a) + g_n;
    let v1 = x0.v + 0.5 * (a0 + a1) * dt;
    let x1 = Nominal {
        p: x0.p + 0.5 * (x0.v + v1) * dt,
        v: v1,
        q: q1,
        ..*x0
    };
    (x1, half)
}

/// The nominal (full) navigation state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nominal {
    /// Position, m, navigation frame.
    pub p: Vector3<f64>,
    /// Velocity, m/s, navigation frame.
    pub v: Vector3<f64>,
    /// Attitude, sensor to navigation.
    pub q: UnitQuaternion<f64>,
    /// Accelerometer bias, m/s^2, sensor frame.
    pub b_a: Vector3<f64>,
    /// Gyro bias, rad/s, sensor frame.
    pub b_g: Vector3<f64>,
    /// Scale error of the wheel-speed source, fraction (it reads `(1 + k)` times the truth).
    pub k: f64,
    /// Correction to an estimated mounting's yaw since it was taken, rad about body up
    /// (counter-clockwise): the mounting in use is `R_z(m) R_bs` ([`Eskf::mounted`]).
    pub m: f64,
}

/// One IMU measurement in SI units, sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Imu {
    /// Specific force, m/s^2.
    pub f: Vector3<f64>,
    /// Angular rate, rad/s.
    pub w: Vector3<f64>,
}

/// The filter: nominal state, error covariance and the previous measurement.
#[derive(Debug, Clone)]
pub struct Eskf {
    /// Nominal state.
    pub x: Nominal,
    /// Error-state covariance, as of the last propagation ([`Self::propagate`]).
    pub cov: Cov,
    g_n: Vector3<f64>,
    noise: NoiseModel,
    last: Imu,
    /// `M^T`, the transpose of `M = d(dx)/d(e)` for the consider parameters `e` (stored
    /// transposed: `M`'s rows, which propagation and updates take, are its columns).
    sens: Sensitivity,
    /// Their variances, in the order of [`NC`].
    consider_var: SVector<f64, NC>,
    /// The bias-corrected specific force at alignment, m/s^2, sensor frame.
    f_align: Vector3<f64>,
    /// Transition, noise and sensitivity of the samples since the last propagation.
    inc: Increment,
    /// Longest interval the covariance waits for before it is propagated, s.
    interval_s: f64,
    /// Position and velocity variances (m^2, (m/s)^2) of the covariance as last propagated or
    /// updated, the consider parameters' share included.
    var: (Vector3<f64>, Vector3<f64>),
    /// Per-sample standard deviation of the specific force (m/s^2) and the rate (rad/s) the
    /// stream shows ([`Self::set_sampled_noise`]).
    sampled_sd: (f64, f64),
    /// What the published 1-sigma carries beyond the covariance ([`Self::set_consistency`]).
    reported: Reported,
    /// Factor on the process noise ([`Self::set_consistency`] with `process`), 1 by default.
    q_scale: f64,
    /// The calibration stage's refinement of the last sample: accelerometer offset (m/s^2)
    /// and gyroscope bias (rad/s), sensor frame (module `refinement`).
    refined: Option<Refinement>,
    /// `refined` is an alignment window's mean ([`Self::with_refinement`]): the next
    /// [`Self::follow_refinement`] follows the gyroscope's change as well.
    refined_window: bool,
}

/// Skew-symmetric matrix: `skew(a) * b == a.cross(&b)`.
pub fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    a.cross_matrix()
}

impl Eskf {
    /// A filter starting from `x` with covariance `cov`, gravity magnitude `g` (m/s^2), and the
    /// measurement taken at the start time.
    pub fn new(x: Nominal, cov: Cov, g: f64, noise: NoiseModel, first: Imu) -> Self {
        Self {
            x,
            cov,
            g_n: Vector3::new(0.0, 0.0, -g),
            noise,
            last: first,
            sens: Sensitivity::zeros(),
            consider_var: SVector::zeros(),
            f_align: first.f - x.b_a,
            inc: Increment::default(),
            interval_s: 0.0,
            var: (Vector3::zeros(), Vector3::zeros()),
            sampled_sd: (0.0, 0.0),
            reported: Reported::default(),
            q_scale: 1.0,
            refined: None,
            refined_window: false,
        }
        .with_sigma()
    }

    /// The filter propagating its covariance once the samples since the last propagation
    /// span `interval_s` seconds (to within half a sample), and before every update; 0 (the
    /// default) propagates at every sample.
    pub fn with_propagation_interval(mut self, interval_s: f64) -> Self {
        self.interval_s = interval_s;
        self
    }

    /// Whether the covariance is propagated to the newest sample (nothing accumulated since).
    pub fn propagated(&self) -> bool {
        self.inc.steps() == 0
    }

    /// Propagates the covariance and the consider sensitivity over the samples accumulated
    /// since the last propagation (module `increment`).
    pub fn propagate(&mut self) {
        if self.propagated() {
            return;
        }
        let before = self.var;
        self.inc.apply(&mut self.cov, &mut self.sens);
        self.refresh_sigma();
        self.reported.propagated(&before, &self.var);
    }

    /// The normalized innovation squared of `residual` with the filter's innovation
    /// covariance `s` and the consider parameters' share, `g` being the sensitivity of the
    /// measurement to them (`M^T H^T`): `r^T (S + G^T Sigma G)^-1 r`, the innovation's whole
    /// predicted covariance, as the published 1-sigma holds both (`crate::consistency`).
    fn nis<const D: usize>(
        &self,
        residual: &SVector<f64, D>,
        s: &SMatrix<f64, D, D>,
        g: &SMatrix<f64, NC, D>,
    ) -> f64 {
        let weighted = SMatrix::<f64, NC, D>::from_fn(|q, a| g[(q, a)] * self.consider_var[q]);
        let share = g.transpose() * weighted;
        (s + share)
            .try_inverse()
            .map_or(f64::NAN, |inv| residual.dot(&(inv * residual)))
    }

    /// The innovation consistency's factor `lambda` (>= 1, `crate::consistency`) from now on:
    /// with `process` false it multiplies the variance each propagation adds, in the
    /// published 1-sigma only (module `reported`: estimates unchanged); with `process` true it
    /// multiplies the process noise instead (adaptive process noise: the estimates change).
    pub fn set_consistency(&mut self, lambda: f64, process: bool) {
        let lambda = lambda.max(1.0);
        (self.reported.lambda, self.q_scale) = if process {
            (1.0, lambda)
        } else {
            (lambda, 1.0)
        };
    }

    /// Adds `p` (m^2) and `v` ((m/s)^2) to the published position and velocity variances of
    /// the horizontal axes (x, y): motion the filter could not see, which its estimates keep
    /// out.
    pub fn widen_reported(&mut self, p: [f64; 2], v: [f64; 2]) {
        self.reported.widen_horizontal(p, v);
    }

    /// Sets the published position variance of a systematic error the filter holds no state
    /// for, m^2 per horizontal axis (x, y) (module `reported`): replaced, not added to.
    pub fn set_systematic(&mut self, p: [f64; 2]) {
        self.reported.systematic[0] = p[0].max(0.0);
        self.reported.systematic[1] = p[1].max(0.0);
    }

    /// Widens the wheel-speed scale error's variance to `var` when it is smaller, its
    /// covariances with the other states in proportion: a prior the data refuted.
    pub fn widen_scale(&mut self, var: f64) {
        self.widen(KS, var);
    }

    /// Widens the gyro bias's variances (sensor frame, (rad/s)^2 per axis) to `var` where
    /// they are smaller, as [`Self::widen_scale`].
    pub fn widen_gyro_bias(&mut self, var: Vector3<f64>) {
        for (i, v) in var.iter().enumerate() {
            self.widen(BG + i, *v);
        }
    }

    /// Widens error-state component `i`'s variance to `var` when it is smaller, its
    /// covariances with the other states in proportion (`D P D` with `D` diagonal: the
    /// covariance stays positive semi-definite).
    fn widen(&mut self, i: usize, var: f64) {
        let now = self.cov[(i, i)];
        if !(var > now && now > 0.0) {
            self.cov[(i, i)] = self.cov[(i, i)].max(var);
            return;
        }
        let f = (var / now).sqrt();
        for j in 0..N {
            self.cov[(j, i)] *= f;
            self.cov[(i, j)] *= f;
        }
    }

    /// Starts the mounting-yaw state ([`MY`]) at a newly estimated mounting: correction zero,
    /// 1-sigma `sigma_rad`, uncorrelated with the other states (the estimate is new).
    pub fn restart_mounting(&mut self, sigma_rad: f64) {
        self.x.m = 0.0;
        self.cov.column_mut(MY).fill(0.0);
        self.cov.row_mut(MY).fill(0.0);
        self.cov[(MY, MY)] = sigma_rad * sigma_rad;
    }

    /// The estimated mounting `r_bs` (sensor to body) turned by the mounting-yaw correction:
    /// `R_z(m) r_bs`, the mounting in use.
    pub fn mounted(&self, r_bs: &Matrix3<f64>) -> Matrix3<f64> {
        nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), self.x.m).into_inner() * r_bs
    }

    /// The mounting-yaw correction and its 1-sigma, rad.
    pub fn mounting_yaw(&self) -> (f64, f64) {
        (self.x.m, self.cov[(MY, MY)].max(0.0).sqrt())
    }

    /// The wheel-speed scale error and its 1-sigma, fraction.
    pub fn scale(&self) -> (f64, f64) {
        (self.x.k, self.cov[(KS, KS)].max(0.0).sqrt())
    }

    /// A direct measurement of the wheel-speed scale error: `k_meas` with variance `var`,
    /// through the filter's one update (`update`, Joseph form): every state moves by
    /// its covariance with the scale.
    pub fn measure_scale(&mut self, k_meas: f64, var: f64) {
        let mut h = SMatrix::<f64, 1, N>::zeros();
        h[(0, KS)] = 1.0;
        let r = SMatrix::<f64, 1, 1>::new(var);
        self.update(
            &h,
            SVector::<f64, 1>::new(k_meas - self.x.k),
            &r,
            Heading::Corrected,
        );
    }

    fn with_sigma(mut self) -> Self {
        self.refresh_sigma();
        self
    }

    /// Recomputes the position and velocity variances from the covariance and the consider
    /// parameters' share.
    fn refresh_sigma(&mut self) {
        let var = |i: usize| self.cov[(i, i)] + self.consider_variance(i);
        self.var = (
            Vector3::new(var(P), var(P + 1), var(P + 2)),
            Vector3::new(var(V), var(V + 1), var(V + 2)),
        );
    }

    /// The filter with the consider parameters of `model` (none by default), the specific
    /// force at alignment being `f_align` (m/s^2, sensor frame, before bias correction).
    pub fn with_consider(mut self, model: ConsiderModel, f_align: Vector3<f64>) -> Self {
        let sq = |m: &Matrix3<f64>| m.transpose().map(|s| s * s);
        for (i, v) in sq(&model.gyro)
            .iter()
            .chain(sq(&model.accel).iter())
            .enumerate()
        {
            self.consider_var[i] = *v;
        }
        self.f_align = f_align - self.x.b_a;
        self.with_sigma()
    }

    /// The per-sample standard deviation of the specific force (`accel`, m/s^2) and of the
    /// rate (`gyro`, rad/s) that the stream shows (`crate::sampled_noise`): each prediction's
    /// velocity (attitude) noise is the larger of the noise model's density squared times
    /// `dt` and the sample's own `(sd dt)^2`. Zero (the default) keeps the noise model alone.
    pub fn set_sampled_noise(&mut self, accel: f64, gyro: f64) {
        self.sampled_sd = (accel, gyro);
    }

    /// Gravity in the navigation frame, m/s^2.
    pub fn gravity(&self) -> Vector3<f64> {
        self.g_n
    }

    /// Advances the state by `dt` seconds to the new measurement `m` (trapezoid rule between the
    /// previous and the new measurement) and accumulates the covariance's transition and noise,
    /// propagating it when the interval is complete.
    pub fn predict(&mut self, m: Imu, dt: f64) {
        let x0 = self.x;
        let (x1, half) = advance(&x0, &self.last, &m, dt, &self.g_n);
        self.x = x1;
        let q_mid = x0.q * half;
        let w_mid = 0.5 * ((self.last.w - x0.b_g) + (m.w - x0.b_g));
        let f0 = self.last.f - x0.b_a;
        let f1 = m.f - x0.b_a;

        // Error-state transition at the interval's midpoint, first order in dt: the identity
        // but for the blocks of `Step` (Sola 2017, eq. 269).
        let r_mid = q_mid.to_rotation_matrix().into_inner();
        let f_mid = 0.5 * (f0 + f1);
        let n = &self.noise;
        let speed = x0.v.norm();
        let (sd_a, sd_w) = self.sampled_sd;
        self.inc.push(&Step {
            dt,
            v_th: -r_mid * skew(&f_mid) * dt,
            v_ba: -r_mid * dt,
            th_th: (half * half).inverse().to_rotation_matrix().into_inner(),
            q_v: self.q_scale
                * (n.accel_noise_density.powi(2)
                    + (n.vibration_accel_density_per_mps * speed).powi(2))
                .max(sd_a * sd_a * dt)
                * dt,
            q_th: self.q_scale
                * (n.gyro_noise_density.powi(2)
                    + (n.vibration_gyro_density_per_mps * speed).powi(2))
                .max(sd_w * sd_w * dt)
                * dt,
            q_ba: self.q_scale * n.accel_bias_random_walk.powi(2) * dt,
            q_bg: self.q_scale * n.gyro_bias_random_walk.powi(2) * dt,
            w: w_mid,
            df: f_mid - self.f_align,
            r: r_mid,
        });
        self.last = m;
        if self.inc.interval_s() + 0.5 * dt >= self.interval_s {
            self.propagate();
        }
    }

    /// The nominal state after `readings` (each a measurement and its interval, s), predicted
    /// as [`Self::predict`] predicts it, without touching the filter or its covariance.
    pub fn coast(&self, readings: impl Iterator<Item = (Imu, f64)>) -> Nominal {
        let (mut x, mut last) = (self.x, self.last);
        for (m, dt) in readings {
            x = advance(&x, &last, &m, dt, &self.g_n).0;
            last = m;
        }
        x
    }

    /// Widens the covariance for `t` seconds whose measurements are missing (a gap in the
    /// stream). The prediction across the gap interpolated the readings on either side; the
    /// truth may differ from them by an unknown constant acceleration and rotation rate, of
    /// 1-sigma `m.accel` (m/s^2, each axis) and `m.rate` (rad/s, about the vertical) for a gap
    /// as long as the platform's quickest manoeuvre `m.duration_s` or longer, and in proportion
    /// to the gap below it (the readings on either side of a short gap bound what happened in
    /// it). Velocity error `a t`, position `a t^2 / 2`, heading `w t` (at most pi), tilt as
    /// much but at most `m.tilt` (a ground robot stays about level). The position's share is
    /// added uncorrelated with the velocity's: the path inside the gap is not known from the
    /// velocity at its end, so a zero-velocity update after the gap must not shrink it (fully
    /// correlated, as a constant acceleration would make them, it did, and the 1-sigma at the
    /// end of a simulated drive fell below its error).
    pub fn missed(&mut self, t: f64, m: &Manoeuvre) {
        self.unobserved(0.0, t, m);
    }

    /// Widens the covariance as [`Self::missed`] does for an unobserved stretch that grows from
    /// `t0` to `t1` seconds (samples the filter did not integrate, one at a time: implausible
    /// ones): the widening of `t1` less that of `t0`, so a stretch bridged sample by sample
    /// ends as wide as one gap of its length.
    pub fn unobserved(&mut self, t0: f64, t1: f64, m: &Manoeuvre) {
        self.propagate();
        let (e0, e1) = (envelope(t0, m), envelope(t1, m));
        let [pp, vv, tilt, yaw] = std::array::from_fn(|i| (e1[i] - e0[i]).max(0.0));
        for i in 0..3 {
            self.cov[(P + i, P + i)] += pp;
            self.cov[(V + i, V + i)] += vv;
        }
        // Navigation-frame rotation uncertainty, into the local attitude error's frame.
        let r = self.x.q.to_rotation_matrix().into_inner();
        let nav = Matrix3::from_diagonal(&Vector3::new(tilt, tilt, yaw));
        let local = r.transpose() * nav * r;
        let mut th = self.cov.fixed_view_mut::<3, 3>(TH, TH);
        th += local;
        self.refresh_sigma();
    }

    /// Widens the covariance for what clipped axes hid: `var[i]` is the variance of the unseen
    /// velocity along accelerometer axis `i` (0-2, (m/s)^2) or of the unseen rotation about
    /// gyroscope axis `i - 3` (3-5, rad^2), sensor frame (`crate::untrusted` sizes them). A
    /// gyroscope axis's share goes to the attitude error about that sensor axis; an
    /// accelerometer axis's to the velocity along it, in the navigation frame.
    pub fn clipped(&mut self, var: &[f64; 6]) {
        self.propagate();
        let r = self.x.q.to_rotation_matrix().into_inner();
        for (i, var) in var.iter().enumerate().filter(|(_, v)| **v > 0.0) {
            if i < 3 {
                let along = r.column(i).into_owned();
                let mut vv = self.cov.fixed_view_mut::<3, 3>(V, V);
                vv += along * along.transpose() * *var;
            } else {
                self.cov[(TH + i - 3, TH + i - 3)] += var;
            }
        }
        self.refresh_sigma();
    }

    /// As [`Eskf::clipped`] for the gyroscope axes (`var[3..6]`, rad^2, sensor frame; the
    /// accelerometer's entries are not read), but each axis's variance widens only the tilt
    /// about its horizontal part (navigation frame), not the heading about its vertical part.
    pub fn clipped_tilt(&mut self, var: &[f64; 6]) {
        self.propagate();
        let r = self.x.q.to_rotation_matrix().into_inner();
        for (i, var) in var[3..].iter().enumerate().filter(|(_, v)| **v > 0.0) {
            let mut horizontal = r.column(i).into_owned();
            horizontal.z = 0.0;
            // Into the local attitude error's frame, where `clipped` adds its share.
            let local = r.transpose() * horizontal;
            let mut th = self.cov.fixed_view_mut::<3, 3>(TH, TH);
            th += local * local.transpose() * *var;
        }
    }

    /// Zero-velocity update: the true velocity is zero, measured with 1-sigma `sigma` (m/s).
    /// The covariance is propagated to the newest sample first (as for every update).
    /// Returns the normalized innovation squared (3 degrees of freedom), `None` when its
    /// covariance was singular and nothing was updated.
    pub fn zero_velocity(&mut self, sigma: f64) -> Option<f64> {
        let residual = -self.x.v;
        self.update_selected(V, residual, sigma * sigma)
    }

    /// Position update: the true position (m, navigation frame) is `p`, measured with
    /// independent errors of variance `var` (m^2, per axis). Returns the normalized innovation
    /// squared (3 degrees of freedom), `None` when its covariance was singular and nothing was
    /// updated.
    pub fn position_update(&mut self, p: Vector3<f64>, var: Vector3<f64>) -> Option<f64> {
        let residual = p - self.x.p;
        self.update_selected_diag(P, residual, &var)
    }

    /// Whether the velocity is consistent with rest: every component within `gate` standard
    /// deviations of zero, the standard deviation combining the velocity's own with a
    /// zero-velocity measurement's 1-sigma `sigma` (m/s). The velocity's own is that of the
    /// last propagation.
    pub fn velocity_consistent_with_zero(&self, sigma: f64, gate: f64) -> bool {
        (0..3)
            .all(|i| self.x.v[i].abs() <= gate * (self.cov[(V + i, V + i)] + sigma * sigma).sqrt())
    }

    /// Zero-angular-rate update: the body does not rotate, so the gyro reading `w` (rad/s,
    /// sensor frame, corrected; a sample's, or the mean of several at rest) measures the gyro
    /// bias with white noise of 1-sigma `sigma` (rad/s; the gyro's noise density over the
    /// square root of the time `w` spans). Skipped, returning `false`, when a component of
    /// the innovation lies beyond `gate` times its predicted standard deviation: the body is
    /// rotating after all (an in-place spin flagged as rest), and the reading must not become
    /// the bias.
    pub fn zero_rate(&mut self, w: Vector3<f64>, sigma: f64, gate: f64) -> bool {
        self.propagate();
        let residual = w - self.x.b_g;
        let predicted_var = self
            .cov
            .fixed_view::<3, 3>(BG, BG)
            .diagonal()
            .add_scalar(sigma * sigma);
        if residual
            .iter()
            .zip(predicted_var.iter())
            .any(|(r, v)| r.abs() > gate * v.sqrt())
        {
            return false;
        }
        self.update_selected(BG, residual, sigma * sigma);
        true
    }

    /// Restarts the velocity at `v` (m/s, navigation frame) with covariance `cov_v`, uncorrelated
    /// with the rest of the state: for a velocity the filter knows less about than a new
    /// measurement gives, which an update linearized about it would take out on the attitude.
    /// The position takes what its covariance with the velocity says of the velocity's change
    /// (the Gaussian conditional on the new velocity taken as exact: `p += P_pv P_vv^-1
    /// (v - v_old)`, and the whole covariance `P -= P_xv P_vv^-1 P_vx`, which stays positive
    /// semi-definite): the distance a velocity started at zero for want of a direction left
    /// out (a start in motion, [`crate::cruise`]). The other states keep their means.
    pub fn restart_velocity(&mut self, v: Vector3<f64>, cov_v: &Matrix3<f64>) {
        self.propagate();
        let p_vv = self.cov.fixed_view::<3, 3>(V, V).into_owned();
        if let Some(inv) = p_vv.try_inverse() {
            let p_xv = self.cov.fixed_view::<N, 3>(0, V).into_owned();
            let gain = p_xv * inv;
            self.x.p += gain.fixed_view::<3, 3>(P, 0) * (v - self.x.v);
            self.cov -= gain * p_xv.transpose();
            self.cov = (self.cov + self.cov.transpose()) * 0.5;
        }
        self.reset_velocity(v, cov_v);
    }

    /// Sets the velocity to `v` (m/s, navigation frame) with covariance `cov_v`, uncorrelated
    /// with the other states, whose means and covariance stay as they are: for a velocity
    /// known wrong beyond what its covariance says (a certain stop,
    /// `crate::stops::CERTAIN_S`), whose covariance with the position then says nothing of
    /// the position's error either.
    pub fn reset_velocity(&mut self, v: Vector3<f64>, cov_v: &Matrix3<f64>) {
        self.propagate();
        self.x.v = v;
        for i in 0..N {
            for j in V..V + 3 {
                (self.cov[(i, j)], self.cov[(j, i)]) = (0.0, 0.0);
            }
        }
        self.cov.fixed_view_mut::<3, 3>(V, V).copy_from(cov_v);
        self.reported.v = Vector3::zeros();
        self.refresh_sigma();
    }

    /// Sets the position to `p` (m, navigation frame) with independent errors of variance
    /// `var` (m^2 per axis), uncorrelated with the other states, whose means and covariance
    /// stay as they are: for a position the filter's own covariance claims to know far better
    /// than it does (integrated from a velocity without direction, then conditioned on a
    /// restarted one as if its error had been constant, [`Self::restart_velocity`]), so that a
    /// measurement of it would barely move it.
    pub fn reset_position(&mut self, p: Vector3<f64>, var: Vector3<f64>) {
        self.propagate();
        self.x.p = p;
        for i in 0..N {
            for j in P..P + 3 {
                (self.cov[(i, j)], self.cov[(j, i)]) = (0.0, 0.0);
            }
        }
        self.cov
            .fixed_view_mut::<3, 3>(P, P)
            .copy_from(&Matrix3::from_diagonal(&var));
        self.refresh_sigma();
    }

    /// The velocity in the robot's body frame, m/s: `R_bs q^-1 v`, with `r_bs` rotating
    /// sensor-frame vectors into the body frame (x forward, y left, z up).
    pub fn body_velocity(&self, r_bs: &Matrix3<f64>) -> Vector3<f64> {
        r_bs * self.x.q.inverse_transform_vector(&self.x.v)
    }

    /// Body-frame velocity update from a wheel-speed source: the measurement is
    /// `z = ((1 + k) v_b.x, v_b.y, v_b.z)` with `v_b` the [`Self::body_velocity`], 1-sigma
    /// `sigma` per component (m/s). `residual` is `z` minus its prediction, computed by the
    /// caller (who may take the prediction at the measurement's own time). The Jacobian is
    /// evaluated at the current state: `dv_b = R_bs R^T dv + R_bs [R^T v]x dtheta` and the
    /// forward row also has `v_b.x` for `dk`. Returns the normalized innovation squared
    /// (`None`: singular, nothing updated); a component given a 1-sigma far beyond the
    /// velocity's adds about nothing to it (one degree of freedom fewer). The heading is
    /// corrected with the rest ([`Heading::Corrected`]; [`Self::body_velocity_update_with`]
    /// chooses).
    pub fn body_velocity_update(
        &mut self,
        r_bs: &Matrix3<f64>,
        residual: Vector3<f64>,
        sigma: Vector3<f64>,
    ) -> Option<f64> {
        self.body_velocity_update_with(r_bs, residual, sigma, Heading::Corrected)
    }

    /// [`Self::body_velocity_update`], with `heading` saying whether it may turn the heading
    /// ([`Heading`]).
    pub fn body_velocity_update_with(
        &mut self,
        r_bs: &Matrix3<f64>,
        residual: Vector3<f64>,
        sigma: Vector3<f64>,
        heading: Heading,
    ) -> Option<f64> {
        self.point_velocity_update(
            r_bs,
            &Vector3::zeros(),
            residual,
            sigma,
            heading,
            MountingYaw::Exact,
        )
    }

    /// The measurement of [`Self::update`] with `H` selecting the three error-state components
    /// from `c` (`H = [0 I 0]`) and isotropic variance `var`, the products with `H` written
    /// out: with `L = P_:c`, `S = P_cc + R` and `K = L S^-1`, the Joseph form
    /// `(I - K H) P (I - K H)^T + K R K^T` is `P - K L^T - L K^T + K S K^T`, computed as
    /// `P - K L^T - D K^T` with `D = L - K S` (zero but for rounding with the optimal gain:
    /// kept, it is what the Joseph form keeps), on the upper triangle and mirrored, with plain
    /// loops over the covariance's contiguous columns (nalgebra's products on its row blocks
    /// copied them out element by element). The zero-velocity and zero-rate updates run at
    /// every rest window. Returns the normalized innovation squared `r^T S^-1 r`.
    fn update_selected(&mut self, c: usize, residual: Vector3<f64>, var: f64) -> Option<f64> {
        self.update_selected_diag(c, residual, &Vector3::repeat(var))
    }

    /// [`Self::update_selected`] with a variance per component.
    fn update_selected_diag(
        &mut self,
        c: usize,
        residual: Vector3<f64>,
        var: &Vector3<f64>,
    ) -> Option<f64> {
        self.propagate();
        let before = self.var;
        let l = SMatrix::<f64, N, 3>::from_fn(|i, j| self.cov[(i, c + j)]);
        let s = l.fixed_rows::<3>(c) + Matrix3::from_diagonal(var);
        let s_inv = s.try_inverse()?;
        let m_c = SMatrix::<f64, NC, 3>::from_fn(|q, a| self.sens[(q, c + a)]);
        let nis = self.nis(&residual, &s, &m_c);
        let k = l * s_inv;
        let d = l - k * s;
        let dx: VecN = k * residual;
        let (ks, ds) = (k.as_slice(), d.as_slice());
        let p = self.cov.as_mut_slice();
        for j in 0..N {
            let col = &mut p[j * N..j * N + j + 1];
            for a in 0..3 {
                let (lj, kj) = (l[(j, a)], k[(j, a)]);
                let (ka, da) = (&ks[a * N..], &ds[a * N..]);
                for (i, x) in col.iter_mut().enumerate() {
                    *x -= ka[i] * lj + da[i] * kj;
                }
            }
        }
        for j in 0..N {
            for i in 0..j {
                p[i * N + j] = p[j * N + i];
            }
        }
        // `M <- M - K M_c:`, on `M^T`'s columns: `M^T[:, i] -= sum_a K[i, a] M^T[:, c + a]`.
        let m = self.sens.as_mut_slice();
        for i in 0..N {
            let col = &mut m[i * NC..(i + 1) * NC];
            for a in 0..3 {
                let f = k[(i, a)];
                for (x, y) in col.iter_mut().zip(m_c.column(a).iter()) {
                    *x -= f * y;
                }
            }
        }
        self.inject(&dx);
        self.reported.updated(&before, &self.var);
        Some(nis)
    }

    /// A linear measurement `z = H dx + noise` of `D` components with noise covariance `r`,
    /// in Joseph form, injected into the nominal state. With [`Heading::Kept`] the gain's
    /// heading component (the attitude error's part about the navigation frame's up, `u =
    /// R^T z` in the local attitude error) and the gyro bias's about the same axis (the
    /// heading's rate) are taken out: the Joseph form
    /// `(I - K H) P (I - K H)^T + K R K^T` is the covariance of any gain's estimate (Gelb
    /// 1974, section 4.2), so the covariance stays that of what is done, and the heading
    /// keeps its variance (a Schmidt, "consider", treatment of the heading). Returns the
    /// normalized innovation squared.
    fn update<const D: usize>(
        &mut self,
        h: &SMatrix<f64, D, N>,
        residual: SVector<f64, D>,
        r: &SMatrix<f64, D, D>,
        heading: Heading,
    ) -> Option<f64> {
        self.propagate();
        let before = self.var;
        let s = h * self.cov * h.transpose() + r;
        let s_inv = s.try_inverse()?;
        let g = self.sens * h.transpose();
        let nis = self.nis(&residual, &s, &g);
        let mut k = self.cov * h.transpose() * s_inv;
        if heading == Heading::Kept {
            let u = self.x.q.inverse_transform_vector(&Vector3::z());
            for block in [TH, BG] {
                let mut rows = k.fixed_rows_mut::<3>(block);
                let along_up = u.transpose() * &rows;
                rows -= u * along_up;
            }
        }
        let dx: VecN = k * residual;
        let i_kh = Cov::identity() - k * h;
        self.cov = i_kh * self.cov * i_kh.transpose() + k * r * k.transpose();
        self.cov = 0.5 * (self.cov + self.cov.transpose());
        self.sens -= g * k.transpose();
        self.inject(&dx);
        self.reported.updated(&before, &self.var);
        Some(nis)
    }

    fn inject(&mut self, dx: &VecN) {
        self.x.p += dx.fixed_rows::<3>(P);
        self.x.v += dx.fixed_rows::<3>(V);
        self.x.q *= UnitQuaternion::from_scaled_axis(dx.fixed_rows::<3>(TH).into_owned());
        self.x.b_a += dx.fixed_rows::<3>(BA);
        self.x.b_g += dx.fixed_rows::<3>(BG);
        self.x.k += dx[KS];
        self.x.m += dx[MY];
        self.refresh_sigma();
    }

    /// Variance of error-state component `i` from the consider parameters alone.
    fn consider_variance(&self, i: usize) -> f64 {
        self.sens
            .column(i)
            .iter()
            .zip(self.consider_var.iter())
            .map(|(m, var)| m * m * var)
            .sum()
    }

    /// 1-sigma of position, m, navigation frame: the filter's covariance and the consider
    /// parameters' share as of the last propagation or update, plus the process noise
    /// accumulated since. The transition's effect since (at most one propagation interval) is
    /// left out: computed at every sample it would cost the propagation it saves. The noise is
    /// kept so that at rest, where each propagation comes with the window's updates, the
    /// reported 1-sigma runs between the updated and the predicted one, as a filter updated
    /// at every sample reports, rather than staying at the lower. With the innovation
    /// consistency's share (module `reported`): its extra variance, and the noise since
    /// times its factor. This is the 1-sigma the stage publishes.
    pub fn position_sigma(&self) -> Vector3<f64> {
        let r = &self.reported;
        (self.var.0 + r.position() + self.inc.noise_variance().0 * r.lambda).map(f64::sqrt)
    }

    /// 1-sigma of the accelerometer bias, m/s^2, sensor frame, as of the last propagation or
    /// update (the filter's covariance alone: the consider parameters are not biases).
    pub fn accel_bias_sigma(&self) -> Vector3<f64> {
        Vector3::from_fn(|i, _| self.cov[(BA + i, BA + i)].max(0.0).sqrt())
    }

    /// 1-sigma of the gyro bias, rad/s, sensor frame, as [`Self::accel_bias_sigma`].
    pub fn gyro_bias_sigma(&self) -> Vector3<f64> {
        Vector3::from_fn(|i, _| self.cov[(BG + i, BG + i)].max(0.0).sqrt())
    }

    /// 1-sigma of velocity, m/s, navigation frame, as [`Self::position_sigma`].
    pub fn velocity_sigma(&self) -> Vector3<f64> {
        let r = &self.reported;
        (self.var.1 + r.v + self.inc.noise_variance().1 * r.lambda).map(f64::sqrt)
    }

    /// 1-sigma of velocity, m/s, navigation frame, from the filter's covariance alone (the
    /// consider parameters' share included, the innovation consistency's not): what its
    /// gates compare against, so that the published 1-sigma changes no estimate.
    pub fn filter_velocity_sigma(&self) -> Vector3<f64> {
        (self.var.1 + self.inc.noise_variance().1).map(f64::sqrt)
    }
}

/// Initial state and covariance from a rest interval: `f_mean` and `w_mean` are the mean
/// specific force (m/s^2) and angular rate (rad/s) over `n` samples at rest, sensor frame.
///
/// Roll and pitch come from the direction of `f_mean`; heading is zero. The vertical accelerometer
/// bias is observable here (|f_mean| against the known `g`) and is estimated; the horizontal bias
/// is not (it is indistinguishable from tilt), so the covariance correlates tilt and horizontal
/// bias exactly as the alignment equations do: `dtheta = u x db_a / g` with `u` the measured up
/// direction. Once the heading changes, later zero-velocity updates separate the two.
pub fn align(
    f_mean: Vector3<f64>,
    w_mean: Vector3<f64>,
    g: f64,
    accel_bias_sigma: Vector3<f64>,
    gyro_bias_sigma_after_rest: Vector3<f64>,
) -> (Nominal, Cov) {
    let up = Vector3::z();
    let u = f_mean.normalize();
    let q = UnitQuaternion::rotation_between(&u, &up)
        .unwrap_or_else(|| UnitQuaternion::from_scaled_axis(Vector3::x() * std::f64::consts::PI));
    // Vertical bias: the part of |f| that is not gravity, along the measured up direction.
    let b_a = u * (f_mean.norm() - g);
    let x = Nominal {
        p: Vector3::zeros(),
        v: Vector3::zeros(),
        q,
        b_a,
        b_g: w_mean,
        k: 0.0,
        m: 0.0,
    };

    // Horizontal bias uncertainty (sensor frame), with the vertical component removed: that part
    // is measured above.
    let proj = Matrix3::identity() - u * u.transpose();
    let sigma_ba = Matrix3::from_diagonal(&accel_bias_sigma.map(|s| s * s));
    let cov_ba = proj * sigma_ba * proj.transpose();
    // Tilt error follows from the bias error: dtheta = skew(u) * db_a / g (local frame).
    let j = skew(&u) / g;
    let mut cov = Cov::zeros();
    cov.fixed_view_mut::<3, 3>(BA, BA).copy_from(&cov_ba);
    cov.fixed_view_mut::<3, 3>(TH, TH)
        .copy_from(&(j * cov_ba * j.transpose()));
    let cross = j * cov_ba;
    cov.fixed_view_mut::<3, 3>(TH, BA).copy_from(&cross);
    cov.fixed_view_mut::<3, 3>(BA, TH)
        .copy_from(&cross.transpose());
    // Heading is defined as zero: no uncertainty about the frame we chose, but keep the matrix
    // positive definite with a tiny variance.
    cov[(TH + 2, TH + 2)] += 1e-12;
    cov.fixed_view_mut::<3, 3>(BG, BG)
        .copy_from(&Matrix3::from_diagonal(
            &gyro_bias_sigma_after_rest.map(|s| s * s),
        ));
    // The wheel-speed scale error keeps variance 0 here (no speed source is known to the
    // alignment); a user of speed updates sets its prior at `cov[(KS, KS)]`.
    // Velocity and position are exactly zero at rest; a small variance keeps S invertible.
    for i in 0..6 {
        cov[(i, i)] = 1e-12;
    }
    (x, cov)
}

#[cfg(test)]
pub(crate) mod tests;
