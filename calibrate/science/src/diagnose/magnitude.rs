//! The label-free baseline with optional reading terms, fitted on block means by
//! Levenberg-Marquardt, and its held-out evaluation.
//!
//! Model (g, sensor frame): `m_o = S a_o + b + sum_c beta_c x_c(o) e_axis(c)` with `|a_o| = 1`
//! and unknown directions `a_o`; with `T = S^-1` upper triangular (see [`crate::labelfree`]) the
//! residual of observation `o` is the magnitude error `|T (m_o - b - sum_c beta_c x_c(o)
//! e_axis(c))| - 1` (g), which a term can only change along the corrected direction. Each
//! residual is weighted by the white-noise sigma of that magnitude, `sqrt(sum_i ((T^T u)_i^2
//! v_oi))` with `u` the corrected direction, evaluated at the start of each fit and held fixed.
//!
//! Held-out prediction variance of an observation is `j^T (J^T J)^-1 j` (g^2), with `J` the
//! weighted training Jacobian and `j` the held-out observation's unweighted Jacobian row.

use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::storage::Owned;
use nalgebra::{DMatrix, DVector, Dyn, Matrix3, Vector3};

use crate::fit::{Pose, Weighting};
use crate::labelfree::{LabelFreeError, fit_label_free};

/// Position of `T[row][col]` (upper triangle) in the parameter vector after the 3 biases.
const T_INDEX: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

/// One reading term: its axis and its regressor value per observation.
#[derive(Debug, Clone)]
pub(crate) struct Term {
    pub axis: usize,
    pub values: Vec<f64>,
}

/// A fitted label-free model with terms.
#[derive(Debug, Clone)]
pub(crate) struct MagnitudeFit {
    /// `[b (3), T upper triangle (6), beta (one per term)]`.
    pub x: DVector<f64>,
    /// Weighted sum of squares.
    pub chi2: f64,
    /// `(J^T J)^-1` of the weighted problem (parameter covariance with absolute sigmas).
    pub cov: DMatrix<f64>,
}

impl MagnitudeFit {
    /// `b`, g.
    pub fn bias(&self) -> Vector3<f64> {
        Vector3::new(self.x[0], self.x[1], self.x[2])
    }

    /// `T = S^-1`.
    pub fn t(&self) -> Matrix3<f64> {
        t_matrix(&self.x)
    }
}

fn t_matrix(x: &DVector<f64>) -> Matrix3<f64> {
    let mut t = Matrix3::zeros();
    for (k, &(r, c)) in T_INDEX.iter().enumerate() {
        t[(r, c)] = x[3 + k];
    }
    t
}

/// The corrected vector `T (m_o - b - terms)` of observation `o`.
pub(crate) fn corrected(x: &DVector<f64>, terms: &[Term], m: &[f64; 3], o: usize) -> Vector3<f64> {
    let mut y = Vector3::new(m[0] - x[0], m[1] - x[1], m[2] - x[2]);
    for (c, term) in terms.iter().enumerate() {
        y[term.axis] -= x[9 + c] * term.values[o];
    }
    t_matrix(x) * y
}

/// Magnitude residual (g) of observation `o` at `x` (with `t = T(x)`), writing its unweighted
/// Jacobian row into `row` (length `9 + terms`).
fn residual_row(
    x: &DVector<f64>,
    t: &Matrix3<f64>,
    terms: &[Term],
    m: &[f64; 3],
    o: usize,
    mut row: impl FnMut(usize, f64),
) -> f64 {
    let mut y = Vector3::new(m[0] - x[0], m[1] - x[1], m[2] - x[2]);
    for (c, term) in terms.iter().enumerate() {
        y[term.axis] -= x[9 + c] * term.values[o];
    }
    let z = t * y;
    let norm = z.norm();
    let u = z / norm;
    let g = t.transpose() * u;
    for a in 0..3 {
        row(a, -g[a]);
    }
    for (k, &(r, c)) in T_INDEX.iter().enumerate() {
        row(3 + k, u[r] * y[c]);
    }
    for (c, term) in terms.iter().enumerate() {
        row(9 + c, -g[term.axis] * term.values[o]);
    }
    norm - 1.0
}

/// White-noise sigma (g) of the magnitude residual of observation `o` at `x`.
pub(crate) fn magnitude_sigma(
    x: &DVector<f64>,
    terms: &[Term],
    m: &[f64; 3],
    v: &[f64; 3],
    o: usize,
) -> f64 {
    let t = t_matrix(x);
    let z = corrected(x, terms, m, o);
    let g = t.transpose() * (z / z.norm());
    (0..3).map(|i| g[i] * g[i] * v[i]).sum::<f64>().sqrt()
}

struct Problem<'a> {
    m: &'a [[f64; 3]],
    terms: &'a [Term],
    rows: &'a [usize],
    sigma: Vec<f64>,
    x: DVector<f64>,
    /// Weighted residuals and Jacobian at `x` (computed together: they share every
    /// intermediate).
    cache: (DVector<f64>, DMatrix<f64>),
}

impl Problem<'_> {
    fn eval(&self) -> (DVector<f64>, DMatrix<f64>) {
        let p = self.x.len();
        let t = t_matrix(&self.x);
        let mut r = DVector::zeros(self.rows.len());
        let mut j = DMatrix::zeros(self.rows.len(), p);
        for (k, &o) in self.rows.iter().enumerate() {
            let inv = 1.0 / self.sigma[k];
            let res = residual_row(&self.x, &t, self.terms, &self.m[o], o, |c, v| {
                j[(k, c)] = v * inv;
            });
            r[k] = res * inv;
        }
        (r, j)
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
        self.cache = self.eval();
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        Some(self.cache.0.clone())
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        Some(self.cache.1.clone())
    }
}

/// Why a label-free fit failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum MagnitudeError {
    /// The baseline could not be started.
    #[error(transparent)]
    Start(#[from] LabelFreeError),
    /// The terms are not determined by the data (singular Jacobian).
    #[error("the terms are not determined by these observations")]
    Singular,
}

/// The starting point of a fit on `rows`: the label-free fit of the poses those rows belong to
/// (block means averaged per pose, weighted by their sample counts).
pub(crate) fn start(
    m: &[[f64; 3]],
    v: &[[f64; 3]],
    n: &[usize],
    pose: &[usize],
    rows: &[usize],
) -> Result<DVector<f64>, MagnitudeError> {
    let mut acc: std::collections::BTreeMap<usize, (Vector3<f64>, Vector3<f64>, usize)> =
        std::collections::BTreeMap::new();
    for &o in rows {
        let e = acc
            .entry(pose[o])
            .or_insert((Vector3::zeros(), Vector3::zeros(), 0));
        let w = n[o] as f64;
        e.0 += Vector3::from(m[o]) * w;
        // Per-sample variance from the block's variance of the mean.
        e.1 += Vector3::from(v[o]) * (w * w);
        e.2 += n[o];
    }
    let poses: Vec<Pose> = acc
        .values()
        .map(|(s, var_sum, count)| {
            let c = *count as f64;
            // var(mean) = sum n_k^2 v_k / c^2; per-sample std = sqrt(var(mean) c).
            let std = (var_sum / c).map(f64::sqrt);
            Pose {
                truth_g: Vector3::zeros(),
                mean_g: s / c,
                std_g: std,
                n: Some(*count),
            }
        })
        .collect();
    let fit = fit_label_free(&poses, Weighting::PoseStd)?;
    let t = fit.model.scale_inv();
    let mut x = DVector::zeros(9);
    for a in 0..3 {
        x[a] = fit.model.bias_g()[a];
    }
    for (k, &(r, c)) in T_INDEX.iter().enumerate() {
        x[3 + k] = t[(r, c)];
    }
    Ok(x)
}

/// Fits the terms and the baseline on `rows`, starting from `x0` (9 baseline parameters).
pub(crate) fn fit(
    m: &[[f64; 3]],
    v: &[[f64; 3]],
    terms: &[Term],
    rows: &[usize],
    x0: &DVector<f64>,
) -> Result<MagnitudeFit, MagnitudeError> {
    let mut x = DVector::zeros(9 + terms.len());
    x.rows_mut(0, 9).copy_from(&x0.rows(0, 9));
    let sigma: Vec<f64> = rows
        .iter()
        .map(|&o| magnitude_sigma(&x, terms, &m[o], &v[o], o))
        .collect();
    let mut problem = Problem {
        m,
        terms,
        rows,
        sigma,
        x,
        cache: (DVector::zeros(0), DMatrix::zeros(0, 0)),
    };
    problem.cache = problem.eval();
    let (problem, _report) = LevenbergMarquardt::new()
        .with_patience(100)
        .minimize(problem);
    let (r, j) = problem.cache;
    let svd = j.svd(false, true);
    let s_max = svd.singular_values.max();
    if svd.singular_values.min() <= 1e-9 * s_max {
        return Err(MagnitudeError::Singular);
    }
    let v_t = svd.v_t.expect("requested V^T");
    let inv_s2 = DMatrix::from_diagonal(&svd.singular_values.map(|s| 1.0 / (s * s)));
    let cov = v_t.transpose() * inv_s2 * v_t;
    Ok(MagnitudeFit {
        x: problem.x,
        chi2: r.norm_squared(),
        cov,
    })
}

/// The weighted sum of squares after one Gauss-Newton step from `x0` (9 baseline
/// parameters, terms at zero) with the terms added: the first-order fit of the terms, used to
/// compare candidate shapes (e.g. warm-up time constants) without a full fit each.
pub(crate) fn linearized_chi2(
    m: &[[f64; 3]],
    v: &[[f64; 3]],
    terms: &[Term],
    rows: &[usize],
    x0: &DVector<f64>,
) -> f64 {
    let mut x = DVector::zeros(9 + terms.len());
    x.rows_mut(0, 9).copy_from(&x0.rows(0, 9));
    let sigma: Vec<f64> = rows
        .iter()
        .map(|&o| magnitude_sigma(&x, terms, &m[o], &v[o], o))
        .collect();
    let problem = Problem {
        m,
        terms,
        rows,
        sigma,
        x,
        cache: (DVector::zeros(0), DMatrix::zeros(0, 0)),
    };
    let (r, j) = problem.eval();
    let svd = j.svd(true, false);
    let u = svd.u.expect("requested U");
    let s_max = svd.singular_values.max();
    // r minus its projection on the column space of J.
    let mut proj = DVector::zeros(r.len());
    for (k, s) in svd.singular_values.iter().enumerate() {
        if *s > 1e-12 * s_max {
            let col = u.column(k);
            proj += col * col.dot(&r);
        }
    }
    (r - proj).norm_squared()
}

/// Held-out residual (g) and prediction variance (g^2) of observation `o` under `fit`; `None`
/// when a term is zero throughout training but not at `o`.
pub(crate) fn predict(
    fit: &MagnitudeFit,
    terms: &[Term],
    m: &[f64; 3],
    o: usize,
    trained: &[bool],
) -> Option<(f64, f64)> {
    for (c, term) in terms.iter().enumerate() {
        if !trained[c] && term.values[o] != 0.0 {
            return None;
        }
    }
    let mut row = DVector::zeros(fit.x.len());
    let res = residual_row(&fit.x, &fit.t(), terms, m, o, |c, v| row[c] = v);
    let pv = (row.transpose() * &fit.cov * &row)[(0, 0)];
    Some((res, pv))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    /// A bias drift added to readings of many orientations is recovered by the magnitude fit.
    #[test]
    fn recovers_a_drift_term_with_the_model() {
        let s = Matrix3::new(1.02, 0.01, -0.005, 0.0, 0.98, 0.012, 0.0, 0.0, 1.01);
        let b = Vector3::new(0.05, -0.03, 0.08);
        let drift = Vector3::new(2e-4, -1e-4, 3e-4);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let mut m = Vec::new();
        let mut pose = Vec::new();
        let mut t = Vec::new();
        for p in 0..16 {
            let d = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal)).normalize();
            for k in 0..10 {
                let time = (p * 10 + k) as f64;
                let r = s * d + b + drift * time;
                m.push([r.x, r.y, r.z]);
                pose.push(p);
                t.push(time);
            }
        }
        let n_obs = m.len();
        let v = vec![[1e-8; 3]; n_obs];
        let n = vec![1000; n_obs];
        let rows: Vec<usize> = (0..n_obs).collect();
        let x0 = start(&m, &v, &n, &pose, &rows).unwrap();
        let terms: Vec<Term> = (0..3)
            .map(|axis| Term {
                axis,
                values: t.clone(),
            })
            .collect();
        let f = fit(&m, &v, &terms, &rows, &x0).unwrap();
        for i in 0..3 {
            assert!((f.x[9 + i] - drift[i]).abs() < 1e-9, "{}", f.x[9 + i]);
            assert!((f.bias()[i] - b[i]).abs() < 1e-7);
        }
        let t_true = s.try_inverse().unwrap();
        assert!((f.t() - t_true).norm() < 1e-7);
        assert!(f.chi2 < 1e-6);
    }
}
