//! Fit of the three-term noise model to an Allan curve, with the parameters' uncertainty.
//!
//! Model (IEEE Std 952-1997, annex C), for a rate series in unit `u` (m/s^2 or rad/s):
//! `AVAR(tau) = N^2 / tau + (2 ln 2 / pi) B^2 + K^2 tau / 3`, with
//! - `N`, white noise density (velocity / angle random walk), `u / sqrt(Hz)` (= `u sqrt(s)`);
//! - `B`, bias instability, `u` (the Allan deviation floor is `0.664 B`);
//! - `K`, rate random walk (Kalibr's "random walk"), `u sqrt(Hz)` (= `u / sqrt(s)`).
//!
//! The fit is linear in `p = (N^2, B^2, K^2)`: generalised least squares with the covariance
//! of the Allan variance estimates, constrained to `p >= 0` (exact NNLS by enumerating the
//! faces of the orthant). The covariance is that of the model being fitted, for this record's
//! length and segments ([`crate::covariance`]): its diagonal is `2 AVAR^2 / edf` (the
//! equivalent degrees of freedom that set the chi-squared confidence intervals), and its
//! off-diagonal terms carry the correlation of cluster times that share most of their data
//! (ignoring it, the Monte Carlo test finds the truth within 1 sigma of N in only 44% of the
//! records: the sigmas come out about 1.7x too small). The first iteration
//! uses the measured variances with white-noise degrees of freedom (Howe, Allan & Barnes) and
//! no correlation.
//!
//! The model and the covariance are iterated to convergence. The parameters' covariance is
//! `(X' C^-1 X)^-1`, inflated by the reduced chi-squared when that exceeds 1 (model misfit).
//! A term is reported when its `p_k` is at least twice its sigma; otherwise the result says why
//! and gives a 2-sigma upper limit from the unconstrained fit.

use calibrate::noise_params::{AxisNoise, Estimate, UpperLimits};
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::allan::{self, AllanCurve, NoiseKind};
use crate::covariance;

/// `2 ln 2 / pi`: the Allan variance of flicker rate noise per `B^2`.
pub const FLICKER_FACTOR: f64 = 2.0 * std::f64::consts::LN_2 / std::f64::consts::PI;

/// A term is reported when its squared coefficient is at least this many sigmas from zero.
pub const SIGNIFICANCE: f64 = 2.0;

/// Fewest cluster times a fit needs.
pub const MIN_POINTS: usize = 4;

/// Iterations of the model / covariance loop at most.
const MAX_ITERATIONS: usize = 30;

/// The outcome for one coefficient (`N`, `B` or `K`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum Term {
    /// Significant: the coefficient and its 1-sigma (delta method from `p_k`).
    Resolved {
        /// The coefficient (`N`, `B` or `K`) in its unit.
        value: f64,
        /// Its 1-sigma.
        sigma: f64,
    },
    /// Not significant: a 2-sigma upper limit and why.
    Unresolved {
        /// `sqrt(max(p_k, 0) + 2 sigma_k)` from the unconstrained fit, in the coefficient's
        /// unit.
        upper_limit: f64,
        /// Why the record cannot determine the term.
        reason: String,
    },
}

impl Term {
    /// The value and sigma when resolved.
    pub fn resolved(&self) -> Option<(f64, f64)> {
        match *self {
            Self::Resolved { value, sigma } => Some((value, sigma)),
            Self::Unresolved { .. } => None,
        }
    }

    /// The value when resolved, else the upper limit: a conservative figure for consumers that
    /// need a number.
    pub fn value_or_limit(&self) -> f64 {
        match *self {
            Self::Resolved { value, .. } => value,
            Self::Unresolved { upper_limit, .. } => upper_limit,
        }
    }
}

/// One cluster time with the fit's view of it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitPoint {
    /// Cluster time, s.
    pub tau_s: f64,
    /// Measured Allan deviation, u.
    pub adev: f64,
    /// 1-sigma confidence interval of the Allan deviation, u.
    pub adev_low: f64,
    /// Upper end of the interval, u.
    pub adev_high: f64,
    /// Equivalent degrees of freedom used for the interval.
    pub edf: f64,
    /// The fitted model's Allan deviation, u.
    pub model_adev: f64,
    /// The noise that dominates the model here (it sets the degrees of freedom).
    pub dominant: NoiseKind,
    /// Overlapping differences averaged.
    pub terms: usize,
}

/// The fitted noise model of one axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelFit {
    /// White noise density `N`, u/sqrt(Hz).
    pub white: Term,
    /// Bias instability `B`, u.
    pub bias_instability: Term,
    /// Rate random walk `K`, u sqrt(Hz).
    pub random_walk: Term,
    /// Constrained estimate of `(N^2, B^2, K^2)`.
    pub coefficients: [f64; 3],
    /// Covariance of `coefficients` (rows and columns of terms fixed at zero are zero).
    pub covariance: [[f64; 3]; 3],
    /// Generalised chi-squared of the fit.
    pub chi2: f64,
    /// Degrees of freedom (cluster times minus free terms).
    pub dof: usize,
    /// Cluster times, with intervals and the model.
    pub points: Vec<FitPoint>,
}

/// Why a curve cannot be fitted.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FitError {
    /// Too few cluster times (the record is too short).
    #[error(
        "only {found} cluster times (the longest gap-free stretch holds {longest} samples); \
         the fit needs at least {MIN_POINTS}, i.e. a stretch of at least 16 samples"
    )]
    TooFewPoints {
        /// Cluster times available.
        found: usize,
        /// Samples in the longest segment.
        longest: usize,
    },
    /// A variance is not positive and finite (a constant or broken series).
    #[error(
        "the Allan variance at tau = {tau_s} s is {avar}: the series is constant or not finite"
    )]
    Degenerate {
        /// The cluster time.
        tau_s: f64,
        /// The offending value.
        avar: f64,
    },
}

/// The regressors `(1/tau, 2 ln2/pi, tau/3)` at `tau_s`.
pub fn regressors(tau_s: f64) -> [f64; 3] {
    [1.0 / tau_s, FLICKER_FACTOR, tau_s / 3.0]
}

/// The model's Allan variance at `tau_s` for coefficients `p = (N^2, B^2, K^2)`.
pub fn model_avar(p: &[f64; 3], tau_s: f64) -> f64 {
    regressors(tau_s).iter().zip(p).map(|(x, p)| x * p).sum()
}

/// The least-squares problem, and what is needed to rebuild its covariance.
struct Problem<'a> {
    taus: Vec<f64>,
    avars: Vec<f64>,
    /// Per point: overlapping differences averaged (all segments).
    terms: Vec<f64>,
    basis: &'a CovarianceBasis,
}

/// The lag sums of [`crate::covariance`] for a grid of cluster sizes, a sample interval and a
/// set of segment lengths: they do not depend on the noise, so the series analysed on the same
/// grid (the axes of one recording) share them.
#[derive(Debug, Clone, PartialEq)]
pub struct CovarianceBasis {
    sizes: Vec<usize>,
    tau0_s: f64,
    segment_lengths: Vec<usize>,
    /// Per pair (i <= j) of sizes, row-major upper triangle.
    sums: Vec<[f64; covariance::PAIRS]>,
}

impl CovarianceBasis {
    /// The lag sums for the cluster sizes, sample interval and segments of `curve`.
    pub fn for_curve(curve: &AllanCurve) -> Self {
        let sizes: Vec<usize> = curve.points.iter().map(|p| p.m).collect();
        let t = sizes.len();
        let mut sums = Vec::with_capacity(t * (t + 1) / 2);
        for i in 0..t {
            for j in i..t {
                sums.push(covariance::pair_sums(
                    sizes[i],
                    sizes[j],
                    &curve.segment_lengths,
                    curve.tau0_s,
                ));
            }
        }
        Self {
            sizes,
            tau0_s: curve.tau0_s,
            segment_lengths: curve.segment_lengths.clone(),
            sums,
        }
    }

    /// Whether the basis was computed for `curve`'s cluster sizes, interval and segments.
    pub fn matches(&self, curve: &AllanCurve) -> bool {
        self.tau0_s == curve.tau0_s
            && self.segment_lengths == curve.segment_lengths
            && self.sizes.iter().eq(curve.points.iter().map(|p| &p.m))
    }
}

/// A weighted least-squares solution on a subset of the terms.
struct Solution {
    p: [f64; 3],
    covariance: [[f64; 3]; 3],
    chi2: f64,
    free: usize,
}

impl<'a> Problem<'a> {
    fn new(curve: &AllanCurve, basis: &'a CovarianceBasis) -> Self {
        Self {
            taus: curve.points.iter().map(|p| p.tau_s).collect(),
            avars: curve.points.iter().map(|p| p.avar).collect(),
            terms: curve.points.iter().map(|p| p.terms as f64).collect(),
            basis,
        }
    }

    fn len(&self) -> usize {
        self.taus.len()
    }

    /// `Cov(A_i, A_j)` under model `p` (see [`crate::covariance`]).
    fn covariance(&self, i: usize, j: usize, p: &[f64; 3]) -> f64 {
        let (i, j) = (i.min(j), i.max(j));
        let t = self.len();
        let index = i * t - i * (i + 1) / 2 + j;
        let sum: f64 = covariance::PAIR_INDICES
            .iter()
            .zip(&self.basis.sums[index])
            .map(|(&(k, l), v)| {
                let multiplicity = if k == l { 1.0 } else { 2.0 };
                multiplicity * p[k] * p[l] * v
            })
            .sum();
        sum / (2.0 * self.terms[i] * self.terms[j])
    }

    /// Standard deviations and correlation matrix of the estimates under model `p`.
    fn covariance_matrix(&self, p: &[f64; 3]) -> (Vec<f64>, DMatrix<f64>) {
        let t = self.len();
        let sd: Vec<f64> = (0..t).map(|i| self.covariance(i, i, p).sqrt()).collect();
        let correlation = DMatrix::from_fn(t, t, |i, j| {
            if i == j {
                1.0
            } else if sd[i] > 0.0 && sd[j] > 0.0 {
                (self.covariance(i, j, p) / (sd[i] * sd[j])).clamp(-1.0, 1.0)
            } else {
                0.0
            }
        });
        (sd, correlation)
    }

    /// Solves the GLS problem for the terms in `mask` (bit k = term k free) with covariance
    /// `diag(sd) * correlation * diag(sd)`, given as the whitening matrix.
    fn solve(&self, whitening: &DMatrix<f64>, mask: u8) -> Option<Solution> {
        let free: Vec<usize> = (0..3).filter(|k| mask & (1 << k) != 0).collect();
        let t = self.len();
        let y = whitening * DVector::from_vec(self.avars.clone());
        if free.is_empty() {
            return Some(Solution {
                p: [0.0; 3],
                covariance: [[0.0; 3]; 3],
                chi2: y.norm_squared(),
                free: 0,
            });
        }
        let raw = DMatrix::from_fn(t, free.len(), |i, c| regressors(self.taus[i])[free[c]]);
        let x = whitening * raw;
        // Column scaling keeps the normal equations well conditioned (1/tau and tau span
        // many decades).
        let scales: Vec<f64> = (0..free.len()).map(|c| x.column(c).norm()).collect();
        if scales.iter().any(|&s| s == 0.0 || !s.is_finite()) {
            return None;
        }
        let xs = DMatrix::from_fn(t, free.len(), |i, c| x[(i, c)] / scales[c]);
        let normal = xs.transpose() * &xs;
        let inverse = normal.try_inverse()?;
        let beta = &inverse * xs.transpose() * &y;
        let residual = &y - &xs * &beta;
        let mut p = [0.0; 3];
        let mut covariance = [[0.0; 3]; 3];
        for (a, &ka) in free.iter().enumerate() {
            p[ka] = beta[a] / scales[a];
            for (b, &kb) in free.iter().enumerate() {
                covariance[ka][kb] = inverse[(a, b)] / (scales[a] * scales[b]);
            }
        }
        Some(Solution {
            p,
            covariance,
            chi2: residual.norm_squared(),
            free: free.len(),
        })
    }

    /// The whitening matrix `W` with `W' W = C^-1` for standard deviations `sd` and a
    /// correlation matrix (eigenvalues floored so that an approximate correlation matrix
    /// stays positive definite).
    fn whitening(sd: &[f64], correlation: DMatrix<f64>) -> DMatrix<f64> {
        let t = sd.len();
        let eigen = SymmetricEigen::new(correlation);
        let largest = eigen.eigenvalues.max();
        let floor = largest * 1e-9;
        let mut w = eigen.eigenvectors.transpose();
        for (r, &lambda) in eigen.eigenvalues.iter().enumerate() {
            let scale = 1.0 / lambda.max(floor).sqrt();
            for c in 0..t {
                w[(r, c)] *= scale / sd[c];
            }
        }
        w
    }

    /// Non-negative GLS: the best solution over every face of the orthant.
    fn nnls(&self, whitening: &DMatrix<f64>) -> Solution {
        (0u8..8)
            .filter_map(|mask| self.solve(whitening, mask))
            .filter(|s| s.p.iter().all(|&v| v >= 0.0))
            .min_by(|a, b| a.chi2.total_cmp(&b.chi2))
            .expect("the empty model is always feasible")
    }
}

/// The noise that dominates model `p` at `tau_s`.
fn dominant(p: &[f64; 3], tau_s: f64) -> NoiseKind {
    let x = regressors(tau_s);
    let contributions = [x[0] * p[0], x[1] * p[1], x[2] * p[2]];
    let kinds = [NoiseKind::White, NoiseKind::Flicker, NoiseKind::RandomWalk];
    let (k, _) = contributions
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .expect("three terms");
    kinds[k]
}

/// Fits the noise model to an Allan curve (see the module documentation).
pub fn fit(curve: &AllanCurve) -> Result<ModelFit, FitError> {
    fit_with(curve, &CovarianceBasis::for_curve(curve))
}

/// Checks that the curve has enough points and that each is a finite positive variance.
fn check_curve(curve: &AllanCurve) -> Result<(), FitError> {
    if curve.points.len() < MIN_POINTS {
        return Err(FitError::TooFewPoints {
            found: curve.points.len(),
            longest: curve.segment_lengths.iter().copied().max().unwrap_or(0),
        });
    }
    if let Some(bad) = curve
        .points
        .iter()
        .find(|p| !(p.avar.is_finite() && p.avar > 0.0))
    {
        return Err(FitError::Degenerate {
            tau_s: bad.tau_s,
            avar: bad.avar,
        });
    }
    Ok(())
}

/// Iteratively reweighted non-negative least squares: starts from independent points with
/// white-noise degrees of freedom and the measured variances, then weights by the model's own
/// covariance until the model curve settles. Returns the solution and its whitening.
fn reweighted_fit(
    problem: &Problem,
    curve: &AllanCurve,
    white_edf: &[f64],
) -> (Solution, DMatrix<f64>) {
    let t = problem.len();
    let sd: Vec<f64> = curve
        .points
        .iter()
        .zip(white_edf)
        .map(|(point, &edf)| point.avar * (2.0 / edf).sqrt())
        .collect();
    let floor = sd.iter().map(|s| 1e-3 * s).collect::<Vec<f64>>();
    let mut whitening = Problem::whitening(&sd, DMatrix::identity(t, t));
    let mut solution = problem.nnls(&whitening);
    for _ in 0..MAX_ITERATIONS {
        let p = solution.p;
        // The model's covariance (not the measurement's) avoids weighting low fluctuations
        // up; a floor keeps a degenerate model usable.
        let (model_sd, correlation) = problem.covariance_matrix(&p);
        let sd: Vec<f64> = model_sd
            .iter()
            .zip(&floor)
            .map(|(s, f)| s.max(*f))
            .collect();
        whitening = Problem::whitening(&sd, correlation);
        let next = problem.nnls(&whitening);
        let change = problem
            .taus
            .iter()
            .map(|&tau| {
                let (a, b) = (model_avar(&p, tau), model_avar(&next.p, tau));
                (a - b).abs() / a.max(b).max(f64::MIN_POSITIVE)
            })
            .fold(0.0, f64::max);
        solution = next;
        if change < 1e-7 {
            break;
        }
    }
    (solution, whitening)
}

/// The three terms of coefficients `p` with covariance `covariance`: resolved when
/// significant, otherwise an upper limit (from the `unconstrained` fit where there is one,
/// its covariance scaled by `inflation`).
fn terms(
    p: &[f64; 3],
    covariance: &[[f64; 3]; 3],
    unconstrained: Option<&Solution>,
    inflation: f64,
    tau_range: (f64, f64),
) -> [Term; 3] {
    std::array::from_fn(|k| {
        let sigma = covariance[k][k].sqrt();
        if p[k] > 0.0 && p[k] >= SIGNIFICANCE * sigma {
            let value = p[k].sqrt();
            Term::Resolved {
                value,
                sigma: sigma / (2.0 * value),
            }
        } else {
            let limit = match unconstrained {
                Some(u) => u.p[k].max(0.0) + 2.0 * (u.covariance[k][k] * inflation).sqrt(),
                None => p[k] + 2.0 * sigma,
            };
            let estimate = unconstrained.map(|u| (u.p[k], (u.covariance[k][k] * inflation).sqrt()));
            Term::Unresolved {
                upper_limit: limit.sqrt(),
                reason: unresolved_reason(k, p, limit, estimate, tau_range),
            }
        }
    })
}

/// The curve's points with their 1-sigma intervals and the model `p` at them. Equivalent
/// degrees of freedom under model p: 2 AVAR^2 / Var(AVAR estimate), with the noise that
/// dominates (reported; the white-noise formula where the model is empty).
fn fit_points(
    curve: &AllanCurve,
    problem: &Problem,
    p: &[f64; 3],
    white_edf: &[f64],
) -> Vec<FitPoint> {
    curve
        .points
        .iter()
        .enumerate()
        .map(|(i, point)| {
            let model = model_avar(p, problem.taus[i]);
            let variance = problem.covariance(i, i, p);
            let edf = if model > 0.0 && variance > 0.0 {
                2.0 * model * model / variance
            } else {
                white_edf[i]
            };
            let kind = dominant(p, problem.taus[i]);
            let (low, high) = allan::one_sigma_interval(point.avar, edf);
            FitPoint {
                tau_s: point.tau_s,
                adev: point.avar.sqrt(),
                adev_low: low.sqrt(),
                adev_high: high.sqrt(),
                edf,
                model_adev: model_avar(p, point.tau_s).sqrt(),
                dominant: kind,
                terms: point.terms,
            }
        })
        .collect()
}

/// [`fit`] with precomputed integrals (see [`CovarianceBasis`]).
///
/// Panics if `basis` was computed for other cluster sizes or another sample interval.
pub fn fit_with(curve: &AllanCurve, basis: &CovarianceBasis) -> Result<ModelFit, FitError> {
    assert!(
        basis.matches(curve),
        "the covariance basis was computed for other cluster sizes or another sample interval"
    );
    check_curve(curve)?;
    let problem = Problem::new(curve, basis);
    let t = problem.len();
    let white_edf: Vec<f64> = curve
        .points
        .iter()
        .map(|point| allan::pooled_edf(NoiseKind::White, point.m, &curve.segment_lengths))
        .collect();
    let (solution, whitening) = reweighted_fit(&problem, curve, &white_edf);
    let dof = t - solution.free;
    let inflation = if dof > 0 {
        (solution.chi2 / dof as f64).max(1.0)
    } else {
        1.0
    };
    let unconstrained = problem.solve(&whitening, 0b111);
    let p = solution.p;
    let covariance = solution.covariance.map(|row| row.map(|v| v * inflation));
    let tau_range = (problem.taus[0], problem.taus[t - 1]);
    let [white, bias_instability, random_walk] = terms(
        &p,
        &covariance,
        unconstrained.as_ref(),
        inflation,
        tau_range,
    );
    Ok(ModelFit {
        white,
        bias_instability,
        random_walk,
        coefficients: p,
        covariance,
        chi2: solution.chi2,
        dof,
        points: fit_points(curve, &problem, &p, &white_edf),
    })
}

/// A duration for messages, three significant digits: `2.87 s`, `0.00557 s`, `3.20e5 s`.
fn seconds(s: f64) -> String {
    if !s.is_finite() {
        "infinity".to_owned()
    } else if (1e-3..1e4).contains(&s) {
        let decimals = (2 - s.log10().floor() as i32).max(0) as usize;
        format!("{s:.decimals$} s")
    } else {
        format!("{s:.2e} s")
    }
}

/// Where white noise at its upper limit `limit` would dominate (`flicker`: the flicker
/// floor of `p`), against the shortest cluster time `tau_min`.
fn white_dominates(p: &[f64; 3], limit: f64, flicker: f64, tau_min: f64) -> String {
    let a = p[2] / 3.0;
    let edge = if a > 0.0 {
        (-flicker + (flicker * flicker + 4.0 * a * limit).sqrt()) / (2.0 * a)
    } else if flicker > 0.0 {
        limit / flicker
    } else {
        f64::INFINITY
    };
    format!(
        "; at its upper limit it would dominate below {} (the cluster times start at {})",
        seconds(edge),
        seconds(tau_min)
    )
}

/// Where bias instability at its upper limit `limit` would dominate, against the cluster
/// times `(tau_min, tau_max)`.
fn instability_dominates(p: &[f64; 3], limit: f64, (tau_min, tau_max): (f64, f64)) -> String {
    let level = FLICKER_FACTOR * limit;
    let a = p[2] / 3.0;
    // level > N^2/tau + a tau between the roots of a tau^2 - level tau + N^2 = 0.
    let window = if a > 0.0 {
        let disc = level * level - 4.0 * a * p[0];
        (disc > 0.0).then(|| {
            (
                (level - disc.sqrt()) / (2.0 * a),
                (level + disc.sqrt()) / (2.0 * a),
            )
        })
    } else if level > 0.0 {
        Some((p[0] / level, f64::INFINITY))
    } else {
        None
    };
    match window {
        None => "; even at its upper limit it would not dominate at any cluster time".to_owned(),
        Some((low, high)) if high.is_finite() => format!(
            "; at its upper limit it would dominate between {} and {} (the cluster times span {} .. {})",
            seconds(low),
            seconds(high),
            seconds(tau_min),
            seconds(tau_max)
        ),
        Some((low, _)) => format!(
            "; at its upper limit it would dominate above {} (the cluster times span {} .. {})",
            seconds(low),
            seconds(tau_min),
            seconds(tau_max)
        ),
    }
}

/// Where the random walk at its upper limit `limit` would dominate (`flicker`: the flicker
/// floor of `p`), against the longest cluster time `tau_max`.
fn random_walk_dominates(p: &[f64; 3], limit: f64, flicker: f64, tau_max: f64) -> String {
    let a = limit / 3.0;
    let edge = if a > 0.0 {
        (flicker + (flicker * flicker + 4.0 * a * p[0]).sqrt()) / (2.0 * a)
    } else {
        f64::INFINITY
    };
    format!(
        "; at its upper limit it would dominate beyond {} (the cluster times end at {}, a quarter of the longest gap-free stretch)",
        seconds(edge),
        seconds(tau_max)
    )
}

/// Explains why term `k` is not resolved: its estimate, and where it would dominate at its
/// upper limit `limit` (in `p` units) compared with the analysed cluster times.
fn unresolved_reason(
    k: usize,
    p: &[f64; 3],
    limit: f64,
    estimate: Option<(f64, f64)>,
    (tau_min, tau_max): (f64, f64),
) -> String {
    let name = [
        "white noise (N^2)",
        "bias instability (B^2)",
        "random walk (K^2)",
    ][k];
    let mut reason = match estimate {
        Some((value, sigma)) if p[k] == 0.0 && value >= SIGNIFICANCE * sigma => format!(
            "{name}: the non-negative fit sets it to zero (unconstrained {value:.3e} +- {sigma:.3e}, traded against the other terms)"
        ),
        Some((value, sigma)) => format!(
            "{name} = {value:.3e} +- {sigma:.3e} is not significant (below {SIGNIFICANCE} sigma)"
        ),
        None => format!("{name} is not determined"),
    };
    let flicker = FLICKER_FACTOR * p[1];
    // Where the term, at its upper limit, would exceed the other two (closed forms of the
    // quadratic crossings of the model terms), against the analysed cluster times.
    let dominates = match k {
        0 => white_dominates(p, limit, flicker, tau_min),
        1 => instability_dominates(p, limit, (tau_min, tau_max)),
        _ => random_walk_dominates(p, limit, flicker, tau_max),
    };
    reason.push_str(&dominates);
    reason
}

/// The calibration file's parameters of a fit: resolved terms as estimates, the others as upper
/// limits.
pub fn axis_noise(fit: &ModelFit) -> AxisNoise {
    let split = |term: &Term| match *term {
        Term::Resolved { value, sigma } => (Some(Estimate { value, sigma }), None),
        Term::Unresolved { upper_limit, .. } => (None, Some(upper_limit)),
    };
    let (white_noise_density, n_limit) = split(&fit.white);
    let (bias_instability, b_limit) = split(&fit.bias_instability);
    let (random_walk, k_limit) = split(&fit.random_walk);
    AxisNoise {
        white_noise_density,
        bias_instability,
        random_walk,
        upper_limits: UpperLimits {
            white_noise_density: n_limit,
            bias_instability: b_limit,
            random_walk: k_limit,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::allan::{AllanPoint, cluster_sizes};

    /// A noise-free curve of the model itself on a record of `len` samples.
    fn model_curve(p: [f64; 3], tau0: f64, len: usize) -> AllanCurve {
        let points = cluster_sizes(len / 4)
            .into_iter()
            .map(|m| {
                let tau_s = m as f64 * tau0;
                AllanPoint {
                    m,
                    tau_s,
                    avar: model_avar(&p, tau_s),
                    terms: len - 2 * m + 1,
                }
            })
            .collect();
        AllanCurve {
            tau0_s: tau0,
            segment_lengths: vec![len],
            points,
        }
    }

    #[test]
    fn recovers_a_noise_free_model_exactly() {
        let p = [4e-6, 1e-6, 1e-7];
        let fit = fit(&model_curve(p, 0.01, 200_000)).unwrap();
        for (fitted, truth) in fit.coefficients.iter().zip(p) {
            assert!(
                (fitted / truth - 1.0).abs() < 1e-6,
                "{:?}",
                fit.coefficients
            );
        }
        assert!(fit.chi2 < 1e-12);
        let (n, _) = fit.white.resolved().unwrap();
        assert!((n - 2e-3).abs() < 1e-9);
        let (k, _) = fit.random_walk.resolved().unwrap();
        assert!((k - 1e-7f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn sigmas_shrink_with_record_length() {
        // The same model on a 4x longer record: the white-noise sigma halves.
        let p = [4e-6, 1e-6, 1e-7];
        let short = fit(&model_curve(p, 0.01, 50_000)).unwrap();
        let long = fit(&model_curve(p, 0.01, 200_000)).unwrap();
        let (_, s_short) = short.white.resolved().unwrap();
        let (_, s_long) = long.white.resolved().unwrap();
        assert!(
            (s_short / s_long / 2.0 - 1.0).abs() < 0.15,
            "{s_short} {s_long}"
        );
    }

    #[test]
    fn short_record_reports_random_walk_as_unresolved() {
        // K^2 tau / 3 would reach the bias-instability floor only at ~ 50 000 s; the record
        // is 100 s.
        let p = [4e-6, 4e-6, 1e-10];
        let fit = fit(&model_curve(p, 0.01, 10_000)).unwrap();
        assert!(fit.white.resolved().is_some());
        assert!(fit.bias_instability.resolved().is_some());
        match &fit.random_walk {
            Term::Unresolved {
                upper_limit,
                reason,
            } => {
                assert!(
                    reason.starts_with("random walk (K^2) = 1.000e-10 +- "),
                    "{reason}"
                );
                assert!(reason.contains("is not significant"), "{reason}");
                assert!(reason.contains("would dominate beyond"), "{reason}");
                // The limit is above the truth and is what a 100 s record can exclude.
                assert!(*upper_limit > 1e-5 && *upper_limit < 1e-2, "{upper_limit}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn rejects_degenerate_curves() {
        let mut curve = model_curve([1.0, 0.0, 0.0], 0.01, 15);
        assert!(matches!(
            fit(&curve),
            Err(FitError::TooFewPoints {
                found: 3,
                longest: 15
            })
        ));
        curve = model_curve([1.0, 0.0, 0.0], 0.01, 1000);
        curve.points[3].avar = 0.0;
        assert!(matches!(fit(&curve), Err(FitError::Degenerate { .. })));
    }
}
