//! Labelled linear least squares for the three models: each pose pairs a known true specific
//! force (its gravity label, g) with the mean reading measured in it (g).
//!
//! `a' = S a + b` is linear in the parameters and each output axis `i` involves only row `i` of
//! `S` and `b_i`, so the fit is three independent small least-squares problems (one per axis,
//! solved by SVD). Axes are treated as having independent noise, so the covariance between
//! parameters of different axes is zero.
//!
//! Weighting and covariance (stated explicitly because scipy's `curve_fit`, which the thesis
//! used, has two conventions):
//! - [`Weighting::Unweighted`]: ordinary least squares. The noise level is unknown, so it is
//!   estimated from the residuals: `Cov = s^2 (X^T X)^-1`, `s^2 = RSS / (m - p)` per axis
//!   (`curve_fit` with `absolute_sigma=False`). With few poses `s^2` is itself uncertain
//!   (six poses and the full model leave 2 degrees of freedom per axis), so the 1-sigma is
//!   then only a rough guide.
//! - [`Weighting::PoseStd`]: weights `1/sigma^2` per pose and axis. The datum being fitted is a
//!   pose *mean*, so its sigma is the standard error of that mean, `std / sqrt(n)` (the noise
//!   of the thesis's samples is white after torn-read repair: lag-1 autocorrelation below
//!   0.05). When every pose knows its sample count `n` the sigmas are absolute and
//!   `Cov = (X^T W X)^-1` (`absolute_sigma=True`). When `n` is unknown (the thesis's means
//!   files store only the mean and std), only relative weights are known: the per-sample std
//!   is used as sigma and the covariance is scaled by `chi^2 / (m - p)` as in the unweighted
//!   case. Which one applied is recorded in [`LabelledFit::covariance_mode`]. Absolute
//!   covariances ignore error sources other than white noise (a table that is not level, an
//!   imperfect cube); [`LabelledFit::reduced_chi2`] far above 1 is the sign of those.

use nalgebra::{DMatrix, DVector, Vector3};

use calibrate::model::{
    AccelModel, ModelError, ModelKind, PARAM_NAMES, ParamCovariance, ParamVector, scale_index,
};

/// One static pose: its gravity label and the statistics of the readings taken in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// The specific force the pose should produce, g, sensor frame (the label; for the
    /// label-free fit it is ignored).
    pub truth_g: Vector3<f64>,
    /// Mean reading, g, sensor frame.
    pub mean_g: Vector3<f64>,
    /// Per-sample standard deviation of the readings, g, per axis.
    pub std_g: Vector3<f64>,
    /// Number of independent samples the mean is worth, when known: the samples averaged, or
    /// for correlated samples (a sensor's low-pass filter) that count divided by how much more
    /// their mean scatters than white noise's (`NoiseLevel::mean_variance_factor`).
    pub n: Option<usize>,
}

impl Pose {
    /// Standard error of the mean per axis (g), when the sample count is known.
    pub fn sem_g(&self) -> Option<Vector3<f64>> {
        self.n.map(|n| self.std_g / (n as f64).sqrt())
    }
}

pub use calibrate::calibfile::{CovarianceMode, Weighting};

/// Why a fit could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Fewer poses than the model needs.
    #[error("{kind} model needs at least {needed} poses, got {got}")]
    TooFewPoses {
        /// Model being fitted.
        kind: ModelKind,
        /// Minimum number of poses.
        needed: usize,
        /// Number given.
        got: usize,
    },
    /// The poses' labels do not vary enough to determine some parameters.
    #[error(
        "the poses do not determine {params} (their gravity labels do not span the needed directions; \
         a full model needs each axis pointed up and down)"
    )]
    Undetermined {
        /// Comma-separated names of the undetermined parameters.
        params: String,
    },
    /// A pose's std is zero or not finite, so it cannot be weighted.
    #[error("pose {pose} has std {std} on axis {axis}; cannot weight by 1/std^2")]
    BadStd {
        /// 0-based pose index.
        pose: usize,
        /// Axis name.
        axis: char,
        /// The offending std.
        std: f64,
    },
    /// A pose holds a NaN or infinite value.
    #[error("pose {pose} holds a non-finite value")]
    NotFinite {
        /// 0-based pose index.
        pose: usize,
    },
    /// The residual variance cannot be estimated (as many poses as parameters).
    #[error(
        "{kind} model with {poses} poses leaves no degrees of freedom to estimate the noise; add poses or use --weighted with known sample counts"
    )]
    NoDegreesOfFreedom {
        /// Model being fitted.
        kind: ModelKind,
        /// Number of poses.
        poses: usize,
    },
    /// The fitted parameters do not form an invertible model.
    #[error("the fitted parameters are not a usable model: {0}")]
    Model(#[from] ModelError),
}

/// A fitted labelled model with its uncertainty and residuals.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelledFit {
    /// The fitted model.
    pub model: AccelModel,
    /// Parameter covariance in the 12-parameter layout (see [`calibrate::model`]).
    pub covariance: ParamCovariance,
    /// How `covariance` was obtained.
    pub covariance_mode: CovarianceMode,
    /// The weighting used.
    pub weighting: Weighting,
    /// Per pose, measured mean minus model prediction `S a + b`, g.
    pub residuals_g: Vec<Vector3<f64>>,
    /// Degrees of freedom per axis (poses minus parameters of that axis).
    pub dof: [usize; 3],
    /// Weighted sum of squared residuals per axis (g^2 when unweighted; dimensionless with
    /// absolute sigmas).
    pub chi2: [f64; 3],
}

impl LabelledFit {
    /// 1-sigma of each parameter (square root of the covariance diagonal).
    pub fn sigma(&self) -> ParamVector {
        self.covariance.diagonal().map(f64::sqrt)
    }

    /// `chi^2 / dof` per axis (NaN where dof is 0). With absolute sigmas it should be near 1;
    /// far above 1 means the sigmas miss an error source.
    pub fn reduced_chi2(&self) -> [f64; 3] {
        std::array::from_fn(|i| {
            if self.dof[i] == 0 {
                f64::NAN
            } else {
                self.chi2[i] / self.dof[i] as f64
            }
        })
    }

    /// Root-mean-square residual per axis, g.
    pub fn residual_rms_g(&self) -> [f64; 3] {
        residual_rms(&self.residuals_g)
    }
}

/// Root-mean-square of residual vectors per axis (g in, g out); zeros for an empty slice.
pub fn residual_rms(residuals: &[Vector3<f64>]) -> [f64; 3] {
    let n = residuals.len().max(1) as f64;
    std::array::from_fn(|i| (residuals.iter().map(|r| r[i] * r[i]).sum::<f64>() / n).sqrt())
}

/// Columns of one axis' design matrix, as indices into the full parameter layout.
pub fn axis_params(kind: ModelKind, axis: usize) -> Vec<usize> {
    match kind {
        ModelKind::Bias => vec![axis],
        ModelKind::Scale => vec![scale_index(axis, axis), axis],
        ModelKind::Full => vec![
            scale_index(axis, 0),
            scale_index(axis, 1),
            scale_index(axis, 2),
            axis,
        ],
    }
}

/// Checks that there are enough poses for `kind` and that every value is finite.
fn check_poses(poses: &[Pose], kind: ModelKind) -> Result<(), FitError> {
    let per_axis = axis_params(kind, 0).len();
    if poses.len() < per_axis {
        return Err(FitError::TooFewPoses {
            kind,
            needed: per_axis,
            got: poses.len(),
        });
    }
    for (k, p) in poses.iter().enumerate() {
        if !(p
            .truth_g
            .iter()
            .chain(p.mean_g.iter())
            .chain(p.std_g.iter())
            .all(|v| v.is_finite()))
        {
            return Err(FitError::NotFinite { pose: k });
        }
    }
    Ok(())
}

/// One axis' weighted least-squares problem: design matrix, observations and weights.
pub struct AxisProblem {
    /// The design matrix, one row per pose, columns as [`axis_params`].
    pub x: DMatrix<f64>,
    y: DVector<f64>,
    w: DVector<f64>,
}

/// The least-squares problem of `axis` for `kind` (columns as [`axis_params`]); weights
/// `1 / s^2` with `s` each pose's standard error (`absolute`) or standard deviation when
/// weighting by pose std, else 1.
pub fn axis_problem(
    poses: &[Pose],
    kind: ModelKind,
    axis: usize,
    weighting: Weighting,
    absolute: bool,
) -> Result<AxisProblem, FitError> {
    let (m, p) = (poses.len(), axis_params(kind, axis).len());
    let mut x = DMatrix::zeros(m, p);
    let mut y = DVector::zeros(m);
    let mut w = DVector::from_element(m, 1.0);
    for (r, pose) in poses.iter().enumerate() {
        let t = &pose.truth_g;
        match kind {
            ModelKind::Bias => {
                x[(r, 0)] = 1.0;
                y[r] = pose.mean_g[axis] - t[axis];
            }
            ModelKind::Scale => {
                x[(r, 0)] = t[axis];
                x[(r, 1)] = 1.0;
                y[r] = pose.mean_g[axis];
            }
            ModelKind::Full => {
                for c in 0..3 {
                    x[(r, c)] = t[c];
                }
                x[(r, 3)] = 1.0;
                y[r] = pose.mean_g[axis];
            }
        }
        if weighting == Weighting::PoseStd {
            let s = if absolute {
                pose.sem_g().expect("checked above")[axis]
            } else {
                pose.std_g[axis]
            };
            if !(s > 0.0 && s.is_finite()) {
                return Err(FitError::BadStd {
                    pose: r,
                    axis: axis_name(axis),
                    std: pose.std_g[axis],
                });
            }
            w[r] = 1.0 / (s * s);
        }
    }
    Ok(AxisProblem { x, y, w })
}

/// One axis' solution: parameters, their unscaled covariance `(X^T W X)^-1`, and the weighted
/// sum of squared residuals.
struct AxisSolution {
    theta: DVector<f64>,
    unscaled: DMatrix<f64>,
    chi2: f64,
}

/// Solves `a` by SVD; `cols` (the columns' parameters) name those a rank-deficient design
/// leaves undetermined.
fn solve_axis(a: &AxisProblem, cols: &[usize]) -> Result<AxisSolution, FitError> {
    let AxisProblem { x, y, w } = a;
    let (m, p) = x.shape();
    let sqrt_w = w.map(f64::sqrt);
    let xw = DMatrix::from_fn(m, p, |r, c| x[(r, c)] * sqrt_w[r]);
    let yw = y.component_mul(&sqrt_w);
    let svd = xw.clone().svd(true, true);
    let v_t = svd.v_t.as_ref().expect("requested V^T");
    let s_max = svd.singular_values.max();
    let tol = 1e-9 * s_max.max(f64::MIN_POSITIVE);
    if let Some(k_min) = (0..p).find(|&k| svd.singular_values[k] <= tol) {
        // The null direction names the undetermined parameters.
        let null = v_t.row(k_min);
        let names: Vec<&str> = (0..p)
            .filter(|&c| null[c].abs() > 0.3)
            .map(|c| PARAM_NAMES[cols[c]])
            .collect();
        return Err(FitError::Undetermined {
            params: names.join(", "),
        });
    }
    let theta = svd.solve(&yw, 0.0).expect("U and V^T were computed");
    // (X^T W X)^-1 = V diag(1/s^2) V^T.
    let inv_s2 = DMatrix::from_diagonal(&svd.singular_values.map(|s| 1.0 / (s * s)));
    let unscaled = v_t.transpose() * inv_s2 * v_t;
    let resid = y - x * &theta;
    let chi2 = resid
        .iter()
        .zip(w.iter())
        .map(|(r, wi)| wi * r * r)
        .sum::<f64>();
    Ok(AxisSolution {
        theta,
        unscaled,
        chi2,
    })
}

/// How a fit's covariance is obtained from `poses` weighted by `weighting`: absolute when each
/// pose is weighted by its mean's standard error and every pose knows its sample count,
/// scaled by the residuals otherwise (module documentation).
pub fn covariance_mode(poses: &[Pose], weighting: Weighting) -> CovarianceMode {
    if weighting == Weighting::PoseStd && poses.iter().all(|p| p.n.is_some_and(|n| n > 0)) {
        CovarianceMode::Absolute
    } else {
        CovarianceMode::ResidualScaled
    }
}

/// Fits `kind` to labelled poses by (weighted) linear least squares; see the module
/// documentation for the weighting and covariance conventions.
pub fn fit_labelled(
    poses: &[Pose],
    kind: ModelKind,
    weighting: Weighting,
) -> Result<LabelledFit, FitError> {
    check_poses(poses, kind)?;
    let covariance_mode = covariance_mode(poses, weighting);
    let absolute = covariance_mode == CovarianceMode::Absolute;
    let m = poses.len();
    let mut params = ParamVector::zeros();
    for d in [3, 7, 11] {
        params[d] = 1.0;
    }
    let mut covariance = ParamCovariance::zeros();
    let mut dof = [0usize; 3];
    let mut chi2 = [0.0; 3];
    for axis in 0..3 {
        let cols = axis_params(kind, axis);
        let problem = axis_problem(poses, kind, axis, weighting, absolute)?;
        let sol = solve_axis(&problem, &cols)?;
        dof[axis] = m - cols.len();
        chi2[axis] = sol.chi2;
        let factor = match covariance_mode {
            CovarianceMode::Absolute => 1.0,
            CovarianceMode::ResidualScaled => {
                if dof[axis] == 0 {
                    return Err(FitError::NoDegreesOfFreedom { kind, poses: m });
                }
                sol.chi2 / dof[axis] as f64
            }
        };
        for (a, &ka) in cols.iter().enumerate() {
            params[ka] = sol.theta[a];
            for (b, &kb) in cols.iter().enumerate() {
                covariance[(ka, kb)] = factor * sol.unscaled[(a, b)];
            }
        }
    }
    let model = AccelModel::from_params(kind, &params)?;
    let residuals_g = poses
        .iter()
        .map(|p| p.mean_g - model.measure(&p.truth_g))
        .collect();
    Ok(LabelledFit {
        model,
        covariance,
        covariance_mode,
        weighting,
        residuals_g,
        dof,
        chi2,
    })
}

/// `'x'`, `'y'` or `'z'` for axis 0, 1, 2.
pub fn axis_name(axis: usize) -> char {
    ['x', 'y', 'z'][axis]
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    fn six_axis_poses(model: &AccelModel) -> Vec<Pose> {
        let dirs = [
            Vector3::z(),
            -Vector3::z(),
            Vector3::y(),
            -Vector3::y(),
            Vector3::x(),
            -Vector3::x(),
        ];
        dirs.iter()
            .map(|t| Pose {
                truth_g: *t,
                mean_g: model.measure(t),
                std_g: Vector3::repeat(0.002),
                n: Some(5400),
            })
            .collect()
    }

    #[test]
    fn exact_data_gives_exact_parameters() {
        let s = Matrix3::new(
            1.0, 0.008, 0.009, -0.006, 1.0004, 0.0106, -0.0102, -0.0044, 1.022,
        );
        let truth =
            AccelModel::new(ModelKind::Full, s, Vector3::new(0.0916, 0.0473, -0.2502)).unwrap();
        let fit = fit_labelled(
            &six_axis_poses(&truth),
            ModelKind::Full,
            Weighting::Unweighted,
        )
        .unwrap();
        assert!((fit.model.params() - truth.params()).norm() < 1e-12);
        assert!(fit.residual_rms_g().iter().all(|r| *r < 1e-12));
        assert_eq!(fit.dof, [2, 2, 2]);
    }

    #[test]
    fn six_positions_closed_form() {
        // For six axis-aligned poses, S_ij = (mean_i(+j) - mean_i(-j)) / 2 and b_i is the mean
        // of axis i over all poses: an independent check of the solver.
        let means = [
            [0.0996, 0.0624, 0.7721],
            [0.0815, 0.0412, -1.2718],
            [0.1000, 1.0460, -0.2559],
            [0.0841, -0.9547, -0.2471],
            [1.0922, 0.0380, -0.2594],
            [-0.9079, 0.0508, -0.2390],
        ];
        let labels = [
            [0., 0., 1.],
            [0., 0., -1.],
            [0., 1., 0.],
            [0., -1., 0.],
            [1., 0., 0.],
            [-1., 0., 0.],
        ];
        let poses: Vec<Pose> = means
            .iter()
            .zip(labels.iter())
            .map(|(m, t)| Pose {
                truth_g: Vector3::from(*t),
                mean_g: Vector3::from(*m),
                std_g: Vector3::repeat(0.003),
                n: None,
            })
            .collect();
        let fit = fit_labelled(&poses, ModelKind::Full, Weighting::Unweighted).unwrap();
        // Pose index with label +j and -j.
        let plus = [4, 2, 0];
        let minus = [5, 3, 1];
        for i in 0..3 {
            let b = means.iter().map(|m| m[i]).sum::<f64>() / 6.0;
            assert!((fit.model.bias_g()[i] - b).abs() < 1e-12);
            for j in 0..3 {
                let sij = (means[plus[j]][i] - means[minus[j]][i]) / 2.0;
                assert!((fit.model.scale()[(i, j)] - sij).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn undetermined_parameters_are_named() {
        let truth = AccelModel::identity(ModelKind::Full);
        // Only z up and z down: nothing about the x and y columns of S.
        let poses: Vec<Pose> = six_axis_poses(&truth)
            .into_iter()
            .take(2)
            .chain(six_axis_poses(&truth).into_iter().take(2))
            .collect();
        let err = fit_labelled(&poses, ModelKind::Full, Weighting::Unweighted).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("S_xx") || msg.contains("S_xy"), "{msg}");
    }

    #[test]
    fn weighted_absolute_covariance_is_the_textbook_formula() {
        // Bias-only model, one axis: b = weighted mean, var(b) = 1 / sum(1/sigma^2).
        let truth = AccelModel::identity(ModelKind::Bias);
        let mut poses = six_axis_poses(&truth);
        for (k, p) in poses.iter_mut().enumerate() {
            p.std_g = Vector3::repeat(0.001 * (k + 1) as f64);
            p.n = Some(100);
            p.mean_g.x += 0.001 * k as f64;
        }
        let fit = fit_labelled(&poses, ModelKind::Bias, Weighting::PoseStd).unwrap();
        assert_eq!(fit.covariance_mode, CovarianceMode::Absolute);
        let w: Vec<f64> = poses
            .iter()
            .map(|p| 100.0 / (p.std_g.x * p.std_g.x))
            .collect();
        let sw: f64 = w.iter().sum();
        let b = poses
            .iter()
            .zip(&w)
            .map(|(p, wi)| wi * (p.mean_g.x - p.truth_g.x))
            .sum::<f64>()
            / sw;
        assert!((fit.model.bias_g().x - b).abs() < 1e-15);
        assert!((fit.covariance[(0, 0)] - 1.0 / sw).abs() < 1e-18);
        // Without sample counts, the same weights give a residual-scaled covariance.
        for p in poses.iter_mut() {
            p.n = None;
        }
        let rel = fit_labelled(&poses, ModelKind::Bias, Weighting::PoseStd).unwrap();
        assert_eq!(rel.covariance_mode, CovarianceMode::ResidualScaled);
        assert!((rel.model.bias_g().x - b).abs() < 1e-15);
    }
}
