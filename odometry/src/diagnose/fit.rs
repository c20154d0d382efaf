//! Weighted least squares of the rows on a set of candidates, and its held-out score: each
//! group of rows (one rest, one motion) predicted by the fit to all the others, as
//! `mems-calibrate diagnose` scores its candidates (`calibrate_science::diagnose`): the
//! chi-square gain over no correction, in units of the rows' white noise.

use nalgebra::{DMatrix, DVector};

use super::rows::{Candidate, Row};

/// A fit of a set of candidates.
#[derive(Debug, Clone)]
pub struct Fit {
    /// The candidates, in their parameter order (three parameters each).
    pub candidates: Vec<Candidate>,
    /// The parameters.
    pub theta: DVector<f64>,
    /// Their 1-sigma from the rows' noise.
    pub sigma: DVector<f64>,
    /// Held-out chi-square gain over no correction (white-noise units).
    pub gain: f64,
    /// In-sample residuals, one per row.
    pub residuals: Vec<f64>,
}

fn design(rows: &[Row], candidates: &[Candidate]) -> DMatrix<f64> {
    let cols: Vec<usize> = candidates
        .iter()
        .map(|c| Candidate::ALL.iter().position(|a| a == c).unwrap_or(0))
        .collect();
    DMatrix::from_fn(rows.len(), 3 * cols.len(), |i, j| {
        rows[i].design[cols[j / 3]][j % 3]
    })
}

/// `X' W X` with a tiny ridge: columns the rows do not constrain (a candidate with no rows:
/// all zero) stay 0, with a huge sigma.
fn regularized(xtwx: &DMatrix<f64>) -> DMatrix<f64> {
    let n = xtwx.nrows();
    let scale = (0..n).map(|i| xtwx[(i, i)]).fold(0.0, f64::max).max(1e-300);
    xtwx + DMatrix::identity(n, n) * (scale * 1e-12)
}

/// Solves the weighted normal equations `(X' W X + ridge) theta = X' W r`.
fn solve(xtwx: &DMatrix<f64>, xtwr: &DVector<f64>) -> Option<DVector<f64>> {
    regularized(xtwx).cholesky().map(|c| c.solve(xtwr))
}

/// Fits `candidates` to `rows` and scores the fit on held-out groups.
pub fn fit(rows: &[Row], candidates: &[Candidate]) -> Option<Fit> {
    let x = design(rows, candidates);
    let w = DVector::from_iterator(rows.len(), rows.iter().map(|r| 1.0 / r.sigma.powi(2)));
    let r = DVector::from_iterator(rows.len(), rows.iter().map(|r| r.r));
    let xt_w = x.transpose() * DMatrix::from_diagonal(&w);
    let xtwx = &xt_w * &x;
    let xtwr = &xt_w * &r;
    let theta = solve(&xtwx, &xtwr)?;
    let cov = regularized(&xtwx).cholesky()?.inverse();
    let sigma = DVector::from_iterator(
        cov.nrows(),
        (0..cov.nrows()).map(|i| cov[(i, i)].max(0.0).sqrt()),
    );
    let fitted = &x * &theta;
    let residuals = (0..rows.len()).map(|i| r[i] - fitted[i]).collect();
    let mut gain = 0.0;
    let last_group = rows.iter().map(|r| r.group).max().unwrap_or(0);
    for group in 0..=last_group {
        let idx: Vec<usize> = (0..rows.len())
            .filter(|&i| rows[i].group == group)
            .collect();
        if idx.is_empty() {
            continue;
        }
        let (mut a, mut b) = (xtwx.clone(), xtwr.clone());
        for &i in &idx {
            let xi = x.row(i).transpose();
            a -= &xi * xi.transpose() * w[i];
            b -= &xi * (w[i] * r[i]);
        }
        let Some(held) = solve(&a, &b) else { continue };
        for &i in &idx {
            let predicted = (x.row(i) * &held)[0];
            gain += w[i] * (r[i].powi(2) - (r[i] - predicted).powi(2));
        }
    }
    Some(Fit {
        candidates: candidates.to_vec(),
        theta,
        sigma,
        gain,
        residuals,
    })
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::diagnose::rows::Kind;

    /// Magnitude rows of rests in spread attitudes, whose residual is a bias `b` along each
    /// rest's gravity direction plus a deterministic +-`noise` pattern.
    fn rows(b: Vector3<f64>, noise: f64) -> Vec<Row> {
        (0..24)
            .map(|k| {
                let a = k as f64 * 0.7;
                let u = Vector3::new(
                    a.cos() * (0.3 * a).sin(),
                    a.sin() * (0.3 * a).sin(),
                    (0.3 * a).cos(),
                )
                .normalize();
                let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
                Row {
                    kind: Kind::Magnitude,
                    group: k,
                    r: u.dot(&b) + sign * noise,
                    sigma: noise.max(1e-6),
                    floor: 0.0,
                    design: std::array::from_fn(|c| match c {
                        0 => u,
                        1 => u.component_mul(&u) * 9.8,
                        _ => Vector3::zeros(),
                    }),
                }
            })
            .collect()
    }

    #[test]
    fn a_bias_is_recovered_and_scores_on_held_out_rests() {
        let b = Vector3::new(0.05, -0.03, 0.02);
        let f = fit(&rows(b, 1e-3), &[Candidate::AccelBias]).unwrap();
        for i in 0..3 {
            assert!(
                (f.theta[i] - b[i]).abs() < 3e-3,
                "{} against {}",
                f.theta[i],
                b[i]
            );
        }
        assert!(f.gain > 1000.0, "gain {}", f.gain);
    }

    #[test]
    fn noise_alone_gains_nothing_held_out() {
        let f = fit(&rows(Vector3::zeros(), 1e-3), &[Candidate::AccelBias]).unwrap();
        assert!(f.gain < 12.0, "gain {}", f.gain);
    }

    #[test]
    fn a_candidate_without_rows_stays_zero() {
        let f = fit(
            &rows(Vector3::new(0.05, 0.0, 0.0), 1e-3),
            &[Candidate::GyroScale],
        )
        .unwrap();
        assert!(f.theta.iter().all(|t| *t == 0.0), "{:?}", f.theta);
        assert!(f.gain.abs() < 1e-9);
    }
}
