//! The navigator's hint state: the hints waiting for their delivery time, the newest one, the
//! speed hints still to apply and the body-velocity history they are applied against (see
//! [`crate::stage`] for the behaviour, [`crate::hints`] for frames and times).

use crate::cruise::{ForwardAxis, Reference, horizontal_bias_sigma, initial_velocity};
use crate::eskf::{BG, Eskf, MountingYaw, P, V};
use crate::handover::{WaitPath, WaitRevision};
use crate::hints::{
    AxisSource, ForwardAxisReport, ForwardFit, HintConfig, HintStats, MountingEstimator, Ring,
    SCALE_CONFLICT_SIGMAS, ScaleTaken,
};
use crate::speed_lag::LagNoise;
use crate::velocity_axis::{PathAxis, fuse};
use ipc_types::{RobotHint, hint_flags, odometry_flags};
use nalgebra::{Matrix3, Vector3};

/// Speed hints that can wait for the next sample's update (more arrive at once only at sample
/// rates below the hint rate).
pub(super) const SPEED_QUEUE: usize = 8;

/// One sample's body velocity minus the corrections made up to it (see the module docs).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct BodyVelocity {
    pub(super) t_ns: u64,
    pub(super) uncorrected: Vector3<f64>,
}

/// How long a rest the stationary hints decided is gathered before its mean gyro reading is
/// checked against the filter's gyro bias ([`Hints::wheels_still`]), s.
pub(super) const WHEELS_STILL_CHECK_S: f64 = 1.0;

/// Corrected gyro readings of a rest the stationary hints decided, since it began or was last
/// checked ([`Hints::wheels_still`]).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct WheelsStill {
    n: u32,
    /// Their intervals' sum, s.
    t_s: f64,
    /// Sums of the readings and of their squares, sensor frame, rad/s and (rad/s)^2.
    sum: Vector3<f64>,
    sum_sq: Vector3<f64>,
}

/// What the hints did at the current sample.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct HintSample {
    pub(super) flags: u16,
}

/// What the hints delivered by a sample's time say about it.
pub(super) struct HintDecision {
    /// The newest delivered hint, if not older than the maximum age.
    pub(super) fresh: Option<RobotHint>,
    /// The fresh hint's rest decision, if it has a rest source.
    pub(super) rest: Option<bool>,
    /// Hints were received, but none is fresh.
    pub(super) stale: bool,
    /// The flags the hints set on this sample's state.
    pub(super) sample: HintSample,
}

/// Hint state of the stage.
pub(super) struct Hints {
    pub(super) cfg: HintConfig,
    pub(super) delivery_ns: u64,
    pub(super) max_age_ns: u64,
    /// Hints waiting for their delivery time, in arrival order.
    pub(super) waiting: Ring<RobotHint>,
    /// The newest delivered hint.
    pub(super) newest: Option<RobotHint>,
    /// Delivered speed hints not yet applied, oldest first (several can be delivered at one
    /// sample when their latencies differ).
    pub(super) speed: Ring<RobotHint>,
    /// Sequence number of the last hint counted as applied for its rest decision.
    pub(super) newest_used: Option<u64>,
    /// Sensor-to-body rotation `R_bs`, once known.
    pub(super) r_bs: Option<Matrix3<f64>>,
    /// 1-sigma of `r_bs`'s yaw when [`ForwardAxis`] estimated it, rad (0 otherwise).
    pub(super) yaw_sigma_rad: f64,
    pub(super) estimator: MountingEstimator,
    /// The forward axis from the speed hints' changes (mounting not given).
    pub(super) forward: ForwardAxis,
    /// The forward axis from the path the filter integrates (mounting not given), and its
    /// trusted estimate, which later speed-change fits are fused with.
    pub(super) velocity_axis: PathAxis,
    pub(super) path_fit: Option<ForwardFit>,
    /// Time the forward axis was first trusted, ns (sample clock).
    pub(super) mounting_at_ns: Option<u64>,
    /// The latest trusted forward-axis fit, and where it came from.
    pub(super) latest_fit: Option<ForwardFit>,
    pub(super) axis_source: Option<AxisSource>,
    /// What the filter took from the first trusted fit's speed scale.
    pub(super) scale_taken: Option<ScaleTaken>,
    /// The estimated mounting's yaw error carried as a systematic position error: `sum
    /// sigma_j (-dp_y, dp_x)` over the horizontal steps `dp` since the fit was trusted, with
    /// `sigma_j` the fit's whole yaw 1-sigma then, m (navigation frame x, y).
    pub(super) systematic: [f64; 2],
    /// The speed scale's error beyond the scale state's 1-sigma carried as a systematic
    /// position error: `sum e_j dp_j` over the horizontal steps since the speed hints apply,
    /// `e_j` the relative distance error then ([`Self::carry_systematic`]), m (navigation
    /// frame x, y).
    pub(super) along: [f64; 2],
    /// Body velocity minus corrections, one per sample since the mounting is known.
    pub(super) history: Ring<BodyVelocity>,
    /// The current rest's gyro readings while stationary hints decide it.
    pub(super) still: WheelsStill,
    /// The path driven while the velocity has no direction ([`Self::wait_step`]).
    pub(super) wait: WaitPath,
    /// That path with its direction, once the forward axis is known, until its states are
    /// published again (`Navigator::republish_wait`).
    pub(super) wait_revision: Option<WaitRevision>,
    /// Sum of the body-velocity changes every update has made since the mounting is known,
    /// m/s.
    pub(super) corrections: Vector3<f64>,
    pub(super) applied: u32,
    pub(super) disagreements: u32,
    pub(super) stats: HintStats,
    /// The speed hints' unknown time as speed noise ([`LagNoise`]).
    pub(super) lag: LagNoise,
}

impl Hints {
    /// The hint state of a navigator with the (validated) configuration `cfg`, its velocity
    /// history holding `velocity_capacity` samples. An earlier pass's fit
    /// ([`HintConfig::mounting_fit`]) is taken as the first fit (no mounting before it, so
    /// nothing to turn), trusted from the start.
    pub(super) fn new(cfg: HintConfig, velocity_capacity: usize) -> Self {
        let mut hints = Self::without_fit(cfg, velocity_capacity);
        if let Some(fit) = cfg.mounting_fit {
            hints.r_bs = None;
            hints.remount(&fit, 0);
            hints.axis_source = Some(AxisSource::FirstPass);
        }
        hints
    }

    /// [`Self::new`] before an earlier pass's fit is taken.
    fn without_fit(cfg: HintConfig, velocity_capacity: usize) -> Self {
        Self {
            cfg,
            delivery_ns: (cfg.delivery_s * 1e9).round() as u64,
            max_age_ns: (cfg.max_age_s * 1e9).round() as u64,
            waiting: Ring::new(cfg.capacity),
            newest: None,
            speed: Ring::new(SPEED_QUEUE),
            newest_used: None,
            r_bs: cfg.mounting.map(|q| q.to_rotation_matrix().into_inner()),
            yaw_sigma_rad: 0.0,
            estimator: MountingEstimator::default(),
            forward: ForwardAxis::default(),
            velocity_axis: PathAxis::default(),
            path_fit: None,
            mounting_at_ns: None,
            latest_fit: None,
            axis_source: None,
            scale_taken: None,
            systematic: [0.0; 2],
            along: [0.0; 2],
            history: Ring::new(velocity_capacity),
            still: WheelsStill::default(),
            wait: WaitPath::default(),
            wait_revision: None,
            corrections: Vector3::zeros(),
            applied: 0,
            disagreements: 0,
            stats: HintStats::default(),
            lag: LagNoise::default(),
        }
    }

    /// Makes this a copy of `other`, reusing the rings' storage (see [`Navigator::copy_from`]).
    pub(super) fn copy_from(&mut self, other: &Self) {
        self.cfg = other.cfg;
        self.delivery_ns = other.delivery_ns;
        self.max_age_ns = other.max_age_ns;
        self.waiting.clone_from(&other.waiting);
        self.newest = other.newest;
        self.speed.clone_from(&other.speed);
        self.newest_used = other.newest_used;
        self.r_bs = other.r_bs;
        self.yaw_sigma_rad = other.yaw_sigma_rad;
        self.estimator = other.estimator;
        self.forward = other.forward;
        self.velocity_axis = other.velocity_axis;
        self.path_fit = other.path_fit;
        self.mounting_at_ns = other.mounting_at_ns;
        self.latest_fit = other.latest_fit;
        self.axis_source = other.axis_source;
        self.scale_taken = other.scale_taken;
        self.systematic = other.systematic;
        self.along = other.along;
        self.history.clone_from(&other.history);
        self.still = other.still;
        self.wait = other.wait;
        self.wait_revision = other.wait_revision;
        self.corrections = other.corrections;
        self.applied = other.applied;
        self.disagreements = other.disagreements;
        self.stats = other.stats;
        self.lag = other.lag;
    }

    /// The body velocity minus corrections at `t_ns`, interpolated between the stored samples
    /// around it (the newest one for a time after it); `None` when `t_ns` is older than the
    /// history.
    pub(super) fn uncorrected_at(&self, t_ns: u64) -> Option<Vector3<f64>> {
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

    /// Whether speed hints are being applied at `t_ns`: the mounting is known and the newest
    /// delivered hint carries a speed and is fresh. Their updates hold the non-holonomic
    /// constraint (the lateral and vertical body velocity), so the IMU-only one
    /// (`crate::nonholonomic`) waits: applied between them as well, at the IMU's rate, it took
    /// the same lateral velocity error for new information several times per hint, and with
    /// the heading kept ([`crate::eskf::Heading`]) turned the gyro bias about up instead.
    pub(super) fn speed_in_use(&self, t_ns: u64) -> bool {
        self.r_bs.is_some() && self.fresh_speed(t_ns).is_some()
    }

    /// The newest delivered hint if it carries a speed and is fresh at `t_ns`.
    fn fresh_speed(&self, t_ns: u64) -> Option<RobotHint> {
        self.newest.filter(|h| {
            h.flags & hint_flags::SPEED_VALID != 0
                && t_ns.saturating_sub(h.stamps.sample_ns) <= self.max_age_ns
        })
    }

    /// Whether the mounting is still to be estimated from the path ([`PathAxis`]): none
    /// given nor estimated yet.
    fn path_wanted(&self) -> bool {
        self.r_bs.is_none() && self.cfg.mounting_from_turns
    }

    /// What the speed hint `h` at `t_ns` (before its update) brings to an estimated mounting
    /// (no `--mount`): the speed-change fit's interval closed with the filter's `reference`,
    /// and the mounting taken from it or the path ([`Self::fit_to_take`]); the first restarts
    /// the velocity ([`Self::restart_velocity`]), a later one turns the stored body velocities.
    /// Returns the fit taken and the turn of the body frame it made (identity for the first).
    pub(super) fn mount_from(
        &mut self,
        kf: &mut Eskf,
        h: &RobotHint,
        reference: &Reference,
        t_ns: u64,
        direction_unknown: bool,
    ) -> Option<(ForwardFit, Matrix3<f64>)> {
        let turns = self.cfg.mounting_from_turns.then(|| {
            let (speed, sigma) = (h.forward_speed_mps, h.forward_speed_sigma_mps);
            self.forward
                .hint(h.stamps.sample_ns, speed, sigma, reference)
        });
        let (fit, source) = self.fit_to_take(turns.flatten(), kf)?;
        self.axis_source = Some(source);
        let turn = match self.remount(&fit, t_ns) {
            None => {
                self.restart_velocity(kf, h, direction_unknown);
                Matrix3::identity()
            }
            Some(turn) => turn,
        };
        self.scale_from_fit(kf, &fit, t_ns);
        Some((fit, turn))
    }

    /// The mounting to take from the speed-change fit `turns` (if one was trusted at this hint)
    /// and the path's ([`Self::path_fit`]): the fit fused with the path's estimate once there is
    /// one ([`crate::velocity_axis::fuse`]), else whichever there is.
    fn fit_to_take(
        &mut self,
        turns: Option<ForwardFit>,
        kf: &Eskf,
    ) -> Option<(ForwardFit, AxisSource)> {
        let path = self.path_fit.or_else(|| self.velocity_fit(kf));
        match (turns, path) {
            (Some(t), Some(p)) => Some((fuse(&t, &p), AxisSource::Fused)),
            (Some(t), None) => Some((t, AxisSource::SpeedChanges)),
            (None, Some(p)) if self.r_bs.is_none() => Some((p, AxisSource::Path)),
            (None, _) => None,
        }
    }

    /// A sample of `dt_s` in motion at `t_ns` (after its prediction) while no mounting is
    /// known: the filter's velocity joins the motion's path against the fresh speed hint's
    /// distance ([`PathAxis`]); a velocity with no direction or no fresh speed hint starts the
    /// motion's path anew.
    pub(super) fn velocity_step(
        &mut self,
        kf: &Eskf,
        dt_s: f64,
        t_ns: u64,
        direction_unknown: bool,
    ) {
        if !self.path_wanted() {
            return;
        }
        let Some(h) = self.fresh_speed(t_ns).filter(|_| !direction_unknown) else {
            self.velocity_axis.restart();
            return;
        };
        let v_s = kf.x.q.inverse_transform_vector(&kf.x.v);
        let v_sigma = horizontal_velocity_var(kf).sqrt();
        let (speed, sigma) = (h.forward_speed_mps, h.forward_speed_sigma_mps);
        self.velocity_axis.step(&v_s, v_sigma, speed, sigma, dt_s);
    }

    /// The forward axis from the path ([`PathAxis`]) while no mounting is known:
    /// the fit to take, once trusted (its speed scale unknown).
    fn velocity_fit(&mut self, kf: &Eskf) -> Option<ForwardFit> {
        if !self.path_wanted() {
            return None;
        }
        let up_s = kf.x.q.inverse_transform_vector(&Vector3::z());
        let (mounting, sigma_rad) = self.velocity_axis.mounting(&up_s)?;
        let fit = ForwardFit {
            mounting,
            sigma_rad,
            bias_sigma_rad: 0.0,
            scale: None,
            scale_sigma: f64::INFINITY,
        };
        self.path_fit = Some(fit);
        Some(fit)
    }

    /// Takes the forward-axis fit `fit` at `t_ns` as the mounting; returns `None` for the first
    /// one, else the turn `R_new R_old^T` of the refined mounting. The stored body velocities
    /// and their corrections are turned with it, so that the speed hints still compare like
    /// with like.
    pub(super) fn remount(&mut self, fit: &ForwardFit, t_ns: u64) -> Option<Matrix3<f64>> {
        let r_new = fit.mounting.to_rotation_matrix().into_inner();
        self.yaw_sigma_rad = fit.sigma_rad;
        self.latest_fit = Some(*fit);
        let Some(r_old) = self.r_bs.replace(r_new) else {
            self.mounting_at_ns = Some(t_ns);
            return None;
        };
        let turn = r_new * r_old.transpose();
        for i in 0..self.history.len() {
            if let Some(e) = self.history.oldest_mut(i) {
                e.uncorrected = turn * e.uncorrected;
            }
        }
        self.corrections = turn * self.corrections;
        Some(turn)
    }

    /// With the mounting just estimated: when the filter's horizontal velocity has no
    /// direction (`direction_unknown`, [`super::Navigator::direction_unknown`]) or is known
    /// worse than the hint's speed (1-sigma per axis above it: the IMU alone integrated since
    /// the alignment), restarts the velocity from the hint along the body's forward axis, as a
    /// cruise alignment with a known mounting does ([`crate::cruise::initial_velocity`]). An
    /// update linearized about a velocity that far off turns the attitude instead (on the
    /// F1TENTH car of docs/real-data.md, by 90 degrees after 30 s on the IMU alone; on the
    /// comma2k19 car, whose speed had grown past the cruise start's 1-sigma, by 40 degrees).
    pub(super) fn restart_velocity(
        &mut self,
        kf: &mut Eskf,
        h: &RobotHint,
        direction_unknown: bool,
    ) {
        let Some(r_bs) = self.r_bs else {
            return;
        };
        let speed = h.forward_speed_mps;
        if !direction_unknown && horizontal_velocity_var(kf).sqrt() <= speed.abs() {
            return;
        }
        let forward_sigma = h
            .forward_speed_sigma_mps
            .hypot(speed * self.cfg.speed_scale_sigma);
        let lateral = self
            .cfg
            .nonholonomic_sigma_mps
            .hypot(speed * self.yaw_sigma_rad);
        let (v, cov) = initial_velocity(&kf.x.q, Some(&r_bs), speed, forward_sigma, lateral, speed);
        kf.restart_velocity(v, &cov);
        if direction_unknown {
            self.position_from_wait(kf, &r_bs);
        }
    }

    /// A sample of `dt_s` while the velocity has no direction (`direction_unknown`,
    /// [`super::Navigator::direction_unknown`]; nothing otherwise): adds it to the path driven
    /// meanwhile ([`WaitPath`]) with the newest hint's speed if it is a fresh one at `t_ns`.
    pub(super) fn wait_step(&mut self, kf: &Eskf, dt_s: f64, t_ns: u64, direction_unknown: bool) {
        if !direction_unknown {
            return;
        }
        let speed = self
            .newest
            .filter(|h| h.flags & hint_flags::SPEED_VALID != 0)
            .filter(|h| t_ns.saturating_sub(h.stamps.sample_ns) <= self.max_age_ns)
            .map(|h| h.forward_speed_mps / (1.0 + kf.x.k));
        self.wait.add(&kf.x.p, &kf.x.q, speed, dt_s);
    }

    /// With the forward axis first trusted after a wait without a direction: the path the hints
    /// and the attitude say was driven meanwhile ([`WaitPath`]) becomes the position
    /// ([`Eskf::reset_position`]), its variance per axis the filter's own plus the distance
    /// times the speed scale's prior 1-sigma and the fit's whole yaw 1-sigma in quadrature,
    /// squared (the speeds' white noise averages out over the wait). The filter's own position
    /// integrated the specific force twice from a velocity that far off, and its conditioning
    /// on the restarted velocity assumes that velocity's error constant over the wait (true of
    /// the start's error, not of the tilt's share) and leaves it a 1-sigma of metres: a
    /// measurement with the path's 1-sigma would barely move it (the comma2k19 car of
    /// docs/real-data.md: 57 m from the path, 1-sigma 1.5-2.6 m, after 107 m).
    /// The path's states are then due to be published again ([`Self::wait_revision`]).
    fn position_from_wait(&mut self, kf: &mut Eskf, r_bs: &Matrix3<f64>) {
        let forward_s = r_bs.row(0).transpose();
        let Some((p, distance)) = self.wait.displacement(&forward_s) else {
            return;
        };
        let yaw = self.latest_fit.map_or(0.0, |f| f.systematic_sigma_rad());
        let relative = self.cfg.speed_scale_sigma.hypot(yaw);
        let sigma = distance * relative;
        kf.propagate();
        let own = Vector3::from_fn(|i, _| kf.cov[(P + i, P + i)]);
        let var = own + Vector3::repeat(sigma * sigma);
        kf.reset_position(p, var);
        self.wait_revision = self.wait.revision(&forward_s, &kf.x.p, relative);
    }

    /// Applies a speed hint as a body-velocity measurement at the hint's time; returns its
    /// normalized innovation squared (3 dof; NaN when its covariance was singular), `None`
    /// when it cannot be applied (mounting unknown, or the hint stale at `t_ns` or older than
    /// the velocity history).
    pub(super) fn apply_speed(&mut self, kf: &mut Eskf, h: &RobotHint, t_ns: u64) -> Option<f64> {
        let lag_var = self.lag.variance(
            h.stamps.sample_ns,
            h.forward_speed_mps,
            h.forward_speed_sigma_mps,
            self.max_age_ns,
        );
        let r_bs = self.r_bs?;
        if t_ns.saturating_sub(h.stamps.sample_ns) > self.max_age_ns {
            return None;
        }
        let lag_ns = (self.cfg.speed_time_offset_s * 1e9) as i64;
        let then = self.uncorrected_at(h.stamps.sample_ns.saturating_add_signed(lag_ns))?;
        // The body velocity the filter now believes it had at the hint's time, at the axle.
        let r_b = self.cfg.lever_arm_m;
        let mut predicted = then + self.corrections;
        if r_b != Vector3::zeros() {
            predicted += kf.lever_velocity(&r_bs, &r_b);
        }
        let residual = Vector3::new(
            h.forward_speed_mps - (1.0 + kf.x.k) * predicted.x,
            -predicted.y,
            -predicted.z,
        );
        let nh = self.cfg.nonholonomic_sigma_mps;
        // A mounting yaw known to `yaw_sigma_rad` puts that much of the speed sideways.
        let lateral = nh.hypot(h.forward_speed_mps * self.yaw_sigma_rad);
        let nis = kf.point_velocity_update(
            &r_bs,
            &r_b,
            residual,
            Vector3::new(
                (h.forward_speed_sigma_mps.powi(2) + lag_var).sqrt(),
                lateral,
                nh,
            ),
            self.cfg.speed_heading,
            MountingYaw::Exact,
        );
        Some(nis.unwrap_or(f64::NAN))
    }

    /// What the forward-axis fit takes from the filter at this sample ([`Reference`]); the
    /// horizontal bias 1-sigma only while the fit runs and has no reference yet (it keeps the
    /// first), `g` gravity, m/s^2.
    pub(super) fn reference(&self, kf: &Eskf, g: f64) -> Reference {
        Reference {
            up: kf.x.q.inverse_transform_vector(&Vector3::z()),
            accel_bias: kf.x.b_a,
            gyro_bias: kf.x.b_g,
            horizontal_sigma_mps2: if self.cfg.mounting_from_turns && !self.forward.has_reference()
            {
                horizontal_bias_sigma(&kf.cov, &kf.x.q, g)
            } else {
                0.0
            },
        }
    }

    /// Checks the filter's speed scale against a trusted forward-axis fit's at `t_ns`, once,
    /// when the fit's is first observable (its 1-sigma below the scale state's prior,
    /// [`HintConfig::speed_scale_sigma`]; see [`ScaleTaken`]). When the two lie more than
    /// [`SCALE_CONFLICT_SIGMAS`] apart (their 1-sigmas in quadrature) the scale state's
    /// prior was wrong for this robot (a misconfigured wheel-speed gain, a tyre of another
    /// size), which a state learning slowly from its speed updates does not recover from: its
    /// variance is widened to cover the difference and the fit enters as a measurement of it.
    /// When they agree nothing changes: the filter learns the scale from the same
    /// accelerations the fit uses, and taking the fit as well would count them twice.
    pub(super) fn scale_from_fit(&mut self, kf: &mut Eskf, fit: &ForwardFit, t_ns: u64) {
        let observable = fit.scale_sigma < self.cfg.speed_scale_sigma;
        let (Some(k_fit), None, true) = (fit.scale, self.scale_taken, observable) else {
            return;
        };
        let (k0, sigma0) = kf.scale();
        let conflict = SCALE_CONFLICT_SIGMAS * sigma0.hypot(fit.scale_sigma);
        let prior_refuted = (k_fit - k0).abs() > conflict;
        if prior_refuted {
            kf.widen_scale((k_fit - k0).powi(2));
            kf.measure_scale(k_fit, fit.scale_sigma * fit.scale_sigma);
        }
        self.scale_taken = Some(ScaleTaken {
            at_ns: t_ns,
            fit: (k_fit, fit.scale_sigma),
            prior_sigma: sigma0,
            prior_refuted,
            taken: kf.scale(),
        });
    }

    /// A sample at a rest a fresh stationary hint decided (`w` its corrected rate, rad/s,
    /// sensor frame; `dt` s): the wheels stand still, so the body does not turn. Once
    /// [`WHEELS_STILL_CHECK_S`] of such samples are gathered, their mean is compared with the
    /// filter's gyro bias, with the variance of the mean from their own scatter (a stop's
    /// settling and the part's real noise, at least the noise density `density`,
    /// rad/s/sqrt(Hz), over the root of the span) and the bias's: beyond `gate` 1-sigmas on
    /// an axis, the reading says the bias is wrong, not that the robot spins. A bias learned
    /// while the robot moved (a start in motion: the calibration stage's first steady window
    /// was a steady turn) is that far off, and the zero-rate updates' gate, made for an
    /// in-place spin flagged rest, then refuses every rest. As for the speed scale
    /// ([`Self::scale_from_fit`], a prior-data conflict) the bias variance is widened to cover
    /// the difference and the mean taken. Counted in [`HintStats::gyro_bias_refuted`].
    pub(super) fn wheels_still(
        &mut self,
        kf: &mut Eskf,
        w: &Vector3<f64>,
        dt: f64,
        density: f64,
        gate: f64,
    ) {
        let still = &mut self.still;
        still.n += 1;
        still.t_s += dt;
        still.sum += w;
        still.sum_sq += w.component_mul(w);
        if still.t_s < WHEELS_STILL_CHECK_S || still.n < 3 {
            return;
        }
        let n = f64::from(still.n);
        let mean = still.sum / n;
        let spread = (still.sum_sq / n - mean.component_mul(&mean)) * (n / (n - 1.0));
        let floor = density * density / still.t_s;
        let var_mean = spread.map(|v| (v / n).max(floor));
        *still = WheelsStill::default();
        let residual = mean - kf.x.b_g;
        let p_bg = kf.cov.fixed_view::<3, 3>(BG, BG).diagonal();
        let refuted = (0..3).any(|i| residual[i].abs() > gate * (p_bg[i] + var_mean[i]).sqrt());
        if refuted {
            kf.widen_gyro_bias(residual.map(|r| r * r));
            kf.zero_rate(mean, var_mean.max().sqrt(), f64::INFINITY);
            self.stats.gyro_bias_refuted += 1;
        }
    }

    /// Carries what the filter's covariance does not hold of the speed hints' two systematic
    /// errors into the published position 1-sigma (estimates unchanged), for a step of `dt_s`
    /// seconds at the filter's velocity, while speed hints are applied (`t_ns`):
    /// - the estimated mounting's yaw error (see [`Self::systematic`]): a yaw error `d` turns
    ///   every velocity the speed hints give by `d`, so the position error is `d` times the
    ///   displacement since, turned by 90 degrees; the speed updates' lateral 1-sigma (per
    ///   hint, white) averages it away. Taken as one error scaled by each fit's 1-sigma (a
    ///   refined fit's error is the earlier one's, shrunk);
    /// - the speed scale beyond the scale state's 1-sigma (see [`Self::along`]): the
    ///   forward-axis fit's scale and the state's are two estimates of one scale from the same
    ///   run, and where they lie further apart than the state's 1-sigma the state does not know
    ///   the scale that well (on the F1TENTH car of docs/real-data.md the state ended tens of
    ///   its 1-sigmas from the particle filter's ratio). The excess, `sqrt(d^2 - sigma_k^2)`
    ///   over `1 + k`, is a relative error of the distance along the velocity.
    ///
    /// Each is one error for the whole run: the variance per axis is its sum's square, and
    /// the two, independent, add.
    pub(super) fn carry_systematic(&mut self, kf: &mut Eskf, dt_s: f64, t_ns: u64) {
        if !self.speed_in_use(t_ns) {
            return;
        }
        let v = kf.x.v;
        let fit = self.latest_fit.filter(|_| self.mounting_at_ns.is_some());
        if let Some(fit) = fit {
            let sigma = fit.systematic_sigma_rad();
            self.systematic[0] -= sigma * v.y * dt_s;
            self.systematic[1] += sigma * v.x * dt_s;
        }
        let (k, sigma_k) = kf.scale();
        if let Some(k_fit) = fit.and_then(|f| f.scale) {
            let excess = ((k - k_fit).powi(2) - sigma_k * sigma_k).max(0.0).sqrt();
            let relative = excess / (1.0 + k).max(f64::EPSILON);
            self.along[0] += relative * v.x * dt_s;
            self.along[1] += relative * v.y * dt_s;
        }
        let var = |i: usize| self.systematic[i].powi(2) + self.along[i].powi(2);
        kf.set_systematic([var(0), var(1)]);
    }

    /// The forward axis's report once trusted.
    pub(super) fn forward_report(&self) -> Option<ForwardAxisReport> {
        let (t, fit) = (self.mounting_at_ns?, self.latest_fit?);
        Some(ForwardAxisReport {
            trusted_at_ns: t,
            source: self.axis_source?,
            fit,
            scale_taken: self.scale_taken,
        })
    }
}

/// The filter's velocity variance per horizontal axis (navigation frame), (m/s)^2.
fn horizontal_velocity_var(kf: &Eskf) -> f64 {
    0.5 * (kf.cov[(V, V)] + kf.cov[(V + 1, V + 1)])
}

impl super::Navigator {
    /// Whether the filter's horizontal velocity carries no direction: it aligned on a cruise
    /// without a mounting ([`crate::cruise::initial_velocity`]: zero, with the window's largest
    /// speed as its 1-sigma per axis), and neither a rest (a zero-velocity update) nor the
    /// forward axis ([`Hints::restart_velocity`]) has given it one since. Its integral over
    /// time is then no path: the IMU-only non-holonomic constraint does not estimate its
    /// mounting from it (`crate::nonholonomic::ImuConstraint::apply`), and the first trusted
    /// forward axis restarts it whatever its 1-sigma has become.
    pub(super) fn direction_unknown(&self) -> bool {
        self.aligned_in_motion.is_some() && self.rest_count == 0 && self.hints.r_bs.is_none()
    }

    /// Whether the aligned filter takes this sample as rest (decided before its prediction).
    #[inline]
    pub(super) fn rest_decision(&self, d: &HintDecision, imu_rest: bool) -> bool {
        // The IMU's rest flag decides without a fresh hint; after hints went stale, only when
        // the velocity (at the previous sample) is consistent with rest (a detector that takes
        // cruising for rest must not stop a robot the hints have just seen moving), and never
        // while it has no direction ([`Self::direction_unknown`]): zero, its 1-sigma the
        // cruise's speed, it is consistent with anything.
        match d.rest {
            Some(r) => r,
            None if d.stale && imu_rest && self.direction_unknown() => false,
            None if d.stale && imu_rest => self
                .kf
                .as_ref()
                .expect("aligned")
                .velocity_consistent_with_zero(
                    self.cfg.zupt_sigma_mps,
                    self.hints.cfg.fallback_zupt_gate_sigma,
                ),
            None => imu_rest,
        }
    }

    /// Counts the hint's disagreement with the detector and its first use.
    #[inline]
    pub(super) fn count_hint_use(&mut self, d: &HintDecision) {
        if d.sample.flags & odometry_flags::HINT_DISAGREE != 0 {
            self.hints.disagreements += 1;
        }
        if d.rest.is_some()
            && d.fresh
                .is_some_and(|h| self.hints.newest_used != Some(h.seq))
        {
            self.hints.newest_used = d.fresh.map(|h| h.seq);
            self.hints.applied += 1;
        }
    }
}
