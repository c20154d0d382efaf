//! The odometry stage: corrected samples in, odometry states out. No I/O and no allocation per
//! sample; the live process and the offline runner both drive it, so they agree exactly.
//!
//! Life cycle: wait for the first rest interval (the zero-state flag of the calibration stage,
//! or a stationary robot hint, once the calibration stage's detector is ready), align on
//! `align_s` seconds of it (roll, pitch, gyro bias, vertical accelerometer bias), then
//! navigate with the error-state filter of [`crate::eskf`] on gyro rates corrected by
//! [`OdometryConfig::gyro_correction`], applying zero-velocity updates while the sample is
//! flagged at rest, and zero-angular-rate updates too unless the gyro shows rotation (a spin
//! in place that the rest detector took for rest). When a motion interval ends,
//! the corrections the updates made are spread back over that interval's states (a cubic
//! blend that reduces to the thesis's linear velocity-drift model when the filter's position
//! and velocity corrections agree with it) and republished with the `REVISION` flag.
//!
//! **Robot hints** ([`OdometryStage::hint`], see [`crate::hints`] for frames, times and
//! configuration). Each sample uses the newest hint delivered by its time:
//! - while that hint is fresh (younger than [`HintConfig::max_age_s`]) and has a rest source,
//!   it decides rest instead of the IMU's zero-state flag: stationary gives the zero-velocity
//!   (and gated zero-rate) updates and `HINT_STATIONARY`, moving gives none. The IMU detector's
//!   flag is still read: where it disagrees (once it is ready), the sample is flagged
//!   `HINT_DISAGREE` and counted in `hint_disagreements`;
//! - a speed hint, once delivered, is a body-frame velocity measurement (forward speed times
//!   the filter's scale state `1 + k`, and zero lateral and vertical velocity: the
//!   non-holonomic constraint of a wheeled robot) taken at the hint's own time: the prediction
//!   is the body velocity at that time plus every correction the filter has made since
//!   (a per-sample ring of the body velocity minus the corrections), so latency does not bias
//!   it. Flagged `HINT_SPEED`;
//! - once hints have been used and the newest is older than the maximum age, the stage runs on
//!   the IMU alone (its zero-state flag) and flags `HINT_STALE`; there is a state for every
//!   sample either way. In that fallback a rest flag is only taken when the filter's velocity
//!   is within [`HintConfig::fallback_zupt_gate_sigma`] standard deviations of zero: on a
//!   smooth floor the IMU's detector takes cruising for rest, and a robot the hints saw
//!   cruising a moment ago has not stopped unless its integrated velocity says so.
//!
//! **Rest in hindsight.** The calibration stage's detector decides over a window that still
//! holds the rest before a motion, so it flags the first fraction of a second of a gentle start
//! as rest; a zero-velocity update there cuts the speed the robot has already gained, and the
//! distance of the whole motion with it (measured in docs/odometry.md). So a rest flag counts
//! only in hindsight: it stands unless a confirmed motion starts within
//! [`OdometryConfig::rest_hindsight_s`] after it. When the IMU's flag turns from rest to
//! motion, the flags of the last `rest_hindsight_s` are withdrawn and those samples are
//! navigated again as motion. A run of motion flags shorter than
//! [`OdometryConfig::motion_confirm_s`] that is followed by `rest_hindsight_s` of rest flags
//! is not a confirmed motion (a bump, or a false alarm on a sensor at rest, which would
//! otherwise cost every such rest its last updates): once that rest has passed, the flags it
//! withdrew are reinstated and the samples navigated again as rest. Runs closer together than
//! the hindsight confirm each other (a gentle start flickers). Samples navigated again are
//! republished with the `REVISION` flag; the forward state never waits for the hindsight.
//!
//! **Provisional flags.** The calibration stage emits each sample at once, before its batch is
//! decided, with the latest verdict carried over (`PROVISIONAL`); the batch's last sample
//! settles the samples before it (`settles`). Each sample's state is computed and emitted in
//! the call that takes it, by a navigator running on the flags as they stand. Everything
//! above (hindsight, motion-end revisions) runs on settled flags only, one batch behind, in a
//! second navigator, after the live state is emitted: where its state for a settled sample
//! differs from the one emitted, it is republished with `REVISION` and the live navigator
//! continues from the settled one. So the final history (the last state emitted for each
//! sample) is that of a stage fed final flags, and only the live state of a batch whose
//! verdict changed (the start and end of a rest, 20 samples at most) ran on the previous one.
//!
//! For that the stage runs two navigators (module `navigator`): one on every input, whose
//! states it emits, and the settled one. A change of the flags in force navigates again, from
//! the state a navigator fed only final flags had `2 rest_hindsight_s + motion_confirm_s`
//! before (as long as flags can change), the inputs since (kept, in arrival order, in a ring
//! allocated up front), so the output is what one pass with the final flags gives. That
//! state needs no navigator of its own lagging behind: the settled navigator takes the
//! same inputs, and on the same flags unless they changed, so copies of it are kept every
//! `CHECKPOINT_EVERY` (256) inputs, and one whose inputs have all become final unchanged stands
//! for it (a replay first takes it through the final inputs after it, at most a few hundred).
//! Nor is the settled navigator run while it would repeat the live one (the same inputs in
//! the same order, every batch settled with its provisional verdict): the live navigator's
//! states and motion-end revisions are taken for it, and when a batch's verdict changes (or
//! a hint came while samples were unsettled) its state is rebuilt from the newest copy and the
//! inputs since, and it runs until the two agree again. Every sample is therefore navigated
//! about once, but around the changes of the flags.
//!
//! The settling is the stage's postprocess ([`OdometryStage::postprocess`], Copper's
//! `postprocess` after `process`): the live driver calls it after the sample's state is
//! published and its subscribers woken, the offline driver right after `process`; the next
//! input does it first if nothing did, so the outputs and their order are the same either way.
//! The replay is spread
//! over calls, at most [`REPLAY_PER_CALL`] inputs per call, so that no call holds up the
//! samples behind it for long: meanwhile the live navigator goes on with the flags it had (its
//! states are republished by the replay), and when the replay has caught up it takes the
//! replay's state. [`OdometryStage::finish`] completes a replay still under way at the end of
//! the stream. Rest decided by a fresh
//! robot hint is not withdrawn (the controller knows).

use crate::axes::{AxesCheck, AxesReport};
use crate::config::OdometryConfig;
use crate::eskf::Eskf;
pub use crate::hindsight::REPLAY_PER_CALL;
use crate::hindsight::{Hindsight, Input};
use crate::hints::{HintConfig, HintConfigError, HintError, HintStats, Ring, check_hint};
use crate::navigator::Navigator;
use ipc_types::stream::{self, Holes, SampleError, Step, TimeLine};
use ipc_types::{
    CorrectedImuSample, OdometryState, RobotHint, corrected_flags, limits, odometry_flags,
    raw_flags,
};
use nalgebra::UnitQuaternion;

/// Input the stage refuses; the message names the sample.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OdometryError {
    /// The stream contract refuses the sample ([`ipc_types::stream`]): a value not finite or
    /// beyond the calibrated bounds, or a time not after the previous sample's.
    #[error(transparent)]
    Sample(#[from] SampleError),
    /// A sample's time is more than [`limits::MAX_STEP_S`] after the previous one's: no
    /// dead reckoning bridges it; the caller starts a new stage.
    #[error(
        "sample seq {seq}: time {t_ns} ns is more than {} s after the previous sample's \
         {prev_ns} ns",
        limits::MAX_STEP_S
    )]
    TimeStep {
        /// Sequence number of the offending sample.
        seq: u64,
        /// Its time.
        t_ns: u64,
        /// The previous sample's time.
        prev_ns: u64,
    },
    /// Nothing was observed for longer than the odometry bridges
    /// ([`crate::eskf::Manoeuvre::bridge_limit_s`]): the heading after it is unknown.
    #[error(
        "sample seq {seq}: nothing observed for {:.3} s before it (time {t_ns} ns), longer \
         than the {limit_s:.2} s the odometry bridges (then the heading is wholly unknown: \
         pi over the manoeuvre's rotation rate)",
        (*t_ns - *prev_ns) as f64 * 1e-9
    )]
    HoleBeyondBridge {
        /// Sequence number of the sample after the hole.
        seq: u64,
        /// Its time.
        t_ns: u64,
        /// The previous sample's time.
        prev_ns: u64,
        /// The longest interval bridged, s.
        limit_s: f64,
    },
}

/// Provisional samples the stage holds until their batch is settled: more than the two
/// batches a calibration stage can leave unsettled (a batch cut by a gap, then a new one).
const UNSETTLED: usize = 64;

/// A provisional sample, the live state emitted for it, and what the live navigator did at it
/// that the settled stage takes over while in step ([`OdometryStage::in_step`]).
#[derive(Debug, Clone, Copy, Default)]
struct Unsettled {
    s: CorrectedImuSample,
    state: OdometryState,
    /// The live navigator's [`Navigator::imu_decided`] after the sample.
    imu_decided: bool,
    /// End of the sample's motion-end revisions in [`OdometryStage::revisions`].
    revisions_end: usize,
}

/// The odometry state machine (see the module documentation).
pub struct OdometryStage {
    /// The navigator on every sample as it arrives, flags as they stand: the live states.
    ahead: Navigator,
    /// Everything on settled flags.
    settled: Settled,
    /// Provisional samples not settled yet, oldest first.
    unsettled: Ring<Unsettled>,
    /// Whether the settled navigator's state is the live navigator's as it was at the last
    /// settled input: the live navigator has taken the same inputs in the same order since
    /// they last agreed, and the settled flags of those settled since were the provisional
    /// ones. The settled navigator is then not run: a batch settled with its provisional
    /// flags takes the live navigator's states and motion-end revisions, and the live
    /// navigator stands for it at the batch's end. Otherwise (a verdict changed, a hint came
    /// while samples were unsettled, a replay is under way) the settled navigator runs, its
    /// state first rebuilt from the hindsight's newest copy and journal. Only with hindsight.
    in_step: bool,
    /// The live navigator's motion-end revisions of the unsettled samples, in order (while in
    /// step), allocated up front.
    revisions: Vec<OdometryState>,
    /// How many of `revisions` the settled stage has taken.
    revisions_taken: usize,
    /// Whether the unsettled samples cannot be settled in step: a hint came while they were
    /// unsettled (the settled navigator took it before them, the live one after), or
    /// `revisions` was full.
    out_of_step: bool,
    /// The stream's time line ([`ipc_types::stream`]).
    time: TimeLine,
    /// Holes in it: unmarked gaps, bridged as marked ones.
    holes: Holes,
    /// [`crate::eskf::Manoeuvre::bridge_limit_s`], ns.
    bridge_ns: u64,
    revisions_emitted: u64,
    /// A final sample whose live state is emitted and whose batch is not settled yet: the
    /// work [`OdometryStage::postprocess`] does (or the next call that takes an input).
    pending: Option<Unsettled>,
    /// Whether the accelerometer's and gyroscope's axes agree.
    axes: AxesCheck,
}

/// The stage on settled flags: hindsight and the navigator whose states are final.
struct Settled {
    /// The navigator on every settled input.
    live: Navigator,
    /// `None` without hindsight.
    hindsight: Option<Hindsight>,
    /// The previous sample's IMU zero-state flag.
    imu_rest: bool,
    /// The settled navigator's [`Navigator::imu_decided`] after the previous sample.
    imu_decided: bool,
}

impl OdometryStage {
    /// A stage with the default hint configuration ([`HintConfig::default`]: the IMU mounted
    /// aligned with the body). Its storage is allocated here: the motion history for
    /// `max_motion_s` at `revision_rate_hz` (only decimated states are kept), and the inputs of
    /// `2 rest_hindsight_s + motion_confirm_s` at `max_rate_hz`.
    pub fn new(cfg: OdometryConfig) -> Self {
        Self::with_hints(cfg, HintConfig::default())
            .expect("the default hint configuration is valid")
    }

    /// A stage with the hint configuration `hints`; its velocity history holds `max_age_s` at
    /// `max_rate_hz`, allocated here too.
    pub fn with_hints(cfg: OdometryConfig, hints: HintConfig) -> Result<Self, HintConfigError> {
        hints.validate()?;
        let lag_s = cfg.rest_hindsight_s.max(0.0);
        let confirm_s = cfg.motion_confirm_s.max(0.0);
        let hindsight = (lag_s > 0.0).then(|| Hindsight::new(cfg, hints, lag_s, confirm_s));
        // A motion-end revision republishes at most the motion history.
        let history = (cfg.max_motion_s * cfg.revision_rate_hz).ceil() as usize + 1;
        let ahead = Navigator::new(cfg, hints);
        Ok(Self {
            in_step: hindsight.is_some(),
            revisions: Vec::with_capacity(history + UNSETTLED),
            revisions_taken: 0,
            out_of_step: false,
            settled: Settled {
                live: Navigator::new(cfg, hints),
                hindsight,
                imu_rest: false,
                imu_decided: ahead.imu_decided(),
            },
            ahead,
            unsettled: Ring::new(UNSETTLED),
            time: TimeLine::default(),
            holes: Holes::default(),
            bridge_ns: (cfg.manoeuvre.bridge_limit_s() * 1e9) as u64,
            revisions_emitted: 0,
            pending: None,
            axes: AxesCheck::default(),
        })
    }

    /// Takes a robot hint. It waits (in a buffer allocated up front) until a sample taken at
    /// least [`HintConfig::delivery_s`] after its publication, which then uses it. A refused
    /// hint changes nothing. The batch settling left from the previous sample is done first
    /// (its revisions go to `emit`).
    pub fn hint(
        &mut self,
        h: &RobotHint,
        emit: &mut impl FnMut(&OdometryState),
    ) -> Result<(), HintError> {
        check_hint(h)?;
        self.postprocess(emit);
        if let Some(hs) = self.settled.hindsight.as_mut() {
            // Only above `max_rate_hz` does this push an input out of the journal; a replay
            // that had not taken it then does not republish its state.
            hs.keep(Input::Hint(*h), &mut |_| {});
        }
        self.settled.live.hint(h);
        self.ahead.hint(h);
        self.out_of_step |= !self.unsettled.is_empty();
        Ok(())
    }

    /// Counters of the hints seen so far.
    pub fn hint_stats(&self) -> HintStats {
        self.ahead.hint_stats()
    }

    /// Clipped runs reconstructed and left bridged so far (`crate::clip`), by the navigator
    /// on the newest inputs.
    pub fn clip_stats(&self) -> crate::clip::ClipStats {
        self.ahead.clip_stats()
    }

    /// The IMU-to-body mounting (sensor to body), configured or estimated; `None` while it is
    /// being estimated.
    pub fn mounting(&self) -> Option<UnitQuaternion<f64>> {
        self.ahead.mounting()
    }

    /// The lever arm from the IMU to the rear axle, body frame, m (`HintConfig::lever_arm_m`).
    pub fn lever_arm_m(&self) -> nalgebra::Vector3<f64> {
        self.ahead.lever_arm_m()
    }

    /// The forward axis estimated from the speed hints, by the navigator on the newest inputs
    /// ([`crate::cruise::ForwardAxis`]): when it was first trusted, its latest 1-sigmas and
    /// speed scale, and what the filter took of that scale.
    pub fn forward_axis(&self) -> Option<crate::hints::ForwardAxisReport> {
        self.ahead.forward_axis()
    }

    /// The filter's wheel-speed scale error and its 1-sigma, fractions (the speed hints read
    /// `1 + k` times the speed), by the navigator on the newest inputs; `None` before
    /// alignment.
    pub fn speed_scale(&self) -> Option<(f64, f64)> {
        self.ahead.speed_scale()
    }

    /// Takes `cfg` from the next sample on: every navigator's rest handling, manoeuvre and
    /// wheeled constraint (a profile recognized from the data). The hindsight's lag and
    /// confirmation, the history sizes and the bridge limit stay those the stage was built
    /// with.
    pub fn reconfigure(&mut self, cfg: OdometryConfig) {
        self.ahead.reconfigure(cfg);
        self.settled.live.reconfigure(cfg);
        if let Some(h) = self.settled.hindsight.as_mut() {
            h.reconfigure(cfg);
        }
    }

    /// The IMU-only non-holonomic constraint (a wheeled profile): its counters and mounting.
    pub fn imu_constraint(&self) -> Option<crate::nonholonomic::ImuConstraint> {
        self.ahead.imu_constraint().copied()
    }

    /// What hand-held walking did (`crate::walking`), in that mode.
    pub fn walking_stats(&self) -> Option<crate::walking::WalkingStats> {
        self.ahead.walking_stats()
    }

    /// Whether alignment is done.
    pub fn aligned(&self) -> bool {
        self.ahead.aligned()
    }

    /// The mean hint speed of the steady cruise the filter aligned on, m/s; `None` when it
    /// aligned at rest or has not aligned ([`crate::cruise`]).
    pub fn aligned_in_motion(&self) -> Option<f64> {
        self.ahead.aligned_in_motion()
    }

    /// The holes in the time line so far (unmarked gaps, found here or marked
    /// [`corrected_flags::HOLE_BEFORE`] by the calibration stage), each bridged as a gap.
    pub fn holes(&self) -> Holes {
        self.holes
    }

    /// Whether the accelerometer's and gyroscope's axes agreed at the turns between still
    /// moments so far ([`crate::axes`]).
    pub fn axes(&self) -> AxesReport {
        self.axes.report()
    }

    /// Number of republished (revised) states so far.
    pub fn revisions_emitted(&self) -> u64 {
        self.revisions_emitted
    }

    /// Number of samples whose rest flag stands withdrawn in hindsight so far (those still
    /// within the hindsight may yet be reinstated).
    pub fn withdrawn_rest_samples(&self) -> u64 {
        self.settled.hindsight.as_ref().map_or(0, |hs| {
            let pending = (hs.final_pos..hs.end_pos())
                .filter(|&pos| {
                    matches!(hs.at(pos), Some(Input::Sample { s, imu_rest: true })
                        if s.flags & corrected_flags::ZERO_STATE == 0)
                })
                .count() as u64;
            hs.withdrawn + pending
        })
    }

    /// 1-sigma of one sample's zero-velocity update, m/s: `zupt_sigma_mps`, widened once
    /// aligned by the alignment rest's effective-sample factor when `effective_samples` is
    /// set (for diagnostics).
    pub fn zupt_sigma_mps(&self) -> f64 {
        self.ahead.zupt_sigma_mps()
    }

    /// What the settled filter holds of the accelerometer's error, once aligned
    /// ([`crate::uncalibrated`]).
    pub fn accel_estimate(&self) -> Option<crate::uncalibrated::AccelEstimate> {
        // In step, the live navigator stands for the settled one (not run meanwhile).
        let settled = (!self.in_step).then(|| self.settled.live.accel_estimate());
        settled.flatten().or_else(|| self.ahead.accel_estimate())
    }

    /// What the filter's innovations said of its covariance so far
    /// ([`crate::consistency`]), by the settled navigator (the live one while in step).
    pub fn consistency(&self) -> crate::consistency::ConsistencyReport {
        match self.in_step {
            true => self.ahead.consistency(),
            false => self.settled.live.consistency(),
        }
    }

    /// The filter, once aligned (for diagnostics and tests).
    pub fn filter(&self) -> Option<&Eskf> {
        self.ahead.filter()
    }

    /// Processes one sample: emits its live state. What its subscribers do not wait for, the
    /// revised states (a motion interval's drift removed, rest flags withdrawn or reinstated
    /// in hindsight, a batch's verdict that changed the states navigated on its provisional
    /// flags), comes from [`OdometryStage::postprocess`]; if that was not called, this call
    /// does it first. A refused sample changes nothing but that.
    pub fn process(
        &mut self,
        s: &CorrectedImuSample,
        emit: &mut impl FnMut(&OdometryState),
    ) -> Result<(), OdometryError> {
        self.postprocess(emit);
        stream::check_corrected(s)?;
        let s = &self.check_time(s)?;
        self.time.accept(s.stamps.sample_ns);
        self.axes.take(s);
        let state = self.navigate_ahead(s);
        emit(&state);
        let sample = Unsettled {
            s: *s,
            state,
            imu_decided: self.ahead.imu_decided(),
            revisions_end: self.revisions.len(),
        };
        if s.flags & corrected_flags::PROVISIONAL != 0 {
            if self.unsettled.is_full() {
                self.leave_step();
            }
            if let Some(old) = self.unsettled.push(sample) {
                // Never settled in time: final as it stands.
                let mut budget = REPLAY_PER_CALL;
                self.settle(&old, &mut budget, emit);
            }
            return Ok(());
        }
        self.pending = Some(sample);
        Ok(())
    }

    /// Whether [`OdometryStage::postprocess`] has work: the last sample was final, and the
    /// batch it ends is still to settle.
    pub fn postprocess_due(&self) -> bool {
        self.pending.is_some()
    }

    /// Settles the batch the last final sample ended (see the module documentation), after
    /// its live state was published: emits the revised states, at most [`REPLAY_PER_CALL`]
    /// inputs of a replay at a time.
    pub fn postprocess(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        if let Some(sample) = self.pending.take() {
            let mut budget = REPLAY_PER_CALL;
            self.settle_batch(&sample, &mut budget, emit);
        }
    }

    /// Refuses a sample whose time does not increase, jumps by more than
    /// [`limits::MAX_STEP_NS`] or follows a hole longer than the odometry bridges; returns the
    /// sample, marked as a gap after an unmarked hole in the time line (counted).
    #[inline]
    fn check_time(&mut self, s: &CorrectedImuSample) -> Result<CorrectedImuSample, OdometryError> {
        let t_ns = s.stamps.sample_ns;
        stream::check_increasing(s.seq, t_ns, self.time.prev_ns())?;
        let prev_ns = self.time.prev_ns().unwrap_or(t_ns);
        if t_ns - prev_ns > limits::MAX_STEP_NS {
            return Err(OdometryError::TimeStep {
                seq: s.seq,
                t_ns,
                prev_ns,
            });
        }
        let marked = s.raw_flags & raw_flags::GAP_BEFORE != 0;
        if (marked || self.time.step(t_ns) != Step::Regular) && t_ns - prev_ns > self.bridge_ns {
            return Err(OdometryError::HoleBeyondBridge {
                seq: s.seq,
                t_ns,
                prev_ns,
                limit_s: self.bridge_ns as f64 * 1e-9,
            });
        }
        let mut s = *s;
        let hole = matches!(self.time.step(t_ns), Step::Hole { .. });
        if hole && !marked || s.flags & corrected_flags::HOLE_BEFORE != 0 {
            s.raw_flags |= raw_flags::GAP_BEFORE;
            s.flags |= corrected_flags::HOLE_BEFORE;
            self.holes.record(s.seq, t_ns, t_ns - prev_ns);
        }
        Ok(s)
    }

    /// The live navigator's state for `s`. Its motion-end revisions come again, on settled
    /// flags, from the settled stage: kept for it while in step.
    #[inline]
    fn navigate_ahead(&mut self, s: &CorrectedImuSample) -> OdometryState {
        let mut state = OdometryState::default();
        let (in_step, revisions, full) = (self.in_step, &mut self.revisions, &mut self.out_of_step);
        self.ahead.process(s, &mut |o| {
            if o.flags & odometry_flags::REVISION == 0 {
                state = *o;
            } else if in_step {
                if revisions.len() < revisions.capacity() {
                    revisions.push(*o);
                } else {
                    *full = true;
                }
            }
        });
        state
    }

    /// Settles the batch that final sample `sample` (with its live state) ends: the
    /// unsettled samples take its verdict, and the live navigator the settled one's state
    /// when a verdict changed.
    #[inline]
    fn settle_batch(
        &mut self,
        sample: &Unsettled,
        budget: &mut usize,
        emit: &mut impl FnMut(&OdometryState),
    ) {
        let s = &sample.s;
        // Older samples than those `s` settles were cut from their batch: final as they are.
        let settles = stream::settled_by(s, self.unsettled.len());
        let n = self.unsettled.len();
        let verdict_changed = (n - settles..n).any(|i| {
            self.unsettled
                .oldest(i)
                .is_some_and(|u| u.s.flags & stream::VERDICT != s.flags & stream::VERDICT)
        });
        if verdict_changed || self.out_of_step {
            self.leave_step();
        }
        let mut diverged = false;
        while self.unsettled.len() > settles {
            let old = self.unsettled.pop().expect("len > settles");
            diverged |= self.settle(&old, budget, emit);
        }
        while let Some(mut u) = self.unsettled.pop() {
            diverged |= stream::settle(&mut u.s, s);
            diverged |= self.settle(&u, budget, emit);
        }
        diverged |= self.settle(sample, budget, emit);
        if diverged {
            self.ahead.copy_from(&self.settled.live);
        }
        self.end_batch(diverged);
    }

    /// After a batch has settled (`diverged`: the live navigator took the settled one's
    /// state): whether the two are in step from here, and the live navigator's state kept as
    /// a hindsight copy when they are.
    fn end_batch(&mut self, diverged: bool) {
        let Some(hs) = self.settled.hindsight.as_mut() else {
            return;
        };
        let replaying = hs.redo_pos.is_some();
        if self.in_step && replaying {
            // Until the replay catches up, the settled navigator goes on with the flags it had,
            // as the live one did: from here it runs itself.
            self.settled.live.copy_from(&self.ahead);
            self.in_step = false;
        } else if diverged && !replaying {
            self.in_step = true;
        }
        if self.in_step {
            hs.checkpoint(&self.ahead);
        }
        self.revisions.clear();
        self.revisions_taken = 0;
        self.out_of_step = false;
    }

    /// Runs the settled navigator itself from here: its state at the last settled input is
    /// rebuilt from the hindsight's newest copy and the journal's inputs since.
    fn leave_step(&mut self) {
        if !self.in_step {
            return;
        }
        self.in_step = false;
        if let Some(hs) = self.settled.hindsight.as_ref() {
            hs.rebuild(&mut self.settled.live);
        }
    }

    /// End of the stream: completes a replay under way (see [`REPLAY_PER_CALL`]), so that the
    /// last state emitted for every sample is final. Samples still provisional keep the state
    /// emitted for them (their flags stand, as [`calibrate::stage::Settler::finish`] leaves
    /// them). The stage can take more samples afterwards.
    pub fn finish(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        self.postprocess(emit);
        let revisions = &mut self.revisions_emitted;
        if self.settled.finish(&mut |o| {
            *revisions += 1;
            emit(o);
        }) {
            self.ahead.copy_from(&self.settled.live);
            self.in_step = self.unsettled.is_empty();
        }
    }

    /// Runs one sample with its final flags through the settled stage; republishes (as
    /// `REVISION`) its state where it differs from the live one, and every revision. Returns
    /// whether the settled navigator departed from the live one.
    fn settle(
        &mut self,
        u: &Unsettled,
        budget: &mut usize,
        emit: &mut impl FnMut(&OdometryState),
    ) -> bool {
        let revisions = &mut self.revisions_emitted;
        if self.in_step {
            let kept = &self.revisions[self.revisions_taken..u.revisions_end];
            self.revisions_taken = u.revisions_end;
            let replayed =
                self.settled
                    .process_in_step(&u.s, u.imu_decided, kept, budget, &mut |o| {
                        *revisions += 1;
                        emit(o);
                    });
            self.in_step = !replayed;
            return replayed;
        }
        let mut differs = false;
        let replayed = self.settled.process(&u.s, budget, &mut |o| {
            let o = if o.flags & odometry_flags::REVISION != 0 {
                *o
            } else if *o != u.state {
                differs = true;
                OdometryState {
                    flags: o.flags | odometry_flags::REVISION,
                    ..*o
                }
            } else {
                return;
            };
            *revisions += 1;
            emit(&o);
        });
        differs || replayed
    }
}

impl Settled {
    /// Processes one (checked) sample with settled flags: emits its state and any revised
    /// states. Returns whether a change of the flags in force navigated the journal again.
    fn process(
        &mut self,
        s: &CorrectedImuSample,
        budget: &mut usize,
        emit: &mut impl FnMut(&OdometryState),
    ) -> bool {
        let replayed = self.navigate(s, budget, emit);
        self.imu_decided = self.live.imu_decided();
        replayed
    }

    /// The sample's IMU rest flag, whether it differs from the previous sample's, and whether
    /// that change is a transition the detector decided (rest decided by a fresh hint is not
    /// the detector's to withdraw); keeps the flag for the next sample.
    fn take_flag(&mut self, s: &CorrectedImuSample) -> (bool, bool, bool) {
        let imu_rest = s.flags & corrected_flags::ZERO_STATE != 0;
        let flipped = imu_rest != self.imu_rest;
        self.imu_rest = imu_rest;
        (imu_rest, flipped, flipped && self.imu_decided)
    }

    /// [`Self::process`] but for following the navigator's rest decision.
    fn navigate(
        &mut self,
        s: &CorrectedImuSample,
        budget: &mut usize,
        emit: &mut impl FnMut(&OdometryState),
    ) -> bool {
        let (imu_rest, flipped, imu_transition) = self.take_flag(s);
        let Some(hs) = self.hindsight.as_mut() else {
            self.live.process(s, emit);
            return false;
        };
        hs.journal(s, imu_rest, flipped, imu_transition, emit);
        if hs.redo_pos.is_none() {
            self.live.process(s, emit);
            hs.checkpoint(&self.live);
            return false;
        }
        // While a replay is under way the live navigator runs on the flags it had: its states
        // go out (the replay republishes them), its motion-end revisions do not.
        self.live.process(s, &mut |o| {
            if o.flags & odometry_flags::REVISION == 0 {
                emit(o);
            }
        });
        if hs.redo_advance(budget, emit) {
            self.live.copy_from(&hs.redo);
            return true;
        }
        false
    }

    /// Takes one (checked) sample with settled flags in step with the live navigator (see
    /// [`OdometryStage::in_step`]): the hindsight's bookkeeping as [`Self::process`], but the
    /// navigator's states are the live one's (`imu_decided` after it, and its motion-end
    /// revisions `kept`), emitted as the settled navigator would have. Returns whether a
    /// replay caught up (the settled navigator then holds its state and runs itself).
    fn process_in_step(
        &mut self,
        s: &CorrectedImuSample,
        imu_decided: bool,
        kept: &[OdometryState],
        budget: &mut usize,
        emit: &mut impl FnMut(&OdometryState),
    ) -> bool {
        let (imu_rest, flipped, imu_transition) = self.take_flag(s);
        self.imu_decided = imu_decided;
        let hs = self
            .hindsight
            .as_mut()
            .expect("in step only with hindsight");
        hs.journal(s, imu_rest, flipped, imu_transition, emit);
        if hs.redo_pos.is_none() {
            for o in kept {
                emit(o);
            }
            return false;
        }
        // The state is the one emitted live; the revisions are not republished meanwhile.
        if hs.redo_advance(budget, emit) {
            self.live.copy_from(&hs.redo);
            self.imu_decided = self.live.imu_decided();
            return true;
        }
        false
    }

    /// Completes a replay under way; whether there was one.
    fn finish(&mut self, emit: &mut impl FnMut(&OdometryState)) -> bool {
        let Some(hs) = self.hindsight.as_mut() else {
            return false;
        };
        let mut unbounded = usize::MAX;
        if hs.redo_pos.is_none() || !hs.redo_advance(&mut unbounded, emit) {
            return false;
        }
        self.live.copy_from(&hs.redo);
        self.imu_decided = self.live.imu_decided();
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use ipc_types::Stamps;

    #[test]
    fn absurd_values_and_hour_long_steps_are_refused_and_the_state_stays_finite() {
        let g = 9.81;
        let mut stage = OdometryStage::new(OdometryConfig::mpu9250(g));
        let sample = |k: u64| CorrectedImuSample {
            stamps: Stamps {
                sample_ns: k * 5_000_000,
                ..Default::default()
            },
            seq: k,
            accel_mps2: [0.0, 0.0, g],
            // Moving after the first two seconds: every state integrates.
            flags: if k < 400 {
                corrected_flags::ZERO_STATE
            } else {
                0
            },
            ..Default::default()
        };
        let mut states = Vec::new();
        let (mut refused, mut k) = (0, 0);
        let mut feed = |stage: &mut OdometryStage, s: &CorrectedImuSample| {
            if stage.process(s, &mut |o| states.push(*o)).is_err() {
                refused += 1;
            }
        };
        while k < 800 {
            let mut s = sample(k);
            match k {
                450 => s.accel_mps2[0] = 1e300 * g,
                460 => s.accel_mps2[1] = 100.0 * g,
                470 => s.gyro_rps[2] = 1e6,
                480 => s.zs_mean_mps2[2] = f64::NAN,
                490 => s.stamps.sample_ns += 3_600_000_000_000,
                _ => {}
            }
            feed(&mut stage, &s);
            k += 1;
        }
        assert_eq!(refused, 5);
        assert!(stage.aligned());
        for o in &states {
            let values = o
                .position_m
                .iter()
                .chain(&o.position_sigma_m)
                .chain(&o.velocity_mps);
            assert!(values.copied().all(f64::is_finite), "{o:?}");
        }
        let e = stage.process(&sample(799), &mut |_| {}).unwrap_err();
        assert!(
            matches!(
                e,
                OdometryError::Sample(SampleError::TimeNotIncreasing { .. })
            ),
            "{e}"
        );
        let mut big = sample(800);
        big.accel_mps2[0] = 1e300;
        let e = stage.process(&big, &mut |_| {}).unwrap_err();
        assert!(
            e.to_string().contains("accel_mps2") && e.to_string().contains("beyond"),
            "{e}"
        );
        let mut late = sample(800);
        late.stamps.sample_ns += 3_600_000_000_000;
        let e = stage.process(&late, &mut |_| {}).unwrap_err();
        assert!(matches!(e, OdometryError::TimeStep { seq: 800, .. }), "{e}");
    }

    #[test]
    fn alignment_counts_the_residual_scale_as_bias() {
        // A level sensor at rest: after alignment the horizontal bias uncertainty is the
        // turn-on repeatability and g times the residual scale/misalignment, in quadrature.
        let g = 9.81;
        let cfg = OdometryConfig::mpu9250(g);
        let mut stage = OdometryStage::new(cfg);
        // Stop at the alignment, before any update or propagation changes the covariance.
        for k in 0.. {
            if stage.aligned() {
                break;
            }
            let s = CorrectedImuSample {
                stamps: Stamps {
                    sample_ns: k * 5_000_000,
                    ..Default::default()
                },
                seq: k,
                accel_mps2: [0.0, 0.0, g],
                flags: corrected_flags::ZERO_STATE,
                ..Default::default()
            };
            stage.process(&s, &mut |_| {}).unwrap();
        }
        let cov = &stage.filter().expect("aligned").cov;
        for axis in 0..2 {
            let want = cfg.accel_bias_sigma_mps2[axis].hypot(g * cfg.accel_residual_scale);
            assert_relative_eq!(cov[(9 + axis, 9 + axis)].sqrt(), want, max_relative = 1e-6);
        }
    }
}
