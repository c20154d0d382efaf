//! The odometry stage as every process runs it ([`OdometrySession`], a [`Stage`]): corrected
//! samples and robot hints in, in the order they arrive, odometry states out. It holds the
//! policies around [`OdometryStage`] that the live process and the offline run must share:
//!
//! - **Hint order.** A hint waits in a queue (allocated up front, [`HINT_QUEUE`] hints, in
//!   publication order) and goes to the stage just before the first sample taken at or after
//!   its publication (`stamps.acquired_ns`); the stage's own delivery rule then decides which
//!   samples use it. So the states do not depend on how hints and samples interleave in
//!   transport, and a replay gives the same states. A hint is checked when it arrives
//!   ([`check_hint`]): a refused one never reaches the queue.
//! - **Sensor sessions.** The calibration stage decides where a new sensor session starts (the
//!   rule: [`ipc_types::stream`]) and marks its first sample
//!   [`corrected_flags::NEW_SESSION`]; the session follows the mark: the old stage's revisions
//!   are completed and a new stage aligns again.
//! - **Holes beyond the bridge.** A sample after more than
//!   [`crate::eskf::Manoeuvre::bridge_limit_s`] with nothing observed is refused (the offline
//!   run stops there, naming it; the live process drops it, counted), and the stage starts
//!   again from the next sample: the heading across such a hole is unknown, so the track after
//!   it is a new one (counted in [`SessionStats::unbridged`]).
//! - **Values no platform makes.** Every sample is tested against the profile's envelope
//!   (`OdometryConfig::plausible`, the rule: `ipc_types::stream::plausible`); one that fails
//!   is marked `corrected_flags::IMPLAUSIBLE` and counted (with the clipped ones,
//!   [`SessionStats::clipped`]) before the stage, whose filter bridges it as unobserved.
//! - **Samples without a gyroscope** (`raw_flags::GYRO_VALID` clear: an accelerometer-only
//!   sensor mode, the MPU-9250 at 4 kHz): nothing tracks the attitude, so what they give is
//!   configuration ([`NoGyro`]).
//! - **The platform from the data** ([`OdometrySession::auto`], `--profile auto` live): the
//!   session runs the `other` profile's rest handling (no platform assumed) and feeds every
//!   sample to [`crate::platform::Classifier`]; after [`AUTO_DECIDE_MOVING_S`] seconds of
//!   motion it decides, says so on stderr, and from the next sample on runs the recognized
//!   profile's ([`OdometryStage::reconfigure`]). The decision depends on the samples alone, so a
//!   replay decides at the same sample.

use std::collections::VecDeque;

use ipc_types::stream::{self, plausible::Plausibility, range::Clipping};
use ipc_types::{
    CorrectedImuSample, OdometryState, RobotHint, corrected_flags, odometry_flags, raw_flags,
};
use mems_stage::Stage;

use crate::config::OdometryConfig;
use crate::hints::{HintConfig, HintConfigError, HintError, HintStats, check_hint};
use crate::platform::{Classifier, Features};
use crate::profile::Profile;
use crate::stage::{OdometryError, OdometryStage};

/// Hints the session holds for samples still to come: a hint rate 20 times the 50 Hz of a
/// wheel controller for a second. The live driver takes no hint while the queue is full (it
/// stays in the subscriber's queue).
pub const HINT_QUEUE: usize = 1024;

/// Seconds of motion after which a session with `--profile auto` decides its platform.
pub const AUTO_DECIDE_MOVING_S: f64 = 10.0;

/// The platform a session recognized (`--profile auto`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AutoChoice {
    /// What the classifier measured and the class.
    pub features: Features,
    /// The profile taken.
    pub profile: Profile,
    /// The sample time of the decision, ns.
    pub at_ns: u64,
}

/// The recognition under way or done.
#[derive(Debug, Clone, Copy)]
struct Auto {
    classifier: Classifier,
    /// The configuration the profiles adjust.
    base: OdometryConfig,
    choice: Option<AutoChoice>,
}

/// What a sample without a gyroscope gives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoGyro {
    /// A state flagged `NO_GYRO` with no position or velocity (zero), never `ALIGNED`; the
    /// stage does not see the sample. The live process: a moving robot's attitude is unknown.
    Unnavigated,
    /// The stage navigates it with the attitude held at its alignment: meaningful only if the
    /// sensor never rotated (a static recording, such as the thesis's). Offline runs.
    HoldAttitude,
}

/// An input of the session.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Input {
    /// A corrected sample: its state (and revisions) are emitted.
    Sample(CorrectedImuSample),
    /// A robot hint: queued until the samples reach its publication.
    Hint(RobotHint),
}

impl From<CorrectedImuSample> for Input {
    fn from(s: CorrectedImuSample) -> Self {
        Self::Sample(s)
    }
}

/// An input the session refuses; it changes nothing.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// The stage refused the sample.
    #[error(transparent)]
    Sample(#[from] OdometryError),
    /// The hint is malformed.
    #[error(transparent)]
    Hint(#[from] HintError),
    /// [`HINT_QUEUE`] hints already wait for their samples.
    #[error(
        "robot hint seq {seq}: {HINT_QUEUE} hints already wait for the samples they precede \
         (hints published far ahead of the samples)"
    )]
    HintQueueFull {
        /// The hint's sequence number.
        seq: u64,
    },
}

/// Counters of a session, for the processes' summaries.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SessionStats {
    /// Sensor sessions seen (1 from the first sample).
    pub sessions: u64,
    /// Hints accepted into the queue.
    pub hints: u64,
    /// Samples without a gyroscope.
    pub no_gyro: u64,
    /// The first of them, by sequence number.
    pub first_no_gyro_seq: Option<u64>,
    /// Holes longer than the odometry bridges (each refused, then a new stage).
    pub unbridged: u64,
    /// Samples with an axis at the end of its range (`corrected_flags::CLIPPED`), per axis.
    pub clipped: Clipping,
    /// Samples the plausibility test refused (`corrected_flags::IMPLAUSIBLE`).
    pub implausible: u64,
    /// The first of them: sequence number and time, ns.
    pub first_implausible: Option<(u64, u64)>,
}

/// The odometry stage with the policies of every process (module documentation).
pub struct OdometrySession {
    config: OdometryConfig,
    hint_config: HintConfig,
    no_gyro: NoGyro,
    stage: OdometryStage,
    /// Hints waiting for their samples, in publication order.
    waiting: VecDeque<RobotHint>,
    stats: SessionStats,
    auto: Option<Auto>,
    /// The plausibility test (`ipc_types::stream::plausible`) with the profile's envelope.
    plausibility: Plausibility,
}

impl OdometrySession {
    /// A session whose stages run `config` with `hint_config`; a sample without a gyroscope
    /// gives what `no_gyro` says.
    pub fn new(
        config: OdometryConfig,
        hint_config: HintConfig,
        no_gyro: NoGyro,
    ) -> Result<Self, HintConfigError> {
        Ok(Self {
            stage: OdometryStage::with_hints(config, hint_config)?,
            config,
            hint_config,
            no_gyro,
            waiting: VecDeque::with_capacity(HINT_QUEUE),
            stats: SessionStats::default(),
            auto: None,
            plausibility: Plausibility::new(config.plausible, config.gravity_mps2),
        })
    }

    /// A session that recognizes its platform from the samples (module documentation):
    /// `base` is the configuration the profiles adjust (a calibration file's).
    pub fn auto(
        base: OdometryConfig,
        hint_config: HintConfig,
        no_gyro: NoGyro,
    ) -> Result<Self, HintConfigError> {
        let mut session = Self::new(Profile::Auto.odometry(base), hint_config, no_gyro)?;
        session.auto = Some(Auto {
            classifier: Classifier::default(),
            base,
            choice: None,
        });
        Ok(session)
    }

    /// The platform recognized, once decided (`--profile auto`).
    pub fn auto_choice(&self) -> Option<AutoChoice> {
        self.auto.and_then(|a| a.choice)
    }

    /// Feeds the classifier and, at the decision, takes the recognized profile.
    fn recognize(&mut self, s: &CorrectedImuSample) {
        let Some(auto) = self.auto.as_mut().filter(|a| a.choice.is_none()) else {
            return;
        };
        if s.raw_flags & raw_flags::GYRO_VALID != 0 {
            // The calibrated sample before the calibration stage's refinement at rest, as the
            // offline whole-recording classifier reads it: a detector that learned its rest
            // while the robot moved refines the robot's turning into the gyro bias (the corpus's
            // f1tenth-ds1: 20-35 deg/s about up), and the rotation's statistics lose it.
            let g = auto.base.gravity_mps2;
            let accel_g = std::array::from_fn(|i| (s.accel_mps2[i] + s.refined_accel_mps2[i]) / g);
            let gyro_dps =
                std::array::from_fn(|i| (s.gyro_rps[i] + s.refined_gyro_rps[i]).to_degrees());
            auto.classifier.push(s.stamps.sample_ns, accel_g, gyro_dps);
        }
        if auto.classifier.moving_s() < AUTO_DECIDE_MOVING_S {
            return;
        }
        let features = auto.classifier.features();
        let profile = Profile::for_platform(features.platform);
        auto.choice = Some(AutoChoice {
            features,
            profile,
            at_ns: s.stamps.sample_ns,
        });
        tracing::info!(
            "--profile auto: {} platform after {:.0} s of motion (sample seq {}): profile {} from \
             here on (tilt rate {:.1} deg/s, principal-axis share {:.2} at {:.0} deg from \
             gravity, {:.1} impacts/min)",
            features.platform.name(),
            features.moving_s,
            s.seq,
            profile.name(),
            features.tilt_rate_dps,
            features.principal_share,
            features.principal_axis_deg,
            features.impacts_per_min
        );
        // The detector is the one the session started with (the calibration stage's, chosen
        // before the platform was known): the hindsight that suits its window stays.
        self.config = OdometryConfig {
            rest_hindsight_s: self.config.rest_hindsight_s,
            ..profile.odometry(auto.base)
        };
        self.stage.reconfigure(self.config);
        self.plausibility = Plausibility::new(self.config.plausible, self.config.gravity_mps2);
    }

    /// The current sensor session's stage.
    pub fn stage(&self) -> &OdometryStage {
        &self.stage
    }

    /// The current sensor session's hint counters.
    pub fn hint_stats(&self) -> HintStats {
        self.stage.hint_stats()
    }

    /// The current sensor session's IMU-only non-holonomic constraint (a wheeled profile).
    pub fn imu_constraint(&self) -> Option<crate::nonholonomic::ImuConstraint> {
        self.stage.imu_constraint()
    }

    /// The current sensor session's hand-held walking counters (the walking profile).
    pub fn walking_stats(&self) -> Option<crate::walking::WalkingStats> {
        self.stage.walking_stats()
    }

    /// The session's counters.
    pub fn stats(&self) -> SessionStats {
        self.stats
    }

    /// Whether a hint would find room in the queue.
    pub fn hint_room(&self) -> bool {
        self.waiting.len() < HINT_QUEUE
    }

    /// Queues a checked hint after those published before it or with it.
    fn queue(&mut self, h: &RobotHint) -> Result<(), Refusal> {
        check_hint(h)?;
        if !self.hint_room() {
            return Err(Refusal::HintQueueFull { seq: h.seq });
        }
        let t = h.stamps.acquired_ns;
        let at = self.waiting.partition_point(|q| q.stamps.acquired_ns <= t);
        self.waiting.insert(at, *h);
        self.stats.hints += 1;
        Ok(())
    }

    /// Starts a new stage when `s` begins a new sensor session (marked
    /// [`corrected_flags::NEW_SESSION`] by the calibration stage), completing the old one's
    /// revisions first.
    fn new_session(&mut self, s: &CorrectedImuSample, emit: &mut impl FnMut(&OdometryState)) {
        if self.stats.sessions == 0 {
            self.stats.sessions = 1;
        } else if s.flags & corrected_flags::NEW_SESSION != 0 {
            self.restart(emit);
            self.stats.sessions += 1;
            self.plausibility.restart();
        }
    }

    /// `s` marked `IMPLAUSIBLE` when the plausibility test fails it (a value the stream
    /// contract refuses is left to the stage to refuse); clipped and implausible samples
    /// counted.
    fn judge(&mut self, s: &CorrectedImuSample) -> CorrectedImuSample {
        let mut s = *s;
        if stream::check_corrected(&s).is_err() {
            return s;
        }
        if s.flags & corrected_flags::CLIPPED != 0 {
            // A source that did not say which axes counts as SATURATED alone.
            self.stats.clipped.count(s.raw_flags | raw_flags::SATURATED);
        }
        let (t_ns, f, w) = (s.stamps.sample_ns, s.accel_mps2, s.gyro_rps);
        if self.plausibility.check(t_ns, &f, &w).is_some() {
            s.flags |= corrected_flags::IMPLAUSIBLE;
            self.stats.implausible += 1;
            self.stats.first_implausible.get_or_insert((s.seq, t_ns));
        }
        s
    }

    /// Completes the stage's revisions and starts a new one.
    fn restart(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        self.stage.finish(emit);
        self.stage = OdometryStage::with_hints(self.config, self.hint_config)
            .expect("validated when the session was made");
    }
}

impl Stage for OdometrySession {
    type Input = Input;
    type Output = OdometryState;
    type Refusal = Refusal;

    /// A sample: the previous sample's settling if no driver did it ([`Self::postprocess`]),
    /// then the hints published by its time go to the stage, then the sample: its live state.
    /// A hint: queued.
    fn process(
        &mut self,
        input: &Input,
        emit: &mut impl FnMut(&OdometryState),
    ) -> Result<(), Refusal> {
        let s = match input {
            Input::Hint(h) => return self.queue(h),
            Input::Sample(s) => s,
        };
        // Before anything here can change the stage (a new session, a recognized platform).
        self.stage.postprocess(emit);
        self.new_session(s, emit);
        let s = &self.judge(s);
        while let Some(h) = self.waiting.front()
            && h.stamps.acquired_ns <= s.stamps.sample_ns
        {
            let checked = self.stage.hint(h, emit);
            debug_assert!(checked.is_ok(), "checked when queued");
            self.waiting.pop_front();
        }
        if s.raw_flags & raw_flags::GYRO_VALID == 0 {
            self.stats.no_gyro += 1;
            self.stats.first_no_gyro_seq.get_or_insert(s.seq);
            if self.no_gyro == NoGyro::Unnavigated {
                emit(&OdometryState {
                    stamps: s.stamps,
                    seq: s.seq,
                    attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
                    flags: odometry_flags::NO_GYRO,
                    ..OdometryState::default()
                });
                return Ok(());
            }
        }
        match self.stage.process(s, emit) {
            Err(e @ OdometryError::HoleBeyondBridge { .. }) => {
                self.restart(emit);
                self.stats.unbridged += 1;
                Err(e.into())
            }
            taken => {
                taken?;
                self.recognize(s);
                Ok(())
            }
        }
    }

    /// Completes a replay of the hindsight still under way.
    fn finish(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        self.stage.finish(emit);
    }

    /// A sample that settled a zero-state batch: that batch's settling and revisions (a few
    /// hundred us) are due.
    fn postprocess_due(&self) -> bool {
        self.stage.postprocess_due()
    }

    /// The stage's settling and revisions ([`OdometryStage::postprocess`]).
    fn postprocess(&mut self, emit: &mut impl FnMut(&OdometryState)) {
        self.stage.postprocess(emit);
    }
}
