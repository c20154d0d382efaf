//! The navigator's checks of a wheeled platform without speed hints (`crate::nonholonomic`):
//! a rest flag the filter's velocity contradicts, and the along-track drift's share of the
//! published 1-sigma.

use ipc_types::{hint_flags, odometry_flags};

use crate::config::OdometryConfig;
use crate::eskf::Imu;
use crate::hints::HintConfig;
use crate::nonholonomic::ImuConstraint;
use crate::stops::{BLOCK_S, PushFlags, WINDOW_BLOCKS};

use super::Navigator;
use super::hint_state::{HintDecision, HintSample};

/// A rest flag is refused when the filter's horizontal velocity lies beyond this many of its
/// published 1-sigma (with the zero-velocity update's) from zero: the hints' fallback gate
/// (`HintConfig::fallback_zupt_gate_sigma`'s default). At 3, a simulated car on a level road
/// (docs/detectors.md, "Short rests", seed 1) had its real stops refused while the filter held
/// its speed far off, and drove on for kilometres.
pub const REST_GATE_SIGMA: f64 = 5.0;

/// A quiet window the detector calls motion is a stop only once the windows have been quiet
/// for this long without a break, s: one window's length, so that the stop's first sample
/// lies in no window with motion in it. A car's braking ends smoothly, its deceleration steady
/// below 2 Hz and so no spread: on wid-car-06 with an uncalibrated part's errors added
/// (docs/real-data.md) one quiet window while it still crept at 0.3-0.5 m/s was taken for a
/// stop, and its zero-velocity updates read the deceleration as a tilt and bias error and
/// moved the position 75 m back.
pub const STOP_QUIET_S: f64 = WINDOW_BLOCKS as f64 * BLOCK_S;

impl Navigator {
    /// Whether the IMU-only constraint runs with no speed measurement at this sample: a
    /// wheeled platform whose speed only the accelerometer tells.
    pub(super) fn unaided_wheeled(&self, d: &HintDecision) -> bool {
        self.nhc.is_some()
            && d.rest.is_none()
            && d.fresh
                .is_none_or(|h| h.flags & hint_flags::SPEED_VALID == 0)
    }

    /// Whether the detector's rest flag is refused because the filter's velocity
    /// (at the previous sample) is further from zero than [`REST_GATE_SIGMA`] times its
    /// published 1-sigma (with the zero-velocity update's) on a horizontal axis,
    /// on a wheeled platform without speed hints (flagged `REST_MOVING`). A car cruising as
    /// smoothly as it stood is still to the detector; its velocity is not. A real stop after
    /// a drive whose speed the filter got wrong by more than that is refused too, until the
    /// along-track drift's share of the 1-sigma has grown to cover it: the 1-sigma is what
    /// decides, so it must be honest.
    /// `unaided` is [`Self::unaided_wheeled`]'s answer for this sample.
    pub(super) fn moving_rest(&self, unaided: bool, hs: &mut HintSample) -> bool {
        if !unaided {
            return false;
        }
        let moving = self.velocity_beyond_gate();
        if moving {
            hs.flags |= odometry_flags::REST_MOVING;
        }
        moving
    }

    /// Whether the filter's horizontal velocity lies beyond [`REST_GATE_SIGMA`] times its
    /// published 1-sigma (with the zero-velocity update's) from zero on either axis.
    fn velocity_beyond_gate(&self) -> bool {
        let Some(kf) = self.kf.as_ref() else {
            return false;
        };
        let sigma = kf.velocity_sigma();
        (0..2).any(|i| kf.x.v[i].abs() > REST_GATE_SIGMA * sigma[i].hypot(self.zupt_sigma_mps))
    }

    /// The rest decision of a wheeled platform without speed hints (`unaided`, as in
    /// [`Self::unaided_wheeled`]) from the detector's (`imu_rest`, after the vibration check)
    /// and the low-frequency test (`crate::stops`): a rest whose window is not quiet is
    /// refused (flagged `REST_VIBRATING`: it shakes below 2 Hz as the platform did not
    /// standing); a quiet window the detector calls motion (`detector_ready`, and no step of a
    /// walk) is a stop with its engine running (flagged `VIBRATING_STOP`). Either way the
    /// filter's velocity may still refuse it ([`Self::moving_rest`]), until the windows have been
    /// quiet for `stops::CERTAIN_S` ([`Self::restart_at_rest`]). A rest after a motion
    /// gives the along-track drift its velocity correction
    /// (`crate::nonholonomic::ImuConstraint::stop_seen`).
    pub(super) fn wheeled_rest(
        &mut self,
        imu_rest: bool,
        detector_ready: bool,
        unaided: bool,
        hs: &mut HintSample,
    ) -> bool {
        if self.kf.is_none() || !unaided {
            return imu_rest;
        }
        let quiet = self.stops.quiet();
        if imu_rest && quiet == Some(false) {
            hs.flags |= odometry_flags::REST_VIBRATING;
            return false;
        }
        let told = quiet == Some(true) && self.stops.driving_told() && self.engine_running();
        let stop = !imu_rest && detector_ready && told && self.stops.quiet_for_s() >= STOP_QUIET_S;
        if !(imu_rest || stop) {
            return false;
        }
        if told && self.stops.quiet_for_s() >= crate::stops::CERTAIN_S {
            self.restart_at_rest();
        } else if self.moving_rest(unaided, hs) {
            return false;
        }
        if stop {
            hs.flags |= odometry_flags::VIBRATING_STOP;
        }
        let v = self.kf.as_ref().expect("aligned").x.v.xy().norm();
        if let Some(nhc) = self.nhc.as_mut() {
            nhc.stop_seen(v);
        }
        true
    }

    /// A stop the low-frequency test has shown for `stops::CERTAIN_S` without a break
    /// (`crate::stops`) whose velocity the filter holds beyond its gate
    /// ([`Self::moving_rest`]): the velocity, not the stop, is wrong, and its 1-sigma was too
    /// small to say so (an uncalibrated part's horizontal bias learned on a stop taken while
    /// the car still crept, wid-car-06 perturbed in docs/real-data.md: 0.55 m/s^2 the filter
    /// held to 0.06). The velocity is reset to zero with the zero-velocity update's 1-sigma,
    /// uncorrelated (`eskf::Eskf::reset_velocity`), rather than updated: a zero-velocity
    /// update linearized about a velocity tens of its 1-sigma off would turn the attitude and
    /// the bias to explain it, and the position would take what the velocity's dishonest
    /// covariance with it says (on that run, 64 m of its 143). Within the gate it changes
    /// nothing: the zero-velocity update follows.
    fn restart_at_rest(&mut self) {
        if !self.velocity_beyond_gate() {
            return;
        }
        let sigma = self.zupt_sigma_mps;
        if let Some(nhc) = self.nhc.as_mut() {
            nhc.velocity_resets += 1;
        }
        if let Some(kf) = self.kf.as_mut() {
            kf.reset_velocity(
                nalgebra::Vector3::zeros(),
                &(nalgebra::Matrix3::identity() * (sigma * sigma)),
            );
        }
    }

    /// Feeds the low-frequency test (`crate::stops`) the sample `m`, `dt_s` after the
    /// previous one, with the detector's rest flag `rest` (once it is ready): the standing
    /// before the first motion (under a metre travelled) is its reference.
    pub(super) fn push_stops(&mut self, m: &Imu, dt_s: f64, rest: bool) {
        let flags = PushFlags {
            rest,
            learn: self.distance_m < 1.0 && rest,
            moving: self.kf.is_some() && !self.at_rest,
        };
        self.stops.push(&m.f, &m.w, dt_s, flags);
    }

    /// Whether the platform stood at its alignment with an engine running (`crate::stops`):
    /// its specific force's standard deviation (three axes) more than `stops::FACTOR` times
    /// what the profile's white-noise density makes at the sample rate.
    fn engine_running(&self) -> bool {
        let Some(rate_hz) = self.stops.rate_hz() else {
            return false;
        };
        let noise = self.cfg.noise.accel_noise_density * (1.5 * rate_hz).sqrt();
        self.standing_accel_sd > crate::stops::FACTOR * noise
    }

    /// The IMU-only constraint of `cfg`, taken in the middle of a motion (a platform
    /// recognized as wheeled after seconds of driving): the along-track drift counts that
    /// motion from its start.
    pub(super) fn started_constraint(&mut self, cfg: &OdometryConfig) -> ImuConstraint {
        let mut nhc = imu_constraint(cfg, &self.hints.cfg);
        let moving_s = match (self.motion_start_ns, self.last, self.at_rest) {
            (Some(start), Some((t_ns, _, _)), false) => t_ns.saturating_sub(start) as f64 * 1e-9,
            _ => 0.0,
        };
        if let Some(kf) = self.kf.as_mut().filter(|_| moving_s > 0.0) {
            nhc.drift_along_track(kf, moving_s);
        }
        nhc
    }

    /// After the updates of an aligned sample: the along-track drift of a wheeled platform's
    /// motion without speed grows over `dt` (`crate::nonholonomic::AlongTrack`); a rest or a
    /// speed measurement ends it (`unaided` as in [`Self::moving_rest`]).
    pub(super) fn along_track(&mut self, unaided: bool, dt: f64, rest: bool) {
        let (Some(nhc), Some(kf)) = (self.nhc.as_mut(), self.kf.as_mut()) else {
            return;
        };
        if rest || !unaided {
            nhc.stopped();
        } else {
            nhc.drift_along_track(kf, dt);
        }
    }
}

/// The IMU-only constraint of `cfg` with the hints' mounting and lever arm: the mounting the
/// user gave, else an earlier pass's forward-axis fit followed with its yaw 1-sigma
/// ([`HintConfig::mounting_fit`]), else estimated from the first drive.
pub(super) fn imu_constraint(cfg: &OdometryConfig, hints: &HintConfig) -> ImuConstraint {
    let mut nhc = ImuConstraint::new(cfg.imu_nonholonomic_sigma_mps, hints.imu_mounting)
        .with_lever_arm(hints.lever_arm_m);
    if let Some(fit) = hints.mounting_fit {
        nhc.follow(fit.mounting, fit.sigma_rad);
    }
    nhc
}
