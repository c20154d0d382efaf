//! The navigator's bookkeeping records: the motion history's entries, the alignment's sums,
//! a pending revision and the rest window still to be updated.

use crate::eskf::RefinementMean;
use crate::handover::WaitMark;
use crate::rest_noise::RestNoise;
use ipc_types::{OdometryState, Stamps, odometry_flags};
use nalgebra::{UnitQuaternion, Vector3};

/// One decimated state of the motion history, kept for the revision at the next rest.
#[derive(Debug, Clone, Copy)]
pub(super) struct HistoryEntry {
    pub(super) t_ns: u64,
    pub(super) stamps: Stamps,
    pub(super) seq: u64,
    pub(super) p: Vector3<f64>,
    pub(super) v: Vector3<f64>,
    pub(super) sigma_p: Vector3<f64>,
    pub(super) sigma_v: Vector3<f64>,
    pub(super) q: UnitQuaternion<f64>,
    pub(super) distance_m: f64,
    /// The wait path's sums at this state while the velocity had no direction
    /// (`crate::handover`).
    pub(super) wait: Option<WaitMark>,
}

/// The counters a revised state carries (the navigator's at the revision).
#[derive(Debug, Clone, Copy)]
pub(super) struct Counts {
    pub(super) rest_count: u32,
    pub(super) hints_applied: u32,
    pub(super) hint_disagreements: u32,
}

impl HistoryEntry {
    /// This state published again with position `p` and velocity `v` (m, m/s, navigation
    /// frame), flagged `REVISION`; `g` gravity, m/s^2.
    pub(super) fn revision(
        &self,
        p: &Vector3<f64>,
        v: &Vector3<f64>,
        g: f64,
        counts: Counts,
    ) -> OdometryState {
        let g_s = self.q.inverse() * Vector3::new(0.0, 0.0, g);
        let q = self.q;
        OdometryState {
            stamps: self.stamps,
            seq: self.seq,
            position_m: (*p).into(),
            position_sigma_m: self.sigma_p.into(),
            velocity_mps: (*v).into(),
            velocity_sigma_mps: self.sigma_v.into(),
            gravity_sensor_mps2: g_s.into(),
            attitude_wxyz: [q.w, q.i, q.j, q.k],
            distance_m: self.distance_m,
            flags: odometry_flags::ALIGNED | odometry_flags::REVISION,
            reserved16: 0,
            rest_count: counts.rest_count,
            hints_applied: counts.hints_applied,
            hint_disagreements: counts.hint_disagreements,
        }
    }
}

/// What the alignment rest has gathered so far.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct AlignSums {
    pub(super) t0_ns: u64,
    /// A sample of the rest was flagged `GRAVITY_OFF` (the calibration stage's learned rest
    /// read gravity off before its refinement removed that from the samples).
    pub(super) gravity_off: bool,
    pub(super) accel: RestNoise,
    pub(super) gyro: RestNoise,
    /// The calibration stage's refinement the samples carry (`crate::eskf::Refinement`).
    pub(super) refined: RefinementMean,
}

/// What happens to the motion history after a motion interval has ended.
#[derive(Debug, Clone, Copy)]
pub(super) struct PendingRevision {
    /// Time the motion interval ended (first rest sample), ns.
    pub(super) end_ns: u64,
    /// Sum of the corrections the updates injected since, position and velocity.
    pub(super) dp: Vector3<f64>,
    pub(super) dv: Vector3<f64>,
}

/// The rest samples whose zero-velocity and zero-rate updates are still to be made: at rest
/// the updates are made once per covariance propagation (`OdometryConfig::
/// propagation_interval_s`) or sooner, for all the rest samples since the last ones, with
/// their information (see [`super::Navigator::rest_updates`]).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct RestWindow {
    /// Samples.
    pub(super) n: u32,
    /// Their intervals' sum, s.
    pub(super) t_s: f64,
    /// Sum of their (corrected) gyro readings, rad/s, sensor frame.
    pub(super) w_sum: Vector3<f64>,
    /// Time of the newest, ns.
    pub(super) t_ns: u64,
}
