//! The last step: what the diagnosis reports beside the models: residual points, the
//! acquisition findings, the validation used and the histogram of sample deviations.

use std::collections::BTreeMap;

use super::data::{AcquisitionFindings, Session};
use super::effects::direction;
use super::evaluate::Eval;
use super::observations::ObsSet;
use super::{Diagnoser, Folds, ResidualPoint, SampleHistogram};

impl Diagnoser<'_> {
    pub(super) fn points(&self, set: &ObsSet, e: &Eval) -> Vec<ResidualPoint> {
        let mut by_obs: BTreeMap<usize, ResidualPoint> = BTreeMap::new();
        for (k, &(o, axis)) in e.entries.iter().enumerate() {
            let ob = &set.obs[o];
            let p = by_obs.entry(o).or_insert_with(|| ResidualPoint {
                resid_g: [f64::NAN; 3],
                sigma_g: [f64::NAN; 3],
                t_s: ob.t_s,
                temp_c: ob.temp_c,
                class: ob.class,
                direction: direction(ob, set.dir_est.as_ref().map(|d| &d[o])),
                session: ob.session,
                test: ob.test,
            });
            let i = axis.unwrap_or(0);
            p.resid_g[i] = e.resid[k];
            p.sigma_g[i] = e.v[k].sqrt();
        }
        by_obs.into_values().collect()
    }

    /// The acquisition findings of the raw sessions.
    pub(super) fn acquisition(&self) -> Vec<AcquisitionFindings> {
        self.sessions
            .iter()
            .filter_map(|s| match s {
                Session::Raw(r) => Some(r.findings.clone()),
                Session::Means { .. } => None,
            })
            .collect()
    }

    pub(super) fn validation_text(&self, set: &ObsSet) -> String {
        let n_test = set.obs.iter().filter(|o| o.test).count();
        if n_test > 0 {
            return format!(
                "fitted on the calibration data ({} observations), evaluated on the test data ({n_test})",
                set.calib_rows.len()
            );
        }
        if self
            .sessions
            .iter()
            .any(|s| matches!(s, Session::Means { .. }))
        {
            return format!(
                "leave-one-pose-out over {} poses (a means file: {} samples per pose assumed \
                 for the noise)",
                set.calib_rows.len(),
                self.cfg.data.pose_samples
            );
        }
        let kind = match self.folds {
            Folds::Sessions => {
                "whole sessions (session mod k; each held-out session's own constant refitted on it)"
            }
            Folds::Poses => "whole poses (pose mod k)",
            Folds::Blocks => "interleaved blocks of each static segment (block mod k)",
        };
        format!(
            "{} rounds over {kind}, {} observations of {} s",
            set.rounds.len(),
            set.calib_rows.len(),
            self.cfg.data.block_s
        )
    }

    /// Histogram of sample deviations from their block means in every raw session.
    pub(super) fn histogram(&self) -> Option<SampleHistogram> {
        const START: f64 = -520.0;
        const WIDTH: f64 = 8.0;
        const BINS: usize = 130;
        let mut h = SampleHistogram {
            start_counts: START,
            bin_counts: WIDTH,
            raw: std::array::from_fn(|_| vec![0; BINS]),
            repaired: std::array::from_fn(|_| vec![0; BINS]),
        };
        let mut any = false;
        let lsb = self.cfg.data.accel_lsb_per_g;
        let block = (self.cfg.data.block_s * 1e9) as u64;
        for s in &self.sessions {
            let Session::Raw(r) = s else { continue };
            any = true;
            for seg in &r.segments {
                let mut k0 = seg.start;
                while k0 < seg.end {
                    let mut k1 = k0;
                    while k1 < seg.end && r.t_ns[k1] - r.t_ns[k0] < block {
                        k1 += 1;
                    }
                    for (values, hist) in [(&r.a_raw, &mut h.raw), (&r.a_repaired, &mut h.repaired)]
                    {
                        let block = &values[k0..k1];
                        let mut mean = [0.0; 3];
                        for a in block {
                            for (m, x) in mean.iter_mut().zip(a) {
                                *m += x;
                            }
                        }
                        let mean = mean.map(|m| m / block.len() as f64);
                        for a in block {
                            for (i, (x, m)) in a.iter().zip(&mean).enumerate() {
                                let bin = ((x - m) * lsb - START) / WIDTH;
                                if bin >= 0.0 && bin < BINS as f64 {
                                    hist[i][bin as usize] += 1;
                                }
                            }
                        }
                    }
                    k0 = k1;
                }
            }
        }
        any.then_some(h)
    }
}
