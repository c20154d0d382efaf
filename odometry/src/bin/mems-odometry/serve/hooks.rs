//! What the live driver (`mems_stage::live`) calls back into for `serve`: the session's inputs
//! from the hint and sample subscribers, the per-input hooks (the steady-state allocation
//! count, the one warning about samples without a gyroscope), and the summary at the end.

use alloc_count::steady::SteadyState;
use anyhow::Result;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use ipc_types::service::{self, ServiceError};
use ipc_types::{CorrectedImuSample, RobotHint};
use mems_stage::live::{Counts, Hooks, Receive};
use odometry::profile::Profile;
use odometry::session::{Input, OdometrySession};

/// The session's inputs: each hint that has arrived (while the session has room for it),
/// then a sample.
pub struct Inputs {
    /// `mems/robot/hint`.
    pub hints: Subscriber<ipc::Service, RobotHint, ()>,
    /// `mems/imu/corrected`.
    pub samples: Subscriber<ipc::Service, CorrectedImuSample, ()>,
}

impl Receive<OdometrySession> for Inputs {
    fn receive(&mut self, session: &OdometrySession) -> Result<Option<Input>, ServiceError> {
        let err = |e| ServiceError(format!("cannot receive: {e:?}"));
        if session.hint_room()
            && let Some(h) = self.hints.receive().map_err(err)?
        {
            return Ok(Some(Input::Hint(*h.payload())));
        }
        Ok(self
            .samples
            .receive()
            .map_err(err)?
            .map(|s| Input::Sample(*s.payload())))
    }
}

/// The steady-state allocation count, and the one warning about samples without a gyroscope.
pub struct Watch {
    steady: SteadyState,
    warned_no_gyro: bool,
    /// The profile asked for, for the summary.
    profile: Profile,
}

impl Hooks<OdometrySession> for Watch {
    fn input(&mut self) {
        self.steady.inputs(1);
    }

    fn drained(&mut self, session: &OdometrySession) -> Result<()> {
        if let (false, Some(seq)) = (self.warned_no_gyro, session.stats().first_no_gyro_seq) {
            self.warned_no_gyro = true;
            tracing::warn!(
                "sample seq {seq} has no gyroscope (GYRO_VALID clear: an accelerometer-only \
                 sensor mode, such as the MPU-9250 at 4 kHz); without it the attitude cannot be \
                 tracked, so no position is estimated: states carry NO_GYRO and never ALIGNED. \
                 Run the sensor at 1000 Hz or below for odometry"
            );
        }
        Ok(())
    }
}

impl Watch {
    /// Counts from the process's allocator, as `SteadyState::from_env` configures.
    pub fn new(profile: Profile) -> Result<Self> {
        Ok(Self {
            profile,
            steady: SteadyState::from_env(|| crate::ALLOCATOR.counts())
                .map_err(anyhow::Error::msg)?,
            warned_no_gyro: false,
        })
    }

    /// The run's summary on stderr: what the driver counted (`counts`), the session's
    /// sessions and hints, and the steady-state and small-block pool counts.
    pub fn report(&self, counts: &Counts, session: &OdometrySession) {
        let stats = session.stats();
        let axes = session.stage().axes();
        tracing::info!(
            "received {}, published {} (revisions included), refused {}, sessions {}, holes \
             bridged {} (this session), beyond the bridge {}, discarded for stalled subscribers \
             {}; hints received {}, this session: {}; axes: gravity turned as the gyroscope \
             says at {} of {} turns between still moments",
            counts.received,
            counts.published,
            counts.refused,
            stats.sessions,
            session.stage().holes().count,
            stats.unbridged,
            service::stalled_discards(),
            stats.hints,
            session.hint_stats(),
            axes.checked - axes.disagreed,
            axes.checked
        );
        if let Some(a) = session.stage().accel_estimate() {
            tracing::info!("{a}");
        }
        tracing::info!("{}", session.stage().consistency());
        if let Some(w) = session.walking_stats() {
            tracing::info!("{w}");
        }
        if axes.disagree() {
            tracing::warn!(
                "the accelerometer's and the gyroscope's axes disagree (odometry::axes): {axes:?}"
            );
        }
        match (self.profile, session.auto_choice()) {
            (Profile::Auto, Some(c)) => tracing::info!(
                "profile auto: {} platform, ran profile {} from sample time {:.3} s",
                c.features.platform.name(),
                c.profile.name(),
                c.at_ns as f64 * 1e-9
            ),
            (Profile::Auto, None) => tracing::info!(
                "profile auto: undecided (less than {} s of motion): ran profile other",
                odometry::session::AUTO_DECIDE_MOVING_S
            ),
            (p, _) => tracing::info!("profile {}", p.name()),
        }
        if stats.clipped.samples > 0 || stats.implausible > 0 {
            tracing::warn!(
                "clipped {} samples ({}), implausible {}: bridged as unobserved and counted in the 1-sigma (states flagged UNTRUSTED_INPUT); clipped gyroscope motions reconstructed at their rest {}, left bridged {}",
                stats.clipped.samples,
                stats.clipped.per_axis_text(),
                stats.implausible,
                session.stage().clip_stats().reconstructed,
                session.stage().clip_stats().bridged
            );
        }
        tracing::info!("{}; {}", self.steady.summary(), crate::ALLOCATOR.summary());
    }
}
