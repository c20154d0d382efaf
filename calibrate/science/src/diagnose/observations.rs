//! The first step: the observations of each choice of fixes ([`ObsSet`], built once each),
//! with their validation rounds and, for the label-free baseline, its fit on all calibration
//! data.

use nalgebra::{DVector, Vector3};

use super::data::{self, AcquisitionFindings, Fixes, Labelling, Obs, Session};
use super::effects::Effect;
use super::linear::Round;
use super::magnitude;
use super::{BaselineKind, DiagnoseError, Diagnoser, Folds};

/// The observations of one choice of fixes.
#[derive(Debug, Clone)]
pub(super) struct ObsSet {
    pub(super) obs: Vec<Obs>,
    pub(super) m: Vec<[f64; 3]>,
    pub(super) v: Vec<[f64; 3]>,
    pub(super) n: Vec<usize>,
    pub(super) pose: Vec<usize>,
    pub(super) calib_rows: Vec<usize>,
    pub(super) rounds: Vec<Round>,
    /// Reference temperature (mean over the calibration observations), degC.
    pub(super) t_ref_c: Option<f64>,
    /// Longest elapsed time in the calibration observations, s.
    pub(super) t_max_s: Option<f64>,
    /// Corrected direction of each observation under the label-free baseline fitted on all
    /// calibration data (label-free kind only).
    pub(super) dir_est: Option<Vec<[f64; 3]>>,
    /// Label-free baseline fitted on all calibration data (its starting point).
    pub(super) lf_start: Option<DVector<f64>>,
}

impl Diagnoser<'_> {
    fn labelling(&self) -> Labelling {
        match self.kind {
            BaselineKind::Full => Labelling::NearestAxis,
            _ => Labelling::None,
        }
    }

    /// The observations with the given fixes (built once).
    fn set(&mut self, fixes: Fixes) -> Result<&ObsSet, DiagnoseError> {
        let key = (fixes.torn, fixes.dedup);
        if !self.sets.contains_key(&key) {
            let set = self.build_set(fixes)?;
            self.sets.insert(key, set);
        }
        Ok(&self.sets[&key])
    }

    fn build_set(&self, fixes: Fixes) -> Result<ObsSet, DiagnoseError> {
        let mut obs = Vec::new();
        let mut first_pose = 0;
        for (k, s) in self.sessions.iter().enumerate() {
            let test = k >= self.n_calib;
            data::observations(
                s,
                k,
                first_pose,
                test,
                self.labelling(),
                fixes,
                &self.cfg.data,
                &mut obs,
            );
            first_pose += s.pose_means().len();
        }
        for o in &mut obs {
            match self.folds {
                Folds::Sessions => o.fold = o.session % self.cfg.data.folds,
                Folds::Poses => o.fold = o.pose % self.cfg.data.folds,
                Folds::Blocks => {}
            }
        }
        let calib_rows: Vec<usize> = (0..obs.len()).filter(|&o| !obs[o].test).collect();
        let rounds = validation_rounds(&obs, &calib_rows);
        let t_ref_c = obs
            .iter()
            .all(|o| o.temp_c.is_some())
            .then(|| mean(calib_rows.iter().map(|&o| obs[o].temp_c.expect("checked"))));
        let t_max_s = obs.iter().all(|o| o.t_s.is_some()).then(|| {
            calib_rows
                .iter()
                .map(|&o| obs[o].t_s.expect("checked"))
                .fold(0.0, f64::max)
        });
        let m: Vec<[f64; 3]> = obs.iter().map(|o| o.m).collect();
        let v: Vec<[f64; 3]> = obs.iter().map(|o| o.v).collect();
        let n: Vec<usize> = obs.iter().map(|o| o.n).collect();
        let pose: Vec<usize> = obs.iter().map(|o| o.pose).collect();
        let (dir_est, lf_start) = if self.kind == BaselineKind::LabelFree {
            let (dirs, x) = self.label_free_start(&m, &v, &n, &pose, &calib_rows)?;
            (Some(dirs), Some(x))
        } else {
            (None, None)
        };
        Ok(ObsSet {
            obs,
            m,
            v,
            n,
            pose,
            calib_rows,
            rounds,
            t_ref_c,
            t_max_s,
            dir_est,
            lf_start,
        })
    }

    /// The label-free baseline's fit on all calibration rows: each observation's direction
    /// (its corrected reading, normalized) and the parameters, the start of later fits.
    fn label_free_start(
        &self,
        m: &[[f64; 3]],
        v: &[[f64; 3]],
        n: &[usize],
        pose: &[usize],
        calib_rows: &[usize],
    ) -> Result<(Vec<[f64; 3]>, DVector<f64>), DiagnoseError> {
        let baseline_error = |e: String| DiagnoseError::Baseline {
            kind: self.kind.name(),
            reason: e,
        };
        let x0 = magnitude::start(m, v, n, pose, calib_rows)
            .map_err(|e| baseline_error(e.to_string()))?;
        let f = magnitude::fit(m, v, &[], calib_rows, &x0)
            .map_err(|e| baseline_error(e.to_string()))?;
        let (t, b) = (f.t(), f.bias());
        let dirs = m
            .iter()
            .map(|mm| {
                let c = (t * (Vector3::from(*mm) - b)).normalize();
                [c.x, c.y, c.z]
            })
            .collect();
        Ok((dirs, f.x))
    }

    pub(super) fn fixes_of(effects: &[Effect]) -> Fixes {
        Fixes {
            torn: effects.contains(&Effect::TornReads),
            dedup: effects.contains(&Effect::RepeatedSamples),
        }
    }

    /// Builds the observation sets of the applied fixes, and of each fix the data call for
    /// (a fix without findings is not applicable and needs none); returns the applied fixes.
    pub(super) fn prepare_sets(&mut self, applied: &[Effect]) -> Result<Fixes, DiagnoseError> {
        let base_fixes = Self::fixes_of(applied);
        self.set(base_fixes)?;
        let raw = |f: fn(&AcquisitionFindings) -> bool| {
            self.sessions.iter().any(|s| match s {
                Session::Raw(r) => f(&r.findings),
                Session::Means { .. } => false,
            })
        };
        let needed = [
            (
                raw(|a| a.torn.total() > 0),
                Fixes {
                    torn: true,
                    ..base_fixes
                },
            ),
            (
                raw(|a| a.repeats_significant),
                Fixes {
                    dedup: true,
                    ..base_fixes
                },
            ),
        ];
        for (need, fixes) in needed {
            if need {
                self.set(fixes)?;
            }
        }
        Ok(base_fixes)
    }
}

/// The validation rounds: the test observations against all calibration rows when there are
/// any, otherwise one round per fold of the calibration rows.
fn validation_rounds(obs: &[Obs], calib_rows: &[usize]) -> Vec<Round> {
    let test_rows: Vec<usize> = (0..obs.len()).filter(|&o| obs[o].test).collect();
    if !test_rows.is_empty() {
        return vec![Round {
            train: calib_rows.to_vec(),
            eval: test_rows,
        }];
    }
    let folds: std::collections::BTreeSet<usize> =
        calib_rows.iter().map(|&o| obs[o].fold).collect();
    folds
        .iter()
        .map(|&f| Round {
            train: calib_rows
                .iter()
                .copied()
                .filter(|&o| obs[o].fold != f)
                .collect(),
            eval: calib_rows
                .iter()
                .copied()
                .filter(|&o| obs[o].fold == f)
                .collect(),
        })
        .collect()
}

/// Weighted mean of per-observation values.
fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    s / n.max(1) as f64
}
