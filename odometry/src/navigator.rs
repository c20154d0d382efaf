//! The navigator: the odometry stage's filter-driving state machine for one stream of inputs
//! (alignment, prediction, rest and hint updates, motion-interval revisions). The public
//! [`crate::stage::OdometryStage`] validates the inputs and runs two navigators, one on the
//! newest inputs and one on settled flags (and replays on final flags); this module holds what
//! each of them does. The module documentation of [`crate::stage`] describes the behaviour.

use crate::attitudes::RestAttitudes;
use crate::clip::{ClipRepair, ClipStats};
use crate::config::OdometryConfig;
use crate::consistency::{Consistency, ConsistencyReport, Kind};
use crate::cruise::CruiseWindow;
use crate::eskf::{ConsiderModel, Cov, Eskf, Imu, KS, Nominal, Refinement, align};
use crate::hand_bound::HandBound;
use crate::hints::{
    ForwardAxisReport, HintConfig, HintStats, has_rest_source, turns_while_stationary,
    usable_from_ns,
};
use crate::nonholonomic::{ImuConstraint, Outcome};
use crate::rest_scatter::RestScatter;
use crate::sampled_noise::SampledNoise;
use crate::stops::StopTest;
use crate::uncalibrated::{AccelEstimate, AccelPrior};
use crate::untrusted::{Untrusted, Verdict};
use crate::walking::Walk;
use ipc_types::{
    CorrectedImuSample, OdometryState, RobotHint, corrected_flags, hint_flags, odometry_flags,
    raw_flags,
};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

mod hint_state;
mod in_motion;
mod learning;
mod records;
mod wait_revision;
mod walk_hooks;
mod wheeled;
use hint_state::{BodyVelocity, HintDecision, HintSample, Hints, WheelsStill};
use learning::{Learned, LearningWindow};
use records::{AlignSums, HistoryEntry, PendingRevision, RestWindow};

/// Rest a filter with speed hints aligns on at least, s: a robot that creeps off from its
/// first sample is as still to the IMU as a rest for a second (its encoders do not tick
/// yet), and its hints' cruise alignment ([`crate::cruise`]) is what should start it. A
/// simulated drive that starts moving at once (odometry/tests/start_in_motion.rs), aligned on
/// half a second of that, ended outside its 1-sigma.
const HINT_ALIGN_S: f64 = 1.0;

/// The odometry state machine for one stream of inputs. Its storage is allocated once, in
/// [`Navigator::new`]; [`Navigator::copy_from`] copies another navigator into it without
/// allocating.
pub(crate) struct Navigator {
    cfg: OdometryConfig,
    hints: Hints,
    align: AlignSums,
    /// The samples before the detector's learned verdict, for the alignment.
    learning: LearningWindow,
    /// The learning window's alignment sums and the rest flagged after it, while the flagged
    /// rest is too short to align on by itself (`navigator::learning`).
    learned: Option<Learned>,
    /// The cruise window gathered while unaligned ([`crate::cruise`]).
    cruise: CruiseWindow,
    /// Mean hint speed of the cruise window aligned on, m/s; `None`: aligned at rest or not yet.
    aligned_in_motion: Option<f64>,
    /// 1-sigma of one sample's zero-velocity update, m/s: the configured one, widened by the
    /// square root of the alignment rest's accelerometer mean-variance factor when
    /// `effective_samples` is set.
    zupt_sigma_mps: f64,
    kf: Option<Eskf>,
    /// Rest samples whose updates are still to be made.
    rest_window: RestWindow,
    /// Time (ns), sequence number and measurement of the previous sample.
    last: Option<(u64, u64, Imu)>,
    /// The calibration stage's refinement of the current sample.
    refinement: Refinement,
    /// The share of `refinement` the stage made while a fresh speed hint said the robot moved,
    /// until the filter aligned: the stage averaged a moving platform there (its detector
    /// learned its noise in motion), no bias ([`Self::take_refinement`]); a cruise window that
    /// turns leaves it out ([`crate::cruise::CruiseWindow::turning`]).
    motion_refinement: Refinement,
    history: Vec<HistoryEntry>,
    history_overflowed: bool,
    motion_start_ns: Option<u64>,
    pending: Option<PendingRevision>,
    at_rest: bool,
    rest_count: u32,
    distance_m: f64,
    /// Whether the IMU's zero-state flag made the last rest decision (no fresh rest hint).
    imu_decided: bool,
    /// The IMU-only non-holonomic constraint (wheeled platforms).
    nhc: Option<ImuConstraint>,
    /// Standard deviation of the specific force's norm over the alignment rest, m/s^2.
    standing_accel_sd: f64,
    /// The low-frequency test of a wheeled platform's stops (`crate::stops`).
    stops: StopTest,
    /// Clipped and implausible stretches in progress.
    untrusted: Untrusted,
    /// The clipped motion gathered for its reconstruction (boxed, 170 kB, made in `new`).
    clip: Box<ClipRepair>,
    /// The accelerometer prior the filter aligned with.
    accel_prior: Option<AccelPrior>,
    /// The rest samples by attitude (`crate::attitudes`).
    attitudes: RestAttitudes,
    /// The stream's per-sample scatter, for the prediction's noise (`cfg.sampled_noise`).
    sampled: SampledNoise,
    /// The gyro's scatter at rest, for a wheeled platform's zero-rate update.
    rest_scatter: RestScatter,
    /// What the updates' innovations say of the covariance (`crate::consistency`).
    consistency: Consistency,
    /// Hand-held walking's steps and updates (`cfg.walking`).
    walk: Option<Walk>,
    /// The hand's velocity bound (`crate::hand_bound`).
    hand: HandBound,
}

impl Navigator {
    /// A navigator with the (validated) hint configuration `hints`. Allocated here: the
    /// motion history for `max_motion_s` at `revision_rate_hz` (only decimated states are
    /// kept), and the velocity history for the hints' `max_age_s` at `max_rate_hz`.
    pub fn new(cfg: OdometryConfig, hints: HintConfig) -> Self {
        let capacity = (cfg.max_motion_s * cfg.revision_rate_hz).ceil() as usize + 1;
        let velocity_capacity = (hints.max_age_s * cfg.max_rate_hz).ceil() as usize + 2;
        Self {
            cfg,
            hints: Hints::new(hints, velocity_capacity),
            align: AlignSums::default(),
            learning: LearningWindow::new(cfg.learned_rest_s, cfg.max_rate_hz),
            learned: None,
            cruise: CruiseWindow::default(),
            aligned_in_motion: None,
            zupt_sigma_mps: cfg.zupt_sigma_mps,
            kf: None,
            rest_window: RestWindow::default(),
            last: None,
            refinement: Refinement::default(),
            motion_refinement: Refinement::default(),
            history: Vec::with_capacity(capacity),
            history_overflowed: false,
            motion_start_ns: None,
            pending: None,
            at_rest: false,
            rest_count: 0,
            distance_m: 0.0,
            imu_decided: true,
            nhc: (cfg.imu_nonholonomic_sigma_mps > 0.0)
                .then(|| wheeled::imu_constraint(&cfg, &hints)),
            standing_accel_sd: 0.0,
            stops: StopTest::default(),
            untrusted: Untrusted::default(),
            clip: Box::default(),
            accel_prior: None,
            attitudes: RestAttitudes::default(),
            sampled: SampledNoise::default(),
            rest_scatter: RestScatter::default(),
            consistency: Consistency::new(cfg.consistency),
            walk: cfg.walking.map(Walk::new),
            hand: HandBound::default(),
        }
    }

    /// Makes this navigator a copy of `other` (built alike), in its own storage: no allocation.
    pub fn copy_from(&mut self, other: &Self) {
        self.cfg = other.cfg;
        self.hints.copy_from(&other.hints);
        self.align = other.align;
        self.learning.copy_from(&other.learning);
        self.learned = other.learned;
        self.cruise = other.cruise;
        self.aligned_in_motion = other.aligned_in_motion;
        self.zupt_sigma_mps = other.zupt_sigma_mps;
        self.kf.clone_from(&other.kf);
        self.rest_window = other.rest_window;
        self.last = other.last;
        self.refinement = other.refinement;
        self.motion_refinement = other.motion_refinement;
        self.history.clone_from(&other.history);
        self.history_overflowed = other.history_overflowed;
        self.motion_start_ns = other.motion_start_ns;
        self.pending = other.pending;
        self.at_rest = other.at_rest;
        self.rest_count = other.rest_count;
        self.distance_m = other.distance_m;
        self.imu_decided = other.imu_decided;
        self.nhc = other.nhc;
        self.standing_accel_sd = other.standing_accel_sd;
        self.stops = other.stops;
        self.untrusted = other.untrusted;
        self.clip.copy_from(&other.clip);
        self.accel_prior = other.accel_prior;
        self.sampled = other.sampled;
        self.rest_scatter = other.rest_scatter;
        self.consistency = other.consistency;
        self.walk = other.walk;
        self.hand = other.hand;
    }

    /// Takes `cfg` from the next sample on (a profile recognized from the data): its rest
    /// handling, manoeuvre and wheeled constraint. An alignment already made keeps its
    /// effective-sample factor on the zero-velocity sigma.
    pub fn reconfigure(&mut self, cfg: OdometryConfig) {
        let factor = self.zupt_sigma_mps / self.cfg.zupt_sigma_mps;
        self.zupt_sigma_mps = cfg.zupt_sigma_mps * if cfg.effective_samples { factor } else { 1.0 };
        self.nhc = match (cfg.imu_nonholonomic_sigma_mps > 0.0, self.nhc) {
            (false, _) => None,
            (true, Some(nhc)) => Some(nhc),
            (true, None) => Some(self.started_constraint(&cfg)),
        };
        self.walk = match (cfg.walking, self.walk) {
            (None, _) => None,
            (Some(_), Some(walk)) => Some(walk),
            (Some(c), None) => Some(Walk::new(c)),
        };
        self.cfg = cfg;
    }

    /// The IMU-only non-holonomic constraint, on a wheeled platform.
    pub fn imu_constraint(&self) -> Option<&ImuConstraint> {
        self.nhc.as_ref()
    }

    /// Takes a (checked) robot hint. It waits (in a buffer allocated up front) until a sample
    /// taken at least [`HintConfig::delivery_s`] after its publication, which then uses it.
    pub fn hint(&mut self, h: &RobotHint) {
        self.hints.stats.received += 1;
        if self.hints.waiting.push(*h).is_some() {
            self.hints.stats.overflowed += 1;
        }
    }

    /// Counters of the hints seen so far.
    pub fn hint_stats(&self) -> HintStats {
        self.hints.stats
    }

    /// 1-sigma of one sample's zero-velocity update, m/s (see the field).
    pub fn zupt_sigma_mps(&self) -> f64 {
        self.zupt_sigma_mps
    }

    /// The lever arm from the IMU to the rear axle, body frame, m (`HintConfig::lever_arm_m`).
    pub fn lever_arm_m(&self) -> Vector3<f64> {
        self.hints.cfg.lever_arm_m
    }

    /// The IMU-to-body mounting (sensor to body), configured or estimated (`None`: not yet).
    pub fn mounting(&self) -> Option<UnitQuaternion<f64>> {
        self.hints.r_bs.map(|r| {
            UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r))
        })
    }

    /// The forward axis estimated from the speed hints ([`crate::cruise::ForwardAxis`]): when
    /// it was first trusted, its latest 1-sigmas and speed scale, and what the filter took.
    pub fn forward_axis(&self) -> Option<ForwardAxisReport> {
        self.hints.forward_report()
    }

    /// The filter's wheel-speed scale error and its 1-sigma (fractions: the speed hints read
    /// `1 + k` times the speed); `None` before alignment.
    pub fn speed_scale(&self) -> Option<(f64, f64)> {
        self.kf.as_ref().map(Eskf::scale)
    }

    /// Whether alignment is done.
    pub fn aligned(&self) -> bool {
        self.kf.is_some()
    }

    /// The mean hint speed of the cruise window the filter aligned on, m/s; `None` when it
    /// aligned at rest or has not aligned ([`crate::cruise`]).
    pub fn aligned_in_motion(&self) -> Option<f64> {
        self.aligned_in_motion
    }

    /// Whether the last sample's rest decision was the IMU's zero-state flag (no fresh hint
    /// with a rest source decided it).
    pub fn imu_decided(&self) -> bool {
        self.imu_decided
    }

    /// What the updates' innovations said so far (`crate::consistency`).
    pub fn consistency(&self) -> ConsistencyReport {
        self.consistency.report()
    }

    /// What the reconstruction of clipped runs did so far.
    pub fn clip_stats(&self) -> ClipStats {
        self.clip.stats()
    }

    /// The filter, once aligned (for diagnostics and tests).
    pub fn filter(&self) -> Option<&Eskf> {
        self.kf.as_ref()
    }

    /// What the filter holds of the accelerometer's error, once aligned.
    pub fn accel_estimate(&self) -> Option<AccelEstimate> {
        Some(AccelEstimate::of(
            self.kf.as_ref()?,
            self.accel_prior.as_ref()?,
            &self.cfg.uncalibrated,
            &self.attitudes,
            self.cfg.gravity_mps2,
        ))
    }

    /// Processes one (checked: finite, later than the previous) sample: emits its state, and
    /// any revised states that the end of a motion interval made available, through `emit`.
    pub fn process(&mut self, s: &CorrectedImuSample, emit: &mut impl FnMut(&OdometryState)) {
        let t_ns = s.stamps.sample_ns;
        let verdict = Verdict::of(s, &self.cfg);
        let m = match self.last {
            // Not a measurement: the previous reading is held across it.
            Some((_, _, held)) if verdict.implausible => held,
            _ => Imu {
                f: Vector3::from(s.accel_mps2),
                w: self.cfg.gyro_correction * Vector3::from(s.gyro_rps),
            },
        };
        let imu_rest = s.flags & corrected_flags::ZERO_STATE != 0;
        self.sampled.push(t_ns, &m.f, &m.w);
        let prev = self
            .last
            .replace((t_ns, s.seq, m))
            .map(|(t, seq, m)| ((t, m), seq));
        // Samples are missing before this one: the raw stream says so, or the sequence skips.
        let gap = s.raw_flags & raw_flags::GAP_BEFORE != 0
            || prev.is_some_and(|(_, seq)| s.seq != seq + 1);
        let prev_ns = prev.map(|((t, _), _)| t);
        let detector_ready = s.flags & corrected_flags::DETECTOR_READY != 0;
        let mut d = self.hint_decision(t_ns, imu_rest, detector_ready);
        let hint_moving = d.rest == Some(false);
        self.take_refinement(s, hint_moving);
        // Hand-held walking: the quiet instants between steps are no rests.
        let (step, walking) = self.walk_step(t_ns, &m, verdict.implausible);
        let imu_rest = imu_rest && !walking;
        let dt = (t_ns - prev_ns.unwrap_or(t_ns)) as f64 * 1e-9;
        self.push_stops(&m, dt, imu_rest && detector_ready);

        if self.kf.is_none() {
            let rest = d.rest.unwrap_or(imu_rest);
            // A stationary hint aligns only once the calibration stage has learned its
            // references (its zero-state flag never comes earlier): until then the stage's gyro
            // output still carries the turn-on bias it is about to subtract, and a filter
            // aligned on it would take that step for rotation.
            let ready = detector_ready || d.rest.is_none();
            // An implausible sample is no reading of the rest: skipped; a clipped one, no rest.
            if !verdict.implausible {
                let gravity_off = s.flags & corrected_flags::GRAVITY_OFF != 0;
                let rest = rest && ready && verdict.clipped == 0;
                self.gather_attitude(&m, rest);
                if !self.seed_alignment(s, &m, verdict.clipped == 0, d.rest, gravity_off) {
                    self.accumulate_alignment(t_ns, &m, rest, gravity_off);
                }
                let still = imu_rest && detector_ready && verdict.clipped == 0;
                self.accumulate_cruise(t_ns, &m, d.fresh.filter(|_| still), gravity_off);
                self.align_on_steps(&m, step.as_ref(), gravity_off);
            }
            emit(&self.unaligned_state(s, rest, d.sample));
            return;
        }
        let imu_rest = imu_rest && !self.vibrating(s, &mut d.sample);
        let unaided = self.unaided_wheeled(&d);
        let imu_rest =
            self.wheeled_rest(imu_rest, !walking && detector_ready, unaided, &mut d.sample);
        let rest = self.rest_decision(&d, imu_rest);
        self.gather_attitude(&m, rest && !verdict.implausible && verdict.clipped == 0);
        if !rest {
            // The rest ended at the previous sample: its last updates are made there.
            self.close_rest_window();
        }
        let reconstruct = self.cfg.reconstruct_clipped && !verdict.implausible;
        let clipped = if reconstruct { verdict.clipped } else { 0 };
        self.clip
            .before_predict(self.kf.as_ref().expect("aligned"), clipped);
        let refused = self.refinement_measured_motion(&m, &d.sample, hint_moving);
        self.kf
            .as_mut()
            .expect("aligned")
            .follow_refinement(self.refinement, refused);
        let moved = self.predict(m, dt, gap, &mut d.sample);
        let kf = self.kf.as_mut().expect("aligned");
        if self.untrusted.widen(kf, &m, dt, verdict, &self.cfg) {
            d.sample.flags |= odometry_flags::UNTRUSTED_INPUT;
        }
        if gap || verdict.implausible {
            self.clip.spoil();
        }
        self.clip
            .after_predict(kf, &m, dt, clipped, rest, &self.cfg);
        self.count_hint_use(&d);
        self.track_motion(t_ns, prev_ns, rest, emit);
        self.update(t_ns, dt, &m, rest, moved, &mut d.sample);
        self.along_track(unaided, dt, rest);
        self.walk_update(t_ns, step.as_ref(), rest);
        self.hand_update(t_ns, rest, d.fresh.is_some() || d.stale);

        let state = self.state(s, rest, d.sample);
        if !rest && self.motion_start_ns.is_some() {
            self.record(&state);
        }
        emit(&state);
        self.revisions_due(t_ns, rest, emit);
    }

    /// Publishes the revisions due after the state of the sample at `t_ns` (`rest`: taken as
    /// rest): the wait's once the forward axis ended it ([`Self::republish_wait`]), and the
    /// last motion's once the rest after it has lasted `revision_delay_s`.
    fn revisions_due(&mut self, t_ns: u64, rest: bool, emit: &mut impl FnMut(&OdometryState)) {
        self.republish_wait(emit);
        if let Some(pending) = self.pending
            && rest
            && (t_ns - pending.end_ns) as f64 * 1e-9 >= self.cfg.revision_delay_s
        {
            self.republish(pending, emit);
        }
    }

    /// Gathers a rest sample's specific force by attitude (`crate::attitudes`; no allocation).
    #[inline]
    fn gather_attitude(&mut self, m: &Imu, rest: bool) {
        if rest {
            self.attitudes.push(&m.f);
        }
    }

    /// Delivers the hints due by `t_ns` and decides what they say about this sample: the
    /// newest fresh one with a rest source decides rest.
    #[inline]
    fn hint_decision(&mut self, t_ns: u64, imu_rest: bool, detector_ready: bool) -> HintDecision {
        self.deliver_hints(t_ns);
        let fresh = self
            .hints
            .newest
            .filter(|h| t_ns.saturating_sub(h.stamps.sample_ns) <= self.hints.max_age_ns);
        let rest = fresh
            .filter(|h| has_rest_source(h) && !turns_while_stationary(h))
            .map(|h| h.flags & hint_flags::STATIONARY != 0);
        self.imu_decided = rest.is_none();
        let mut sample = HintSample::default();
        let stale = self.hints.newest.is_some() && fresh.is_none();
        if stale {
            sample.flags |= odometry_flags::HINT_STALE;
        }
        if rest == Some(true) {
            sample.flags |= odometry_flags::HINT_STATIONARY;
        }
        if rest.is_some_and(|h| detector_ready && h != imu_rest) {
            sample.flags |= odometry_flags::HINT_DISAGREE;
        }
        HintDecision {
            fresh,
            rest,
            stale,
            sample,
        }
    }

    /// The aligned filter's prediction over `dt` (widened across a gap): metres moved.
    #[inline]
    fn predict(&mut self, m: Imu, dt: f64, gap: bool, hs: &mut HintSample) -> f64 {
        let kf = self.kf.as_mut().expect("aligned");
        // Only with speed hints (see `OdometryConfig::sampled_noise`).
        let (sd_a, sd_w) = match self.cfg.sampled_noise && self.hints.newest.is_some() {
            true => self.sampled.sd(),
            false => (0.0, 0.0),
        };
        kf.set_sampled_noise(sd_a, sd_w);
        let p_before = kf.x.p;
        // Across a gap the trapezoid of the readings on either side is the guess (on simulated
        // drives it ended closer than coasting with velocity and attitude held: NEES/2 at the
        // end 0.09-0.86 against 0.01-16), and the covariance is widened for the rest.
        kf.predict(m, dt);
        if gap {
            kf.missed(dt, &self.cfg.manoeuvre);
            hs.flags |= odometry_flags::GAP_BEFORE;
        }
        (kf.x.p - p_before).xy().norm()
    }

    /// Whether the detector window that flagged this sample rest vibrated more than
    /// `rest_vibration_factor` times the alignment rest (flagged `REST_VIBRATING`).
    #[inline]
    fn vibrating(&self, s: &CorrectedImuSample, hs: &mut HintSample) -> bool {
        let factor = self.cfg.rest_vibration_factor;
        if factor <= 0.0 || s.flags & corrected_flags::ZERO_STATE == 0 {
            return false;
        }
        // A floor of 1 mg: a quantised part can show no variance at all standing.
        let floor = 1e-3 * self.cfg.gravity_mps2;
        let window_sd = Vector3::from(s.zs_std_mps2).norm();
        let vibrating = window_sd > factor * self.standing_accel_sd.max(floor);
        if vibrating {
            hs.flags |= odometry_flags::REST_VIBRATING;
        }
        vibrating
    }

    /// Motion interval bookkeeping: a rest after motion opens a pending revision; motion that
    /// resumes before the revision delay has passed revises with what was gathered.
    #[inline]
    fn track_motion(
        &mut self,
        t_ns: u64,
        prev_ns: Option<u64>,
        rest: bool,
        emit: &mut impl FnMut(&OdometryState),
    ) {
        if rest && !self.at_rest {
            self.consistency.rest_started();
        }
        if rest && !self.at_rest && self.motion_start_ns.is_some() && self.pending.is_none() {
            self.rest_count += 1;
            self.pending = Some(PendingRevision {
                end_ns: t_ns,
                dp: Vector3::zeros(),
                dv: Vector3::zeros(),
            });
        }
        if !rest {
            if let Some(pending) = self.pending {
                self.republish(pending, emit);
            }
            if self.motion_start_ns.is_none() {
                self.motion_start_ns = Some(prev_ns.unwrap_or(t_ns));
                self.history.clear();
                self.history_overflowed = false;
            }
        }
        self.at_rest = rest;
    }

    /// The aligned filter's updates at this sample: at rest the sample joins the rest window,
    /// whose updates are made when the covariance has just been propagated or the window has
    /// reached its drift bound ([`Self::rest_updates`]); in motion the waiting speed hints.
    /// The body velocity's corrections are tracked for the mounting estimate.
    #[inline]
    fn update(&mut self, t_ns: u64, dt: f64, m: &Imu, rest: bool, moved: f64, hs: &mut HintSample) {
        let mut body_before = self.body_velocity();
        if let Some(v_b) = body_before {
            let hints = &mut self.hints;
            hints.history.push(BodyVelocity {
                t_ns,
                uncorrected: v_b - hints.corrections,
            });
        }
        if rest {
            self.hints.velocity_axis.restart();
        }
        if rest && self.cfg.rest_updates {
            if hs.flags & odometry_flags::HINT_STATIONARY != 0 {
                let kf = self.kf.as_mut().expect("aligned");
                let density = self.cfg.noise.gyro_noise_density;
                let gate = self.cfg.zaru_gate_sigma;
                self.hints.wheels_still(kf, &m.w, dt, density, gate);
            } else {
                self.hints.still = WheelsStill::default();
            }
            let kf = self.kf.as_ref().expect("aligned");
            self.rest_scatter.push(&(m.w - kf.x.b_g), dt);
            let w = &mut self.rest_window;
            w.n += 1;
            w.t_s += dt;
            w.w_sum += m.w;
            w.t_ns = t_ns;
            let accel_var = self.cfg.noise.accel_noise_density.powi(2) * w.t_s;
            let quasi_static = accel_var * f64::from(w.n)
                < self.cfg.rest_window_drift * self.zupt_sigma_mps.powi(2);
            if (kf.propagated() || !quasi_static) && !self.clip.waiting() {
                self.rest_updates();
            }
            // A stationary robot's speed hint says nothing the zero-velocity update did not.
            self.hints.speed.clear();
        } else {
            self.hints.still = WheelsStill::default();
            self.distance_m += moved;
            if self.nhc.is_some() || !self.hints.speed.is_empty() {
                // An update the reconstruction's predictions would not redo.
                self.clip.spoil();
            }
            let unknown = self.direction_unknown();
            let kf = self.kf.as_mut().expect("aligned");
            let hints = &mut self.hints;
            // Turns a refined mounting made ([`Hints::remount`]), for `body_before`.
            let mut body_turn = Matrix3::identity();
            let reference = hints.reference(kf, self.cfg.gravity_mps2);
            if hints.cfg.mounting_from_turns {
                hints.forward.sample(&m.f, &m.w, &reference);
            }
            hints.wait_step(kf, dt, t_ns, unknown);
            hints.velocity_step(kf, dt, t_ns, unknown);
            while let Some(h) = hints.speed.pop() {
                if let Some((fit, turn)) = hints.mount_from(kf, &h, &reference, t_ns, unknown) {
                    body_turn = turn * body_turn;
                    if let Some(nhc) = self.nhc.as_mut() {
                        nhc.follow(fit.mounting, fit.sigma_rad);
                    }
                }
                if let Some(nis) = hints.apply_speed(kf, &h, t_ns) {
                    let nis = Some(nis).filter(|x| x.is_finite());
                    self.consistency.update(kf, Kind::Speed, t_ns, nis, 3.0);
                    hs.flags |= odometry_flags::HINT_SPEED;
                    hints.applied += 1;
                    hints.stats.speed_updates += 1;
                } else {
                    hints.stats.speed_skipped += 1;
                }
            }
            if let Some(nhc) = self.nhc.as_mut().filter(|_| !hints.speed_in_use(t_ns)) {
                let interval = self.cfg.propagation_interval_s.max(dt);
                match nhc.apply(kf, dt, interval, !unknown) {
                    Some(Outcome::Rejected) => hs.flags |= odometry_flags::NONHOLONOMIC_REJECTED,
                    Some(Outcome::Applied { nis, dof }) => {
                        let nis = Some(nis).filter(|x| x.is_finite());
                        self.consistency
                            .update(kf, Kind::Nonholonomic, t_ns, nis, dof);
                    }
                    None => {}
                }
            }
            hints.carry_systematic(kf, dt, t_ns);
            body_before = body_before.map(|v| body_turn * v);
        }
        self.track_corrections(body_before);
    }

    /// The body velocity, once the mounting is known (before [`Self::track_corrections`]).
    fn body_velocity(&self) -> Option<Vector3<f64>> {
        let kf = self.kf.as_ref().expect("aligned");
        self.hints.r_bs.map(|r| kf.body_velocity(&r))
    }

    /// Adds the change the updates made to the body velocity since `before` to the
    /// corrections.
    fn track_corrections(&mut self, before: Option<Vector3<f64>>) {
        if let (Some(v_b), Some(before)) = (self.body_velocity(), before) {
            self.hints.corrections += v_b - before;
        }
    }

    /// Redoes a clipped motion waiting for the rest, then makes its updates (at its last sample).
    fn close_rest_window(&mut self) {
        self.clip
            .rest_ended(self.kf.as_mut().expect("aligned"), &self.cfg);
        if self.rest_window.n == 0 {
            return;
        }
        let before = self.body_velocity();
        self.rest_updates();
        self.track_corrections(before);
    }

    /// The zero-velocity and zero-rate updates of the rest window's `n` samples, made at its
    /// last sample, and the window emptied. They carry the information of `n` updates, one per
    /// sample: the zero-velocity update's variance is the per-sample one, `sigma^2`, over `n`,
    /// which holds while the velocity error stays the same over the window to within that
    /// update's 1-sigma: the window is closed early once the velocity noise accumulated over
    /// it, `q_a T` (`q_a` the accelerometer's noise density squared, `T` the window's span),
    /// reaches `OdometryConfig::rest_window_drift` of `sigma^2 / n`. The zero-rate update
    /// takes the mean of the window's gyro readings with the noise density over the square
    /// root of their span (the gyro bias is constant over the window: the mean of the `n`
    /// readings is what they tell of it), on a wheeled or not yet recognized platform at least
    /// the rests' shake over `sqrt(n)` (`crate::rest_scatter`; `odometry/tests/rest_window.rs`).
    fn rest_updates(&mut self) {
        let w = std::mem::take(&mut self.rest_window);
        if w.n == 0 {
            return;
        }
        let kf = self.kf.as_mut().expect("aligned");
        let (p0, v0) = (kf.x.p, kf.x.v);
        let n = f64::from(w.n);
        let nis = kf.zero_velocity(self.zupt_sigma_mps / n.sqrt());
        let removed = [v0.x - kf.x.v.x, v0.y - kf.x.v.y];
        self.consistency
            .rest_window(kf, w.t_ns, nis, w.t_s, removed);
        let shake = self.rest_scatter.taken_sd(&self.cfg);
        let gyro_sigma = (self.cfg.noise.gyro_noise_density / w.t_s.sqrt()).max(shake / n.sqrt());
        kf.zero_rate(w.w_sum / n, gyro_sigma, self.cfg.zaru_gate_sigma);
        // (Hand-held walking's position is the walk's, not the filter's: nothing to revise.)
        if let Some(pending) = self.pending.as_mut().filter(|_| self.walk.is_none()) {
            pending.dp += kf.x.p - p0;
            pending.dv += kf.x.v - v0;
        }
    }

    /// Moves the hints delivered by `t_ns` out of the waiting buffer: the newest becomes the
    /// current hint, and the speed hints among them wait for the update.
    fn deliver_hints(&mut self, t_ns: u64) {
        let hints = &mut self.hints;
        while let Some(h) = hints.waiting.front().copied() {
            if usable_from_ns(&h, hints.delivery_ns) > t_ns {
                break;
            }
            hints.waiting.pop();
            if hints
                .newest
                .is_some_and(|n| h.stamps.sample_ns <= n.stamps.sample_ns)
            {
                hints.stats.out_of_order += 1;
                continue;
            }
            hints.stats.consumed += 1;
            hints.newest = Some(h);
            if h.flags & hint_flags::SPEED_VALID != 0 && hints.speed.push(h).is_some() {
                hints.stats.speed_skipped += 1;
            }
        }
    }

    /// Aligns on the alignment sums when they span the rest the alignment needs.
    fn try_align(&mut self, t_ns: u64, m: &Imu) {
        let a = &self.align;
        // With speed hints a rest is aligned on for at least `HINT_ALIGN_S`.
        let align_s = if self.hints.newest.is_some() {
            self.cfg.align_s.max(HINT_ALIGN_S)
        } else {
            self.cfg.align_s
        };
        if (t_ns - a.t0_ns) as f64 * 1e-9 < align_s || a.accel.len() < 2 {
            return;
        }
        let f_mean = a.accel.mean();
        let w_mean = a.gyro.mean();
        // Gyro bias from the rest mean, with its mean's variance; each zero-velocity update
        // then counts for one effective sample of the accelerometer's noise
        // (`OdometryConfig::effective_samples`).
        let w_sigma = a
            .gyro
            .mean_variance(self.cfg.effective_samples)
            .map(f64::sqrt);
        self.zupt_sigma_mps = self.cfg.zupt_sigma_mps;
        if self.cfg.effective_samples {
            self.zupt_sigma_mps *= a.accel.mean_variance_factor().max().sqrt();
        }
        self.standing_accel_sd = a.accel.variance().sum().sqrt();
        let g = self.cfg.gravity_mps2;
        let prior = AccelPrior::at_rest(&self.cfg, &f_mean, a.gravity_off);
        let (x, mut cov) = align(f_mean, w_mean, g, prior.bias_sigma_mps2, w_sigma);
        // Hand-held walking holds its step-length uncertainty outside the filter
        // (`crate::walking`): the scale state stays at zero.
        cov[(KS, KS)] = match &self.walk {
            Some(_) => 0.0,
            None => self.hints.cfg.speed_scale_sigma.powi(2),
        };
        let refined = a.refined.mean().unwrap_or(self.refinement);
        self.start_filter(x, cov, prior, (f_mean, refined), m);
        self.at_rest = true;
    }

    /// Starts the filter at `x`, `cov` (an alignment at rest or in motion) with the
    /// accelerometer prior `prior`, the window's mean specific force and the calibration
    /// stage's refinement that mean carries (`window`).
    fn start_filter(
        &mut self,
        x: Nominal,
        cov: Cov,
        prior: AccelPrior,
        window: (Vector3<f64>, Refinement),
        m: &Imu,
    ) {
        let (f_mean, refined) = window;
        let consider = ConsiderModel {
            gyro: self.cfg.gyro_correction_sigma,
            accel: prior.consider,
        };
        self.kf = Some(
            Eskf::new(x, cov, self.cfg.gravity_mps2, prior.noise(&self.cfg), *m)
                .with_consider(consider, f_mean)
                .with_refinement(refined)
                .with_propagation_interval(self.cfg.propagation_interval_s),
        );
        self.accel_prior = Some(prior);
        self.motion_refinement = Refinement::default();
    }

    fn unaligned_state(&self, s: &CorrectedImuSample, rest: bool, hs: HintSample) -> OdometryState {
        OdometryState {
            stamps: s.stamps,
            seq: s.seq,
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            flags: hs.flags
                | if rest {
                    odometry_flags::ZERO_VELOCITY
                } else {
                    0
                },
            ..Default::default()
        }
    }

    /// The filter's position 1-sigma with the heading the clip reconstruction could not
    /// measure (`ClipRepair::unseen_heading_variance`) added, m.
    fn position_sigma(&self, kf: &Eskf) -> Vector3<f64> {
        let [x, y] = self.clip.unseen_heading_variance(&kf.x.p);
        let s = kf.position_sigma();
        Vector3::new((s.x * s.x + x).sqrt(), (s.y * s.y + y).sqrt(), s.z)
    }

    fn state(&self, s: &CorrectedImuSample, rest: bool, hs: HintSample) -> OdometryState {
        let kf = self.kf.as_ref().expect("state() is called once aligned");
        let q = kf.x.q;
        let g_s = q.inverse() * (-kf.gravity());
        let mut flags = odometry_flags::ALIGNED | hs.flags;
        if rest {
            flags |= odometry_flags::ZERO_VELOCITY;
        }
        // Hand-held walking: the position is the walk's (the sum of the steps).
        let (position, position_sigma, distance_m) = match &self.walk {
            Some(walk) => (
                walk.position(),
                walk.position_sigma(kf.position_sigma().z),
                walk.distance_m(),
            ),
            None => (kf.x.p, self.position_sigma(kf), self.distance_m),
        };
        OdometryState {
            stamps: s.stamps,
            seq: s.seq,
            position_m: position.into(),
            position_sigma_m: position_sigma.into(),
            velocity_mps: kf.x.v.into(),
            velocity_sigma_mps: kf.velocity_sigma().into(),
            gravity_sensor_mps2: g_s.into(),
            attitude_wxyz: [q.w, q.i, q.j, q.k],
            distance_m,
            flags,
            reserved16: 0,
            rest_count: self.rest_count,
            hints_applied: self.hints.applied,
            hint_disagreements: self.hints.disagreements,
        }
    }

    /// Keeps a decimated copy of a motion state for later revision.
    fn record(&mut self, state: &OdometryState) {
        let period_ns = (1e9 / self.cfg.revision_rate_hz) as u64;
        let due = self
            .history
            .last()
            .is_none_or(|h| state.stamps.sample_ns >= h.t_ns + period_ns);
        if !due {
            return;
        }
        if self.history.len() == self.history.capacity() {
            self.history_overflowed = true;
            return;
        }
        self.history.push(HistoryEntry {
            t_ns: state.stamps.sample_ns,
            stamps: state.stamps,
            seq: state.seq,
            p: Vector3::from(state.position_m),
            v: Vector3::from(state.velocity_mps),
            sigma_p: Vector3::from(state.position_sigma_m),
            sigma_v: Vector3::from(state.velocity_sigma_mps),
            q: UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                state.attitude_wxyz[0],
                state.attitude_wxyz[1],
                state.attitude_wxyz[2],
                state.attitude_wxyz[3],
            )),
            distance_m: state.distance_m,
            wait: self
                .direction_unknown()
                .then(|| self.hints.wait.mark())
                .flatten(),
        });
    }

    /// Spreads the corrections gathered at the start of a rest back over the motion interval
    /// and emits the revised states.
    ///
    /// With `T` the interval length and `s = t - t0`, the position correction is the cubic
    /// `c(s) = a s^2 + b s^3` with `c(0) = c'(0) = 0`, `c(T) = dp`, `c'(T) = dv`; for a constant
    /// velocity drift (`dp = dv T / 2`) this is the thesis's linear velocity-error model.
    fn republish(&mut self, pending: PendingRevision, emit: &mut impl FnMut(&OdometryState)) {
        self.pending = None;
        let Some(t0) = self.motion_start_ns.take() else {
            return;
        };
        if self.history_overflowed {
            self.history.clear();
            return;
        }
        let big_t = (pending.end_ns - t0) as f64 * 1e-9;
        if big_t <= 0.0 {
            return;
        }
        let (dp, dv) = (pending.dp, pending.dv);
        let a = (3.0 * dp - dv * big_t) / (big_t * big_t);
        let b = (dv * big_t - 2.0 * dp) / (big_t * big_t * big_t);
        let g = self.cfg.gravity_mps2;
        // Revised velocities tell the forward axis only when the velocity was known at the
        // alignment (a rest), and only when asked to (not `mounting_from_turns`).
        let estimating = self.hints.r_bs.is_none()
            && self.aligned_in_motion.is_none()
            && !self.hints.cfg.mounting_from_turns;
        for (i, h) in self.history.iter().enumerate() {
            let s = (h.t_ns.saturating_sub(t0)) as f64 * 1e-9;
            let p = h.p + a * s * s + b * s * s * s;
            let v = h.v + 2.0 * a * s + 3.0 * b * s * s;
            if estimating {
                // The revised velocity in the sensor frame, held until the next stored state.
                let next_ns = self.history.get(i + 1).map_or(pending.end_ns, |n| n.t_ns);
                let dt = next_ns.saturating_sub(h.t_ns) as f64 * 1e-9;
                // Revised at the rest: no 1-sigma is asked of this estimate.
                self.hints
                    .estimator
                    .add(&h.q.inverse_transform_vector(&v), 0.0, dt);
            }
            emit(&h.revision(&p, &v, g, self.counts()));
        }
        self.history.clear();
        if estimating && self.hints.estimator.path_m() >= self.hints.cfg.mounting_min_path_m {
            let kf = self.kf.as_ref().expect("revisions happen once aligned");
            let up_s = kf.x.q.inverse_transform_vector(&Vector3::z());
            if let Some(q) = self.hints.estimator.mounting(&up_s) {
                self.hints.r_bs = Some(q.to_rotation_matrix().into_inner());
                self.hints.history.clear();
                self.hints.corrections = Vector3::zeros();
            }
        }
    }
}
