//! The third step: each candidate effect added to the baseline, scored against it, and the
//! selection rule (see the module documentation of [`super`]).

use super::data::Session;
use super::effects::Effect;
use super::evaluate::{Eval, Skip};
use super::observations::ObsSet;
use super::{
    BaselineKind, CandidateResult, CandidateStatus, DiagnoseConfig, Diagnoser, ModelScore,
};

impl Diagnoser<'_> {
    /// The parameters `effect` adds to `effects` minus itself (`base_rank`: the baseline's
    /// rank), refused when the calibration data cannot tell it from the baseline.
    fn added_params(
        &self,
        set: &ObsSet,
        effect: Effect,
        effects: &[Effect],
        base_rank: usize,
    ) -> Result<usize, Skip> {
        if effect.is_fix() {
            return Ok(0);
        }
        if self.kind == BaselineKind::LabelFree {
            return Ok(3 + usize::from(effect == Effect::WarmUp));
        }
        let (_, rank) = self.final_fit(set, effects);
        let added = rank.saturating_sub(base_rank);
        if added == 0 {
            return Err(Skip::NotIdentifiable(
                "the calibration data cannot tell it from the baseline".into(),
            ));
        }
        Ok(added + usize::from(effect == Effect::WarmUp))
    }

    /// Evaluates the applied effects plus `effect` against the baseline; also returns the
    /// evaluation and the effects when it was evaluated.
    pub(super) fn candidate(
        &self,
        effect: Effect,
        applied: &[Effect],
        base_set: &ObsSet,
        base_rank: usize,
        baseline: &ModelScore,
    ) -> (CandidateResult, Option<(Eval, Vec<Effect>)>) {
        let mut effects = applied.to_vec();
        effects.push(effect);
        let fixes = Self::fixes_of(&effects);
        // Applicability depends on the sessions, not on the fixes: judged on the baseline's
        // observations, so that a fix's observations are only needed when it applies.
        let outcome = self.applicability(effect, base_set).and_then(|()| {
            let set = &self.sets[&(fixes.torn, fixes.dedup)];
            let params = self.added_params(set, effect, &effects, base_rank)?;
            self.evaluate(set, &effects).map(|e| (e, params))
        });
        match outcome {
            Ok((eval, params)) => {
                let s = self.score(&eval, &effects);
                // Constants fitted on held-out data absorb about one unit each of the
                // scaled chi-square: charged after scaling.
                let scale = (s.chi2 / s.expected_chi2.max(1.0)).max(1.0);
                let mut score = (baseline.chi2 - s.chi2) / scale
                    - (s.local_params as f64 - baseline.local_params as f64);
                if effect == Effect::Gaps {
                    score -= self.placebo_gap_score(base_set, &effects, baseline);
                }
                let excess = baseline.chi2 - baseline.expected_chi2;
                let explained = if excess > 0.0 {
                    (baseline.chi2 - s.chi2) / excess
                } else if score > 0.0 {
                    1.0
                } else {
                    0.0
                };
                let result = CandidateResult {
                    effect,
                    status: CandidateStatus::Evaluated,
                    result: Some(s),
                    score,
                    explained,
                    params,
                };
                (result, Some((eval, effects)))
            }
            Err(skip) => {
                let result = CandidateResult {
                    effect,
                    status: match skip {
                        Skip::NotApplicable(r) => CandidateStatus::NotApplicable(r),
                        Skip::NotIdentifiable(r) => CandidateStatus::NotIdentifiable(r),
                    },
                    result: None,
                    score: f64::NAN,
                    explained: f64::NAN,
                    params: 0,
                };
                (result, None)
            }
        }
    }

    /// The best score of bias steps placed at the same number of times as the gaps but a third
    /// and two thirds of each session later (cyclically), or 0 when those score below 0. Steps
    /// anywhere absorb some low-frequency noise, which held-out blocks or whole held-out
    /// sessions do not charge fully; a step at a gap counts by what it gains beyond them.
    fn placebo_gap_score(&self, set: &ObsSet, effects: &[Effect], baseline: &ModelScore) -> f64 {
        let mut best: f64 = 0.0;
        for fraction in [1.0 / 3.0, 2.0 / 3.0] {
            let mut placebo = set.clone();
            for o in &mut placebo.obs {
                let Session::Raw(r) = &self.sessions[o.session] else {
                    continue;
                };
                let t0 = r.t_ns[0];
                let duration = (r.t_ns[r.t_ns.len() - 1] - t0) as f64 * 1e-9;
                // Elapsed times count from the time origin, which may precede the session.
                let start = (t0 - r.t0_ns) as f64 * 1e-9;
                let t = o.t_s.expect("raw sessions have times");
                o.gap_index = r
                    .gap_at
                    .iter()
                    .map(|&g| {
                        start + ((r.t_ns[g] - t0) as f64 * 1e-9 + fraction * duration) % duration
                    })
                    .filter(|&p| p <= t)
                    .count();
            }
            if let Ok(e) = self.evaluate(&placebo, effects) {
                let s = self.score(&e, effects);
                let scale = (s.chi2 / s.expected_chi2.max(1.0)).max(1.0);
                let score = (baseline.chi2 - s.chi2) / scale
                    - (s.local_params as f64 - baseline.local_params as f64);
                best = best.max(score);
            }
        }
        best
    }
}

/// The selection rule (see the module documentation).
pub(super) fn select(candidates: &[CandidateResult], cfg: &DiagnoseConfig) -> Option<Effect> {
    let eligible: Vec<&CandidateResult> = candidates
        .iter()
        .filter(|c| {
            c.status == CandidateStatus::Evaluated
                && c.score >= cfg.select_threshold
                && c.explained >= cfg.explain_fraction
        })
        .collect();
    let best = eligible
        .iter()
        .map(|c| c.score)
        .fold(f64::NEG_INFINITY, f64::max);
    eligible
        .into_iter()
        .filter(|c| c.score >= best - cfg.select_threshold)
        .min_by(|a, b| a.params.cmp(&b.params).then(b.score.total_cmp(&a.score)))
        .map(|c| c.effect)
}
