//! Alignment on a steady cruise, for a wheeled robot that starts in motion, and the forward
//! axis from the speed hints' changes when the mounting is not given.
//!
//! A cruise window: the filter is not aligned, the IMU's detector flags the sample still (no
//! acceleration and no rotation beyond its noise: on a wheeled robot, straight driving at a
//! constant speed), and a fresh speed hint from a source that knows about rest (encoders or
//! commands, `hint_flags::SOURCE_*`) says the robot moves at [`MIN_SPEED_MPS`] or more, within
//! the hints' noise band of the window's other hints ([`CruiseWindow::push`]). After `OdometryConfig::align_s` of such samples
//! the filter aligns as on a rest (roll and pitch from the mean specific force, the gyro bias
//! from the mean rate), with what a cruise is not assumed away but carried in the sigmas:
//! - the window's mean acceleration along the road (its hints' speed slope and that slope's
//!   1-sigma) and
//!   across it (the speed times the rate the gyro's mean cannot tell from bias) is
//!   indistinguishable from a horizontal accelerometer bias: it is added to the bias sigma
//!   the alignment turns into its tilt sigma;
//! - a turn slower than the gyro mean's own 1-sigma is not seen: the gyro bias sigma is the
//!   rest's times `sqrt(2)` (such a turn and the noise, in quadrature);
//! - a mean rate beyond a MEMS gyro's turn-on bias on any axis ([`MAX_TURN_ON_BIAS_RPS`]) is a
//!   turn the detector did not see (its noise learned in motion, on a robot that drove off at
//!   once), not a bias ([`CruiseWindow::turning`]): the gyro bias starts at zero with the
//!   turn-on bias as its 1-sigma, and the turn's centripetal acceleration is taken out of the
//!   mean specific force before it gives the tilt ([`centripetal`]). Its error (the bias's
//!   share of the rate, the speed band's, and without a mounting the direction's) joins what
//!   the window hides.
//!
//! Frames and signs as in [`crate::hints`]: body x forward, y left, z up; `R_bs` sensor to
//! body; navigation frame z up, heading fixed at alignment. The velocity starts from the hint's
//! speed along body x when the mounting is known (`--mount`): forward 1-sigma the hint's own,
//! its scale error's and half the window's speed spread, in quadrature; lateral and vertical
//! the non-holonomic 1-sigma. When the mounting is not known the direction of travel is not:
//! the horizontal velocity starts at zero with a 1-sigma per axis of the largest speed of the
//! window (covering any direction), vertical the non-holonomic 1-sigma, and the speed hints wait
//! for the forward axis ([`ForwardAxis`]). No zero-velocity update comes from a
//! cruise window.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::config::OdometryConfig;
use crate::eskf::{BA, Cov, KS, Nominal, Refinement, RefinementMean, TH, V, align};
use crate::hints::{ForwardFit, HintConfig, mounting_from};
use crate::rest_noise::RestNoise;
use crate::uncalibrated::AccelPrior;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Slowest hint speed a cruise window takes, m/s (below it, a hint's noise is the speed).
pub const MIN_SPEED_MPS: f64 = 0.1;
/// Smallest band (max minus min) the hint speeds of one cruise window may spread over, m/s.
pub const STEADY_MPS: f64 = 0.15;
/// Largest least-squares slope of the hint speeds over a cruise window, m/s^2 (an
/// acceleration hidden in the mean specific force tilts the alignment by `a / g`: 0.9 deg).
pub const MAX_ACCEL_MPS2: f64 = 0.15;
/// Largest gyro bias a cruise window's mean rate is taken for, per axis, rad/s (5 deg/s): the
/// MPU-9250's initial zero-rate output tolerance at 25 C (InvenSense PS-MPU-9250A-01 rev. 1.0,
/// table 1, "Initial ZRO Tolerance": +-5 deg/s). A larger mean is a turn: on the F1TENTH car
/// of docs/real-data.md (f1tenth-ds5), whose BMI160 reads -0.4 deg/s about up standing, a
/// window taken in a turn the detector flagged still read -55 deg/s (raw), and the filter that
/// took it for bias turned its heading at 65 deg/s against the gyro's.
pub const MAX_TURN_ON_BIAS_RPS: f64 = 5.0 * core::f64::consts::PI / 180.0;

/// Whether the rate `w` (rad/s, without the calibration stage's refinements) exceeds
/// [`MAX_TURN_ON_BIAS_RPS`] on an axis: a turn, not a bias.
pub fn beyond_turn_on_bias(w: &Vector3<f64>) -> bool {
    w.amax() > MAX_TURN_ON_BIAS_RPS
}

/// 1-sigma of a gyro's turn-on bias, rad/s: [`MAX_TURN_ON_BIAS_RPS`] as a uniform bound (GUM,
/// JCGM 100:2008, 4.3.7).
pub fn turn_on_bias_sigma_rps() -> f64 {
    MAX_TURN_ON_BIAS_RPS / 3f64.sqrt()
}
/// Intervals the forward-axis estimate gathers before use, the least excitation it takes (3 s
/// at one per half second; the 1-sigma's upper confidence bound, [`ForwardAxis`], covers what
/// few intervals leave unknown).
pub const FORWARD_MIN_INTERVALS: u32 = 6;
/// Largest 1-sigma of the forward-axis fit's direction for use, rad (10 degrees); the speed
/// hints' lateral 1-sigma then covers it ([`ForwardAxis`]).
pub const FORWARD_MAX_SIGMA_RAD: f64 = 0.175;
/// Shortest interval between two speed hints the forward-axis estimate compares, s.
pub const FORWARD_INTERVAL_S: f64 = 0.5;
/// Confidence of the upper bound on the forward-axis fit's residual variance.
const CONFIDENCE: f64 = 0.95;

/// The cruise window being gathered.
#[derive(Debug, Clone, Copy, Default)]
pub struct CruiseWindow {
    /// Time of its first sample, ns.
    pub t0_ns: u64,
    /// Specific force, m/s^2, sensor frame.
    pub accel: RestNoise,
    /// Rate, rad/s, sensor frame.
    pub gyro: RestNoise,
    /// Smallest hint speed, m/s.
    pub speed_min: f64,
    /// Largest hint speed, m/s.
    pub speed_max: f64,
    /// Sums for the mean speed and its least-squares slope over time (`t` s from `t0_ns`,
    /// speeds m/s): `n`, `t`, `t^2`, `s`, `t s`; and the hint 1-sigmas' sum.
    sums: [f64; 5],
    sigma_sum: f64,
    /// Sum of the hint speed times the rate, m/s * rad/s, sensor frame: the centripetal
    /// acceleration's `w x v` summed, but for the forward axis ([`centripetal`]).
    speed_rate: Vector3<f64>,
    /// The calibration stage's refinements made in motion that the samples carry (their mean
    /// is added back where the window is a turn: [`CruiseWindow::turning`]).
    motion: RefinementMean,
    /// A sample of the window was flagged `GRAVITY_OFF` (the calibration stage found the part
    /// reading gravity off: `crate::uncalibrated`).
    pub gravity_off: bool,
}

impl CruiseWindow {
    /// Adds a sample (specific force `f`, rate `w`, carrying the stage's refinements made in
    /// motion `motion`) with the hint speed `speed` (1-sigma `sigma`); a speed outside the
    /// window's band (its smallest and largest speed at most [`STEADY_MPS`] or six hint
    /// 1-sigmas apart: the hints' own noise) starts a new window with it.
    pub fn push(
        &mut self,
        t_ns: u64,
        f: &Vector3<f64>,
        w: &Vector3<f64>,
        motion: &Refinement,
        speed: f64,
        sigma: f64,
    ) {
        let band = STEADY_MPS.max(6.0 * sigma);
        let steady = speed.max(self.speed_max) - speed.min(self.speed_min) <= band;
        if self.accel.is_empty() || !steady {
            *self = Self {
                t0_ns: t_ns,
                speed_min: speed,
                speed_max: speed,
                ..Self::default()
            };
        }
        self.accel.push(*f);
        self.gyro.push(*w);
        self.speed_min = self.speed_min.min(speed);
        self.speed_max = self.speed_max.max(speed);
        let t = self.span_s(t_ns);
        for (sum, x) in self.sums.iter_mut().zip([1.0, t, t * t, speed, t * speed]) {
            *sum += x;
        }
        self.sigma_sum += sigma;
        self.speed_rate += (w + motion.gyro) * speed;
        self.motion.push(*motion);
    }

    /// The mean specific force (m/s^2) and rate (rad/s) without the stage's refinements made
    /// in motion.
    fn unrefined(&self) -> (Vector3<f64>, Vector3<f64>) {
        let m = self.motion.mean().unwrap_or_default();
        (self.accel.mean() + m.accel, self.gyro.mean() + m.gyro)
    }

    /// The window's span at `t_ns`, s.
    pub fn span_s(&self, t_ns: u64) -> f64 {
        t_ns.saturating_sub(self.t0_ns) as f64 * 1e-9
    }

    /// Mean hint speed and mean hint 1-sigma, m/s.
    pub fn speed(&self) -> (f64, f64) {
        let n = self.sums[0].max(1.0);
        (self.sums[3] / n, self.sigma_sum / n)
    }

    /// The least-squares slope of the hint speeds over the window and its 1-sigma (from the
    /// hints' mean 1-sigma), m/s^2; `None` with fewer than two distinct times.
    pub fn slope(&self) -> Option<(f64, f64)> {
        let [n, t, tt, s, ts] = self.sums;
        let sxx = tt - t * t / n;
        if n < 2.0 || sxx <= 0.0 {
            return None;
        }
        let (_, sigma) = self.speed();
        Some(((ts - t * s / n) / sxx, sigma / sxx.sqrt()))
    }

    /// Whether the window's speed slope is at most [`MAX_ACCEL_MPS2`].
    pub fn steady(&self) -> bool {
        self.slope().is_some_and(|(a, _)| a.abs() <= MAX_ACCEL_MPS2)
    }

    /// Whether the window's mean rate, without the stage's refinements made in motion, exceeds
    /// [`MAX_TURN_ON_BIAS_RPS`] on an axis: a turn, not a bias (module documentation).
    pub fn turning(&self) -> bool {
        beyond_turn_on_bias(&self.unrefined().1)
    }

    /// The acceleration the window may hide, m/s^2: along the road its speed slope plus that
    /// slope's 1-sigma, across it the largest speed times the rate `w` (rad/s).
    pub fn hidden_accel(&self, w: &Vector3<f64>) -> f64 {
        let along = self.slope().map_or(0.0, |(a, s)| a.abs() + s);
        along.hypot(self.speed_max * w.norm())
    }
}

/// The initial velocity (navigation frame, m/s) and its covariance after a cruise window of
/// mean speed `speed` (1-sigma `forward_sigma`), with the mounting `r_bs` when known and the
/// attitude `q` (sensor to navigation); `lateral_sigma` for the non-holonomic directions,
/// `speed_max` the window's largest speed (see the module documentation).
pub fn initial_velocity(
    q: &UnitQuaternion<f64>,
    r_bs: Option<&Matrix3<f64>>,
    speed: f64,
    forward_sigma: f64,
    lateral_sigma: f64,
    speed_max: f64,
) -> (Vector3<f64>, Matrix3<f64>) {
    match r_bs {
        Some(r_bs) => {
            // Columns: the body axes in the navigation frame.
            let r_nb = q.to_rotation_matrix().into_inner() * r_bs.transpose();
            let var = Vector3::new(forward_sigma, lateral_sigma, lateral_sigma).map(|s| s * s);
            let v = r_nb * Vector3::new(speed, 0.0, 0.0);
            (v, r_nb * Matrix3::from_diagonal(&var) * r_nb.transpose())
        }
        None => {
            let h = speed_max * speed_max;
            let var = Vector3::new(h, h, lateral_sigma * lateral_sigma);
            (Vector3::zeros(), Matrix3::from_diagonal(&var))
        }
    }
}

/// The filter's start from a cruise window.
pub struct CruiseStart {
    /// Initial state.
    pub x: Nominal,
    /// Its covariance.
    pub cov: Cov,
    /// The standing spread of the specific force's norm the vibration check compares against,
    /// m/s^2: none was seen, so the noise model's white noise over the band the window's rate
    /// passes (Nyquist), all three axes.
    pub standing_accel_sd: f64,
}

/// The initial state and covariance from the cruise window `c` of `span_s` seconds (see the
/// module documentation for what is assumed and how the sigmas carry it), with the mounting
/// `r_bs` when known and the accelerometer bias prior of `prior` (as at a rest); `motion` is
/// the stage's refinement made in motion that the stream carries from here (a turning
/// window's biases are put in its terms).
pub fn cruise_start(
    c: &CruiseWindow,
    span_s: f64,
    cfg: &OdometryConfig,
    hints: &HintConfig,
    r_bs: Option<Matrix3<f64>>,
    prior: &AccelPrior,
    motion: &Refinement,
) -> CruiseStart {
    let n = c.accel.len() as f64;
    let g = cfg.gravity_mps2;
    let turning = c.turning();
    let (f_up, w_bias, w_sigma, hidden) = if turning {
        // The bias is the part's turn-on bias, and the whole mean rate turns the velocity.
        let (a_c, a_c_sigma) = centripetal(c, r_bs.as_ref(), g);
        let hidden = c.hidden_accel(&Vector3::zeros()).hypot(a_c_sigma);
        let w_sigma = Vector3::repeat(turn_on_bias_sigma_rps());
        (c.unrefined().0 - a_c, Vector3::zeros(), w_sigma, hidden)
    } else {
        // A turn as slow as the mean's own 1-sigma is not seen: in quadrature with it.
        let w_sigma = (c.gyro.mean_variance(cfg.effective_samples) * 2.0).map(f64::sqrt);
        let hidden = c.hidden_accel(&w_sigma);
        (c.accel.mean(), c.gyro.mean(), w_sigma, hidden)
    };
    let bias_sigma = prior.bias_sigma_mps2.map(|s| s.hypot(hidden));
    let (mut x, mut cov) = align(f_up, w_bias, g, bias_sigma, w_sigma);
    if turning {
        // Aligned without the stage's refinements made in motion; the stream carries them.
        x.b_a -= motion.accel;
        x.b_g -= motion.gyro;
    }
    cov[(KS, KS)] = hints.speed_scale_sigma.powi(2);
    let (speed, hint_sigma) = c.speed();
    let forward_sigma = hint_sigma
        .hypot(speed * hints.speed_scale_sigma)
        .hypot((c.speed_max - c.speed_min) / 2.0);
    let (v, v_cov) = initial_velocity(
        &x.q,
        r_bs.as_ref(),
        speed,
        forward_sigma,
        hints.nonholonomic_sigma_mps,
        c.speed_max + hint_sigma,
    );
    x.v = v;
    cov.fixed_view_mut::<3, 3>(V, V).copy_from(&v_cov);
    let rate_hz = (n - 1.0) / span_s;
    CruiseStart {
        x,
        cov,
        standing_accel_sd: cfg.noise.accel_noise_density * (1.5 * rate_hz).sqrt(),
    }
}

/// The mean centripetal acceleration of the turning window `c` and its 1-sigma, m/s^2, sensor
/// frame. A platform turning at `w` while it moves at `v = s x_f` (`x_f` its forward axis)
/// feels `w x v` besides gravity; the window's mean is `(mean of s w) x x_f` (the speed within
/// its band). With the mounting `r_bs` known, `x_f` is its first row. Without it, a wheeled
/// platform turns about up, so the acceleration is perpendicular to the mean rate, of magnitude
/// `|mean of s w|`, and it points along the part of the mean specific force perpendicular to
/// the rate: gravity's share there, up to `g` times the angle a turn-on bias (its 1-sigma,
/// [`turn_on_bias_sigma_rps`]) tilts the rate from up, turns it, and that error (at most the
/// acceleration's twice) is carried. Both carry the bias's share of the rate (at most
/// [`MAX_TURN_ON_BIAS_RPS`]) times the largest speed and the speed band times the rate.
pub fn centripetal(c: &CruiseWindow, r_bs: Option<&Matrix3<f64>>, g: f64) -> (Vector3<f64>, f64) {
    let n = c.accel.len().max(1) as f64;
    let sw = c.speed_rate / n;
    let (f, w) = c.unrefined();
    let common = (c.speed_max * MAX_TURN_ON_BIAS_RPS).hypot((c.speed_max - c.speed_min) * w.norm());
    match r_bs {
        Some(r_bs) => (sw.cross(&r_bs.row(0).transpose()), common),
        None => {
            let w_hat = w.normalize();
            let across = f - w_hat * f.dot(&w_hat);
            let a_c = across
                .try_normalize(1e-9)
                .map_or(Vector3::zeros(), |d| d * sw.norm());
            let leak = (g * turn_on_bias_sigma_rps() / w.norm()).min(2.0 * sw.norm());
            (a_c, common.hypot(leak))
        }
    }
}

/// The forward axis in the sensor frame from the horizontal specific force and the speed
/// hints. A wheeled robot that does not skid accelerates along its forward axis `x` by the
/// speed's rate `ds/dt` and towards its left axis `y = z x x` by the centripetal `s w_z`
/// (`w_z` the yaw rate about body up; standard planar vehicle kinematics, e.g. Gillespie,
/// "Fundamentals of Vehicle Dynamics", SAE 1992, ch. 6): in the horizontal plane of the sensor
/// frame, written as complex numbers on a basis `(e1, e2)` with `e1 x e2 = up`, the mean
/// horizontal specific force over an interval is `A = F (ds/dt + i s w_z)` with `F` the forward
/// axis. The least-squares `F = sum(A conj(B)) / sum(|B|^2)`, `B = ds/dt + i s w_z`, keeps the
/// sign (a displacement cannot tell forward from reverse) and does not depend on the filter's
/// velocity, which a start in motion leaves unknown. The fit has no intercept: a robot turning
/// steadily has a constant `B`, which an intercept (a constant horizontal bias) would take
/// away (with one, the Husky recording of the corpus, turning about a parking lot, was not
/// trusted for 250 s). Intervals run between speed hints at least [`FORWARD_INTERVAL_S`]
/// apart.
///
/// The direction's 1-sigma is the fit's: the residuals' variance per component (their sum of
/// squares over `2k - 2` degrees of freedom, `k` intervals and one complex unknown) over the
/// excitation `sum|B|^2`, relative to `|F|`. From a few intervals that variance is itself
/// uncertain (the plain estimate from fewer than 60 intervals came out optimistic on the Husky
/// recording), so the 1-sigma used is the one from its one-sided 95 % upper confidence bound
/// (chi-square with `2k - 2` degrees of freedom: the residual sum of squares over the 5 %
/// quantile). The estimate is trusted once it has at least [`FORWARD_MIN_INTERVALS`] intervals
/// and that 1-sigma is at most [`FORWARD_MAX_SIGMA_RAD`]: the excitation it takes is what the
/// residuals say is enough; it is refined at every interval after. The speed hints take a
/// lateral 1-sigma that covers it (`s` times that angle, with the non-holonomic one). `|F|`
/// gives the hints' speed scale, and a bias the residuals cannot show adds a share to both
/// 1-sigmas ([`ForwardFit`]). Body z is the gravity-up direction
/// (a level floor), taken once, from the filter's attitude at the first sample after alignment
/// (the alignment's measured gravity): the attitude drifts while the speed hints wait for this
/// estimate, and a later up direction would tilt the mounting by that drift (on the F1TENTH
/// car of docs/real-data.md, 5-16 degrees after 30 s of driving on the IMU alone).
#[derive(Debug, Clone, Copy, Default)]
pub struct ForwardAxis {
    /// The filter's up direction and biases, fixed at the first sample.
    reference: Option<Reference>,
    /// Time (ns), speed (m/s) and speed 1-sigma (m/s) of the hint that opened the current
    /// interval.
    anchor: Option<(u64, f64, f64)>,
    /// The current interval's sums: horizontal specific force (sensor frame, m/s^2), rate
    /// about up (rad/s), samples.
    f_sum: Vector3<f64>,
    w_up_sum: f64,
    n: u32,
    /// Basis of the horizontal plane (sensor frame) fixed at the first interval.
    basis: Option<(Vector3<f64>, Vector3<f64>)>,
    /// `sum(A conj B)` as (re, im), `sum |A|^2`, `sum |B|^2`, intervals.
    cross: (f64, f64),
    aa: f64,
    bb: f64,
    intervals: u32,
    /// `sum B` as (re, im): what a horizontal bias left in `A` aliases into the fit.
    b_sum: (f64, f64),
    /// The hints' own noise's share of `sum |B|^2` (their speed 1-sigmas through `ds/dt`).
    bb_noise: f64,
}

/// What [`ForwardAxis`] takes from the filter, once, at the first sample after alignment:
/// later values would bring in the attitude's drift on the IMU alone and, once the speed hints
/// apply along the estimated axis, that axis's own error (through the updates' corrections of
/// the biases).
#[derive(Debug, Clone, Copy)]
pub struct Reference {
    /// Body up in the sensor frame (unit).
    pub up: Vector3<f64>,
    /// Accelerometer bias, sensor frame, m/s^2.
    pub accel_bias: Vector3<f64>,
    /// Gyro bias, sensor frame, rad/s.
    pub gyro_bias: Vector3<f64>,
    /// 1-sigma per horizontal axis of the specific force that the reference leaves after
    /// taking away gravity and the bias, m/s^2: the filter's tilt and accelerometer bias
    /// uncertainty ([`horizontal_bias_sigma`]) with a floor slope of [`FLOOR_SLOPE_RAD`].
    pub horizontal_sigma_mps2: f64,
}

/// 1-sigma of the floor's slope under a wheeled robot, rad: 1:48 (1.2 deg), the steepest a
/// parking space or a wheelchair turning space may be (2010 ADA Standards for
/// Accessible Design, 502.4 and 304.2); a robot that turns on a slope sees `g` times it in
/// its horizontal specific force, which the forward-axis fit cannot tell from a bias.
pub const FLOOR_SLOPE_RAD: f64 = 1.0 / 48.0;

/// The [`Reference::horizontal_sigma_mps2`] of a filter with covariance `cov` (error state:
/// attitude at [`TH`] in the navigation frame, accelerometer bias at [`BA`] in the sensor
/// frame), attitude `q` (sensor to navigation) and gravity `g` (m/s^2). A navigation-frame
/// tilt error `d` leaves `g (z x d) = g (-d_y, d_x)` of gravity in the horizontal specific
/// force, the bias error `R db` its horizontal part; their variance (cross terms included:
/// an alignment makes them cancel), per axis, with the floor's slope in quadrature.
pub fn horizontal_bias_sigma(cov: &Cov, q: &UnitQuaternion<f64>, g: f64) -> f64 {
    let r = q.to_rotation_matrix().into_inner();
    let mut j = nalgebra::SMatrix::<f64, 2, 6>::zeros();
    (j[(0, 1)], j[(1, 0)]) = (-g, g);
    j.fixed_view_mut::<2, 3>(0, 3)
        .copy_from(&r.fixed_view::<2, 3>(0, 0));
    let mut p = nalgebra::SMatrix::<f64, 6, 6>::zeros();
    for (a, ia) in [(0, TH), (3, BA)] {
        for (b, ib) in [(0, TH), (3, BA)] {
            p.fixed_view_mut::<3, 3>(a, b)
                .copy_from(&cov.fixed_view::<3, 3>(ia, ib));
        }
    }
    let var = (j * p * j.transpose()).trace() / 2.0;
    var.max(0.0).sqrt().hypot(g * FLOOR_SLOPE_RAD)
}

impl ForwardAxis {
    /// Whether the reference was taken (the first sample or hint after alignment).
    pub fn has_reference(&self) -> bool {
        self.reference.is_some()
    }

    /// Adds a sample's specific force `f_s` (m/s^2) and rate `w_s` (rad/s), sensor frame, with
    /// the filter's reference `r` (only the first one given is used).
    pub fn sample(&mut self, f_s: &Vector3<f64>, w_s: &Vector3<f64>, r: &Reference) {
        let r = *self.reference.get_or_insert(*r);
        if self.anchor.is_none() {
            return;
        }
        let f_s = f_s - r.accel_bias;
        self.f_sum += f_s - r.up * r.up.dot(&f_s);
        self.w_up_sum += (w_s - r.gyro_bias).dot(&r.up);
        self.n += 1;
    }

    /// Takes a speed hint of `speed` m/s (1-sigma `sigma`) at `t_ns` with the filter's
    /// reference `r` (only the first one given is used, as in [`Self::sample`]); returns the
    /// fit when this hint closed an interval and the fit is trusted (see the type's
    /// documentation).
    pub fn hint(&mut self, t_ns: u64, speed: f64, sigma: f64, r: &Reference) -> Option<ForwardFit> {
        let reference = *self.reference.get_or_insert(*r);
        let up_s = reference.up;
        let Some((t0, s0, sigma0)) = self.anchor else {
            self.anchor = Some((t_ns, speed, sigma));
            return None;
        };
        let dt = t_ns.saturating_sub(t0) as f64 * 1e-9;
        if dt < FORWARD_INTERVAL_S {
            return None;
        }
        let n = f64::from(self.n.max(1));
        let (f, w_up) = (self.f_sum / n, self.w_up_sum / n);
        let had = self.n > 0;
        *self = Self {
            anchor: Some((t_ns, speed, sigma)),
            ..*self
        };
        (self.f_sum, self.w_up_sum, self.n) = (Vector3::zeros(), 0.0, 0);
        if !had {
            return None;
        }
        let (e1, e2) = *self.basis.get_or_insert_with(|| horizontal_basis(&up_s));
        let a = (f.dot(&e1), f.dot(&e2));
        let b = ((speed - s0) / dt, 0.5 * (speed + s0) * w_up);
        // A conj(B).
        self.cross.0 += a.0 * b.0 + a.1 * b.1;
        self.cross.1 += a.1 * b.0 - a.0 * b.1;
        self.aa += a.0 * a.0 + a.1 * a.1;
        self.bb += b.0 * b.0 + b.1 * b.1;
        self.b_sum = (self.b_sum.0 + b.0, self.b_sum.1 + b.1);
        self.bb_noise += (sigma * sigma + sigma0 * sigma0) / (dt * dt);
        self.intervals += 1;
        let sigma = self.angle_sigma_rad();
        if self.intervals < FORWARD_MIN_INTERVALS || sigma > FORWARD_MAX_SIGMA_RAD {
            return None;
        }
        let forward = e1 * self.cross.0 + e2 * self.cross.1;
        let mounting = mounting_from(&forward, &up_s)?;
        Some(self.fit(mounting, sigma, reference.horizontal_sigma_mps2))
    }

    /// The trusted fit's scale and bias share (see [`ForwardFit`]), with the fit's direction
    /// 1-sigma `sigma` (rad) and the reference's horizontal bias 1-sigma `bias` (m/s^2).
    ///
    /// A bias `b` in every `A` moves the estimate by `b sum(conj B) / sum|B|^2`: relative to
    /// `|F|`, `bias |sum B| / (sum|B|^2 |F|)` per component. The scale comes from `|F|`, whose
    /// relative 1-sigma per component is the direction's (`sigma`, the bias share in
    /// quadrature), and `k = 1 / |F| - 1` has 1-sigma `(1 + k)` times that. Noise in the
    /// regressor `B` (the hints' speed 1-sigmas through `ds/dt`) would shrink `|F|` by the
    /// share of `sum|B|^2` it makes (regression dilution; W. A. Fuller, "Measurement Error
    /// Models", Wiley 1987, sec. 1.1): it is taken away from `sum|B|^2`, and with half or
    /// more of it noise no scale is given.
    fn fit(&self, mounting: UnitQuaternion<f64>, sigma: f64, bias: f64) -> ForwardFit {
        let cross = self.cross.0.hypot(self.cross.1);
        let f_norm = cross / self.bb;
        let b_sum = self.b_sum.0.hypot(self.b_sum.1);
        let bias_sigma_rad = bias * b_sum / (self.bb * f_norm);
        let signal = self.bb - self.bb_noise;
        let scale = (signal > 0.5 * self.bb).then(|| signal / cross - 1.0);
        let relative = sigma.hypot(bias_sigma_rad);
        ForwardFit {
            mounting,
            sigma_rad: sigma,
            bias_sigma_rad,
            scale,
            scale_sigma: (1.0 + scale.unwrap_or(0.0)) * relative,
        }
    }
}

impl ForwardAxis {
    /// 1-sigma of the fit's direction, rad (see the type's documentation): the residual sum of
    /// squares `sum|A|^2 - |sum A conj B|^2 / sum|B|^2` over its chi-square 5 % quantile
    /// (`2k - 2` degrees of freedom), per component, over `sum|B|^2`, square-rooted, relative
    /// to `|F|`; infinite before two intervals.
    fn angle_sigma_rad(&self) -> f64 {
        let k = f64::from(self.intervals);
        let cross2 = self.cross.0 * self.cross.0 + self.cross.1 * self.cross.1;
        let dof = 2.0 * k - 2.0;
        let Some(chi2) = ChiSquared::new(dof)
            .ok()
            .filter(|_| self.bb > 0.0 && cross2 > 0.0)
        else {
            return f64::INFINITY;
        };
        let residual = (self.aa - cross2 / self.bb).max(0.0) / chi2.inverse_cdf(1.0 - CONFIDENCE);
        let f_norm = cross2.sqrt() / self.bb;
        (residual / self.bb).sqrt() / f_norm
    }
}

/// Two unit vectors spanning the plane normal to `up` with `e1 x e2 = up`.
fn horizontal_basis(up: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let i = up.iamin();
    let any = Vector3::from_fn(|r, _| if r == i { 1.0 } else { 0.0 });
    let e1 = (any - up * up.dot(&any)).normalize();
    (e1, up.cross(&e1))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fit on a robot (IMU mounted +y up, -z forward, -x left: the Husky's) slowing down
    /// and turning both ways, 0.5 s between hints, 10 samples each, whose hints read `gain`
    /// times its speed; a horizontal bias `bias` (sensor frame, m/s^2) on every sample.
    fn fit_on_a_drive(gain: f64, bias: Vector3<f64>) -> (ForwardFit, UnitQuaternion<f64>) {
        let (fwd_s, up_s) = (Vector3::new(0.0, 0.0, -1.0), Vector3::new(0.0, 1.0, 0.0));
        let left_s = up_s.cross(&fwd_s);
        let truth = mounting_from(&fwd_s, &up_s).unwrap();
        let mut est = ForwardAxis::default();
        let r = Reference {
            up: up_s,
            accel_bias: Vector3::zeros(),
            gyro_bias: Vector3::zeros(),
            horizontal_sigma_mps2: bias.norm(),
        };
        let mut got = None;
        for k in 0..80 {
            let t = f64::from(k) * 0.5;
            let (speed, accel, yaw_rate) = (1.5 - 0.02 * t, -0.02, 0.3 * (0.4 * t).sin());
            // Over the interval that this hint opens: the mean speed is the mid-interval one.
            let mid = speed - 0.02 * 0.25;
            let f = fwd_s * accel + left_s * mid * yaw_rate + up_s * 9.81 + bias;
            got = est.hint((t * 1e9) as u64, gain * speed, 0.0, &r).or(got);
            for _ in 0..10 {
                est.sample(&f, &(up_s * yaw_rate), &r);
            }
        }
        (got.unwrap(), truth)
    }

    #[test]
    fn forward_axis_from_speed_changes_and_turns_keeps_its_sign() {
        let (fit, truth) = fit_on_a_drive(1.0, Vector3::zeros());
        let (q, sigma) = (fit.mounting, fit.sigma_rad);
        assert!(q.angle_to(&truth) < 0.01 && sigma < 0.01, "{q:?} {sigma}");
        assert!(fit.scale.unwrap().abs() < 0.01, "{fit:?}");
    }

    #[test]
    fn hints_reading_high_show_their_scale() {
        let (fit, _) = fit_on_a_drive(1.3, Vector3::zeros());
        let k = fit.scale.unwrap();
        assert!((k - 0.3).abs() < 0.01 && fit.scale_sigma < 0.02, "{fit:?}");
    }

    #[test]
    fn a_horizontal_bias_is_carried_in_the_systematic_sigma() {
        // 0.05 m/s^2 along the left axis, which the steady part of the turns aliases.
        let bias = Vector3::new(-0.05, 0.0, 0.0);
        let (fit, truth) = fit_on_a_drive(1.0, bias);
        let (clean, _) = fit_on_a_drive(1.0, Vector3::zeros());
        let error = fit.mounting.angle_to(&truth);
        assert!(fit.bias_sigma_rad > clean.bias_sigma_rad, "{fit:?}");
        assert!(error <= 2.0 * fit.systematic_sigma_rad(), "{error} {fit:?}");
        let k_error = fit.scale.unwrap().abs();
        assert!(k_error <= 2.0 * fit.scale_sigma, "{k_error} {fit:?}");
    }

    #[test]
    fn unknown_direction_is_covered_by_the_speed() {
        let q = UnitQuaternion::identity();
        let (v, cov) = initial_velocity(&q, None, 1.0, 0.05, 0.02, 1.1);
        assert_eq!(v, Vector3::zeros());
        assert!((cov[(0, 0)].sqrt() - 1.1).abs() < 1e-12 && cov[(2, 2)].sqrt() < 0.03);
        let r_bs = Matrix3::identity();
        let (v, cov) = initial_velocity(&q, Some(&r_bs), 1.0, 0.05, 0.02, 1.1);
        assert!((v - Vector3::x()).norm() < 1e-12 && (cov[(0, 0)].sqrt() - 0.05).abs() < 1e-12);
    }

    /// A window of 1 s at 25 Hz, driving at 1.4 m/s in a steady turn of 60 deg/s about up, the
    /// sensor tilted 4 deg and yawed 90 deg on the body (the F1TENTH car's VESC), no bias: what
    /// the accelerometer reads is gravity and the centripetal `w x v`, computed here from the
    /// body's kinematics.
    fn turning_window() -> (CruiseWindow, Matrix3<f64>, Vector3<f64>) {
        let r_bs = (UnitQuaternion::from_euler_angles(0.04, 0.05, 0.0)
            * UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2))
        .to_rotation_matrix()
        .into_inner();
        let (speed, yaw_rate) = (1.4, 60f64.to_radians());
        // Body frame: up z, forward x; the centripetal points left (+y) in a left turn.
        let f_b = Vector3::new(0.0, speed * yaw_rate, 9.81);
        let w_b = Vector3::new(0.0, 0.0, yaw_rate);
        let (f_s, w_s) = (r_bs.transpose() * f_b, r_bs.transpose() * w_b);
        let mut c = CruiseWindow::default();
        for k in 0..26u64 {
            c.push(
                k * 40_000_000,
                &f_s,
                &w_s,
                &Refinement::default(),
                speed,
                0.02,
            );
        }
        (c, r_bs, r_bs.transpose() * Vector3::z())
    }

    #[test]
    fn a_turning_window_takes_the_centripetal_out_of_the_tilt() {
        use crate::eskf::BG;
        let (c, r_bs, up_s) = turning_window();
        assert!(c.turning());
        let cfg = OdometryConfig::mpu9250(9.81);
        let prior = AccelPrior::at_rest(&cfg, &c.accel.mean(), false);
        let hints = HintConfig::default();
        // The tilt the plain mean would give: the centripetal, 1.47 m/s^2, tilts it 8.5 deg.
        let plain = c.accel.mean().angle(&up_s).to_degrees();
        assert!(plain > 8.0, "{plain}");
        for (r_bs, within_deg) in [(Some(r_bs), 0.01), (None, 0.01)] {
            let start = cruise_start(&c, 1.0, &cfg, &hints, r_bs, &prior, &Refinement::default());
            let up = start.x.q.inverse_transform_vector(&Vector3::z());
            let off = up.angle(&up_s).to_degrees();
            assert!(
                off < within_deg,
                "mounting {}: up {off} deg off",
                r_bs.is_some()
            );
            assert_eq!(start.x.b_g, Vector3::zeros());
            assert!((start.cov[(BG, BG)].sqrt() - turn_on_bias_sigma_rps()).abs() < 1e-12);
        }
    }
}
