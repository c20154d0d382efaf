//! The fourth step: the selected model fitted on all calibration observations ([`FinalFit`]),
//! and the fit a calibration file can carry.

use std::collections::BTreeMap;

use calibrate::model::{AccelModel, ModelKind, ParamCovariance, bias_index, scale_index};
use calibrate::terms::ReadingTerms;
use nalgebra::{Matrix3, Vector3};

use super::data::Session;
use super::effects::{Effect, Tag};
use super::linear;
use super::magnitude::{self, Term};
use super::observations::ObsSet;
use super::{BaselineKind, Diagnoser, FinalFit};

/// A label-free fit for one warm-up time constant: its chi-square, the fit, its terms and
/// the time constant.
type MagnitudeChoice = (f64, magnitude::MagnitudeFit, Vec<(Effect, Term)>, f64);

impl Diagnoser<'_> {
    /// The final fit of `final_effects`, and the one a calibration file can carry: not the
    /// set-up's label errors nor the steps of one session's gaps.
    pub(super) fn final_fits(&self, final_effects: &[Effect]) -> (FinalFit, FinalFit) {
        let fixes = Self::fixes_of(final_effects);
        let final_set = &self.sets[&(fixes.torn, fixes.dedup)];
        let (final_fit, _) = self.final_fit(final_set, final_effects);
        let sensor_effects: Vec<Effect> = final_effects
            .iter()
            .copied()
            .filter(|e| !matches!(e, Effect::ReferenceTilt | Effect::Gaps))
            .collect();
        let calibration_fit = if sensor_effects == final_effects {
            final_fit.clone()
        } else {
            self.final_fit(final_set, &sensor_effects).0
        };
        (final_fit, calibration_fit)
    }

    /// Fits the model with `effects` on all calibration observations of `set`; also returns
    /// the total rank it uses (linear: shared rank over the axes plus group constants;
    /// label-free: its parameter count).
    pub(super) fn final_fit(&self, set: &ObsSet, effects: &[Effect]) -> (FinalFit, usize) {
        let tau_grid = if effects.contains(&Effect::WarmUp) {
            self.tau_grid(set)
        } else {
            vec![1.0]
        };
        let mut out = self.empty_fit(set, effects);
        let solved = match self.kind {
            BaselineKind::LabelFree => self.final_label_free(set, effects, tau_grid, &mut out),
            _ => Some(self.final_linear(set, effects, &tau_grid, &mut out)),
        };
        let Some(solved) = solved else {
            return (out, 0);
        };
        out.per_pose_residual_g = per_pose_residual(set, &solved.resid);
        out.terms = reading_terms(set, &solved.coef, solved.tau);
        (out, solved.rank)
    }

    /// A final fit of `effects` on `set`'s calibration observations with what the data say
    /// (poses, repaired samples, temperature range) and nothing fitted yet.
    fn empty_fit(&self, set: &ObsSet, effects: &[Effect]) -> FinalFit {
        let rows = &set.calib_rows;
        let repaired_samples = if effects.contains(&Effect::TornReads) {
            self.sessions[..self.n_calib]
                .iter()
                .map(|s| match s {
                    Session::Raw(r) => r.findings.torn.total(),
                    Session::Means { .. } => 0,
                })
                .sum()
        } else {
            0
        };
        let temps: Vec<f64> = rows.iter().filter_map(|&o| set.obs[o].temp_c).collect();
        let temperature_range_c = (!temps.is_empty()).then(|| {
            [
                temps.iter().copied().fold(f64::INFINITY, f64::min),
                temps.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            ]
        });
        let poses: std::collections::BTreeSet<usize> =
            rows.iter().map(|&o| set.obs[o].pose).collect();
        FinalFit {
            kind: self.kind,
            effects: effects.to_vec(),
            model: None,
            covariance: None,
            terms: ReadingTerms::default(),
            tilt_g: Vec::new(),
            per_pose_residual_g: Vec::new(),
            chi2: 0.0,
            dof: 0,
            poses: poses.len(),
            repaired_samples,
            temperature_range_c,
        }
    }

    /// The label-free final fit (the best warm-up time constant of `tau_grid`): the model,
    /// its covariance and chi-square go into `out`; `None` if no fit converged.
    fn final_label_free(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau_grid: Vec<f64>,
        out: &mut FinalFit,
    ) -> Option<Solved> {
        let rows = &set.calib_rows;
        let x0 = set.lf_start.clone().expect("label-free start");
        let tau_grid = if tau_grid.len() > 1 {
            vec![self.best_tau_magnitude(set, effects, rows, &x0, &tau_grid)]
        } else {
            tau_grid
        };
        let mut best: Option<MagnitudeChoice> = None;
        for &t in &tau_grid {
            let terms = self.magnitude_terms(set, effects, t);
            let plain: Vec<Term> = terms.iter().map(|(_, t)| t.clone()).collect();
            if let Ok(f) = magnitude::fit(&set.m, &set.v, &plain, rows, &x0)
                && best.as_ref().is_none_or(|b| f.chi2 < b.0)
            {
                best = Some((f.chi2, f, terms, t));
            }
        }
        let (chi2, f, terms, tau) = best?;
        let mut solved = Solved::new(set, tau, f.x.len());
        for (c, (e, term)) in terms.iter().enumerate() {
            solved.coef.entry(*e).or_insert([0.0; 3])[term.axis] = f.x[9 + c];
        }
        let plain: Vec<Term> = terms.into_iter().map(|(_, t)| t).collect();
        for &o in rows {
            let z = magnitude::corrected(&f.x, &plain, &set.m[o], o);
            solved.resid[o] = [z.norm() - 1.0, 0.0, 0.0];
        }
        let t_mat = f.t();
        let s = t_mat.try_inverse().unwrap_or_else(Matrix3::identity);
        out.model = AccelModel::new(ModelKind::Full, s, f.bias()).ok();
        let dof = rows.len().saturating_sub(f.x.len());
        let scale = if dof > 0 {
            (chi2 / dof as f64).max(1.0)
        } else {
            1.0
        };
        out.covariance = Some(label_free_covariance(&s, &f.cov, scale));
        out.chi2 = chi2;
        out.dof = dof;
        Some(solved)
    }

    /// The linear final fit (the best warm-up time constant of `tau_grid`): the model (full
    /// baseline), its covariance, the reference tilts and chi-square go into `out`.
    fn final_linear(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau_grid: &[f64],
        out: &mut FinalFit,
    ) -> Solved {
        let rows = &set.calib_rows;
        let mut best: Option<(f64, linear::AxisFit, [Vec<Tag>; 3], f64)> = None;
        for &t in tau_grid {
            let (design, tags) = self.linear_design(set, effects, t);
            let f = linear::fit(&set.m, &set.v, &design, rows);
            let c: f64 = f.chi2.iter().sum();
            if best.as_ref().is_none_or(|b| c < b.0) {
                best = Some((c, f, tags, t));
            }
        }
        let (chi2, f, tags, tau) = best.expect("at least one time constant");
        let mut solved = Solved::new(set, tau, f.rank.iter().sum::<usize>() + 3 * f.groups);
        let (design, _) = self.linear_design(set, effects, tau);
        let mut unpacked = Unpacked::default();
        let dof = 3 * rows.len() - solved.rank.min(3 * rows.len());
        let red = if dof > 0 {
            (chi2 / dof as f64).max(1.0)
        } else {
            1.0
        };
        for (axis, axis_tags) in tags.iter().enumerate() {
            let th = &f.theta[axis];
            let layout_index = unpacked.axis(axis, th, axis_tags, &mut solved.coef);
            for &(a, ka) in &layout_index {
                for &(b, kb) in &layout_index {
                    unpacked.cov[(ka, kb)] = red * f.cov[axis][(a, b)];
                }
            }
            let consts: BTreeMap<usize, f64> = f.group_const[axis]
                .iter()
                .map(|(g, a, _)| (*g, *a))
                .collect();
            for &o in rows {
                let pred: f64 = design.columns[axis]
                    .iter()
                    .zip(th)
                    .map(|(col, t)| col[o] * t)
                    .sum::<f64>()
                    + design.groups.as_ref().map_or(0.0, |g| consts[&g[o]]);
                solved.resid[o][axis] = set.m[o][axis] - pred;
            }
            if self.kind == BaselineKind::Full && design.groups.is_some() {
                // With bias steps at gaps, b is the constant before the first gap.
                unpacked.bias[axis] = f.group_const[axis].first().map_or(0.0, |e| e.1);
            }
        }
        if self.kind == BaselineKind::Full {
            out.model = AccelModel::new(ModelKind::Full, unpacked.scale, unpacked.bias).ok();
            out.covariance = Some(unpacked.cov);
        }
        out.tilt_g = unpacked.tilt.into_iter().collect();
        out.chi2 = chi2;
        out.dof = dof;
        solved
    }
}

/// What a final fit's solver leaves for the terms and residuals it reports.
struct Solved {
    /// The effects' coefficients per axis.
    coef: BTreeMap<Effect, [f64; 3]>,
    /// Residual of each observation (calibration rows only), g.
    resid: Vec<[f64; 3]>,
    /// Total rank used.
    rank: usize,
    /// The warm-up time constant used, s.
    tau: f64,
}

impl Solved {
    fn new(set: &ObsSet, tau: f64, rank: usize) -> Self {
        Self {
            coef: BTreeMap::new(),
            resid: vec![[0.0; 3]; set.obs.len()],
            rank,
            tau,
        }
    }
}

/// The linear fit's columns sorted into model 3 (scale matrix, bias, their covariance in the
/// 12-parameter layout) and reference tilts per orientation class.
struct Unpacked {
    scale: Matrix3<f64>,
    bias: Vector3<f64>,
    cov: ParamCovariance,
    tilt: BTreeMap<usize, [f64; 3]>,
}

impl Default for Unpacked {
    fn default() -> Self {
        Self {
            scale: Matrix3::zeros(),
            bias: Vector3::zeros(),
            cov: ParamCovariance::zeros(),
            tilt: BTreeMap::new(),
        }
    }
}

impl Unpacked {
    /// Sorts one axis' coefficients `th` (columns tagged `tags`); effects' coefficients go
    /// into `coef`. Returns the (column, parameter index) pairs of model 3's parameters.
    fn axis(
        &mut self,
        axis: usize,
        th: &[f64],
        tags: &[Tag],
        coef: &mut BTreeMap<Effect, [f64; 3]>,
    ) -> Vec<(usize, usize)> {
        let mut layout_index = Vec::new();
        for (c, tag) in tags.iter().enumerate() {
            match tag {
                Tag::Base(j) if *j < 3 => {
                    self.scale[(axis, *j)] = th[c];
                    layout_index.push((c, scale_index(axis, *j)));
                }
                Tag::Base(_) => {
                    self.bias[axis] = th[c];
                    layout_index.push((c, bias_index(axis)));
                }
                Tag::Effect(Effect::ReferenceTilt, class) => {
                    self.tilt.entry(*class).or_insert([0.0; 3])[axis] = th[c];
                }
                Tag::Effect(e, _) => {
                    coef.entry(*e).or_insert([0.0; 3])[axis] = th[c];
                }
            }
        }
        layout_index
    }
}

/// Mean residual per pose over the calibration observations, g.
fn per_pose_residual(set: &ObsSet, resid: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut per_pose: BTreeMap<usize, ([f64; 3], usize)> = BTreeMap::new();
    for &o in &set.calib_rows {
        let e = per_pose.entry(set.obs[o].pose).or_insert(([0.0; 3], 0));
        for (sum, r) in e.0.iter_mut().zip(resid[o]) {
            *sum += r;
        }
        e.1 += 1;
    }
    per_pose
        .values()
        .map(|(s, n)| s.map(|x| x / *n as f64))
        .collect()
}

/// The reading terms of the fitted effects' coefficients (`tau`: the warm-up's time constant,
/// s).
fn reading_terms(set: &ObsSet, coef: &BTreeMap<Effect, [f64; 3]>, tau: f64) -> ReadingTerms {
    let t_ref = set.t_ref_c;
    let mut terms = ReadingTerms::default();
    if let Some(c) = coef.get(&Effect::TemperatureBias) {
        terms.reference_c = t_ref;
        terms.temp_bias_g_per_c = Some(Vector3::from(*c));
    }
    if let Some(c) = coef.get(&Effect::TemperatureScale) {
        terms.reference_c = t_ref;
        terms.temp_scale_per_c = Some(Vector3::from(*c));
    }
    if let Some(c) = coef.get(&Effect::BiasDrift) {
        terms.drift = Some((Vector3::from(*c), set.t_max_s.unwrap_or(0.0)));
    }
    if let Some(c) = coef.get(&Effect::WarmUp) {
        terms.warm_up = Some((Vector3::from(*c), tau));
    }
    if let Some(c) = coef.get(&Effect::ScaleNonlinearity) {
        terms.quadratic_g_per_g2 = Some(Vector3::from(*c));
    }
    terms
}

/// Covariance of `S = T^-1` and `b` in the 12-parameter layout from the covariance of
/// `[b, T upper triangle, ...]`: `dS = -S dT S`, scaled by `scale`.
fn label_free_covariance(
    s: &Matrix3<f64>,
    cov: &nalgebra::DMatrix<f64>,
    scale: f64,
) -> ParamCovariance {
    const T_INDEX: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
    // Jacobian of the 12 layout parameters with respect to the 9 fitted ones.
    let mut j = nalgebra::SMatrix::<f64, 12, 9>::zeros();
    for a in 0..3 {
        j[(bias_index(a), a)] = 1.0;
    }
    for (k, &(r, c)) in T_INDEX.iter().enumerate() {
        let mut e = Matrix3::zeros();
        e[(r, c)] = 1.0;
        let ds = -s * e * s;
        for row in 0..3 {
            for col in 0..3 {
                j[(scale_index(row, col), 3 + k)] = ds[(row, col)];
            }
        }
    }
    let c9 = nalgebra::SMatrix::<f64, 9, 9>::from_fn(|r, c| cov[(r, c)]);
    j * c9 * j.transpose() * scale
}
