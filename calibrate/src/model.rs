//! The thesis's accelerometer error models `a' = S a + b` and their inverse, the correction
//! `a = S^-1 (a' - b)`, with first-order propagation of parameter uncertainty.
//!
//! Units and conventions (for the whole crate): `a'` is the measured and `a` the true specific
//! force, both in **g** in the sensor frame (+1 g on z when lying level, z up); `b` is in g and
//! `S` is dimensionless. "1 g" means the magnitude of *local* gravity at the calibration site:
//! the six-position labels and the label-free constraint `|a| = 1` are both statements about
//! local gravity, so a corrected value in g is converted to m/s^2 by multiplying with the
//! configured local gravity (never with standard gravity).
//!
//! Parameters are always laid out as the 12-vector
//! `[b_x, b_y, b_z, S_xx, S_xy, S_xz, S_yx, S_yy, S_yz, S_zx, S_zy, S_zz]` (the column order of the
//! thesis's `optim_params_N.csv`); a model that holds some of them fixed (the bias-only and
//! diagonal-scale models) has zero rows and columns for those in its covariance.

use std::fmt;

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use serde::{Deserialize, Serialize};

/// Number of entries in the full parameter vector (3 biases and 9 entries of `S`).
pub const N_PARAMS: usize = 12;

/// A 12-vector in the full parameter layout (see the module documentation).
pub type ParamVector = SVector<f64, N_PARAMS>;

/// A 12 x 12 covariance in the full parameter layout (units g^2 for bias pairs, g for
/// bias-scale pairs, dimensionless for scale pairs).
pub type ParamCovariance = SMatrix<f64, N_PARAMS, N_PARAMS>;

/// Jacobian of a corrected vector (g) with respect to the 12 parameters.
pub type CorrectionJacobian = SMatrix<f64, 3, N_PARAMS>;

/// Names of the 12 parameters in layout order.
pub const PARAM_NAMES: [&str; N_PARAMS] = [
    "b_x", "b_y", "b_z", "S_xx", "S_xy", "S_xz", "S_yx", "S_yy", "S_yz", "S_zx", "S_zy", "S_zz",
];

/// Index of bias component `i` in the parameter layout.
pub const fn bias_index(i: usize) -> usize {
    i
}

/// Index of `S[row][col]` in the parameter layout.
pub const fn scale_index(row: usize, col: usize) -> usize {
    3 + 3 * row + col
}

/// Which of the thesis's three models (its equations 3, 4 and 5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum ModelKind {
    /// Model 1: `a' = a + b` (3 parameters).
    Bias,
    /// Model 2: `a' = diag(S) a + b` (6 parameters).
    Scale,
    /// Model 3: `a' = S a + b` with a full 3 x 3 `S` (12 parameters).
    Full,
}

impl ModelKind {
    /// All three models, in order of complexity.
    pub const ALL: [ModelKind; 3] = [ModelKind::Bias, ModelKind::Scale, ModelKind::Full];

    /// Whether parameter `k` (full layout) is estimated by this model.
    pub fn is_free(self, k: usize) -> bool {
        match self {
            ModelKind::Bias => k < 3,
            ModelKind::Scale => k < 3 || matches!(k, 3 | 7 | 11),
            ModelKind::Full => k < N_PARAMS,
        }
    }

    /// Number of estimated parameters.
    pub fn n_free(self) -> usize {
        (0..N_PARAMS).filter(|&k| self.is_free(k)).count()
    }

    /// The name used on the command line and in calibration files.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Bias => "bias",
            ModelKind::Scale => "scale",
            ModelKind::Full => "full",
        }
    }
}

impl fmt::Display for ModelKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a model cannot be built from the given parameters.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// `S` has no usable inverse, so the correction is undefined.
    #[error("the scale matrix S is singular or ill-conditioned (|det S| = {det:e})")]
    SingularScale {
        /// Determinant of `S`.
        det: f64,
    },
    /// A parameter is NaN or infinite.
    #[error("parameter {name} is not finite ({value})")]
    NotFinite {
        /// Parameter name (see [`PARAM_NAMES`]).
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// A model with fixed parameters was given values different from the fixed ones.
    #[error("the {kind} model fixes {name} to {fixed}, got {value}")]
    NotInModel {
        /// The model.
        kind: ModelKind,
        /// Parameter name.
        name: &'static str,
        /// The value the model fixes it to.
        fixed: f64,
        /// The value given.
        value: f64,
    },
}

/// An accelerometer model `a' = S a + b` (g, sensor frame) with its inverse cached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelModel {
    kind: ModelKind,
    scale: Matrix3<f64>,
    bias_g: Vector3<f64>,
    scale_inv: Matrix3<f64>,
}

impl AccelModel {
    /// The ideal sensor (`S = I`, `b = 0`) of the given kind.
    pub fn identity(kind: ModelKind) -> Self {
        Self {
            kind,
            scale: Matrix3::identity(),
            bias_g: Vector3::zeros(),
            scale_inv: Matrix3::identity(),
        }
    }

    /// Builds a model, checking that `S` and `b` are finite, that the fixed entries of the
    /// kind hold their fixed values (identity / diagonal), and that `S` is invertible.
    pub fn new(
        kind: ModelKind,
        scale: Matrix3<f64>,
        bias_g: Vector3<f64>,
    ) -> Result<Self, ModelError> {
        let mut p = ParamVector::zeros();
        p.fixed_rows_mut::<3>(0).copy_from(&bias_g);
        for r in 0..3 {
            for c in 0..3 {
                p[scale_index(r, c)] = scale[(r, c)];
            }
        }
        Self::from_params(kind, &p)
    }

    /// Builds a model from the 12-vector layout (see the module documentation).
    pub fn from_params(kind: ModelKind, p: &ParamVector) -> Result<Self, ModelError> {
        let identity = ParamVector::from_fn(|k, _| if matches!(k, 3 | 7 | 11) { 1.0 } else { 0.0 });
        for k in 0..N_PARAMS {
            if !p[k].is_finite() {
                return Err(ModelError::NotFinite {
                    name: PARAM_NAMES[k],
                    value: p[k],
                });
            }
            if !kind.is_free(k) && p[k] != identity[k] {
                return Err(ModelError::NotInModel {
                    kind,
                    name: PARAM_NAMES[k],
                    fixed: identity[k],
                    value: p[k],
                });
            }
        }
        let scale = Matrix3::from_fn(|r, c| p[scale_index(r, c)]);
        let bias_g = Vector3::new(p[0], p[1], p[2]);
        let det = scale.determinant();
        // A real accelerometer's S is within a few percent of the identity; |det| this small
        // means the parameters are not a sensor model at all.
        let scale_inv = match scale.try_inverse() {
            Some(inv) if det.abs() > 1e-6 => inv,
            _ => return Err(ModelError::SingularScale { det }),
        };
        Ok(Self {
            kind,
            scale,
            bias_g,
            scale_inv,
        })
    }

    /// The model kind.
    pub fn kind(&self) -> ModelKind {
        self.kind
    }

    /// `S` (dimensionless).
    pub fn scale(&self) -> &Matrix3<f64> {
        &self.scale
    }

    /// `S^-1` (dimensionless).
    pub fn scale_inv(&self) -> &Matrix3<f64> {
        &self.scale_inv
    }

    /// `b`, g.
    pub fn bias_g(&self) -> &Vector3<f64> {
        &self.bias_g
    }

    /// The parameters in the 12-vector layout.
    pub fn params(&self) -> ParamVector {
        let mut p = ParamVector::zeros();
        p.fixed_rows_mut::<3>(0).copy_from(&self.bias_g);
        for r in 0..3 {
            for c in 0..3 {
                p[scale_index(r, c)] = self.scale[(r, c)];
            }
        }
        p
    }

    /// The forward model: what the sensor reads (g) for true specific force `a_g` (g).
    pub fn measure(&self, a_g: &Vector3<f64>) -> Vector3<f64> {
        self.scale * a_g + self.bias_g
    }

    /// The correction `a = S^-1 (a' - b)`: true specific force (g) from a reading (g).
    pub fn correct(&self, raw_g: &Vector3<f64>) -> Vector3<f64> {
        self.scale_inv * (raw_g - self.bias_g)
    }

    /// The corrected reading in m/s^2 for a reading in g, using local gravity `gravity_mps2`.
    pub fn correct_mps2(&self, raw_g: &[f64; 3], gravity_mps2: f64) -> [f64; 3] {
        let a = self.correct(&Vector3::from(*raw_g)) * gravity_mps2;
        [a.x, a.y, a.z]
    }

    /// Jacobian of the corrected vector (g) with respect to the 12 parameters, at reading
    /// `raw_g`. Columns of parameters the model holds fixed are zero.
    ///
    /// With `a = S^-1 (a' - b)`: `da/db = -S^-1` and `da/dS_ij = -S^-1 e_i a_j`.
    pub fn correction_jacobian(&self, raw_g: &Vector3<f64>) -> CorrectionJacobian {
        let a = self.correct(raw_g);
        let mut j = CorrectionJacobian::zeros();
        for k in 0..N_PARAMS {
            if !self.kind.is_free(k) {
                continue;
            }
            let col = if k < 3 {
                -self.scale_inv.column(k)
            } else {
                let (row, c) = ((k - 3) / 3, (k - 3) % 3);
                -self.scale_inv.column(row) * a[c]
            };
            j.set_column(k, &col);
        }
        j
    }

    /// The corrected vector (g) and its 3 x 3 covariance (g^2): first-order propagation of the
    /// parameter covariance `param_cov` and of the reading's own covariance `raw_cov` (g^2;
    /// zeros to propagate parameter uncertainty only), `J P J^T + S^-1 R S^-T`.
    pub fn correct_with_covariance(
        &self,
        raw_g: &Vector3<f64>,
        param_cov: &ParamCovariance,
        raw_cov: &Matrix3<f64>,
    ) -> (Vector3<f64>, Matrix3<f64>) {
        let j = self.correction_jacobian(raw_g);
        let cov =
            j * param_cov * j.transpose() + self.scale_inv * raw_cov * self.scale_inv.transpose();
        (self.correct(raw_g), cov)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_full() -> AccelModel {
        let s = Matrix3::new(
            1.01, 0.008, 0.009, -0.006, 0.995, 0.011, -0.010, -0.004, 1.022,
        );
        AccelModel::new(ModelKind::Full, s, Vector3::new(0.09, 0.047, -0.25)).unwrap()
    }

    #[test]
    fn correction_inverts_the_forward_model() {
        let m = sample_full();
        let a = Vector3::new(0.3, -0.5, 0.81);
        let back = m.correct(&m.measure(&a));
        assert!((back - a).norm() < 1e-14);
    }

    #[test]
    fn jacobian_matches_finite_differences() {
        let m = sample_full();
        let raw = Vector3::new(0.4, -0.7, 0.9);
        let j = m.correction_jacobian(&raw);
        let p0 = m.params();
        for k in 0..N_PARAMS {
            let h = 1e-7;
            let mut p = p0;
            p[k] += h;
            let up = AccelModel::from_params(ModelKind::Full, &p)
                .unwrap()
                .correct(&raw);
            p[k] -= 2.0 * h;
            let down = AccelModel::from_params(ModelKind::Full, &p)
                .unwrap()
                .correct(&raw);
            let fd = (up - down) / (2.0 * h);
            assert!(
                (fd - j.column(k)).norm() < 1e-7,
                "parameter {}",
                PARAM_NAMES[k]
            );
        }
    }

    #[test]
    fn fixed_parameters_are_enforced_and_have_zero_jacobian() {
        let mut s = Matrix3::identity();
        s[(0, 1)] = 0.01;
        let err = AccelModel::new(ModelKind::Scale, s, Vector3::zeros()).unwrap_err();
        assert!(
            matches!(err, ModelError::NotInModel { name: "S_xy", .. }),
            "{err}"
        );
        let m = AccelModel::new(
            ModelKind::Scale,
            Matrix3::from_diagonal(&Vector3::new(1.0, 1.1, 0.9)),
            Vector3::zeros(),
        )
        .unwrap();
        let j = m.correction_jacobian(&Vector3::new(0.1, 0.2, 1.0));
        for (k, name) in PARAM_NAMES.iter().enumerate() {
            assert_eq!(
                j.column(k).norm() == 0.0,
                !ModelKind::Scale.is_free(k),
                "{name}"
            );
        }
        assert_eq!(ModelKind::Bias.n_free(), 3);
        assert_eq!(ModelKind::Scale.n_free(), 6);
        assert_eq!(ModelKind::Full.n_free(), 12);
    }

    #[test]
    fn singular_scale_is_refused() {
        let s = Matrix3::new(1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 0.0, 0.0, 1.0);
        assert!(matches!(
            AccelModel::new(ModelKind::Full, s, Vector3::zeros()),
            Err(ModelError::SingularScale { .. })
        ));
    }

    #[test]
    fn covariance_propagation_of_a_bias_only_model() {
        // For the bias-only model a = a' - b, so Cov(a) = Cov(b) + Cov(a').
        let m = AccelModel::new(
            ModelKind::Bias,
            Matrix3::identity(),
            Vector3::new(0.1, 0.0, -0.2),
        )
        .unwrap();
        let mut p = ParamCovariance::zeros();
        p[(0, 0)] = 4e-6;
        p[(1, 1)] = 1e-6;
        p[(0, 1)] = 5e-7;
        p[(1, 0)] = 5e-7;
        let r = Matrix3::from_diagonal_element(1e-6);
        let (_, cov) = m.correct_with_covariance(&Vector3::new(0.0, 0.0, 1.0), &p, &r);
        let expect = p.fixed_view::<3, 3>(0, 0) + r;
        assert!((cov - expect).norm() < 1e-18);
    }
}
