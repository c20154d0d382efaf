//! A robot that is moving before the filter aligns: the cruise window it aligns on
//! ([`crate::cruise`]) and the calibration stage's refinements made in motion, which the
//! filter does not take for bias (`crate::eskf::refinement`).

use super::Navigator;
use super::hint_state::HintSample;
use crate::cruise::{CruiseWindow, MIN_SPEED_MPS, beyond_turn_on_bias, cruise_start};
use crate::eskf::{Imu, Refinement};
use crate::hints::has_rest_source;
use crate::uncalibrated::AccelPrior;
use ipc_types::{CorrectedImuSample, RobotHint, hint_flags, odometry_flags};
use nalgebra::Vector3;

impl Navigator {
    /// Takes the calibration stage's refinement of the sample `s`; before the filter aligns,
    /// its change while a fresh hint says the robot moves (`hint_moving`) is added to
    /// [`Self::motion_refinement`] (after, [`Self::refinement_measured_motion`] says whether
    /// the filter follows it, `crate::eskf::Eskf::follow_refinement`).
    pub(super) fn take_refinement(&mut self, s: &CorrectedImuSample, hint_moving: bool) {
        let r = Refinement {
            accel: Vector3::from(s.refined_accel_mps2),
            gyro: self.cfg.gyro_correction * Vector3::from(s.refined_gyro_rps),
        };
        if hint_moving && self.kf.is_none() {
            self.motion_refinement.accel += r.accel - self.refinement.accel;
            self.motion_refinement.gyro += r.gyro - self.refinement.gyro;
        }
        self.refinement = r;
    }

    /// Whether the stage's gyroscope refinement at the sample `m` measured motion: a rest
    /// refused as vibration (`hs`), or one a fresh hint says the robot drove through
    /// (`hint_moving`) while the rate before the refinement was beyond a gyro's turn-on bias.
    pub(super) fn refinement_measured_motion(
        &self,
        m: &Imu,
        hs: &HintSample,
        hint_moving: bool,
    ) -> bool {
        let turned = beyond_turn_on_bias(&(m.w + self.refinement.gyro));
        hs.flags & odometry_flags::REST_VIBRATING != 0 || (hint_moving && turned)
    }

    /// Gathers the cruise window of an unaligned filter ([`crate::cruise`]; `fresh` is the fresh
    /// hint when the detector flags the sample still) and aligns in motion once it is full.
    pub(super) fn accumulate_cruise(
        &mut self,
        t_ns: u64,
        m: &Imu,
        fresh: Option<RobotHint>,
        gravity_off: bool,
    ) {
        let moving = |h: &RobotHint| {
            has_rest_source(h)
                && h.flags & hint_flags::STATIONARY == 0
                && h.flags & hint_flags::SPEED_VALID != 0
                && h.forward_speed_mps >= MIN_SPEED_MPS
        };
        let Some(h) = fresh.filter(moving).filter(|_| self.kf.is_none()) else {
            self.cruise = CruiseWindow::default();
            return;
        };
        let c = &mut self.cruise;
        c.push(
            t_ns,
            &m.f,
            &m.w,
            &self.motion_refinement,
            h.forward_speed_mps,
            h.forward_speed_sigma_mps,
        );
        c.gravity_off |= gravity_off;
        let span_s = c.span_s(t_ns);
        if span_s < self.cfg.align_s || c.accel.len() < 2 {
            return;
        }
        if c.steady() {
            self.align_in_motion(span_s, m);
        } else {
            // Accelerating or braking: the next window starts afresh.
            self.cruise = CruiseWindow::default();
        }
    }

    /// Aligns on the cruise window of `span_s` seconds, `m` its last sample (see
    /// [`crate::cruise`] for what is assumed and how the sigmas carry it).
    fn align_in_motion(&mut self, span_s: f64, m: &Imu) {
        let c = std::mem::take(&mut self.cruise);
        let prior = AccelPrior::at_rest(&self.cfg, &c.accel.mean(), c.gravity_off);
        let start = cruise_start(
            &c,
            span_s,
            &self.cfg,
            &self.hints.cfg,
            self.hints.r_bs,
            &prior,
            &self.motion_refinement,
        );
        // The stage's refinement over a cruise it took for rest averaged a moving platform's
        // specific force, no bias: the filter follows it from here, not from the window's mean
        // (from the mean, the simulated car of `odometry/tests/hint_handover.rs`, seed 4, ended
        // 103 m off, outside the 68 % radius of its 1-sigma, 62.6 m).
        self.start_filter(
            start.x,
            start.cov,
            prior,
            (c.accel.mean(), self.refinement),
            m,
        );
        self.standing_accel_sd = start.standing_accel_sd;
        self.zupt_sigma_mps = self.cfg.zupt_sigma_mps;
        self.aligned_in_motion = Some(c.speed().0);
        self.at_rest = false;
    }
}
