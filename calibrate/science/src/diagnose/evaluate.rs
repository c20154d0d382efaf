//! The second step: held-out evaluation of a model (the baseline plus effects) on an
//! observation set, and its score ([`ModelScore`]).

use std::collections::BTreeMap;

use nalgebra::DVector;
use statrs::distribution::{ChiSquared, ContinuousCDF};

use super::data::{self, Session};
use super::effects::{Effect, Tag, direction, has_columns, regressor};
use super::linear::{self, Design, Round};
use super::magnitude::{self, Term};
use super::observations::ObsSet;
use super::{BaselineKind, DiagnoseError, Diagnoser, ModelScore};

/// One model's held-out residuals, flattened.
#[derive(Debug, Clone, Default)]
pub(super) struct Eval {
    /// (observation, axis or `None` for a magnitude residual).
    pub(super) entries: Vec<(usize, Option<usize>)>,
    pub(super) resid: Vec<f64>,
    pub(super) v: Vec<f64>,
    pub(super) pv: Vec<f64>,
    pub(super) local: usize,
}

/// Why a model was not evaluated.
pub(super) enum Skip {
    NotApplicable(String),
    NotIdentifiable(String),
}

impl Diagnoser<'_> {
    /// Whether `effect` can act on the data; the reason when not.
    pub(super) fn applicability(&self, effect: Effect, set: &ObsSet) -> Result<(), Skip> {
        let raw: Vec<&data::RawSession> = self
            .sessions
            .iter()
            .filter_map(|s| match s {
                Session::Raw(r) => Some(r.as_ref()),
                Session::Means { .. } => None,
            })
            .collect();
        // The fewest poses any training set of this validation holds.
        let min_train_poses = set
            .rounds
            .iter()
            .map(|r| {
                r.train
                    .iter()
                    .map(|&o| set.obs[o].pose)
                    .collect::<std::collections::BTreeSet<_>>()
                    .len()
            })
            .min()
            .unwrap_or(0);
        match effect {
            Effect::TemperatureBias | Effect::TemperatureScale if set.t_ref_c.is_none() => Err(
                Skip::NotApplicable("the data carry no die temperature".into()),
            ),
            // A nonlinearity acts pose by pose: with the label-free model's 9 parameters it
            // needs 12 poses in every training set (blocks of one pose are one orientation).
            Effect::ScaleNonlinearity
                if self.kind == BaselineKind::LabelFree
                    && min_train_poses < crate::labelfree::MIN_POSES + 3 =>
            {
                Err(Skip::NotIdentifiable(format!(
                    "a label-free fit with a nonlinearity needs 12 poses in every training set, \
                     this validation leaves {min_train_poses}"
                )))
            }
            Effect::BiasDrift | Effect::WarmUp if set.t_max_s.is_none() => Err(
                Skip::NotApplicable("the data carry no sample times (means file)".into()),
            ),
            Effect::ScaleNonlinearity if self.kind == BaselineKind::SessionMean => {
                Err(Skip::NotIdentifiable(
                    "one orientation per session: a_i^2 is constant within each session".into(),
                ))
            }
            Effect::ReferenceTilt if self.kind != BaselineKind::Full => Err(Skip::NotApplicable(
                "the data carry no gravity labels".into(),
            )),
            Effect::Gaps if self.kind == BaselineKind::LabelFree => Err(Skip::NotApplicable(
                "bias steps at gaps are not modelled with the label-free baseline".into(),
            )),
            Effect::Gaps if !set.obs.iter().any(|o| o.gap_index > 0) => {
                Err(Skip::NotApplicable("no gaps inside the static data".into()))
            }
            Effect::TornReads if raw.iter().all(|r| r.findings.torn.total() == 0) => {
                Err(Skip::NotApplicable("no torn reads found".into()))
            }
            Effect::RepeatedSamples if !raw.iter().any(|r| r.findings.repeats_significant) => Err(
                Skip::NotApplicable("repeated samples are as frequent as noise allows".into()),
            ),
            _ => Ok(()),
        }
    }

    /// The warm-up time constants tried, s.
    pub(super) fn tau_grid(&self, set: &ObsSet) -> Vec<f64> {
        let lo = (2.0 * self.cfg.data.block_s).max(0.5);
        let hi = (2.0 * set.t_max_s.unwrap_or(lo)).max(2.0 * lo);
        let k = self.cfg.warm_up_grid.max(2);
        (0..k)
            .map(|j| lo * (hi / lo).powf(j as f64 / (k - 1) as f64))
            .collect()
    }

    /// The linear design of a model with `effects` on `set` (warm-up time constant `tau_s`).
    pub(super) fn linear_design(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau_s: f64,
    ) -> (Design, [Vec<Tag>; 3]) {
        let obs = &set.obs;
        let gaps = effects.contains(&Effect::Gaps);
        let mut columns: [Vec<Vec<f64>>; 3] = Default::default();
        let mut tags: [Vec<Tag>; 3] = Default::default();
        let groups = match self.kind {
            BaselineKind::Full if !gaps => None,
            _ => {
                let mut ids: BTreeMap<(usize, usize), usize> = BTreeMap::new();
                Some(
                    obs.iter()
                        .map(|o| {
                            let key = (o.session, if gaps { o.gap_index } else { 0 });
                            let next = ids.len();
                            *ids.entry(key).or_insert(next)
                        })
                        .collect(),
                )
            }
        };
        let classes: std::collections::BTreeSet<usize> =
            set.calib_rows.iter().map(|&o| obs[o].class).collect();
        for axis in 0..3 {
            if self.kind == BaselineKind::Full {
                for j in 0..3 {
                    columns[axis].push(obs.iter().map(|o| o.label.expect("labelled")[j]).collect());
                    tags[axis].push(Tag::Base(j));
                }
                if groups.is_none() {
                    columns[axis].push(vec![1.0; obs.len()]);
                    tags[axis].push(Tag::Base(3));
                }
            }
            for &e in effects.iter().filter(|e| has_columns(**e)) {
                if e == Effect::ReferenceTilt {
                    for &c in classes.iter().filter(|&&c| c / 2 != axis) {
                        columns[axis].push(
                            obs.iter()
                                .map(|o| f64::from(u8::from(o.class == c)))
                                .collect(),
                        );
                        tags[axis].push(Tag::Effect(e, c));
                    }
                    continue;
                }
                let t_ref = set.t_ref_c.unwrap_or(0.0);
                columns[axis].push(
                    obs.iter()
                        .enumerate()
                        .map(|(k, o)| {
                            let dir = direction(o, set.dir_est.as_ref().map(|d| &d[k]));
                            regressor(e, o, axis, t_ref, tau_s, &dir)
                        })
                        .collect(),
                );
                tags[axis].push(Tag::Effect(e, 0));
            }
        }
        (Design { columns, groups }, tags)
    }

    /// The label-free terms of a model with `effects` (warm-up time constant `tau_s`).
    pub(super) fn magnitude_terms(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau_s: f64,
    ) -> Vec<(Effect, Term)> {
        let t_ref = set.t_ref_c.unwrap_or(0.0);
        let mut terms = Vec::new();
        for &e in effects.iter().filter(|e| has_columns(**e)) {
            for axis in 0..3 {
                let values = set
                    .obs
                    .iter()
                    .enumerate()
                    .map(|(k, o)| {
                        let dir = direction(o, set.dir_est.as_ref().map(|d| &d[k]));
                        regressor(e, o, axis, t_ref, tau_s, &dir)
                    })
                    .collect();
                terms.push((e, Term { axis, values }));
            }
        }
        terms
    }

    /// Held-out evaluation of the model with `effects` on `set`, choosing the warm-up time
    /// constant per round on the training data.
    pub(super) fn evaluate(&self, set: &ObsSet, effects: &[Effect]) -> Result<Eval, Skip> {
        let taus = if effects.contains(&Effect::WarmUp) {
            self.tau_grid(set)
        } else {
            vec![1.0]
        };
        let mut eval = Eval::default();
        for round in &set.rounds {
            let x0 = match self.kind {
                BaselineKind::LabelFree => Some(
                    magnitude::start(&set.m, &set.v, &set.n, &set.pose, &round.train)
                        .map_err(|e| Skip::NotIdentifiable(format!("training poses: {e}")))?,
                ),
                _ => None,
            };
            // The label-free fit is nonlinear: the time constant is chosen by the first-order
            // fit of each, then fitted once.
            let taus = match &x0 {
                Some(x0) if taus.len() > 1 => {
                    vec![self.best_tau_magnitude(set, effects, &round.train, x0, &taus)]
                }
                _ => taus.clone(),
            };
            let mut best: Option<(f64, Eval)> = None;
            for &tau in &taus {
                let (train_chi2, e) = match &x0 {
                    Some(x0) => self.evaluate_magnitude(set, effects, tau, round, x0)?,
                    _ => {
                        let (design, _) = self.linear_design(set, effects, tau);
                        let held = linear::cross_validate(
                            &set.m,
                            &set.v,
                            &design,
                            std::slice::from_ref(round),
                        )
                        .map_err(|_| {
                            Skip::NotIdentifiable(
                                "the training data do not determine the held-out predictions"
                                    .into(),
                            )
                        })?;
                        let mut e = Eval {
                            local: held.local_params,
                            ..Eval::default()
                        };
                        for &o in &round.eval {
                            for axis in 0..3 {
                                e.entries.push((o, Some(axis)));
                                e.resid.push(held.resid[o][axis]);
                                e.v.push(set.v[o][axis]);
                                e.pv.push(held.pred_var[o][axis]);
                            }
                        }
                        (held.train_chi2, e)
                    }
                };
                if best.as_ref().is_none_or(|(c, _)| train_chi2 < *c) {
                    best = Some((train_chi2, e));
                }
            }
            let (_, e) = best.expect("at least one time constant");
            eval.entries.extend(e.entries);
            eval.resid.extend(e.resid);
            eval.v.extend(e.v);
            eval.pv.extend(e.pv);
            eval.local += e.local;
        }
        Ok(eval)
    }

    /// The warm-up time constant of `taus` whose first-order label-free fit on `rows` leaves
    /// the smallest chi-square.
    pub(super) fn best_tau_magnitude(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        rows: &[usize],
        x0: &DVector<f64>,
        taus: &[f64],
    ) -> f64 {
        taus.iter()
            .map(|&tau| {
                let terms: Vec<Term> = self
                    .magnitude_terms(set, effects, tau)
                    .into_iter()
                    .map(|(_, t)| t)
                    .collect();
                (
                    magnitude::linearized_chi2(&set.m, &set.v, &terms, rows, x0),
                    tau,
                )
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or(1.0, |(_, tau)| tau)
    }

    fn evaluate_magnitude(
        &self,
        set: &ObsSet,
        effects: &[Effect],
        tau: f64,
        round: &Round,
        x0: &DVector<f64>,
    ) -> Result<(f64, Eval), Skip> {
        let terms: Vec<Term> = self
            .magnitude_terms(set, effects, tau)
            .into_iter()
            .map(|(_, t)| t)
            .collect();
        let fit = magnitude::fit(&set.m, &set.v, &terms, &round.train, x0)
            .map_err(|e| Skip::NotIdentifiable(e.to_string()))?;
        let trained: Vec<bool> = terms
            .iter()
            .map(|t| round.train.iter().any(|&o| t.values[o] != 0.0))
            .collect();
        let mut e = Eval::default();
        for &o in &round.eval {
            let (r, pv) =
                magnitude::predict(&fit, &terms, &set.m[o], o, &trained).ok_or_else(|| {
                    Skip::NotIdentifiable("a held-out term is not determined by training".into())
                })?;
            let sigma = magnitude::magnitude_sigma(&fit.x, &terms, &set.m[o], &set.v[o], o);
            e.entries.push((o, None));
            e.resid.push(r);
            e.v.push(sigma * sigma);
            e.pv.push(pv);
        }
        Ok((fit.chi2, e))
    }

    fn model_name(&self, effects: &[Effect]) -> String {
        let mut name = self.kind.name().to_string();
        for e in effects {
            name.push('+');
            name.push_str(e.name());
        }
        name
    }

    pub(super) fn score(&self, e: &Eval, effects: &[Effect]) -> ModelScore {
        let n = e.resid.len().max(1);
        let g = self.cfg.gravity_mps2;
        let ss: f64 = e.resid.iter().map(|r| r * r).sum();
        let chi2: f64 = e.resid.iter().zip(&e.v).map(|(r, v)| r * r / v).sum();
        let expected_chi2 =
            e.v.iter()
                .zip(&e.pv)
                .map(|(v, pv)| 1.0 + pv / v)
                .sum::<f64>()
                - e.local as f64;
        let mean_v = e.v.iter().sum::<f64>() / n as f64;
        let expected_ss =
            e.v.iter().zip(&e.pv).map(|(v, pv)| v + pv).sum::<f64>() - e.local as f64 * mean_v;
        let z2: f64 = e
            .resid
            .iter()
            .zip(e.v.iter().zip(&e.pv))
            .map(|(r, (v, pv))| r * r / (v + pv))
            .sum();
        let dof = (n as f64 - e.local as f64).max(1.0);
        let p_value = ChiSquared::new(dof).map_or(f64::NAN, |c| c.sf(z2));
        let rms_axes_mps2 = (self.kind != BaselineKind::LabelFree).then(|| {
            std::array::from_fn(|i| {
                let (ss, k) = e
                    .entries
                    .iter()
                    .zip(&e.resid)
                    .filter(|((_, axis), _)| *axis == Some(i))
                    .fold((0.0, 0usize), |(ss, k), (_, r)| (ss + r * r, k + 1));
                (ss / k.max(1) as f64).sqrt() * g
            })
        });
        ModelScore {
            model: self.model_name(effects),
            rms_mps2: (ss / n as f64).sqrt() * g,
            rms_axes_mps2,
            expected_rms_mps2: (expected_ss.max(0.0) / n as f64).sqrt() * g,
            chi2,
            expected_chi2,
            p_value,
            residuals: e.resid.len(),
            local_params: e.local,
        }
    }

    /// The held-out evaluation of the applied effects, refused when one of them does not
    /// apply to the data or the baseline cannot be evaluated.
    pub(super) fn baseline_eval(
        &self,
        base_set: &ObsSet,
        applied: &[Effect],
    ) -> Result<Eval, DiagnoseError> {
        for &e in applied {
            if let Err(Skip::NotApplicable(reason) | Skip::NotIdentifiable(reason)) =
                self.applicability(e, base_set)
            {
                return Err(DiagnoseError::Apply { effect: e, reason });
            }
        }
        self.evaluate(base_set, applied).map_err(|s| {
            let (Skip::NotApplicable(reason) | Skip::NotIdentifiable(reason)) = s;
            DiagnoseError::Baseline {
                kind: self.kind.name(),
                reason,
            }
        })
    }
}
