//! The navigator's hooks of hand-held walking (`crate::walking`): its steps, its updates and
//! its alignment on whole steps; and the velocity bound of a sensor moved by hand.

use nalgebra::Vector3;

use super::Navigator;
use crate::eskf::{Imu, KS, V, align};
use crate::steps::Step;
use crate::uncalibrated::AccelPrior;
use crate::walking::{ALIGN_VELOCITY_SIGMA_MPS, Walk, WalkingStats};

impl Navigator {
    /// What hand-held walking did, in that mode.
    pub fn walking_stats(&self) -> Option<WalkingStats> {
        self.walk.as_ref().map(Walk::stats)
    }

    /// The step the sample `m` at `t_ns` ends, if any (an implausible sample is no reading),
    /// and whether the walker is walking; `(None, false)` outside the walking mode.
    pub(super) fn walk_step(
        &mut self,
        t_ns: u64,
        m: &Imu,
        implausible: bool,
    ) -> (Option<Step>, bool) {
        match self.walk.as_mut() {
            Some(w) if !implausible => (w.push(t_ns, &m.f), w.walking(t_ns)),
            Some(w) => (None, w.walking(t_ns)),
            None => (None, false),
        }
    }

    /// After the aligned filter's updates: the walking mode's (a step's velocity update, or a
    /// standing walker's).
    pub(super) fn walk_update(&mut self, t_ns: u64, step: Option<&Step>, rest: bool) {
        let Some(walk) = self.walk.as_mut() else {
            return;
        };
        if step.is_some() {
            // An update the reconstruction's predictions would not redo.
            self.clip.spoil();
        }
        walk.update(self.kf.as_mut().expect("aligned"), t_ns, step, rest);
    }

    /// After the aligned filter's updates: the velocity bound of a sensor moved by hand
    /// (`crate::hand_bound`), when the profile asks for it and no robot hint reports the
    /// motion (`hinted`: a robot that sends hints is no hand, and its speed is measured).
    pub(super) fn hand_update(&mut self, t_ns: u64, rest: bool, hinted: bool) {
        let kf = self.kf.as_mut().expect("aligned");
        if self
            .hand
            .update(kf, t_ns, rest || hinted, self.cfg.hand_speed_sigma_mps)
        {
            // An update the reconstruction's predictions would not redo.
            self.clip.spoil();
        }
    }

    /// Hand-held walking without a rest: aligns on the mean specific force over whole steps
    /// (`crate::walking`), the gyro bias unknown. `gravity_off`: the calibration stage flagged
    /// the sample `GRAVITY_OFF` (its learned rest read gravity off and its refinement has
    /// already removed the error along gravity, so the steps' mean reads gravity right: the
    /// part is uncalibrated all the same).
    pub(super) fn align_on_steps(&mut self, m: &Imu, step: Option<&Step>, gravity_off: bool) {
        if self.kf.is_some() {
            return;
        }
        let Some(walk) = self.walk.as_mut() else {
            return;
        };
        let Some(f_mean) = walk.stride_mean(&m.f, step) else {
            return;
        };
        let g = self.cfg.gravity_mps2;
        let prior = AccelPrior::at_rest(&self.cfg, &f_mean, gravity_off);
        let (x, mut cov) = align(
            f_mean,
            Vector3::zeros(),
            g,
            prior.bias_sigma_mps2,
            Walk::gyro_bias_sigma(),
        );
        cov[(KS, KS)] = 0.0;
        for i in 0..3 {
            cov[(V + i, V + i)] = ALIGN_VELOCITY_SIGMA_MPS.powi(2);
        }
        // A stride mean keeps no refinement: the current sample's is taken.
        self.start_filter(x, cov, prior, (f_mean, self.refinement), m);
        self.zupt_sigma_mps = self.cfg.zupt_sigma_mps;
        self.at_rest = false;
    }
}
