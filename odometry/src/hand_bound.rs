//! A bound on the velocity of a sensor moved by a hand or an arm (the `other` profile): such a
//! motion goes back and forth within a person's reach or a workcell, so its velocity, whatever
//! the integration says, is near zero on the scale of a hand's speed. Without it, a hand-moved
//! sensor that never rests integrates freely, and an accelerometer bias of 0.05 m/s^2 puts it
//! 560 m off after 150 s (`b t^2 / 2`); BROAD's box moved by hand for 150 s without a break
//! ended 143 and 151 m off (docs/real-data.md).
//!
//! Method: while the sample is not taken as rest and no robot hint reports the motion, every [`HAND_BOUND_INTERVAL_S`] the filter's
//! velocity (m/s, navigation frame, z up) is measured as zero with 1-sigma
//! [`HAND_SPEED_SIGMA_MPS`] per axis: a pseudo-measurement of the hand's speed scale, not of
//! its rest. Reaching movements peak at 0.5-1.5 m/s and reverse within about a second (T. Flash
//! and N. Hogan, "The coordination of arm movements: an experimentally confirmed mathematical
//! model", J. Neuroscience 5(7), 1985: minimum-jerk reaches of 0.2-0.4 m in 0.5-1 s), so one
//! measurement a second counts each such excursion once. A filter whose velocity is known
//! better than that (after a rest, or with an arm's pauses every few seconds) is barely moved
//! by it (its gain is `P / (P + sigma^2)`); a filter integrating freely has its velocity, and
//! with it the accelerometer bias, held to the hand's scale, and its position then grows as a
//! random walk of about `sigma sqrt(interval t)` instead of `b t^2 / 2`.

use crate::eskf::Eskf;

/// 1-sigma per axis of a hand's or an arm's velocity about zero, m/s (module documentation).
pub const HAND_SPEED_SIGMA_MPS: f64 = 1.0;
/// Interval between the velocity bounds while the sensor moves, s.
pub const HAND_BOUND_INTERVAL_S: f64 = 1.0;

/// The bound's state in a navigator: the time of the last bound or rest.
#[derive(Debug, Clone, Copy, Default)]
pub struct HandBound {
    last_ns: Option<u64>,
}

impl HandBound {
    /// After the aligned filter's updates at `t_ns`: bounds its velocity with 1-sigma
    /// `sigma_mps` (0: off) when [`HAND_BOUND_INTERVAL_S`] has passed in motion since the last
    /// bound or held sample (`held`: the sample is taken as rest, or robot hints report the
    /// motion). Returns whether it updated.
    pub fn update(&mut self, kf: &mut Eskf, t_ns: u64, held: bool, sigma_mps: f64) -> bool {
        if sigma_mps <= 0.0 {
            return false;
        }
        let last = *self.last_ns.get_or_insert(t_ns);
        if held {
            self.last_ns = Some(t_ns);
            return false;
        }
        if (t_ns.saturating_sub(last) as f64) * 1e-9 < HAND_BOUND_INTERVAL_S {
            return false;
        }
        self.last_ns = Some(t_ns);
        kf.zero_velocity(sigma_mps).is_some()
    }
}
