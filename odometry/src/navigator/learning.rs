//! The calibration stage's learning window as the alignment's rest.
//!
//! A robot's detector learns its references from the first half second of rest
//! (`calibrate::zero_state::ROBOT_LEARN_S`) and flags rest only after it; the odometry aligns
//! on `OdometryConfig::align_s` of flagged rest, and the rest hindsight withdraws the flags of
//! the `rest_hindsight_s` before a motion. On a rest of 1 s that leaves nothing: the learning
//! took the first half, the hindsight the second. But the learner already judged its window
//! still, batch by batch (`calibrate::zero_state::learn`: gravity's magnitude, no outlying
//! batch mean, no trend), so the alignment may stand on those samples: the odometry keeps
//! the samples before the learned verdict and, when it comes, the alignment sums of the last
//! `OdometryConfig::learned_rest_s` of them (no more than the learner's window). The rest
//! flagged after the verdict still comes first: when it spans the alignment's rest, the
//! filter aligns on it alone, as without this module. When it ends sooner (the hindsight
//! withdrew its end, or all of it), the filter aligns on the learning window and what
//! remains of that rest, if together they span the alignment's rest, a batch of samples
//! after it ended ([`Navigator::align_on_learned`] says why). (The learner's tests are weaker than the detector's on a short window: at 120 Hz half
//! a second is three batches; aligning on the learning window whenever it came took a real
//! car of docs/real-data.md, wid-car-06, from 55-106 % to 244-406 % of its distance.)
//!
//! Those samples left the calibration stage before its first refinement, which the verdict
//! makes (`calibrate::stage`, "Bias refinement at rest"), so they are put in the terms of the
//! samples after it:
//! - gyroscope (rad/s, sensor frame, after `OdometryConfig::gyro_correction`): the first
//!   refinement subtracts the learned window's mean rate, so the window's own mean is
//!   subtracted; the alignment's gyro bias is then zero with the variance of that mean, which
//!   is what is left of the bias after the refinement;
//! - accelerometer (m/s^2, sensor frame): the refinement moves the offset along gravity. The
//!   kept samples left the stage with the refinement the verdict's sample carries (none yet:
//!   the stage corrected its batch before the verdict), so they are kept as they left, and the
//!   filter aligned on them follows the stage's first refinement from there
//!   (`crate::eskf::Eskf::with_refinement`). (Shifted by the difference of a batch's mean as
//!   emitted and the verdict's detector mean, they carried the difference between the two
//!   means as well: where the last kept batch was not the verdict's, and with an engine
//!   shaking every sample by 0.4 m/s^2, wid-car-06 of docs/real-data.md aligned 0.03 m/s^2 off
//!   along gravity with a GLRT window of 1 s, its vertical velocity ran off at that rate and the
//!   car ended 266 m off after 177 m; with the uncalibrated perturbation of docs/real-data.md,
//!   the shift was the stage's first refinement itself, 2.1 m/s^2 on rtklib-walk-0827, and the
//!   filter, told the samples carried none, took that refinement again for a change of its
//!   bias: 154.9 m off.)
//!
//! The refinement the sums carry (`AlignSums::refined`, which the filter follows the stage's
//! refinement from) is therefore the verdict's, plus the window's mean rate the gyroscope's
//! samples had taken away.
//!
//! The verdict's sample is the first with `BIAS_REFINED` (the samples of its batch before it
//! are flagged `DETECTOR_READY` once settled, but not refined). A stream that starts ready
//! (SHOE, which learns nothing; a resumed calibration state) keeps nothing here.
//!
//! With speed hints the rest is the hints' (`navigator::HINT_ALIGN_S`: a second of it), and
//! the learning window counts toward it only where a fresh hint said stationary at each of
//! its samples (a sample without one empties the window, as a clipped one does): the learner
//! judged the window still and the encoders agree. A robot that creeps off from its first
//! sample is still to the IMU too; its hints' cruise alignment starts it
//! (`odometry/tests/start_in_motion.rs`). Without the learning window a first rest that the
//! learning takes most of never aligned: the PHIL TurtleBot runs
//! of docs/real-data.md (encoders stationary for 1.6-1.7 s at the start, a 1 s learning that
//! ends 1.2 s in at 50 Hz) aligned only at the ends of trials 2 and 3, 47-51 s in.

use super::Navigator;
use super::records::AlignSums;
use crate::eskf::{Imu, Refinement, RefinementMean};
use crate::hints::Ring;
use calibrate::zero_state::BATCH_LEN;
use ipc_types::{CorrectedImuSample, corrected_flags};
use nalgebra::Vector3;

/// The learning window's alignment sums, with the rest flagged after it, and the samples
/// since that rest ended.
#[derive(Debug, Clone, Copy)]
pub(super) struct Learned {
    pub(super) sums: AlignSums,
    /// Time of the rest's last sample, ns.
    pub(super) end_ns: u64,
    pub(super) motion: usize,
}

/// One sample kept before the learned verdict.
#[derive(Debug, Clone, Copy, Default)]
struct Kept {
    t_ns: u64,
    f: Vector3<f64>,
    w: Vector3<f64>,
}

/// The samples before the learned verdict (see the module documentation).
#[derive(Debug, Clone)]
pub(super) struct LearningWindow {
    kept: Ring<Kept>,
    /// Samples kept that were flagged `DETECTOR_READY` (the verdict's batch, once settled).
    ready_kept: usize,
}

impl LearningWindow {
    /// Storage for `learned_rest_s` at `max_rate_hz`, allocated here.
    pub(super) fn new(learned_rest_s: f64, max_rate_hz: f64) -> Self {
        let capacity = (learned_rest_s.max(0.0) * max_rate_hz).ceil() as usize + 1;
        Self {
            kept: Ring::new(capacity),
            ready_kept: 0,
        }
    }

    /// Makes this a copy of `other` (same capacity): nothing is allocated.
    pub(super) fn copy_from(&mut self, other: &Self) {
        self.kept.clone_from(&other.kept);
        self.ready_kept = other.ready_kept;
    }

    /// Takes the unaligned filter's sample `m` at `t_ns` (`usable`: neither clipped nor
    /// implausible; `ready`, `refined`: its `DETECTOR_READY` and `BIAS_REFINED` flags;
    /// `carried`: the stage's refinement it carries). Returns the alignment sums of the
    /// learned window, in the refined terms, at the learned verdict's sample; `None` before
    /// and after it. `learned_rest_s` 0 keeps nothing.
    pub(super) fn take(
        &mut self,
        t_ns: u64,
        m: &Imu,
        flags: (bool, bool, bool),
        carried: Refinement,
        learned_rest_s: f64,
    ) -> Option<AlignSums> {
        let (usable, ready, refined) = flags;
        let learning = !ready || (!refined && !self.kept.is_empty() && self.ready_kept < BATCH_LEN);
        if learned_rest_s <= 0.0 || !(learning || refined && !self.kept.is_empty()) {
            self.clear();
            return None;
        }
        if !usable {
            // A clipped or implausible reading is no part of a rest.
            self.clear();
            return None;
        }
        self.kept.push(Kept {
            t_ns,
            f: m.f,
            w: m.w,
        });
        if learning {
            self.ready_kept += usize::from(ready);
            return None;
        }
        let sums = self.sums(learned_rest_s, carried);
        self.clear();
        sums
    }

    /// The alignment sums of the kept samples of the last `learned_rest_s` (the newest the
    /// verdict's), refined, with the refinement they carry (module documentation; `carried`:
    /// the verdict's).
    fn sums(&self, learned_rest_s: f64, carried: Refinement) -> Option<AlignSums> {
        let last = *self.kept.newest(0)?;
        let dt_ns = last.t_ns - self.kept.newest(1)?.t_ns;
        // The learner's window of `n` samples spans `n - 1` intervals.
        let from_ns = (last.t_ns + dt_ns / 2).saturating_sub((learned_rest_s * 1e9) as u64);
        let n = (0..self.kept.len())
            .take_while(|&i| self.kept.newest(i).is_some_and(|k| k.t_ns >= from_ns))
            .count();
        if n < 2 {
            return None;
        }
        let window = || (0..n).rev().filter_map(|i| self.kept.newest(i));
        let gyro_mean = window().fold(Vector3::zeros(), |acc, k| acc + k.w) / n as f64;
        let mut sums = AlignSums::default();
        for (i, k) in window().enumerate() {
            if i == 0 {
                // The span counts the first sample's interval too (`n` samples, `n`
                // intervals), and a quarter of one for the jitter of the times.
                sums.t0_ns = k.t_ns.saturating_sub(dt_ns + dt_ns / 4);
            }
            sums.accel.push(k.f);
            sums.gyro.push(k.w - gyro_mean);
        }
        let refined = Refinement {
            accel: carried.accel,
            gyro: carried.gyro + gyro_mean,
        };
        sums.refined = RefinementMean::repeated(refined, n as u64);
        Some(sums)
    }

    fn clear(&mut self) {
        self.kept.clear();
        self.ready_kept = 0;
    }
}

impl Navigator {
    /// Keeps the alignment sums of the calibration stage's learning window at its learned
    /// verdict's sample `s` (`navigator::learning`; `usable`: not clipped; `hint_rest`: what
    /// a fresh hint says of rest, if any), for the rest flagged after it to add to; whether
    /// this was that sample.
    pub(super) fn seed_alignment(
        &mut self,
        s: &CorrectedImuSample,
        m: &Imu,
        usable: bool,
        hint_rest: Option<bool>,
        gravity_off: bool,
    ) -> bool {
        // With speed hints, only a sample a fresh hint says stationary is part of the rest.
        let usable = usable && (self.hints.newest.is_none() || hint_rest == Some(true));
        let ready = s.flags & corrected_flags::DETECTOR_READY != 0;
        let refined = s.flags & corrected_flags::BIAS_REFINED != 0;
        let learned_rest_s = self.cfg.learned_rest_s;
        let t_ns = s.stamps.sample_ns;
        let flags = (usable, ready, refined);
        let carried = self.refinement;
        let Some(sums) = self.learning.take(t_ns, m, flags, carried, learned_rest_s) else {
            return false;
        };
        let sums = AlignSums {
            gravity_off,
            ..sums
        };
        self.learned = Some(Learned {
            sums,
            end_ns: t_ns,
            motion: 0,
        });
        true
    }

    /// A motion sample `m` while the rest flagged after the learning window was
    /// too short to align on by itself: a batch of them ([`BATCH_LEN`]) after that rest, the
    /// filter aligns on the learning window and that rest together when they span the
    /// alignment's rest. (Not at the first: the samples of the batch after the learned
    /// verdict leave the calibration stage with its verdict, not rest, until their own
    /// settles them; a filter aligned there would be unaligned again when they turn out rest.)
    pub(super) fn align_on_learned(&mut self, m: &Imu) {
        let Some(learned) = self.learned.as_mut() else {
            return;
        };
        learned.motion += 1;
        if learned.motion < BATCH_LEN {
            return;
        }
        self.align = learned.sums;
        let end_ns = learned.end_ns;
        self.learned = None;
        // The rest's span ends at its last sample.
        self.try_align(end_ns, m);
        self.align = AlignSums::default();
    }

    /// Adds the unaligned filter's sample `m` at `t_ns` to the alignment's rest (`rest`: it
    /// is flagged rest; `gravity_off`: `GRAVITY_OFF`), or ends that rest, and aligns when the
    /// rest spans the alignment's.
    pub(super) fn accumulate_alignment(
        &mut self,
        t_ns: u64,
        m: &Imu,
        rest: bool,
        gravity_off: bool,
    ) {
        if !rest {
            self.align = AlignSums::default();
            self.align_on_learned(m);
            return;
        }
        if self.learned.is_some_and(|l| l.motion > 0) {
            // A motion came between: the learning window is not this rest's.
            self.learned = None;
        }
        let learned = self.learned.as_mut().map(|l| {
            l.end_ns = t_ns;
            &mut l.sums
        });
        for a in std::iter::once(&mut self.align).chain(learned) {
            if a.accel.is_empty() {
                a.t0_ns = t_ns;
            }
            a.accel.push(m.f);
            a.gyro.push(m.w);
            a.refined.push(self.refinement);
            a.gravity_off |= gravity_off;
        }
        self.try_align(t_ns, m);
        if self.kf.is_some() {
            self.learned = None;
        }
    }
}
