//! What an offline run reports: the states it gathers (alignment, rests, the end), and the
//! error against the truth a simulated recording carries.
//!
//! Truth comparison: our navigation frame has its origin at the alignment point and its
//! heading fixed there; the truth's frame is the scenario's. At the first aligned state the
//! rotation between the two frames' headings is taken from the two attitudes (its yaw part
//! only: a roll or pitch difference is our own tilt error and stays in the error), and the
//! truth positions are expressed in our frame relative to the truth position there.

use std::collections::VecDeque;

use ipc_types::{OdometryState, odometry_flags};
use nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};
use recording::Truth;
use serde_json::json;

fn quat(wxyz: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]))
}

/// Maps truth positions into our navigation frame once the first aligned state is known.
struct TruthFrame {
    origin: Vector3<f64>,
    to_ours: Rotation3<f64>,
}

impl TruthFrame {
    fn new(ours: &OdometryState, truth: &Truth) -> Self {
        // Rotation taking truth-frame vectors to ours: ours = q_o q_t^-1 truth; its yaw part.
        let m =
            (quat(ours.attitude_wxyz) * quat(truth.attitude_wxyz).inverse()).to_rotation_matrix();
        let yaw = m[(1, 0)].atan2(m[(0, 0)]);
        Self {
            origin: Vector3::from(truth.position_m),
            to_ours: Rotation3::from_axis_angle(&Vector3::z_axis(), yaw),
        }
    }

    fn position(&self, truth: &Truth) -> Vector3<f64> {
        self.to_ours * (Vector3::from(truth.position_m) - self.origin)
    }
}

/// Truth records not yet passed by the states, in time order.
#[derive(Default)]
pub struct TruthQueue(VecDeque<Truth>);

impl TruthQueue {
    /// Takes the next truth record (they come in time order).
    pub fn push(&mut self, t: Truth) {
        self.0.push_back(t);
    }

    /// The truth at `t_ns`, dropping every earlier one (states come in time order).
    pub fn at(&mut self, t_ns: u64) -> Option<&Truth> {
        while self.0.front().is_some_and(|t| t.t_ns < t_ns) {
            self.0.pop_front();
        }
        self.0.front().filter(|t| t.t_ns == t_ns)
    }
}

/// What the run's report gathers from the odometry states.
#[derive(Default)]
pub struct Summary {
    /// The last state.
    pub last: Option<OdometryState>,
    /// The first aligned state's time, ns.
    pub aligned_ns: Option<u64>,
    rests: Vec<serde_json::Value>,
    frame: Option<TruthFrame>,
    rest_errors: Vec<serde_json::Value>,
    truth_distance: f64,
    prev_truth: Option<Vector3<f64>>,
}

impl Summary {
    /// Takes the (non-revision) state of one sample, with the truth read so far.
    pub fn state(&mut self, state: OdometryState, truth: &mut TruthQueue) {
        if self.aligned_ns.is_none() && state.flags & odometry_flags::ALIGNED != 0 {
            self.aligned_ns = Some(state.stamps.sample_ns);
        }
        let new_rest = self.last.is_some_and(|l| state.rest_count > l.rest_count);
        if new_rest {
            self.rests.push(json!({
                "t_s": state.stamps.sample_ns as f64 * 1e-9,
                "position_m": state.position_m,
                "sigma_m": state.position_sigma_m,
            }));
        }
        if let Some(t) = truth.at(state.stamps.sample_ns) {
            let p = Vector3::from(t.position_m);
            if let Some(q) = self.prev_truth {
                self.truth_distance += (p - q).xy().norm();
            }
            self.prev_truth = Some(p);
            if self.frame.is_none() && state.flags & odometry_flags::ALIGNED != 0 {
                self.frame = Some(TruthFrame::new(&state, t));
            }
            if let (Some(f), true) = (&self.frame, new_rest) {
                let e = Vector3::from(state.position_m) - f.position(t);
                self.rest_errors.push(json!({
                    "t_s": state.stamps.sample_ns as f64 * 1e-9,
                    "error_m": [e.x, e.y, e.z],
                    "truth_distance_m": self.truth_distance,
                }));
            }
        }
        self.last = Some(state);
    }

    /// The end state's error against the truth, m, in our frame (a recording with truth).
    pub fn truth_error(&self, end: &OdometryState, truth: &mut TruthQueue) -> Option<[f64; 3]> {
        let (f, t) = (self.frame.as_ref()?, truth.at(end.stamps.sample_ns)?);
        let e = Vector3::from(end.position_m) - f.position(t);
        Some([e.x, e.y, e.z])
    }

    /// The JSON result from the end state `end` (with `truth_error`) and `extra`'s fields.
    pub fn json(
        &self,
        end: &OdometryState,
        truth_error: Option<[f64; 3]>,
        extra: serde_json::Value,
    ) -> serde_json::Value {
        let mut result = json!({
            "end_displacement_m": end.position_m,
            "sigma_m": end.position_sigma_m,
            "distance_m": end.distance_m,
            "truth_error_m": truth_error,
            "truth_distance_m": truth_error.map(|_| self.truth_distance),
            "rest_intervals": self.rest_errors,
            "rests": self.rests,
            "seq": end.seq,
        });
        if let (Some(r), serde_json::Value::Object(extra)) = (result.as_object_mut(), extra) {
            r.extend(extra);
        }
        result
    }

    /// The human-readable result: the end displacement with its 1-sigma, and the error
    /// against truth where the recording has one.
    pub fn print(&self, end: &OdometryState, truth_error: Option<[f64; 3]>) {
        let p = end.position_m;
        let s = end.position_sigma_m;
        println!(
            "end displacement ({:+.4}, {:+.4}, {:+.4}) m +- ({:.4}, {:.4}, {:.4}) m, distance {:.2} m",
            p[0], p[1], p[2], s[0], s[1], s[2], end.distance_m
        );
        if let Some(e) = truth_error {
            let horizontal = (e[0] * e[0] + e[1] * e[1]).sqrt();
            println!(
                "error against truth ({:+.3}, {:+.3}, {:+.3}) m: {:.2} % of {:.1} m travelled",
                e[0],
                e[1],
                e[2],
                100.0 * horizontal / self.truth_distance.max(f64::EPSILON),
                self.truth_distance
            );
        }
    }
}
