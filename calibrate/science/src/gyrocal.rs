//! Gyroscope scale-factor and misalignment calibration from a pose session (the six-position or
//! N-orientation session used for the accelerometer), without external equipment: between two
//! static poses the integrated gyro must rotate gravity's direction, as measured by the
//! accelerometer in the first pose, into its direction in the second pose.
//!
//! Model: the true angular rate is `omega = C (w - b)` (rad/s) with `w` the gyro's reading,
//! `b` its bias and `C` the 3x3 correction (inverse scale and misalignment, identity for a
//! perfect gyro). The bias during each rotation is the mean of the readings in the two static
//! poses around it (the gyro does not rotate there), which follows a slowly drifting bias.
//!
//! The accelerometer's own residual errors would otherwise leak into `C`: a 0.1% scale error
//! bends the measured gravity directions by up to a milliradian, which biases the fitted gyro
//! scale by several times that. So the fit also estimates, as nuisance parameters, the
//! accelerometer's bias `b_a` and a symmetric shape correction `I + S`: the corrected specific
//! force `f = (I + S)(a / g - b_a)` (in g) must have unit magnitude in every static pose. `S`
//! is symmetric because a rotation of the accelerometer frame is invisible to the magnitudes;
//! the frame of `f` is the orthonormal frame closest to the accelerometer's axes, and `C`
//! gives rates in that frame. With `u_i` the direction of `f` in pose `i` and `R_i(C)` the
//! rotation from the pose-`i` frame to the pose-`i+1` frame integrated from the corrected
//! rates, Levenberg-Marquardt minimises `sum_i (|f_i| - 1)^2 + sum_i |u_(i+1) - R_i(C)^T u_i|^2`
//! over the 18 parameters. Each rotation gives two independent direction constraints (a
//! rotation about gravity is invisible to the accelerometer) and each pose one magnitude
//! constraint, so well-spread poses (at least [`MIN_POSES`]) determine all of them.
//!
//! The approach is that of Tedaldi, Pretto and Menegatti, "A robust and easy to implement
//! method for IMU calibration without external equipments" (ICRA 2014), with the two stages
//! fitted jointly; the code is written here on nalgebra and the `levenberg-marquardt` crate.

use ipc_types::{CorrectedImuSample, corrected_flags};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::storage::Owned;
use nalgebra::{DVector, Dyn, Matrix3, OMatrix, SMatrix, SVector, U18, UnitQuaternion, Vector3};

/// Fewest static poses the fit accepts: 18 unknowns, one magnitude and (between consecutive
/// poses) two direction constraints per pose, and redundancy to judge the fit by.
pub const MIN_POSES: usize = 9;

/// Largest condition number of the fit's Jacobian: beyond it the poses and rotation axes do
/// not span enough directions to determine every parameter.
pub const MAX_CONDITION: f64 = 1e4;

/// Number of fitted parameters: `C - I` (9, row-major), `b_a` (3, g), `S` (6: xx, yy, zz,
/// xy, xz, yz).
const PARAMS: usize = 18;
type Params = SVector<f64, PARAMS>;

/// How the session is cut into static poses, and the local gravity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GyroCalConfig {
    /// Local gravity magnitude, m/s^2.
    pub gravity_mps2: f64,
    /// Shortest run of rest-flagged samples that counts as a static pose, s.
    pub min_static_s: f64,
    /// Time left out at both ends of a static pose when averaging it, s (a rest detector's
    /// flags may extend slightly into the motion).
    pub edge_trim_s: f64,
}

impl GyroCalConfig {
    /// Poses of at least 2 s, averaged without their first and last 0.25 s, under gravity
    /// `gravity_mps2` (m/s^2).
    pub fn new(gravity_mps2: f64) -> Self {
        Self {
            gravity_mps2,
            min_static_s: 2.0,
            edge_trim_s: 0.25,
        }
    }
}

/// The fitted gyro correction, with the accelerometer terms fitted alongside it.
#[derive(Debug, Clone, PartialEq)]
pub struct GyroCalibration {
    /// `C` in `omega = C (w - b)`: multiplies bias-free readings (rad/s) and gives rates in
    /// the orthonormal frame closest to the accelerometer's axes.
    pub correction: Matrix3<f64>,
    /// 1-sigma of each entry of `correction`, from the fit's residuals.
    pub correction_sigma: Matrix3<f64>,
    /// The accelerometer's bias in this session, m/s^2, sensor frame (a nuisance parameter
    /// of the fit).
    pub accel_bias_mps2: Vector3<f64>,
    /// The accelerometer's shape correction `I + S` (symmetric, dimensionless): with the bias,
    /// `(I + S)(a - b_a)` has magnitude `g` in every pose.
    pub accel_shape: Matrix3<f64>,
    /// Number of static poses used.
    pub poses: usize,
    /// RMS of the residuals after the fit (directions in rad, magnitudes in g).
    pub residual_rms: f64,
}

/// Why a session cannot calibrate the gyro.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GyroCalError {
    /// A sample the stream contract refuses (not finite, beyond the calibrated bounds, or its
    /// time not after the previous one's): the same check and message as the odometry stage's.
    #[error(transparent)]
    Sample(#[from] ipc_types::stream::SampleError),
    /// Too few static poses.
    #[error(
        "the session has {found} static poses of at least {min_static_s} s; the gyro fit needs \
         at least {MIN_POSES}"
    )]
    TooFewPoses {
        /// Poses found.
        found: usize,
        /// The configured shortest static pose, s.
        min_static_s: f64,
    },
    /// The poses and rotations do not determine every parameter.
    #[error(
        "the poses do not determine the gyro correction (condition number {condition:.3e} > \
         {MAX_CONDITION:e}): hold more varied attitudes and rotate about more varied axes"
    )]
    IllConditioned {
        /// Condition number of the Jacobian at the solution.
        condition: f64,
    },
    /// Levenberg-Marquardt did not converge.
    #[error("the gyro fit did not converge: {0}")]
    NotConverged(String),
}

/// One static pose: sample index range of its averaged core, mean specific force (in g) and
/// mean gyro reading (rad/s).
struct StaticPose {
    first: usize,
    last: usize,
    accel_g: Vector3<f64>,
    gyro_mean: Vector3<f64>,
}

/// The rotation between two consecutive poses: the bias-free trapezoid-mean rate and the time
/// step of every interval between consecutive samples from one pose's core to the next's.
struct Rotation {
    steps: Vec<(Vector3<f64>, f64)>,
}

impl Rotation {
    /// `R(C)`, integrated from `C`-corrected rates (takes vectors from the later pose's frame
    /// to the earlier one's), and the derivative of its rotation vector, expressed in the
    /// later frame, with respect to the entries of `C` (row-major): a 3x9 matrix.
    ///
    /// Perturbing `C` by `dC` perturbs step `j`'s rotation vector by `dC w_j dt_j`, which
    /// reaches the end of the rotation turned by `R_j^T`-to-end: `d(theta) = R_N^T sum_j R_j dC
    /// w_j dt_j` with `R_j` the rotation up to step `j`. (The exponential map's right Jacobian
    /// is taken as the identity: each step turns by well under a degree, and the derivative
    /// only steers the search, while the residuals are exact.)
    fn integrate(&self, c: &Matrix3<f64>) -> (UnitQuaternion<f64>, SMatrix<f64, 3, 9>) {
        let mut q = UnitQuaternion::identity();
        let mut sum = SMatrix::<f64, 3, 9>::zeros();
        for (w, dt) in &self.steps {
            q *= UnitQuaternion::from_scaled_axis(c * w * *dt);
            let r = q.to_rotation_matrix();
            for row in 0..3 {
                for col in 0..3 {
                    let mut column = sum.column_mut(3 * row + col);
                    column += r.matrix().column(row) * (w[col] * *dt);
                }
            }
        }
        let d_theta = q.to_rotation_matrix().matrix().transpose() * sum;
        (q, d_theta)
    }
}

/// Calibrates the gyro from a pose session's samples (accelerometer calibrated as far as it
/// is, rest flags in `flags`' `ZERO_STATE` bit, times strictly increasing).
pub fn calibrate_gyro(
    samples: &[CorrectedImuSample],
    cfg: &GyroCalConfig,
) -> Result<GyroCalibration, GyroCalError> {
    check_samples(samples)?;
    let poses = static_poses(samples, cfg);
    if poses.len() < MIN_POSES {
        return Err(GyroCalError::TooFewPoses {
            found: poses.len(),
            min_static_s: cfg.min_static_s,
        });
    }
    let rotations: Vec<Rotation> = poses
        .windows(2)
        .map(|pair| {
            let bias = 0.5 * (pair[0].gyro_mean + pair[1].gyro_mean);
            let steps = samples[pair[0].last..=pair[1].first]
                .windows(2)
                .map(|s| {
                    let w0 = Vector3::from(s[0].gyro_rps);
                    let w1 = Vector3::from(s[1].gyro_rps);
                    let dt = (s[1].stamps.sample_ns - s[0].stamps.sample_ns) as f64 * 1e-9;
                    (0.5 * (w0 + w1) - bias, dt)
                })
                .collect();
            Rotation { steps }
        })
        .collect();

    // The geometry decides whether the parameters are determined; judge it before the search
    // (which would wander along an undetermined direction) and again at the solution.
    let problem = JointProblem::new(&poses, &rotations, Params::zeros());
    check_condition(&problem.cache.1)?;
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(100)
        .minimize(problem);
    if !report.termination.was_successful() {
        return Err(GyroCalError::NotConverged(format!(
            "{:?}",
            report.termination
        )));
    }
    let (r, j) = (&problem.cache.0, &problem.cache.1);
    check_condition(j)?;
    let svd = j.clone().svd(false, true);
    let sv = &svd.singular_values;
    // Parameter covariance s^2 (J^T J)^-1 = s^2 V S^-2 V^T, with s^2 the residual variance per
    // degree of freedom. Each rotation's three direction residuals carry two independent
    // constraints (the residual is nearly perpendicular to the unit direction).
    let constraints = poses.len() + 2 * rotations.len();
    let dof = constraints.saturating_sub(PARAMS).max(1) as f64;
    let s2 = r.norm_squared() / dof;
    let v_t = svd.v_t.expect("requested V^T");
    let inv_s2 = Params::from_iterator(sv.iter().map(|s| 1.0 / (s * s)));
    let cov: SMatrix<f64, PARAMS, PARAMS> =
        v_t.transpose() * SMatrix::<f64, PARAMS, PARAMS>::from_diagonal(&inv_s2) * v_t * s2;
    let x = &problem.x;
    Ok(GyroCalibration {
        correction: gyro_correction(x),
        correction_sigma: Matrix3::from_fn(|i, k| cov[(3 * i + k, 3 * i + k)].sqrt()),
        accel_bias_mps2: accel_bias_g(x) * cfg.gravity_mps2,
        accel_shape: accel_shape(x),
        poses: poses.len(),
        residual_rms: (r.norm_squared() / r.len() as f64).sqrt(),
    })
}

/// Refuses a Jacobian whose condition number exceeds [`MAX_CONDITION`].
fn check_condition(j: &OMatrix<f64, Dyn, U18>) -> Result<(), GyroCalError> {
    let sv = j.singular_values();
    let condition = if sv.min() > 0.0 {
        sv.max() / sv.min()
    } else {
        f64::INFINITY
    };
    if condition > MAX_CONDITION {
        return Err(GyroCalError::IllConditioned { condition });
    }
    Ok(())
}

/// Checks every sample by the stream contract ([`ipc_types::stream`]).
fn check_samples(samples: &[CorrectedImuSample]) -> Result<(), GyroCalError> {
    let mut prev_ns = None;
    for s in samples {
        ipc_types::stream::check_corrected(s)?;
        ipc_types::stream::check_increasing(s.seq, s.stamps.sample_ns, prev_ns)?;
        prev_ns = Some(s.stamps.sample_ns);
    }
    Ok(())
}

/// The static poses: runs of rest-flagged samples lasting at least `min_static_s`, averaged
/// over their core (without `edge_trim_s` at each end).
fn static_poses(samples: &[CorrectedImuSample], cfg: &GyroCalConfig) -> Vec<StaticPose> {
    let rest = |s: &CorrectedImuSample| s.flags & corrected_flags::ZERO_STATE != 0;
    let secs = |a: usize, b: usize| {
        (samples[b].stamps.sample_ns - samples[a].stamps.sample_ns) as f64 * 1e-9
    };
    let mut poses = Vec::new();
    let mut i = 0;
    while i < samples.len() {
        if !rest(&samples[i]) {
            i += 1;
            continue;
        }
        let start = i;
        while i < samples.len() && rest(&samples[i]) {
            i += 1;
        }
        let end = i - 1;
        if secs(start, end) < cfg.min_static_s {
            continue;
        }
        let first = (start..=end)
            .find(|&k| secs(start, k) >= cfg.edge_trim_s)
            .unwrap_or(start);
        let last = (start..=end)
            .rev()
            .find(|&k| secs(k, end) >= cfg.edge_trim_s)
            .unwrap_or(end);
        if last <= first {
            continue;
        }
        let n = (last - first + 1) as f64;
        let (f, w) =
            samples[first..=last]
                .iter()
                .fold((Vector3::zeros(), Vector3::zeros()), |(f, w), s| {
                    (
                        f + Vector3::from(s.accel_mps2),
                        w + Vector3::from(s.gyro_rps),
                    )
                });
        poses.push(StaticPose {
            first,
            last,
            accel_g: f / n / cfg.gravity_mps2,
            gyro_mean: w / n,
        });
    }
    poses
}

/// `C = I + X` with `X` the first nine parameters in row-major order.
fn gyro_correction(x: &Params) -> Matrix3<f64> {
    Matrix3::identity() + Matrix3::from_row_slice(&x.as_slice()[..9])
}

/// The accelerometer bias, g.
fn accel_bias_g(x: &Params) -> Vector3<f64> {
    x.fixed_rows::<3>(9).into_owned()
}

/// The accelerometer's symmetric shape correction `I + S`.
fn accel_shape(x: &Params) -> Matrix3<f64> {
    let s = x.fixed_rows::<6>(12);
    Matrix3::new(
        1.0 + s[0],
        s[3],
        s[4],
        s[3],
        1.0 + s[1],
        s[5],
        s[4],
        s[5],
        1.0 + s[2],
    )
}

/// The least-squares problem over the 18 parameters, with residuals and Jacobian cached at the
/// current parameters: one magnitude residual per pose, then three direction residuals per
/// rotation. The gyro columns of the Jacobian come from [`Rotation::integrate`]; the
/// accelerometer columns are central differences with the rotations held (they only move the
/// measured directions, which is cheap to redo).
struct JointProblem<'a> {
    poses: &'a [StaticPose],
    rotations: &'a [Rotation],
    x: Params,
    cache: (DVector<f64>, OMatrix<f64, Dyn, U18>),
}

impl<'a> JointProblem<'a> {
    /// Step of the central difference in the (dimensionless) accelerometer parameters.
    const STEP: f64 = 1e-6;

    fn new(poses: &'a [StaticPose], rotations: &'a [Rotation], x: Params) -> Self {
        let mut p = Self {
            poses,
            rotations,
            x,
            cache: (DVector::zeros(0), OMatrix::<f64, Dyn, U18>::zeros(0)),
        };
        p.cache = p.eval(&x);
        p
    }

    /// The residuals at accelerometer parameters `x` (only its entries 9.. are read) with the
    /// rotations `turns`, and each rotation's predicted direction `R^T u_before`.
    fn residuals_at(
        &self,
        x: &Params,
        turns: &[UnitQuaternion<f64>],
    ) -> (DVector<f64>, Vec<Vector3<f64>>) {
        let shape = accel_shape(x);
        let bias = accel_bias_g(x);
        let n = self.poses.len();
        let mut r = DVector::zeros(n + 3 * turns.len());
        let mut predictions = Vec::with_capacity(turns.len());
        let mut before = Vector3::zeros();
        for (i, p) in self.poses.iter().enumerate() {
            let f = shape * (p.accel_g - bias);
            r[i] = f.norm() - 1.0;
            let u = f.normalize();
            if i > 0 {
                let predicted = turns[i - 1].inverse_transform_vector(&before);
                r.fixed_rows_mut::<3>(n + 3 * (i - 1))
                    .copy_from(&(u - predicted));
                predictions.push(predicted);
            }
            before = u;
        }
        (r, predictions)
    }

    fn eval(&self, x: &Params) -> (DVector<f64>, OMatrix<f64, Dyn, U18>) {
        let c = gyro_correction(x);
        let (turns, d_theta): (Vec<_>, Vec<_>) =
            self.rotations.iter().map(|rot| rot.integrate(&c)).unzip();
        let (r, predictions) = self.residuals_at(x, &turns);
        let n = self.poses.len();
        let mut j = OMatrix::<f64, Dyn, U18>::zeros(r.len());
        // Direction residual u_after - R^T u_before: turning R by d(theta) (in the later frame)
        // moves the prediction p = R^T u_before by p x d(theta).
        for (i, (p, dt)) in predictions.iter().zip(&d_theta).enumerate() {
            j.fixed_view_mut::<3, 9>(n + 3 * i, 0)
                .copy_from(&(-(p.cross_matrix() * dt)));
        }
        for k in 9..PARAMS {
            let mut plus = *x;
            let mut minus = *x;
            plus[k] += Self::STEP;
            minus[k] -= Self::STEP;
            let d = (self.residuals_at(&plus, &turns).0 - self.residuals_at(&minus, &turns).0)
                / (2.0 * Self::STEP);
            j.set_column(k, &d);
        }
        (r, j)
    }
}

impl LeastSquaresProblem<f64, Dyn, U18> for JointProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U18>;
    type ParameterStorage = Owned<f64, U18>;

    fn set_params(&mut self, x: &Params) {
        self.x = *x;
        self.cache = self.eval(x);
    }

    fn params(&self) -> Params {
        self.x
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(self.cache.0.clone())
    }

    fn jacobian(&self) -> Option<OMatrix<f64, Dyn, U18>> {
        Some(self.cache.1.clone())
    }
}
