//! Weighted linear least squares per axis with held-out evaluation: the engine of the labelled
//! (model 3) and static (per-session mean) baselines and of every candidate term on them.
//!
//! Per axis `i` the model of observation `o` is `m_oi = sum_c theta_c x_c(o) + alpha_g(o)`:
//! shared columns `x_c` (the model's regressors) and, when the model has them, a free constant
//! `alpha_g` per *group* (a session, or a stretch of a session between gaps). Weights are
//! `1 / v_oi` (the observation's white-noise variance), so the estimates are the maximum
//! likelihood ones under the noise the samples predict.
//!
//! Group constants are eliminated by weighted centring within each group (Frisch-Waugh-Lovell:
//! the shared estimates are those of the full problem); they are then the weighted group means
//! of `m - x theta`. The shared problem is solved by SVD with the minimum-norm solution, so
//! columns that the training data cannot separate (e.g. a pose tilt and a misalignment) do not
//! stop the fit; a held-out observation whose prediction the training data do not determine
//! (its row outside the row space, or its group absent and no data of its own) makes the model
//! *not identifiable* under that validation.
//!
//! Held-out prediction variance (g^2) of an observation of a group seen in training is
//! `1 / W_g + (x - xbar_g)^T C (x - xbar_g)` (`W_g` the group's total weight, `C` the shared
//! covariance `(X^T W X)^+` of the centred problem); without groups it is `x^T C x`. A group
//! absent from training (a held-out session) gets its constant from its own held-out
//! observations; each such constant is counted, since it absorbs one unit of chi-square.

use nalgebra::{DMatrix, DVector};

/// The design of one model on a set of observations.
#[derive(Debug, Clone)]
pub(crate) struct Design {
    /// Per axis, the shared columns, each a value per observation.
    pub columns: [Vec<Vec<f64>>; 3],
    /// Group of each observation, when the model has free group constants.
    pub groups: Option<Vec<usize>>,
}

/// One validation round: the observations fitted and those predicted.
#[derive(Debug, Clone)]
pub(crate) struct Round {
    pub train: Vec<usize>,
    pub eval: Vec<usize>,
}

/// Why a model could not be evaluated.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum LinearError {
    /// A held-out prediction is not determined by the training data.
    NotEstimable { axis: usize },
}

/// Held-out results of one model.
#[derive(Debug, Clone)]
pub(crate) struct HeldOut {
    /// Residual (measured minus predicted, g) per observation and axis; NaN where the
    /// observation was never held out.
    pub resid: Vec<[f64; 3]>,
    /// Prediction variance per observation and axis, g^2.
    pub pred_var: Vec<[f64; 3]>,
    /// Group constants fitted on held-out data (per axis, summed over rounds).
    pub local_params: usize,
    /// Weighted training sum of squares, summed over rounds and axes.
    pub train_chi2: f64,
}

/// A fit of one model on one set of observations (all axes).
#[derive(Debug, Clone)]
pub(crate) struct AxisFit {
    /// Shared coefficients per axis (zeros for columns the data did not use).
    pub theta: [Vec<f64>; 3],
    /// Covariance of the shared coefficients per axis, `(X^T W X)^+`.
    pub cov: [DMatrix<f64>; 3],
    /// Group constants per axis: (group, constant, 1 / total weight).
    pub group_const: [Vec<(usize, f64, f64)>; 3],
    /// Weighted sum of squares per axis.
    pub chi2: [f64; 3],
    /// Rank of the shared design per axis.
    pub rank: [usize; 3],
    /// Distinct groups fitted.
    pub groups: usize,
}

/// The solved training problem of one axis.
struct Solved {
    theta: DVector<f64>,
    /// Scale of each column in the SVD (1 / its weighted centred norm; 0 for a column the
    /// training data hold constant within every group, which is dropped).
    scale: DVector<f64>,
    /// Largest absolute training value of each column (to judge a dropped column at a
    /// held-out point).
    col_max: DVector<f64>,
    /// Right singular vectors of the scaled, weighted (centred) design with non-negligible
    /// singular values, as columns, and the inverse singular values.
    v: DMatrix<f64>,
    inv_s: DVector<f64>,
    /// Group -> (weighted mean of the columns, constant, 1 / weight).
    group: std::collections::HashMap<usize, (DVector<f64>, f64, f64)>,
    chi2: f64,
    rank: usize,
}

/// Group -> (weighted mean of the columns, weighted mean of y, total weight).
type GroupStats = std::collections::HashMap<usize, (DVector<f64>, f64, f64)>;

/// Weighted means of `y` and of each column per group over `rows` (empty without groups).
fn group_means(
    cols: &[Vec<f64>],
    groups: Option<&[usize]>,
    y: &impl Fn(usize) -> f64,
    w: &impl Fn(usize) -> f64,
    rows: &[usize],
) -> GroupStats {
    let p = cols.len();
    let mut gstats = GroupStats::new();
    if let Some(g) = groups {
        for &o in rows {
            let e = gstats
                .entry(g[o])
                .or_insert_with(|| (DVector::zeros(p), 0.0, 0.0));
            let wo = w(o);
            for (c, col) in cols.iter().enumerate() {
                e.0[c] += wo * col[o];
            }
            e.1 += wo * y(o);
            e.2 += wo;
        }
        for e in gstats.values_mut() {
            e.0 /= e.2;
            e.1 /= e.2;
        }
    }
    gstats
}

/// The SVD solution of the scaled design `x` (n x p) for `yv`, singular values below a
/// relative 1e-10 dropped: (theta in scaled units, kept right singular vectors as columns,
/// their inverse singular values, rank).
fn truncated_svd_solve(
    x: &DMatrix<f64>,
    yv: &DVector<f64>,
) -> (DVector<f64>, DMatrix<f64>, DVector<f64>, usize) {
    let (n, p) = x.shape();
    if p == 0 {
        return (
            DVector::zeros(0),
            DMatrix::zeros(0, 0),
            DVector::zeros(0),
            0,
        );
    }
    let svd = x.clone().svd(true, true);
    let s_max = svd.singular_values.max();
    let tol = 1e-10 * s_max.max(f64::MIN_POSITIVE) * (n.max(p) as f64).sqrt();
    let keep: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&k| svd.singular_values[k] > tol)
        .collect();
    let u = svd.u.as_ref().expect("requested U");
    let v_t = svd.v_t.as_ref().expect("requested V^T");
    let mut v = DMatrix::zeros(p, keep.len());
    let mut inv_s = DVector::zeros(keep.len());
    let mut theta = DVector::zeros(p);
    for (j, &k) in keep.iter().enumerate() {
        let s = svd.singular_values[k];
        inv_s[j] = 1.0 / s;
        let coef = u.column(k).dot(yv) / s;
        for c in 0..p {
            v[(c, j)] = v_t[(k, c)];
            theta[c] += coef * v_t[(k, c)];
        }
    }
    (theta, v, inv_s, keep.len())
}

fn solve_axis(
    cols: &[Vec<f64>],
    groups: Option<&[usize]>,
    y: impl Fn(usize) -> f64,
    w: impl Fn(usize) -> f64,
    rows: &[usize],
) -> Solved {
    let p = cols.len();
    let n = rows.len();
    let gstats = group_means(cols, groups, &y, &w, rows);
    let mut x = DMatrix::zeros(n, p);
    let mut yv = DVector::zeros(n);
    for (r, &o) in rows.iter().enumerate() {
        let sw = w(o).sqrt();
        let (xm, ym) = match groups {
            Some(g) => {
                let e = &gstats[&g[o]];
                (Some(&e.0), e.1)
            }
            None => (None, 0.0),
        };
        for (c, col) in cols.iter().enumerate() {
            x[(r, c)] = sw * (col[o] - xm.map_or(0.0, |m| m[c]));
        }
        yv[r] = sw * (y(o) - ym);
    }
    // Columns are scaled to unit norm so that the rank decision does not depend on their
    // units; a column whose centred variation is below 1e-9 of a unit column's is dropped.
    let unit = rows.iter().map(|&o| w(o)).sum::<f64>().sqrt();
    let mut scale = DVector::zeros(p);
    let mut col_max = DVector::zeros(p);
    for c in 0..p {
        let norm = x.column(c).norm();
        if norm > 1e-9 * unit {
            scale[c] = 1.0 / norm;
        }
        col_max[c] = rows.iter().map(|&o| cols[c][o].abs()).fold(0.0, f64::max);
        let sc = scale[c];
        x.column_mut(c).scale_mut(sc);
    }
    let (theta, v, inv_s, rank) = truncated_svd_solve(&x, &yv);
    let resid = &yv - &x * &theta;
    let chi2 = resid.norm_squared();
    // Back to the columns' own units.
    let theta = theta.component_mul(&scale);
    let group = gstats
        .into_iter()
        .map(|(g, (xm, ym, wsum))| {
            let alpha = ym - xm.dot(&theta);
            (g, (xm, alpha, 1.0 / wsum))
        })
        .collect();
    Solved {
        theta,
        v,
        inv_s,
        scale,
        col_max,
        group,
        chi2,
        rank,
    }
}

impl Solved {
    /// The shared part of a prediction at `xc` (the columns' values, centred on the group's
    /// training means when the model has groups): `xc . theta` and its variance, or `None`
    /// when the training data do not determine it (`xc` outside the row space, or non-zero
    /// in a dropped column).
    fn shared(&self, xc: &DVector<f64>) -> Option<(f64, f64)> {
        if xc.is_empty() {
            return Some((0.0, 0.0));
        }
        for c in 0..xc.len() {
            if self.scale[c] == 0.0 && xc[c].abs() > 1e-9 * self.col_max[c].max(1.0) {
                return None;
            }
        }
        let xs = xc.component_mul(&self.scale);
        let q = self.v.transpose() * &xs;
        let outside = xs.norm_squared() - q.norm_squared();
        if outside > 1e-8 * xs.norm_squared().max(1e-300) {
            return None;
        }
        let pv: f64 = q
            .iter()
            .zip(self.inv_s.iter())
            .map(|(a, s)| (a * s) * (a * s))
            .sum();
        Some((xc.dot(&self.theta), pv))
    }

    /// Prediction and its variance at `x` for an observation of group `g` (seen in
    /// training); `None` when the training data do not determine it.
    fn predict(&self, x: &DVector<f64>, g: Option<usize>) -> Option<(f64, f64)> {
        let (xc, base, base_var) = match g {
            Some(g) => {
                let (xm, alpha, inv_w) = self.group.get(&g)?;
                (x - xm, *alpha + xm.dot(&self.theta), *inv_w)
            }
            None => (x.clone(), 0.0, 0.0),
        };
        let (pred, pv) = self.shared(&xc)?;
        Some((base + pred, base_var + pv))
    }
}

/// Fits `design` on the observations `rows` (readings `m`, variances `v`).
pub(crate) fn fit(m: &[[f64; 3]], v: &[[f64; 3]], design: &Design, rows: &[usize]) -> AxisFit {
    let mut theta: [Vec<f64>; 3] = Default::default();
    let mut cov: [DMatrix<f64>; 3] = Default::default();
    let mut group_const: [Vec<(usize, f64, f64)>; 3] = Default::default();
    let mut chi2 = [0.0; 3];
    let mut rank = [0; 3];
    let mut groups = 0;
    for axis in 0..3 {
        let s = solve_axis(
            &design.columns[axis],
            design.groups.as_deref(),
            |o| m[o][axis],
            |o| 1.0 / v[o][axis],
            rows,
        );
        let vs = DMatrix::from_diagonal(&s.inv_s.map(|x| x * x));
        let d = DMatrix::from_diagonal(&s.scale);
        cov[axis] = &d * &s.v * vs * s.v.transpose() * &d;
        theta[axis] = s.theta.iter().copied().collect();
        let mut gc: Vec<(usize, f64, f64)> = s
            .group
            .iter()
            .map(|(g, (_, a, iw))| (*g, *a, *iw))
            .collect();
        gc.sort_by_key(|e| e.0);
        groups = gc.len();
        group_const[axis] = gc;
        chi2[axis] = s.chi2;
        rank[axis] = s.rank;
    }
    AxisFit {
        theta,
        cov,
        group_const,
        chi2,
        rank,
        groups,
    }
}

/// Evaluates `design` over the validation `rounds`.
pub(crate) fn cross_validate(
    m: &[[f64; 3]],
    v: &[[f64; 3]],
    design: &Design,
    rounds: &[Round],
) -> Result<HeldOut, LinearError> {
    let n = m.len();
    let mut resid = vec![[f64::NAN; 3]; n];
    let mut pred_var = vec![[f64::NAN; 3]; n];
    let mut local_params = 0;
    let mut train_chi2 = 0.0;
    let groups = design.groups.as_deref();
    for round in rounds {
        for axis in 0..3 {
            let cols = &design.columns[axis];
            let s = solve_axis(
                cols,
                groups,
                |o| m[o][axis],
                |o| 1.0 / v[o][axis],
                &round.train,
            );
            train_chi2 += s.chi2;
            // Held-out observations of groups absent from training, by group.
            let mut unseen: std::collections::BTreeMap<usize, Vec<(usize, f64)>> =
                std::collections::BTreeMap::new();
            for &o in &round.eval {
                let x = DVector::from_iterator(cols.len(), cols.iter().map(|c| c[o]));
                let g = groups.map(|g| g[o]);
                match (g, g.is_some_and(|g| s.group.contains_key(&g))) {
                    (Some(g), false) => {
                        // Shared part only; the group constant comes from the held-out data.
                        let (pred, pv) = s.shared(&x).ok_or(LinearError::NotEstimable { axis })?;
                        pred_var[o][axis] = pv;
                        unseen.entry(g).or_default().push((o, pred));
                    }
                    _ => {
                        let (pred, pv) =
                            s.predict(&x, g).ok_or(LinearError::NotEstimable { axis })?;
                        resid[o][axis] = m[o][axis] - pred;
                        pred_var[o][axis] = pv;
                    }
                }
            }
            for members in unseen.values() {
                let (mut sw, mut swr) = (0.0, 0.0);
                for &(o, pred) in members {
                    let w = 1.0 / v[o][axis];
                    sw += w;
                    swr += w * (m[o][axis] - pred);
                }
                let alpha = swr / sw;
                for &(o, pred) in members {
                    resid[o][axis] = m[o][axis] - pred - alpha;
                }
                local_params += 1;
            }
        }
    }
    Ok(HeldOut {
        resid,
        pred_var,
        local_params,
        train_chi2,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Straight line through noisy points: the held-out residual of leave-one-out equals the
    /// textbook `e_i / (1 - h_ii)` and its prediction variance `sigma^2 h / (1 - h)`.
    #[test]
    fn leave_one_out_matches_the_hat_matrix_identity() {
        let xs = [0.0, 1.0, 2.0, 3.0, 5.0, 8.0];
        let ys = [0.1, 0.9, 2.2, 2.8, 5.3, 7.9];
        let sigma2 = 0.04;
        let m: Vec<[f64; 3]> = ys.iter().map(|y| [*y; 3]).collect();
        let v = vec![[sigma2; 3]; xs.len()];
        let cols = vec![vec![1.0; xs.len()], xs.to_vec()];
        let design = Design {
            columns: [cols.clone(), cols.clone(), cols],
            groups: None,
        };
        let rounds: Vec<Round> = (0..xs.len())
            .map(|k| Round {
                train: (0..xs.len()).filter(|&j| j != k).collect(),
                eval: vec![k],
            })
            .collect();
        let held = cross_validate(&m, &v, &design, &rounds).unwrap();
        // Full fit and hat values by hand.
        let n = xs.len() as f64;
        let xbar = xs.iter().sum::<f64>() / n;
        let ybar = ys.iter().sum::<f64>() / n;
        let sxx: f64 = xs.iter().map(|x| (x - xbar).powi(2)).sum();
        let slope = xs
            .iter()
            .zip(&ys)
            .map(|(x, y)| (x - xbar) * (y - ybar))
            .sum::<f64>()
            / sxx;
        let icpt = ybar - slope * xbar;
        for k in 0..xs.len() {
            let h = 1.0 / n + (xs[k] - xbar).powi(2) / sxx;
            let e = ys[k] - icpt - slope * xs[k];
            assert!((held.resid[k][0] - e / (1.0 - h)).abs() < 1e-12);
            assert!((held.pred_var[k][0] - sigma2 * h / (1.0 - h)).abs() < 1e-12);
        }
    }

    /// Group constants: the centred solution equals the one with explicit indicator columns,
    /// and a group absent from training gets its constant from its own held-out data.
    #[test]
    fn group_constants_equal_indicator_columns() {
        let t: Vec<f64> = (0..12).map(|k| k as f64).collect();
        let g: Vec<usize> = (0..12).map(|k| k / 4).collect();
        let y: Vec<f64> = (0..12)
            .map(|k| [1.0, -2.0, 0.5][g[k]] + 0.3 * t[k] + 0.01 * ((k * 7) % 5) as f64)
            .collect();
        let m: Vec<[f64; 3]> = y.iter().map(|y| [*y; 3]).collect();
        let v = vec![[1.0; 3]; 12];
        let grouped = Design {
            columns: [vec![t.clone()], vec![t.clone()], vec![t.clone()]],
            groups: Some(g.clone()),
        };
        let ind: Vec<Vec<f64>> = (0..3)
            .map(|j| g.iter().map(|&gi| f64::from(u8::from(gi == j))).collect())
            .collect();
        let mut cols = ind.clone();
        cols.push(t.clone());
        let explicit = Design {
            columns: [cols.clone(), cols.clone(), cols],
            groups: None,
        };
        let all: Vec<usize> = (0..12).collect();
        let a = fit(&m, &v, &grouped, &all);
        let b = fit(&m, &v, &explicit, &all);
        assert!((a.theta[0][0] - b.theta[0][3]).abs() < 1e-12);
        for (j, &(gi, alpha, _)) in a.group_const[0].iter().enumerate() {
            assert_eq!(gi, j);
            assert!((alpha - b.theta[0][j]).abs() < 1e-12);
        }
        assert!((a.chi2[0] - b.chi2[0]).abs() < 1e-12);
        // Hold out group 2 entirely: its constant is refitted on its own data, so the held-out
        // residuals are the deviations from the training slope around their own mean.
        let rounds = [Round {
            train: (0..8).collect(),
            eval: (8..12).collect(),
        }];
        let held = cross_validate(&m, &v, &grouped, &rounds).unwrap();
        assert_eq!(held.local_params, 3);
        let train = fit(&m, &v, &grouped, &(0..8).collect::<Vec<_>>());
        let slope = train.theta[0][0];
        let mean_r = (8..12).map(|k| y[k] - slope * t[k]).sum::<f64>() / 4.0;
        for k in 8..12 {
            assert!((held.resid[k][0] - (y[k] - slope * t[k] - mean_r)).abs() < 1e-12);
        }
    }

    #[test]
    fn an_undetermined_prediction_is_refused() {
        // Column 2 is zero in training but not at the held-out point.
        let m = vec![[1.0; 3], [2.0; 3], [3.0; 3]];
        let v = vec![[1.0; 3]; 3];
        let cols = vec![vec![1.0, 1.0, 1.0], vec![0.0, 0.0, 1.0]];
        let design = Design {
            columns: [cols.clone(), cols.clone(), cols],
            groups: None,
        };
        let rounds = [Round {
            train: vec![0, 1],
            eval: vec![2],
        }];
        assert_eq!(
            cross_validate(&m, &v, &design, &rounds).unwrap_err(),
            LinearError::NotEstimable { axis: 0 }
        );
    }
}
