//! The states of a start in motion published again once the forward axis is known
//! (`crate::handover`): while the speed hints waited for it, the filter's velocity had no
//! direction and the states it published no path; the hints' speeds and the attitude give the
//! path in hindsight, as the motion-end revisions give a motion's.

use super::records::Counts;
use crate::handover::RevisedWait;
use ipc_types::OdometryState;

impl super::Navigator {
    /// The navigator's counters, for a revised state.
    pub(super) fn counts(&self) -> Counts {
        Counts {
            rest_count: self.rest_count,
            hints_applied: self.hints.applied,
            hint_disagreements: self.hints.disagreements,
        }
    }

    /// Once the forward axis ended a wait (`Hints::restart_velocity`): the motion history's
    /// states of the wait take the path's positions, velocities and 1-sigmas
    /// (`crate::handover::WaitRevision`) and are published again, flagged `REVISION`; a later
    /// motion-end revision starts from them.
    pub(super) fn republish_wait(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        let Some(revision) = self.hints.wait_revision.take() else {
            return;
        };
        let (g, counts) = (self.cfg.gravity_mps2, self.counts());
        for h in &mut self.history {
            let Some(mark) = h.wait.take() else {
                continue;
            };
            let RevisedWait {
                p,
                v,
                sigma_p,
                sigma_v,
            } = revision.at(&mark, &h.q);
            (h.p, h.v, h.sigma_p, h.sigma_v) = (p, v, sigma_p, sigma_v);
            emit(&h.revision(&p, &v, g, counts));
        }
    }
}
