//! Rest in hindsight: the journal of the inputs whose rest flags may still be withdrawn or
//! reinstated, the copies of the settled navigator to navigate them again from, and the
//! replay that does it (the rule and its reasons: the module documentation of
//! [`crate::stage`]).

use crate::config::OdometryConfig;
use crate::hints::{HintConfig, Ring};
use crate::navigator::Navigator;
use ipc_types::{CorrectedImuSample, OdometryState, RobotHint, corrected_flags, odometry_flags};

/// One input of the stage, kept in arrival order while a replay may need it.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Input {
    /// A sample whose `ZERO_STATE` flag is the one in force (the detector's, or cleared when
    /// withdrawn), and the detector's own flag.
    Sample {
        s: CorrectedImuSample,
        imu_rest: bool,
    },
    Hint(RobotHint),
}

impl Default for Input {
    /// Filler for the ring's unused storage.
    fn default() -> Self {
        Self::Hint(RobotHint::default())
    }
}

/// A copy of the settled navigator taken after it had taken the journal's inputs up to an
/// absolute position, with the flags then in force.
#[derive(Debug, Clone, Copy)]
struct Checkpoint {
    /// Inputs the copy has taken since the start.
    pos: u64,
    /// Its navigator in [`Hindsight::pool`].
    slot: usize,
}

/// The inputs of the last `2 rest_hindsight_s + motion_confirm_s` (as long as flags can
/// change) and a navigator state from before them to navigate them again from.
///
/// That state, the base, is what a navigator that took every input with its final flags had
/// at the journal's front. The settled navigator takes every input, on the flags in force
/// when it takes it (or the live navigator does in its stead, `crate::stage::OdometryStage`'s `in_step`); most
/// of the time they stay so. So copies of it are kept every [`CHECKPOINT_EVERY`] inputs: a
/// copy whose inputs have all become final with no flag changed since it was taken holds
/// what a navigator on final flags would, and becomes the base; a change of the flags drops
/// the copies that took a changed input. The base is only fed inputs itself when the journal
/// is full (no copy became final in time).
pub(crate) struct Hindsight {
    /// [`OdometryConfig::rest_hindsight_s`], ns.
    lag_ns: u64,
    /// [`OdometryConfig::motion_confirm_s`], ns.
    confirm_ns: u64,
    /// The navigator state after the inputs before the journal's front, on final flags.
    base: Navigator,
    /// Absolute position (inputs since the start) of the journal's front.
    base_pos: u64,
    /// Absolute position of the first input whose flags are not final yet.
    pub(crate) final_pos: u64,
    /// The inputs from `base_pos` on, in arrival order, with the flags in force.
    journal: Ring<Input>,
    /// Copies of the settled navigator not yet final, oldest first.
    checkpoints: Vec<Checkpoint>,
    /// Storage of the copies, allocated up front.
    pool: Vec<Navigator>,
    /// Slots of `pool` not in use.
    free: Vec<usize>,
    /// The navigator replaying the journal after a change of the flags in force, from the
    /// base's state, a bounded number of inputs per call.
    pub(crate) redo: Navigator,
    /// Absolute position of the next input `redo` takes; `None` when no replay is under way.
    pub(crate) redo_pos: Option<u64>,
    /// Samples that became final with their rest flag withdrawn.
    pub(crate) withdrawn: u64,
    /// Start of the current run of IMU motion flags, ns.
    motion_since_ns: u64,
    /// When the hindsight of rest will have followed a short run of motion flags that ended
    /// (its withdrawals are then undone), ns.
    reinstate_at_ns: Option<u64>,
}

impl Hindsight {
    /// Every navigator takes `cfg` ([`Navigator::reconfigure`]); the hindsight's own lag and
    /// confirmation stay.
    pub(crate) fn reconfigure(&mut self, cfg: OdometryConfig) {
        self.base.reconfigure(cfg);
        self.redo.reconfigure(cfg);
        for nav in &mut self.pool {
            nav.reconfigure(cfg);
        }
    }

    /// Hindsight of `lag_s` and `confirm_s` for `cfg`, its storage allocated here.
    pub(crate) fn new(cfg: OdometryConfig, hints: HintConfig, lag_s: f64, confirm_s: f64) -> Self {
        let window = ((2.0 * lag_s + confirm_s) * cfg.max_rate_hz).ceil() as usize;
        let copies = window.div_ceil(CHECKPOINT_EVERY) + 4;
        Self {
            lag_ns: (lag_s * 1e9).round() as u64,
            confirm_ns: (confirm_s * 1e9).round() as u64,
            base: Navigator::new(cfg, hints),
            base_pos: 0,
            final_pos: 0,
            journal: Ring::new(window + 2 * CHECKPOINT_EVERY + hints.capacity + 2),
            checkpoints: Vec::with_capacity(copies),
            pool: (0..copies).map(|_| Navigator::new(cfg, hints)).collect(),
            free: (0..copies).rev().collect(),
            redo: Navigator::new(cfg, hints),
            redo_pos: None,
            withdrawn: 0,
            motion_since_ns: 0,
            reinstate_at_ns: None,
        }
    }

    /// Follows the runs of IMU motion flags (`flipped`: the flag changed at this sample, now
    /// `imu_rest`); whether, at `t_ns`, a short run that ended has been followed by the
    /// hindsight of rest, so that its withdrawals are to be undone.
    fn reinstatement_due(&mut self, t_ns: u64, imu_rest: bool, flipped: bool) -> bool {
        if flipped {
            if imu_rest {
                self.reinstate_at_ns =
                    (t_ns - self.motion_since_ns < self.confirm_ns).then_some(t_ns + self.lag_ns);
            } else {
                self.motion_since_ns = t_ns;
                self.reinstate_at_ns = None;
            }
        }
        let due = self.reinstate_at_ns.is_some_and(|r| t_ns >= r);
        if due {
            self.reinstate_at_ns = None;
        }
        due
    }

    /// Absolute position after the newest input.
    pub(crate) fn end_pos(&self) -> u64 {
        self.base_pos + self.journal.len() as u64
    }

    /// The input at absolute position `pos`, if the journal holds it.
    pub(crate) fn at(&self, pos: u64) -> Option<&Input> {
        self.journal
            .oldest(pos.checked_sub(self.base_pos)? as usize)
    }

    /// Keeps `input`; when the journal is full, its oldest input goes to the base navigator
    /// (above `max_rate_hz`, early, with its flags as they stand).
    pub(crate) fn keep(&mut self, input: Input, emit: &mut impl FnMut(&OdometryState)) {
        if self.journal.is_full() {
            self.pop_front(emit);
        }
        self.journal.push(input);
    }

    /// Gives the journal's oldest input to the base navigator, making it final if it was not
    /// (a replay under way takes it first if it has not yet, so that every state it changes is
    /// republished).
    fn pop_front(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        if self.final_pos == self.base_pos {
            self.finalise_next(emit);
        }
        if let Some(input) = self.journal.pop() {
            feed(&mut self.base, &input, &mut |_| {});
            self.base_pos += 1;
        }
        while self
            .checkpoints
            .first()
            .is_some_and(|c| c.pos <= self.base_pos)
        {
            let c = self.checkpoints.remove(0);
            self.free.push(c.slot);
        }
    }

    /// Makes the input at `final_pos` final: a replay that has not taken it takes it first,
    /// and a withdrawn rest flag is counted.
    fn finalise_next(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        let Some(input) = self.at(self.final_pos).copied() else {
            return;
        };
        if self.redo_pos == Some(self.final_pos) {
            self.redo_step(emit);
        }
        if let Input::Sample { s, imu_rest: true } = input
            && s.flags & corrected_flags::ZERO_STATE == 0
        {
            self.withdrawn += 1;
        }
        self.final_pos += 1;
    }

    /// The replay takes its next journal input, its states republished as `REVISION`.
    fn redo_step(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        let Some(p) = self.redo_pos else { return };
        let Some(input) = self.at(p).copied() else {
            return;
        };
        feed(&mut self.redo, &input, &mut |o| {
            emit(&OdometryState {
                flags: o.flags | odometry_flags::REVISION,
                ..*o
            })
        });
        self.redo_pos = Some(p + 1);
        self.checkpoint_redo();
    }

    /// Advances the replay by at most `*budget` inputs (counted down); whether it has caught
    /// up with the newest input (then `redo` holds the final state and the replay is over).
    pub(crate) fn redo_advance(
        &mut self,
        budget: &mut usize,
        emit: &mut impl FnMut(&OdometryState),
    ) -> bool {
        while let Some(p) = self.redo_pos {
            if p >= self.end_pos() {
                self.redo_pos = None;
                return true;
            }
            if *budget == 0 {
                return false;
            }
            *budget -= 1;
            self.redo_step(emit);
        }
        false
    }

    /// Journals one sample with settled flags (`flipped`: its IMU rest flag differs from the
    /// previous one; `imu_transition`: and the detector, not a hint, decided that one) and
    /// starts a replay when the flags in force changed.
    pub(crate) fn journal(
        &mut self,
        s: &CorrectedImuSample,
        imu_rest: bool,
        flipped: bool,
        imu_transition: bool,
        emit: &mut impl FnMut(&OdometryState),
    ) {
        let t_ns = s.stamps.sample_ns;
        let reinstate = self.reinstatement_due(t_ns, imu_rest, flipped);
        self.keep(Input::Sample { s: *s, imu_rest }, emit);
        self.catch_up(t_ns, emit);
        if (imu_transition || reinstate) && self.resolve().is_some() {
            // Flags in force changed: navigate the journal again from the state on final
            // flags (starting over if a replay was under way).
            self.start_replay();
        }
    }

    /// Starts a replay of the inputs whose flags are not final, from the state a navigator
    /// on final flags has before them: the base, taken through the final inputs after it
    /// (their states unchanged, so not republished).
    fn start_replay(&mut self) {
        self.redo.copy_from(&self.base);
        for pos in self.base_pos..self.final_pos {
            let input = *self.at(pos).expect("final inputs are journalled");
            feed(&mut self.redo, &input, &mut |_| {});
            self.redo_pos = Some(pos + 1);
            self.checkpoint_redo();
        }
        self.redo_pos = Some(self.final_pos);
    }

    /// Makes final every input up to the last sample whose rest flag is final at `t_ns`: a
    /// motion starting within the hindsight after it is confirmed or not at the latest the
    /// confirmation time plus the hindsight after its start. The newest checkpoint whose
    /// inputs are all final becomes the base.
    fn catch_up(&mut self, t_ns: u64, emit: &mut impl FnMut(&OdometryState)) {
        while let Some(input) = self.at(self.final_pos).copied() {
            if let Input::Sample { s, .. } = input
                && s.stamps.sample_ns + 2 * self.lag_ns + self.confirm_ns > t_ns
            {
                break;
            }
            self.finalise_next(emit);
        }
        while self
            .checkpoints
            .first()
            .is_some_and(|c| c.pos <= self.final_pos)
        {
            let c = self.checkpoints.remove(0);
            std::mem::swap(&mut self.base, &mut self.pool[c.slot]);
            self.free.push(c.slot);
            while self.base_pos < c.pos {
                self.journal.pop();
                self.base_pos += 1;
            }
        }
    }

    /// Makes `nav` the settled navigator as it is after the newest input (no replay under way):
    /// the newest copy (or the base) taken through the journal's inputs after it.
    pub(crate) fn rebuild(&self, nav: &mut Navigator) {
        let (from, pos) = match self.checkpoints.last() {
            Some(c) => (&self.pool[c.slot], c.pos),
            None => (&self.base, self.base_pos),
        };
        nav.copy_from(from);
        for p in pos..self.end_pos() {
            let input = self
                .at(p)
                .expect("the journal holds the inputs after its copies");
            feed(nav, input, &mut |_| {});
        }
    }

    /// Keeps a copy of `settled`, which has taken every input with the flags in force, if the
    /// last copy is [`CHECKPOINT_EVERY`] inputs old.
    pub(crate) fn checkpoint(&mut self, settled: &Navigator) {
        if let Some(slot) = self.checkpoint_slot(self.end_pos()) {
            self.pool[slot].copy_from(settled);
        }
    }

    /// The same for the replay, which has taken the inputs before `redo_pos` with the flags in
    /// force: after a change of the flags, the copies it leaves keep the replays that follow
    /// short.
    fn checkpoint_redo(&mut self) {
        let Some(pos) = self.redo_pos else { return };
        if let Some(slot) = self.checkpoint_slot(pos) {
            self.pool[slot].copy_from(&self.redo);
        }
    }

    /// A free slot for the copy of a navigator that has taken the inputs before `pos`,
    /// registered, if the newest copy (or the base) is [`CHECKPOINT_EVERY`] inputs older.
    fn checkpoint_slot(&mut self, pos: u64) -> Option<usize> {
        let last = self.checkpoints.last().map_or(self.base_pos, |c| c.pos);
        if pos < last + CHECKPOINT_EVERY as u64 {
            return None;
        }
        let slot = self.free.pop()?;
        self.checkpoints.push(Checkpoint { pos, slot });
        Some(slot)
    }

    /// Sets the flag in force of every sample whose flags are not final by the rule (module
    /// docs): a detector rest flag stands unless a confirmed motion starts within the
    /// hindsight after it. A run of motion flags is confirmed unless it lasts less than the
    /// confirmation time and is followed by at least the hindsight of rest flags (so a run
    /// still going on, or one whose rest after it is younger than the hindsight, counts as
    /// confirmed for now). Returns the absolute position of the oldest sample whose flag
    /// changed, and drops the checkpoints that took it.
    fn resolve(&mut self) -> Option<u64> {
        let mut oldest_changed = None;
        // Backwards: the newest sample's time, the start of the nearest later confirmed run
        // and of the nearest later run, the time of the first rest sample after the run being
        // crossed (None: it runs to the newest sample), and whether a run is being crossed.
        let mut newest: Option<u64> = None;
        let mut confirmed_start: Option<u64> = None;
        let mut later_start: Option<u64> = None;
        let mut run_end: Option<u64> = None;
        let mut in_run = false;
        let mut run_start = 0u64;
        let first = (self.final_pos - self.base_pos) as usize;
        for i in (first..self.journal.len()).rev() {
            let Some(Input::Sample { s, imu_rest }) = self.journal.oldest_mut(i) else {
                continue;
            };
            let t = s.stamps.sample_ns;
            let newest = *newest.get_or_insert(t);
            if !*imu_rest {
                in_run = true;
                run_start = t;
                continue;
            }
            if in_run {
                // The run crossed started at `run_start` and ended before `run_end`.
                in_run = false;
                let confirmed = run_end.is_none_or(|end| {
                    end - run_start >= self.confirm_ns
                        || later_start.unwrap_or(newest) - end < self.lag_ns
                });
                if confirmed {
                    confirmed_start = Some(run_start);
                }
                later_start = Some(run_start);
            }
            run_end = Some(t);
            let rest = confirmed_start.is_none_or(|m| m - t >= self.lag_ns);
            let flags = if rest {
                s.flags | corrected_flags::ZERO_STATE
            } else {
                s.flags & !corrected_flags::ZERO_STATE
            };
            if flags != s.flags {
                oldest_changed = Some(self.base_pos + i as u64);
            }
            s.flags = flags;
        }
        let changed = oldest_changed?;
        while self.checkpoints.last().is_some_and(|c| c.pos > changed) {
            let c = self.checkpoints.pop().expect("checked");
            self.free.push(c.slot);
        }
        Some(changed)
    }
}

/// Gives one input to a navigator.
pub(crate) fn feed(nav: &mut Navigator, input: &Input, emit: &mut impl FnMut(&OdometryState)) {
    match input {
        Input::Sample { s, .. } => nav.process(s, emit),
        Input::Hint(h) => nav.hint(h),
    }
}

/// Most journal inputs a replay after a change of the flags in force navigates again in one
/// call of [`crate::stage::OdometryStage::process`] (a replay needs up to `2 rest_hindsight_s +
/// motion_confirm_s` of inputs, 1 500 at 1 kHz, 6 000 at 4 kHz).
pub const REPLAY_PER_CALL: usize = 64;

/// Inputs between two copies of the settled navigator kept by the hindsight: a replay first
/// navigates at most about this many final inputs at once (in the call that starts it), and
/// each copy costs a navigator's storage in use (its motion history).
const CHECKPOINT_EVERY: usize = 4 * REPLAY_PER_CALL;
