//! Label-free calibration: static poses in unknown orientations, fitted on the constraint that
//! the corrected specific force has the magnitude of local gravity, `|S^-1 (a' - b)| = 1 g`.
//!
//! Parameterisation. Only `T = S^-1` up to a rotation is observable from magnitudes
//! (`|Q T y| = |T y|` for any rotation `Q`), so `T` is restricted to be upper triangular
//! (the `R` of a QR decomposition of any `S^-1`): 3 biases and 6 entries of `T`, 9 parameters
//! `[b_x, b_y, b_z, T_xx, T_xy, T_xz, T_yy, T_yz, T_zz]`. The corrected output is then
//! expressed in a frame whose z axis is the sensor's z sensing axis and whose y axis lies in
//! the plane of the sensor's y and z sensing axes; the rotation from that frame to a body
//! frame is left to alignment. The result is reported as a full model with
//! `S = T^-1` (upper triangular) and its covariance mapped to the 12-parameter layout.
//!
//! Method: an algebraic ellipsoid fit (linear, SVD) gives the starting point; Levenberg-
//! Marquardt (`levenberg-marquardt` crate) minimises the (weighted) squared magnitude errors;
//! the covariance is `s^2 (J^T J)^-1` or `(J^T W J)^-1` from the Jacobian at the solution with
//! the same weighting conventions as [`crate::fit`].
//!
//! Identifiability. Nine parameters need at least nine poses in well-spread orientations. The
//! fit refuses (with [`LabelFreeError`]) when there are fewer than [`MIN_POSES`] poses, fewer
//! than [`MIN_POSES`] distinct orientations (poses closer than [`DISTINCT_ANGLE_DEG`] count
//! once), or when the Jacobian at the solution has a condition number above
//! [`MAX_CONDITION`] (some parameter combination is not determined, e.g. all poses in one
//! plane). Six axis-aligned poses are refused: they cannot determine the three cross terms.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::storage::Owned;
use nalgebra::{DMatrix, DVector, Dyn, Matrix3, OMatrix, SMatrix, SVector, U9, Vector3};

use crate::fit::{CovarianceMode, Pose, Weighting, covariance_mode};
use calibrate::model::{AccelModel, ModelError, ModelKind, N_PARAMS, ParamCovariance, scale_index};

/// Minimum number of poses (and of distinct orientations) for the 9-parameter fit.
pub const MIN_POSES: usize = 9;

/// Two poses whose mean readings point within this angle (degrees) count as one orientation.
pub const DISTINCT_ANGLE_DEG: f64 = 5.0;

/// Largest accepted condition number of the Jacobian at the solution (parameters in g and
/// dimensionless have comparable sensitivities, so the unscaled Jacobian is used). Random
/// well-spread poses give 3-20; poses confined to a plane or a narrow cone give 10^4 and more.
pub const MAX_CONDITION: f64 = 1.0e3;

/// Names of the 9 label-free parameters.
pub const LABEL_FREE_PARAM_NAMES: [&str; 9] = [
    "b_x", "b_y", "b_z", "T_xx", "T_xy", "T_xz", "T_yy", "T_yz", "T_zz",
];

/// Position of `T[row][col]` (upper triangle) in the 9-parameter vector.
const T_INDEX: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// Why a label-free fit was refused or failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LabelFreeError {
    /// Not enough poses or orientations to determine 9 parameters.
    #[error(
        "label-free calibration cannot determine its 9 parameters (3 biases and 6 entries of an upper-triangular S^-1, \
         from |S^-1 (a' - b)| = 1 g) from {poses} poses in {distinct} distinct orientations: it needs at least {MIN_POSES} \
         well-spread orientations. Six axis-aligned poses are not enough (they cannot determine the cross-axis terms); \
         use labelled fitting (--labels auto) for a six-position session, or record more orientations"
    )]
    TooFewPoses {
        /// Number of poses given.
        poses: usize,
        /// Number of distinct orientations among them.
        distinct: usize,
    },
    /// The poses do not constrain some parameter combination.
    #[error(
        "label-free calibration refused: the poses do not determine the parameter combination dominated by {params} \
         (Jacobian condition number {condition:.3e} > {MAX_CONDITION:e}); add poses in other orientations \
         (tilt the sensor out of the planes already used)"
    )]
    IllConditioned {
        /// Condition number of the Jacobian.
        condition: f64,
        /// The parameters that dominate the weakest direction.
        params: String,
    },
    /// A pose's std cannot be used as a weight.
    #[error("pose {pose} has a zero or non-finite std; cannot weight it")]
    BadStd {
        /// 0-based pose index.
        pose: usize,
    },
    /// A pose holds NaN or infinity.
    #[error("pose {pose} holds a non-finite value")]
    NotFinite {
        /// 0-based pose index.
        pose: usize,
    },
    /// The starting point could not be computed (the poses do not lie near an ellipsoid).
    #[error(
        "the poses do not lie on an ellipsoid (algebraic fit gave an indefinite quadric); is the sensor static in each pose?"
    )]
    NoEllipsoid,
    /// Levenberg-Marquardt did not converge.
    #[error("Levenberg-Marquardt did not converge: {0}")]
    NotConverged(String),
    /// The solution is not a usable model.
    #[error("the fitted parameters are not a usable model: {0}")]
    Model(#[from] ModelError),
}

/// A label-free fit with its uncertainty and diagnostics.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelFreeFit {
    /// The model: full kind, `S = T^-1` upper triangular.
    pub model: AccelModel,
    /// Covariance in the 12-parameter layout (zero rows for the three structurally zero
    /// lower-triangle entries of `S`).
    pub covariance: ParamCovariance,
    /// Covariance of the 9 fitted parameters ([`LABEL_FREE_PARAM_NAMES`]).
    pub covariance9: SMatrix<f64, 9, 9>,
    /// How the covariance was obtained.
    pub covariance_mode: CovarianceMode,
    /// The weighting used.
    pub weighting: Weighting,
    /// Per pose, `|S^-1 (a' - b)| - 1`, g.
    pub residuals_g: Vec<f64>,
    /// Degrees of freedom (poses minus 9).
    pub dof: usize,
    /// Weighted sum of squared residuals.
    pub chi2: f64,
    /// Condition number of the Jacobian at the solution.
    pub condition: f64,
    /// Number of distinct orientations among the poses.
    pub distinct_orientations: usize,
}

/// Number of distinct orientations: greedy clustering of the mean directions with
/// [`DISTINCT_ANGLE_DEG`].
pub fn distinct_orientations(poses: &[Pose]) -> usize {
    let cos_max = DISTINCT_ANGLE_DEG.to_radians().cos();
    let mut seeds: Vec<Vector3<f64>> = Vec::new();
    for p in poses {
        let Some(u) = p.mean_g.try_normalize(1e-12) else {
            continue;
        };
        if seeds.iter().all(|s| s.dot(&u) < cos_max) {
            seeds.push(u);
        }
    }
    seeds.len()
}

/// Upper-triangular `T` from the 9-parameter vector.
fn t_matrix(x: &SVector<f64, 9>) -> Matrix3<f64> {
    let mut t = Matrix3::zeros();
    for (k, &(r, c)) in T_INDEX.iter().enumerate() {
        t[(r, c)] = x[3 + k];
    }
    t
}

/// The least-squares problem: residual `(|T (m_i - b)| - 1) / sigma_i`.
struct MagnitudeProblem<'a> {
    means: &'a [Vector3<f64>],
    /// Per-pose, per-axis sigma of the mean reading (g); `None` for unweighted.
    sigmas: Option<&'a [Vector3<f64>]>,
    x: SVector<f64, 9>,
    /// Residuals and Jacobian at `x` (computed together: they share every intermediate).
    cache: (DVector<f64>, OMatrix<f64, Dyn, U9>),
}

impl<'a> MagnitudeProblem<'a> {
    fn new(
        means: &'a [Vector3<f64>],
        sigmas: Option<&'a [Vector3<f64>]>,
        x: SVector<f64, 9>,
    ) -> Self {
        let mut p = Self {
            means,
            sigmas,
            x,
            cache: (DVector::zeros(0), OMatrix::<f64, Dyn, U9>::zeros(0)),
        };
        p.cache = p.eval();
        p
    }

    /// Residual sigma of pose `i` (g): the reading's sigma projected through `u^T T`.
    fn residual_sigma(&self, i: usize, t: &Matrix3<f64>, u: &Vector3<f64>) -> f64 {
        match self.sigmas {
            None => 1.0,
            Some(s) => {
                let g = t.transpose() * u;
                g.component_mul(&s[i]).norm()
            }
        }
    }

    fn eval(&self) -> (DVector<f64>, OMatrix<f64, Dyn, U9>) {
        let b = Vector3::new(self.x[0], self.x[1], self.x[2]);
        let t = t_matrix(&self.x);
        let m = self.means.len();
        let mut r = DVector::zeros(m);
        let mut j = OMatrix::<f64, Dyn, U9>::zeros(m);
        for (i, mean) in self.means.iter().enumerate() {
            let y = mean - b;
            let z = t * y;
            let n = z.norm();
            let u = z / n;
            let s = self.residual_sigma(i, &t, &u);
            r[i] = (n - 1.0) / s;
            // d|z|/db = -u^T T; d|z|/dT_rc = u_r y_c. The sigma is held fixed in the
            // derivative (it is a weight, not a function of the parameters being fitted).
            let db = -(t.transpose() * u);
            for a in 0..3 {
                j[(i, a)] = db[a] / s;
            }
            for (k, &(rr, c)) in T_INDEX.iter().enumerate() {
                j[(i, 3 + k)] = u[rr] * y[c] / s;
            }
        }
        (r, j)
    }
}

impl LeastSquaresProblem<f64, Dyn, U9> for MagnitudeProblem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U9>;
    type ParameterStorage = Owned<f64, U9>;

    fn set_params(&mut self, x: &SVector<f64, 9>) {
        self.x = *x;
        self.cache = self.eval();
    }

    fn params(&self) -> SVector<f64, 9> {
        self.x
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(self.cache.0.clone())
    }

    fn jacobian(&self) -> Option<OMatrix<f64, Dyn, U9>> {
        Some(self.cache.1.clone())
    }
}

/// Condition number (largest over smallest singular value) of a Jacobian.
fn condition_number(j: &OMatrix<f64, Dyn, U9>) -> f64 {
    let sv = j.clone().svd(false, false).singular_values;
    if sv.min() > 0.0 {
        sv.max() / sv.min()
    } else {
        f64::INFINITY
    }
}

/// The refusal for a Jacobian whose condition number exceeds [`MAX_CONDITION`], naming the two
/// parameters that dominate its weakest direction; `None` when it is well conditioned.
fn ill_conditioned(j: &OMatrix<f64, Dyn, U9>) -> Option<LabelFreeError> {
    let condition = condition_number(j);
    if condition <= MAX_CONDITION {
        return None;
    }
    let svd = j.clone().svd(false, true);
    let v_t = svd.v_t.expect("requested V^T");
    let weakest = v_t.row(svd.singular_values.imin());
    let mut order: Vec<usize> = (0..9).collect();
    order.sort_by(|&a, &b| weakest[b].abs().total_cmp(&weakest[a].abs()));
    let params: Vec<&str> = order
        .iter()
        .take(2)
        .map(|&k| LABEL_FREE_PARAM_NAMES[k])
        .collect();
    Some(LabelFreeError::IllConditioned {
        condition,
        params: params.join(" and "),
    })
}

/// Algebraic ellipsoid fit: the quadric `m^T M m + v^T m + c = 0` through the means (smallest
/// singular vector of the 10-column design matrix), turned into `b` and `T = chol(M)^T`.
fn algebraic_start(means: &[Vector3<f64>]) -> Option<SVector<f64, 9>> {
    let m = means.len();
    let mut d = DMatrix::zeros(m.max(10), 10);
    for (i, p) in means.iter().enumerate() {
        let (x, y, z) = (p.x, p.y, p.z);
        let row = [
            x * x,
            y * y,
            z * z,
            2.0 * x * y,
            2.0 * x * z,
            2.0 * y * z,
            x,
            y,
            z,
            1.0,
        ];
        for (c, v) in row.iter().enumerate() {
            d[(i, c)] = *v;
        }
    }
    let svd = d.svd(false, true);
    let v_t = svd.v_t?;
    let k_min = svd.singular_values.imin();
    let q = v_t.row(k_min).transpose();
    let mq = Matrix3::new(q[0], q[3], q[4], q[3], q[1], q[5], q[4], q[5], q[2]);
    let v = Vector3::new(q[6], q[7], q[8]);
    let b = -0.5 * mq.try_inverse()? * v;
    let k = (b.transpose() * mq * b)[(0, 0)] - q[9];
    let mm = mq / k;
    let l = mm.cholesky()?.l();
    let t = l.transpose();
    let mut x = SVector::<f64, 9>::zeros();
    x.fixed_rows_mut::<3>(0).copy_from(&b);
    for (idx, &(r, c)) in T_INDEX.iter().enumerate() {
        x[3 + idx] = t[(r, c)];
    }
    Some(x)
}

/// Checks that every pose is finite and that there are enough distinct orientations;
/// returns their number.
fn check_poses(poses: &[Pose]) -> Result<usize, LabelFreeError> {
    for (k, p) in poses.iter().enumerate() {
        if !p.mean_g.iter().chain(p.std_g.iter()).all(|v| v.is_finite()) {
            return Err(LabelFreeError::NotFinite { pose: k });
        }
    }
    let distinct = distinct_orientations(poses);
    if poses.len() < MIN_POSES || distinct < MIN_POSES {
        return Err(LabelFreeError::TooFewPoses {
            poses: poses.len(),
            distinct,
        });
    }
    Ok(distinct)
}

/// Per pose, the sigma (g per axis) its residual is weighted by: the standard error of its
/// mean (`absolute`) or its standard deviation; `None` unweighted.
fn pose_sigmas(
    poses: &[Pose],
    weighting: Weighting,
    absolute: bool,
) -> Result<Option<Vec<Vector3<f64>>>, LabelFreeError> {
    match weighting {
        Weighting::Unweighted => Ok(None),
        Weighting::PoseStd => {
            let s: Vec<Vector3<f64>> = poses
                .iter()
                .map(|p| {
                    if absolute {
                        p.sem_g().expect("checked")
                    } else {
                        p.std_g
                    }
                })
                .collect();
            if let Some(k) = s
                .iter()
                .position(|v| v.iter().any(|x| !(*x > 0.0 && x.is_finite())))
            {
                return Err(LabelFreeError::BadStd { pose: k });
            }
            Ok(Some(s))
        }
    }
}

/// The refusal for means no ellipsoid fits: degenerate geometry (e.g. coplanar orientations)
/// also defeats the algebraic fit, so the conditioning at a nominal point says what is
/// missing.
fn degenerate(means: &[Vector3<f64>]) -> LabelFreeError {
    let mean_norm = means.iter().map(|m| m.norm()).sum::<f64>() / means.len() as f64;
    let mut nominal = SVector::<f64, 9>::zeros();
    for k in [3, 6, 8] {
        nominal[k] = 1.0 / mean_norm;
    }
    let probe = MagnitudeProblem::new(means, None, nominal);
    ill_conditioned(&probe.cache.1).unwrap_or(LabelFreeError::NoEllipsoid)
}

/// The covariance of (b, T) mapped to the 12-parameter layout: b unchanged, dS = -S dT S.
fn covariance_12(s: &Matrix3<f64>, covariance9: &SMatrix<f64, 9, 9>) -> ParamCovariance {
    let mut g = SMatrix::<f64, N_PARAMS, 9>::zeros();
    for a in 0..3 {
        g[(a, a)] = 1.0;
    }
    for (k, &(r_t, c_t)) in T_INDEX.iter().enumerate() {
        for i in 0..3 {
            for jj in 0..3 {
                g[(scale_index(i, jj), 3 + k)] = -s[(i, r_t)] * s[(c_t, jj)];
            }
        }
    }
    g * covariance9 * g.transpose()
}

/// Fits the label-free model to static poses (their labels are ignored); see the module
/// documentation for the parameterisation, the identifiability checks and the covariance.
pub fn fit_label_free(
    poses: &[Pose],
    weighting: Weighting,
) -> Result<LabelFreeFit, LabelFreeError> {
    let distinct = check_poses(poses)?;
    let covariance_mode = covariance_mode(poses, weighting);
    let absolute = covariance_mode == CovarianceMode::Absolute;
    let means: Vec<Vector3<f64>> = poses.iter().map(|p| p.mean_g).collect();
    let sigmas = pose_sigmas(poses, weighting, absolute)?;
    let Some(start) = algebraic_start(&means) else {
        return Err(degenerate(&means));
    };
    let problem = MagnitudeProblem::new(&means, sigmas.as_deref(), start);
    let (problem, report) = LevenbergMarquardt::new()
        .with_patience(200)
        .minimize(problem);
    if !report.termination.was_successful() {
        return Err(LabelFreeError::NotConverged(format!(
            "{:?}",
            report.termination
        )));
    }
    // The condition number is judged on the unweighted Jacobian (weights rescale rows, which
    // would make the threshold depend on the noise level).
    let j_plain = MagnitudeProblem::new(&means, None, problem.x).cache.1;
    if let Some(err) = ill_conditioned(&j_plain) {
        return Err(err);
    }
    let cond_unweighted = condition_number(&j_plain);
    let (r, j) = problem.cache;
    let svd = j.svd(false, true);
    let v_t = svd.v_t.expect("requested V^T");
    let m = poses.len();
    let dof = m - 9;
    let chi2 = r.norm_squared();
    let inv_s2 = SMatrix::<f64, 9, 9>::from_diagonal(&SVector::<f64, 9>::from_iterator(
        svd.singular_values.iter().map(|s| 1.0 / (s * s)),
    ));
    let v_t9 = SMatrix::<f64, 9, 9>::from_iterator(v_t.iter().copied());
    let unscaled = v_t9.transpose() * inv_s2 * v_t9;
    let covariance9 = match covariance_mode {
        CovarianceMode::Absolute => unscaled,
        CovarianceMode::ResidualScaled => {
            // dof >= 0 is guaranteed by MIN_POSES; with exactly 9 poses the residuals are zero
            // and no noise estimate exists.
            if dof == 0 {
                return Err(LabelFreeError::TooFewPoses { poses: m, distinct });
            }
            unscaled * (chi2 / dof as f64)
        }
    };
    let t = t_matrix(&problem.x);
    let s = t.try_inverse().ok_or(ModelError::SingularScale {
        det: t.determinant(),
    })?;
    let b = Vector3::new(problem.x[0], problem.x[1], problem.x[2]);
    let model = AccelModel::new(ModelKind::Full, s, b)?;
    let covariance = covariance_12(&s, &covariance9);
    let residuals_g = means
        .iter()
        .map(|mean| (t * (mean - b)).norm() - 1.0)
        .collect();
    Ok(LabelFreeFit {
        model,
        covariance,
        covariance9,
        covariance_mode,
        weighting,
        residuals_g,
        dof,
        chi2,
        condition: cond_unweighted,
        distinct_orientations: distinct,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(mean: Vector3<f64>) -> Pose {
        Pose {
            truth_g: Vector3::zeros(),
            mean_g: mean,
            std_g: Vector3::repeat(0.002),
            n: Some(2000),
        }
    }

    /// Deterministic well-spread unit vectors (a Fibonacci sphere).
    fn sphere(n: usize) -> Vec<Vector3<f64>> {
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = golden * i as f64;
                Vector3::new(r * phi.cos(), r * phi.sin(), z)
            })
            .collect()
    }

    fn upper_model() -> AccelModel {
        let s = Matrix3::new(1.01, 0.008, -0.012, 0.0, 0.985, 0.011, 0.0, 0.0, 1.022);
        AccelModel::new(ModelKind::Full, s, Vector3::new(0.09, 0.047, -0.25)).unwrap()
    }

    #[test]
    fn noiseless_poses_give_the_exact_model() {
        let truth = upper_model();
        let poses: Vec<Pose> = sphere(14).iter().map(|a| pose(truth.measure(a))).collect();
        let fit = fit_label_free(&poses, Weighting::PoseStd).unwrap();
        assert!(
            (fit.model.params() - truth.params()).norm() < 1e-9,
            "{:?}",
            fit.model.params()
        );
        assert!(fit.condition < 100.0, "condition {}", fit.condition);
        assert_eq!(fit.covariance_mode, CovarianceMode::Absolute);
    }

    #[test]
    fn six_axis_aligned_poses_are_refused() {
        let truth = upper_model();
        let dirs = [
            Vector3::x(),
            -Vector3::x(),
            Vector3::y(),
            -Vector3::y(),
            Vector3::z(),
            -Vector3::z(),
        ];
        let poses: Vec<Pose> = dirs.iter().map(|a| pose(truth.measure(a))).collect();
        let err = fit_label_free(&poses, Weighting::Unweighted).unwrap_err();
        assert_eq!(
            err,
            LabelFreeError::TooFewPoses {
                poses: 6,
                distinct: 6
            }
        );
        assert!(err.to_string().contains("at least 9"), "{err}");
        // Repeating them (with a little jitter) adds poses but not orientations.
        let jitter = [0.01, -0.02, 0.015];
        let twelve: Vec<Pose> = dirs
            .iter()
            .chain(dirs.iter())
            .enumerate()
            .map(|(k, a)| pose(truth.measure(&(a + Vector3::repeat(jitter[k % 3])).normalize())))
            .collect();
        assert!(matches!(
            fit_label_free(&twelve, Weighting::Unweighted),
            Err(LabelFreeError::TooFewPoses {
                poses: 12,
                distinct: 6
            })
        ));
    }

    #[test]
    fn poses_in_one_plane_are_refused_as_ill_conditioned() {
        // Twelve orientations all in the x-y plane: the z bias and z scale are not separable.
        let truth = upper_model();
        let poses: Vec<Pose> = (0..12)
            .map(|k| {
                let a = (k as f64) * std::f64::consts::TAU / 12.0;
                pose(truth.measure(&Vector3::new(a.cos(), a.sin(), 0.0)))
            })
            .collect();
        match fit_label_free(&poses, Weighting::Unweighted) {
            Err(e @ LabelFreeError::IllConditioned { condition, .. }) => {
                assert!(condition > MAX_CONDITION);
                assert!(e.to_string().contains("do not determine"), "{e}");
            }
            other => panic!("expected an ill-conditioning refusal, got {other:?}"),
        }
    }

    #[test]
    fn covariance_mapping_matches_finite_differences_of_the_inverse() {
        // S = T^-1: check the analytic dS/dT used for the covariance mapping.
        let truth = upper_model();
        let t = truth.scale_inv();
        let s = truth.scale();
        let h = 1e-7;
        for &(r, c) in &T_INDEX {
            let mut tp = *t;
            tp[(r, c)] += h;
            let mut tm = *t;
            tm[(r, c)] -= h;
            let fd = (tp.try_inverse().unwrap() - tm.try_inverse().unwrap()) / (2.0 * h);
            for i in 0..3 {
                for j in 0..3 {
                    let analytic = -s[(i, r)] * s[(c, j)];
                    assert!((fd[(i, j)] - analytic).abs() < 1e-6);
                }
            }
        }
    }
}
