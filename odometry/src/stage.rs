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

use crate::eskf::{Eskf, Imu, KS, NoiseModel, align};
use crate::hints::{
    HintConfig, HintConfigError, HintError, HintStats, MountingEstimator, Ring, check_hint,
    has_rest_source, usable_from_ns,
};
use ipc_types::{
    CorrectedImuSample, OdometryState, RobotHint, Stamps, corrected_flags, hint_flags,
    odometry_flags,
};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// Configuration of the stage. Noise figures come from the calibration file's noise parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryConfig {
    /// Local gravity magnitude, m/s^2.
    pub gravity_mps2: f64,
    /// Sensor noise model.
    pub noise: NoiseModel,
    /// Gyro correction `C` applied to every angular rate before the filter (`omega = C w`,
    /// sensor frame): the inverse of the gyro's scale and misalignment, from
    /// [`crate::gyrocal::calibrate_gyro`]; identity for an uncalibrated gyro. (The calibration
    /// stage corrects the accelerometer only, so the gyro's correction is applied here.)
    pub gyro_correction: Matrix3<f64>,
    /// 1-sigma of the accelerometer bias left after calibration (turn-on repeatability),
    /// m/s^2 per sensor axis.
    pub accel_bias_sigma_mps2: [f64; 3],
    /// 1-sigma of the accelerometer's residual scale and misalignment after calibration,
    /// fraction. Under gravity it reads as a bias of about `g` times this on every axis (a
    /// misalignment of 0.1% puts 10 mm/s^2 of gravity on a horizontal axis), which the
    /// alignment's bias uncertainty includes.
    pub accel_residual_scale: f64,
    /// Zero-angular-rate gate: the gyro bias is updated at rest only while the reading is
    /// within this many predicted standard deviations of the bias estimate.
    pub zaru_gate_sigma: f64,
    /// 1-sigma of the zero-velocity pseudo-measurement, m/s.
    pub zupt_sigma_mps: f64,
    /// Rest needed before alignment, s.
    pub align_s: f64,
    /// Time after the end of a motion interval over which corrections are gathered before the
    /// interval is republished, s.
    pub revision_delay_s: f64,
    /// Longest motion interval whose history is kept for revision, s (at `max_rate_hz`).
    pub max_motion_s: f64,
    /// Highest sample rate the history is sized for, Hz.
    pub max_rate_hz: f64,
    /// Republished states per second of motion (the history is decimated to this rate).
    pub revision_rate_hz: f64,
}

impl OdometryConfig {
    /// Defaults for an MPU-9250 after calibration: datasheet noise densities, the thesis's
    /// measured turn-on repeatability (4.5 / 2.5 / 6.1 mm/s^2), and `gravity_mps2`.
    pub fn mpu9250(gravity_mps2: f64) -> Self {
        Self {
            gravity_mps2,
            noise: NoiseModel {
                accel_noise_density: 300e-6 * gravity_mps2,
                gyro_noise_density: 0.01_f64.to_radians(),
                accel_bias_random_walk: 1e-4,
                gyro_bias_random_walk: 1e-6,
                vibration_accel_density_per_mps: 0.0,
                vibration_gyro_density_per_mps: 0.0,
            },
            gyro_correction: Matrix3::identity(),
            accel_bias_sigma_mps2: [4.5e-3, 2.5e-3, 6.1e-3],
            accel_residual_scale: 1e-3,
            zaru_gate_sigma: 5.0,
            zupt_sigma_mps: 2e-3,
            align_s: 1.0,
            revision_delay_s: 0.2,
            max_motion_s: 120.0,
            max_rate_hz: 4000.0,
            revision_rate_hz: 100.0,
        }
    }
}

/// Input the stage refuses; the message names the sample.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OdometryError {
    /// A sample's time is not after the previous one's.
    #[error("sample seq {seq}: time {t_ns} ns is not after the previous sample's {prev_ns} ns")]
    TimeNotIncreasing {
        /// Sequence number of the offending sample.
        seq: u64,
        /// Its time.
        t_ns: u64,
        /// The previous sample's time.
        prev_ns: u64,
    },
    /// A sample holds NaN or infinity.
    #[error("sample seq {seq}: field {field} is not finite")]
    NotFinite {
        /// Sequence number of the offending sample.
        seq: u64,
        /// The field.
        field: &'static str,
    },
}

#[derive(Debug, Clone, Copy)]
struct HistoryEntry {
    t_ns: u64,
    stamps: Stamps,
    seq: u64,
    p: Vector3<f64>,
    v: Vector3<f64>,
    sigma_p: Vector3<f64>,
    sigma_v: Vector3<f64>,
    q: UnitQuaternion<f64>,
    distance_m: f64,
}

#[derive(Debug, Clone, Copy, Default)]
struct AlignSums {
    n: u64,
    t0_ns: u64,
    f: Vector3<f64>,
    w: Vector3<f64>,
    w2: Vector3<f64>,
}

/// What happens to the motion history after a motion interval has ended.
#[derive(Debug, Clone, Copy)]
struct PendingRevision {
    /// Time the motion interval ended (first rest sample), ns.
    end_ns: u64,
    /// Sum of the corrections the updates injected since, position and velocity.
    dp: Vector3<f64>,
    dv: Vector3<f64>,
}

/// Speed hints that can wait for the next sample's update (more arrive at once only at sample
/// rates below the hint rate).
const SPEED_QUEUE: usize = 8;

/// One sample's body velocity minus the corrections made up to it (see the module docs).
#[derive(Debug, Clone, Copy, Default)]
struct BodyVelocity {
    t_ns: u64,
    uncorrected: Vector3<f64>,
}

/// What the hints did at the current sample.
#[derive(Debug, Clone, Copy, Default)]
struct HintSample {
    flags: u16,
}

/// Hint state of the stage.
struct Hints {
    cfg: HintConfig,
    delivery_ns: u64,
    max_age_ns: u64,
    /// Hints waiting for their delivery time, in arrival order.
    waiting: Ring<RobotHint>,
    /// The newest delivered hint.
    newest: Option<RobotHint>,
    /// Delivered speed hints not yet applied, oldest first (several can be delivered at one
    /// sample when their latencies differ).
    speed: Ring<RobotHint>,
    /// Sequence number of the last hint counted as applied for its rest decision.
    newest_used: Option<u64>,
    /// Sensor-to-body rotation `R_bs`, once known.
    r_bs: Option<Matrix3<f64>>,
    estimator: MountingEstimator,
    /// Body velocity minus corrections, one per sample since the mounting is known.
    history: Ring<BodyVelocity>,
    /// Sum of the body-velocity changes every update has made since the mounting is known,
    /// m/s.
    corrections: Vector3<f64>,
    applied: u32,
    disagreements: u32,
    stats: HintStats,
}

impl Hints {
    /// The body velocity minus corrections at `t_ns`, interpolated between the stored samples
    /// around it (the newest one for a time after it); `None` when `t_ns` is older than the
    /// history.
    fn uncorrected_at(&self, t_ns: u64) -> Option<Vector3<f64>> {
        let mut newer: Option<&BodyVelocity> = None;
        for i in 0..self.history.len() {
            let e = self.history.newest(i)?;
            if e.t_ns <= t_ns {
                return Some(match newer {
                    None => e.uncorrected,
                    Some(n) => {
                        let f = (t_ns - e.t_ns) as f64 / (n.t_ns - e.t_ns) as f64;
                        e.uncorrected + (n.uncorrected - e.uncorrected) * f
                    }
                });
            }
            newer = Some(e);
        }
        None
    }

    /// Applies a speed hint as a body-velocity measurement at the hint's time; `false` when it
    /// cannot be (mounting unknown, or the hint stale at `t_ns` or older than the velocity
    /// history).
    fn apply_speed(&mut self, kf: &mut Eskf, h: &RobotHint, t_ns: u64) -> bool {
        let Some(r_bs) = self.r_bs else {
            return false;
        };
        if t_ns.saturating_sub(h.stamps.sample_ns) > self.max_age_ns {
            return false;
        }
        let Some(then) = self.uncorrected_at(h.stamps.sample_ns) else {
            return false;
        };
        // The body velocity the filter now believes it had at the hint's time.
        let predicted = then + self.corrections;
        let residual = Vector3::new(
            h.forward_speed_mps - (1.0 + kf.x.k) * predicted.x,
            -predicted.y,
            -predicted.z,
        );
        let nh = self.cfg.nonholonomic_sigma_mps;
        kf.body_velocity_update(
            &r_bs,
            residual,
            Vector3::new(h.forward_speed_sigma_mps, nh, nh),
        );
        true
    }
}

/// The odometry state machine.
pub struct OdometryStage {
    cfg: OdometryConfig,
    hints: Hints,
    align: AlignSums,
    kf: Option<Eskf>,
    last: Option<(u64, Imu)>,
    history: Vec<HistoryEntry>,
    history_overflowed: bool,
    motion_start_ns: Option<u64>,
    pending: Option<PendingRevision>,
    at_rest: bool,
    rest_count: u32,
    distance_m: f64,
    revisions_emitted: u64,
}

impl OdometryStage {
    /// A stage with the history buffer allocated up front for `max_motion_s` at
    /// `revision_rate_hz` (only decimated states are kept), and the default hint
    /// configuration ([`HintConfig::default`]: the IMU mounted aligned with the body).
    pub fn new(cfg: OdometryConfig) -> Self {
        Self::with_hints(cfg, HintConfig::default())
            .expect("the default hint configuration is valid")
    }

    /// A stage with the hint configuration `hints`; its velocity history holds `max_age_s` at
    /// `max_rate_hz`, allocated here.
    pub fn with_hints(cfg: OdometryConfig, hints: HintConfig) -> Result<Self, HintConfigError> {
        hints.validate()?;
        let capacity = (cfg.max_motion_s * cfg.revision_rate_hz).ceil() as usize + 1;
        let velocity_capacity = (hints.max_age_s * cfg.max_rate_hz).ceil() as usize + 2;
        Ok(Self {
            cfg,
            hints: Hints {
                cfg: hints,
                delivery_ns: (hints.delivery_s * 1e9).round() as u64,
                max_age_ns: (hints.max_age_s * 1e9).round() as u64,
                waiting: Ring::new(hints.capacity),
                newest: None,
                speed: Ring::new(SPEED_QUEUE),
                newest_used: None,
                r_bs: hints.mounting.map(|q| q.to_rotation_matrix().into_inner()),
                estimator: MountingEstimator::default(),
                history: Ring::new(velocity_capacity),
                corrections: Vector3::zeros(),
                applied: 0,
                disagreements: 0,
                stats: HintStats::default(),
            },
            align: AlignSums::default(),
            kf: None,
            last: None,
            history: Vec::with_capacity(capacity),
            history_overflowed: false,
            motion_start_ns: None,
            pending: None,
            at_rest: false,
            rest_count: 0,
            distance_m: 0.0,
            revisions_emitted: 0,
        })
    }

    /// Takes a robot hint. It waits (in a buffer allocated up front) until a sample taken at
    /// least [`HintConfig::delivery_s`] after its publication, which then uses it. A refused
    /// hint changes nothing.
    pub fn hint(&mut self, h: &RobotHint) -> Result<(), HintError> {
        check_hint(h)?;
        self.hints.stats.received += 1;
        if self.hints.waiting.push(*h).is_some() {
            self.hints.stats.overflowed += 1;
        }
        Ok(())
    }

    /// Counters of the hints seen so far.
    pub fn hint_stats(&self) -> HintStats {
        self.hints.stats
    }

    /// The IMU-to-body mounting (sensor to body), configured or estimated; `None` while it is
    /// being estimated.
    pub fn mounting(&self) -> Option<UnitQuaternion<f64>> {
        self.hints.r_bs.map(|r| {
            UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(r))
        })
    }

    /// Whether alignment is done.
    pub fn aligned(&self) -> bool {
        self.kf.is_some()
    }

    /// Number of republished (revised) states so far.
    pub fn revisions_emitted(&self) -> u64 {
        self.revisions_emitted
    }

    /// The filter, once aligned (for diagnostics and tests).
    pub fn filter(&self) -> Option<&Eskf> {
        self.kf.as_ref()
    }

    /// Processes one sample: emits its state, and any revised states that the end of a motion
    /// interval made available, through `emit`.
    pub fn process(
        &mut self,
        s: &CorrectedImuSample,
        emit: &mut impl FnMut(&OdometryState),
    ) -> Result<(), OdometryError> {
        check_finite(s)?;
        let t_ns = s.stamps.sample_ns;
        let m = Imu {
            f: Vector3::from(s.accel_mps2),
            w: self.cfg.gyro_correction * Vector3::from(s.gyro_rps),
        };
        let imu_rest = s.flags & corrected_flags::ZERO_STATE != 0;
        let prev = self.last.replace((t_ns, m));
        if let Some((prev_ns, _)) = prev
            && t_ns <= prev_ns
        {
            self.last = prev;
            return Err(OdometryError::TimeNotIncreasing {
                seq: s.seq,
                t_ns,
                prev_ns,
            });
        }

        // Hints delivered by this sample's time; the newest fresh one with a rest source
        // decides rest.
        self.deliver_hints(t_ns);
        let fresh = self
            .hints
            .newest
            .filter(|h| t_ns.saturating_sub(h.stamps.sample_ns) <= self.hints.max_age_ns);
        let hint_rest = fresh
            .filter(has_rest_source)
            .map(|h| h.flags & hint_flags::STATIONARY != 0);
        let mut hs = HintSample::default();
        let stale = self.hints.newest.is_some() && fresh.is_none();
        if stale {
            hs.flags |= odometry_flags::HINT_STALE;
        }
        if hint_rest == Some(true) {
            hs.flags |= odometry_flags::HINT_STATIONARY;
        }
        let detector_ready = s.flags & corrected_flags::DETECTOR_READY != 0;
        if hint_rest.is_some_and(|h| detector_ready && h != imu_rest) {
            hs.flags |= odometry_flags::HINT_DISAGREE;
        }

        let Some(kf) = self.kf.as_mut() else {
            let rest = hint_rest.unwrap_or(imu_rest);
            // A stationary hint aligns only once the calibration stage has learned its
            // references (its zero-state flag never comes earlier): until then the stage's gyro
            // output still carries the turn-on bias it is about to subtract, and a filter
            // aligned on it would take that step for rotation.
            let ready = detector_ready || hint_rest.is_none();
            self.accumulate_alignment(t_ns, &m, rest && ready);
            emit(&self.unaligned_state(s, rest, hs));
            return Ok(());
        };
        let dt = (t_ns - prev.map_or(t_ns, |p| p.0)) as f64 * 1e-9;
        let p_before = kf.x.p;
        kf.predict(m, dt);
        let moved = (kf.x.p - p_before).xy().norm();
        // The IMU's rest flag decides without a fresh hint; after hints went stale, only when
        // the velocity is consistent with rest (a detector that takes cruising for rest must not
        // stop a robot the hints have just seen moving).
        let rest = match hint_rest {
            Some(r) => r,
            None if stale && imu_rest => kf.velocity_consistent_with_zero(
                self.cfg.zupt_sigma_mps,
                self.hints.cfg.fallback_zupt_gate_sigma,
            ),
            None => imu_rest,
        };

        if hs.flags & odometry_flags::HINT_DISAGREE != 0 {
            self.hints.disagreements += 1;
        }
        if hint_rest.is_some() && fresh.is_some_and(|h| self.hints.newest_used != Some(h.seq)) {
            self.hints.newest_used = fresh.map(|h| h.seq);
            self.hints.applied += 1;
        }

        // Motion interval bookkeeping: a rest after motion opens a pending revision; motion
        // that resumes before the revision delay has passed revises with what was gathered.
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
                self.motion_start_ns = Some(prev.map_or(t_ns, |p| p.0));
                self.history.clear();
                self.history_overflowed = false;
            }
        }
        self.at_rest = rest;

        let kf = self.kf.as_mut().expect("aligned above");
        let hints = &mut self.hints;
        let body_before = hints.r_bs.map(|r| kf.body_velocity(&r));
        if let Some(v_b) = body_before {
            hints.history.push(BodyVelocity {
                t_ns,
                uncorrected: v_b - hints.corrections,
            });
        }
        if rest {
            let (p0, v0) = (kf.x.p, kf.x.v);
            kf.zero_velocity(self.cfg.zupt_sigma_mps);
            let gyro_sigma = self.cfg.noise.gyro_noise_density / dt.sqrt();
            kf.zero_rate(gyro_sigma, self.cfg.zaru_gate_sigma);
            if let Some(pending) = self.pending.as_mut() {
                pending.dp += kf.x.p - p0;
                pending.dv += kf.x.v - v0;
            }
            // A stationary robot's speed hint says nothing the zero-velocity update did not.
            hints.speed.clear();
        } else {
            self.distance_m += moved;
            while let Some(h) = hints.speed.pop() {
                if hints.apply_speed(kf, &h, t_ns) {
                    hs.flags |= odometry_flags::HINT_SPEED;
                    hints.applied += 1;
                    hints.stats.speed_updates += 1;
                } else {
                    hints.stats.speed_skipped += 1;
                }
            }
        }
        if let (Some(r), Some(before)) = (hints.r_bs, body_before) {
            hints.corrections += kf.body_velocity(&r) - before;
        }

        let state = self.state(s, rest, hs);
        if !rest && self.motion_start_ns.is_some() {
            self.record(&state);
        }
        emit(&state);

        if let Some(pending) = self.pending
            && rest
            && (t_ns - pending.end_ns) as f64 * 1e-9 >= self.cfg.revision_delay_s
        {
            self.republish(pending, emit);
        }
        Ok(())
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

    fn accumulate_alignment(&mut self, t_ns: u64, m: &Imu, rest: bool) {
        if !rest {
            self.align = AlignSums::default();
            return;
        }
        let a = &mut self.align;
        if a.n == 0 {
            a.t0_ns = t_ns;
        }
        a.n += 1;
        a.f += m.f;
        a.w += m.w;
        a.w2 += m.w.component_mul(&m.w);
        if (t_ns - a.t0_ns) as f64 * 1e-9 < self.cfg.align_s || a.n < 2 {
            return;
        }
        let n = a.n as f64;
        let f_mean = a.f / n;
        let w_mean = a.w / n;
        // Gyro bias from the rest mean: its uncertainty is the sample std over sqrt(n).
        let w_var = (a.w2 / n - w_mean.component_mul(&w_mean)).map(|v| v.max(0.0));
        let w_sigma = (w_var / n).map(f64::sqrt);
        let g = self.cfg.gravity_mps2;
        let scale_as_bias = g * self.cfg.accel_residual_scale;
        let bias_sigma =
            Vector3::from(self.cfg.accel_bias_sigma_mps2).map(|s| s.hypot(scale_as_bias));
        let (x, mut cov) = align(f_mean, w_mean, g, bias_sigma, w_sigma);
        cov[(KS, KS)] = self.hints.cfg.speed_scale_sigma.powi(2);
        self.kf = Some(Eskf::new(x, cov, self.cfg.gravity_mps2, self.cfg.noise, *m));
        self.at_rest = true;
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

    fn state(&self, s: &CorrectedImuSample, rest: bool, hs: HintSample) -> OdometryState {
        let kf = self.kf.as_ref().expect("state() is called once aligned");
        let q = kf.x.q;
        let g_s = q.inverse() * (-kf.gravity());
        let mut flags = odometry_flags::ALIGNED | hs.flags;
        if rest {
            flags |= odometry_flags::ZERO_VELOCITY;
        }
        OdometryState {
            stamps: s.stamps,
            seq: s.seq,
            position_m: kf.x.p.into(),
            position_sigma_m: kf.position_sigma().into(),
            velocity_mps: kf.x.v.into(),
            velocity_sigma_mps: kf.velocity_sigma().into(),
            gravity_sensor_mps2: g_s.into(),
            attitude_wxyz: [q.w, q.i, q.j, q.k],
            distance_m: self.distance_m,
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
        let estimating = self.hints.r_bs.is_none();
        for (i, h) in self.history.iter().enumerate() {
            let s = (h.t_ns.saturating_sub(t0)) as f64 * 1e-9;
            let p = h.p + a * s * s + b * s * s * s;
            let v = h.v + 2.0 * a * s + 3.0 * b * s * s;
            if estimating {
                // The revised velocity in the sensor frame, held until the next stored state.
                let next_ns = self.history.get(i + 1).map_or(pending.end_ns, |n| n.t_ns);
                let dt = next_ns.saturating_sub(h.t_ns) as f64 * 1e-9;
                self.hints
                    .estimator
                    .add(&h.q.inverse_transform_vector(&v), dt);
            }
            let g_s = h.q.inverse() * Vector3::new(0.0, 0.0, g);
            emit(&OdometryState {
                stamps: h.stamps,
                seq: h.seq,
                position_m: p.into(),
                position_sigma_m: h.sigma_p.into(),
                velocity_mps: v.into(),
                velocity_sigma_mps: h.sigma_v.into(),
                gravity_sensor_mps2: g_s.into(),
                attitude_wxyz: [h.q.w, h.q.i, h.q.j, h.q.k],
                distance_m: h.distance_m,
                flags: odometry_flags::ALIGNED | odometry_flags::REVISION,
                reserved16: 0,
                rest_count: self.rest_count,
                hints_applied: self.hints.applied,
                hint_disagreements: self.hints.disagreements,
            });
            self.revisions_emitted += 1;
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

fn check_finite(s: &CorrectedImuSample) -> Result<(), OdometryError> {
    let fields: [(&'static str, &[f64]); 2] =
        [("accel_mps2", &s.accel_mps2), ("gyro_rps", &s.gyro_rps)];
    for (field, values) in fields {
        if values.iter().any(|v| !v.is_finite()) {
            return Err(OdometryError::NotFinite { seq: s.seq, field });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

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
