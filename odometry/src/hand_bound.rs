//! A bound on the velocity of a sensor moved by a hand or an arm (the `other` profile): such a
//! motion goes back and forth within a person's reach or a workcell, so its velocity, whatever
//! the integration says, is near zero on the scale of a hand's speed. Without it, a hand-moved
//! sensor that never rests integrates freely, and an accelerometer bias of 0.05 m/s^2 puts it
//! 560 m off after 150 s (`b t^2 / 2`); BROAD's box moved by hand for 150 s without a break
//! ended 143 and 151 m off (docs/real-data.md).
//!
//! Method: once the sensor has moved [`HAND_BOUND_AFTER_S`] without a rest (an arm's move
//! between pauses, or a single reach, never lasts that long: it needs no bound, and on the
//! simulated arm runs of docs/diagnosis.md a bound in every move of 1-2 s moved the end by
//! tenths of a metre either way), while the sample is not taken as rest and no robot hint reports the motion, every [`HAND_BOUND_INTERVAL_S`] the filter's
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
//!
//! **Within reach.** A random walk still leaves a hand that moves for minutes tens of metres
//! off (BROAD's box, 150 s without a break: 17-18 m of 1-sigma), while a hand or an arm stays
//! within reach of where it last rested: an adult's arm is about 0.44 of their height from
//! shoulder to grip, 0.77 m at 1.75 m (D. A. Winter, "Biomechanics and Motor Control of Human
//! Movement", 4th ed., Wiley 2009, figure 4.1, after Drillis and Contini 1966: upper arm
//! 0.186 H, forearm 0.146 H, hand 0.108 H), and a collaborative robot arm's reach is
//! 0.5-1.3 m (Universal Robots' UR3e, UR5e and UR10e data sheets: 500, 850, 1300 mm). So
//! once a second while the sensor moves (as the velocity bound, but also within its first
//! [`HAND_BOUND_AFTER_S`]) the position (m, navigation frame) is measured as the filter's
//! position at the anchor with 1-sigma [`REACH_SIGMA_M`] per axis, when the filter's position
//! variance has grown by more than `REACH_SIGMA_M^2` on some axis since the anchor. The anchor
//! is the filter's position at the last sample of a held run of at least [`ANCHOR_REST_S`]
//! (where the sensor was put down). The anchor's own error is shared by the current position,
//! and the reach does not shrink it: with `Pa` the anchor's variance and `D` the growth since
//! (per axis), the position `anchor + drift` observed as `drift + reach` keeps the variance
//! `Pa + D R^2 / (D + R^2)`, and the update measures each axis with the variance that leaves
//! exactly that (an axis whose variance has not grown learns nothing). The position's 1-sigma
//! thus never drops below the anchor's, and the next measurement waits until the drift has
//! again grown past the reach. A platform that travels (a walker, a vehicle) runs another
//! profile; one recognized as other that travels further than a reach would be pulled back
//! by this.

use nalgebra::Vector3;

use crate::eskf::{Eskf, P};

/// 1-sigma per axis of a hand's or an arm's velocity about zero, m/s (module documentation).
pub const HAND_SPEED_SIGMA_MPS: f64 = 1.0;
/// Interval between the velocity bounds while the sensor moves, s.
pub const HAND_BOUND_INTERVAL_S: f64 = 1.0;
/// Motion without a rest before the first bound, s: longer than a reach (module documentation).
pub const HAND_BOUND_AFTER_S: f64 = 5.0;
/// 1-sigma per axis of a hand's or an arm's position about where it last rested, m (module
/// documentation, "Within reach").
pub const REACH_SIGMA_M: f64 = 1.0;

/// Held samples in a row that anchor the reach, s: a rest the filter would align on
/// (`crate::profile::ROBOT_ALIGN_S`), where a hand put the sensor down. A detector's brief rest
/// flags in a slow motion, or an arm's pauses of tenths of a second, keep the anchor where it
/// was: they come where the position has already drifted.
pub const ANCHOR_REST_S: f64 = 0.5;

/// The bound's state in a navigator: the times of the last bound or held sample, of the last
/// held sample and of the start of the held run under way, and the anchor (the filter's
/// position and its variance per axis at the last held sample of a run of at least
/// [`ANCHOR_REST_S`], or where the bound started; m and m^2, navigation frame).
#[derive(Debug, Clone, Copy, Default)]
pub struct HandBound {
    last_ns: Option<u64>,
    held_ns: Option<u64>,
    held_since_ns: Option<u64>,
    anchor: Option<(Vector3<f64>, Vector3<f64>)>,
}

/// The filter's position (m) and its variance per axis (m^2), as of its last propagation.
fn position_of(kf: &Eskf) -> (Vector3<f64>, Vector3<f64>) {
    (kf.x.p, kf.cov.fixed_view::<3, 3>(P, P).diagonal())
}

/// The variance of a position measurement that takes the variance `pp` (m^2) of one axis to
/// `pa + d r2 / (d + r2)`, `d = pp - pa` the growth since the anchor of variance `pa` and `r2`
/// the reach's variance; `None` when the variance has not grown since the anchor (the
/// measurement then says nothing).
fn reach_variance(pp: f64, pa: f64, r2: f64) -> Option<f64> {
    let d = pp - pa;
    if d <= 0.0 {
        return None;
    }
    let target = pa + d * r2 / (d + r2);
    Some(target * pp / (pp - target))
}

/// Variance of a measurement that says nothing on its axis, as a multiple of the axis's own.
const NO_INFORMATION: f64 = 1e9;

impl HandBound {
    /// After the aligned filter's updates at `t_ns`, every [`HAND_BOUND_INTERVAL_S`] since the
    /// last bound or held sample (`held`: the sample is taken as rest, or robot hints report
    /// the motion): bounds its velocity with 1-sigma `sigma_mps` (0: off) when
    /// [`HAND_BOUND_AFTER_S`] has passed in motion since the last held sample, and its position
    /// within [`REACH_SIGMA_M`] of the anchor when it has drifted further (module
    /// documentation). Returns whether it updated.
    pub fn update(&mut self, kf: &mut Eskf, t_ns: u64, held: bool, sigma_mps: f64) -> bool {
        if sigma_mps <= 0.0 {
            return false;
        }
        let since = |t: u64| (t_ns.saturating_sub(t) as f64) * 1e-9;
        let last = *self.last_ns.get_or_insert(t_ns);
        let held_at = *self.held_ns.get_or_insert(t_ns);
        if held {
            let start = *self.held_since_ns.get_or_insert(t_ns);
            if since(start) >= ANCHOR_REST_S || self.anchor.is_none() {
                self.anchor = Some(position_of(kf));
            }
            self.last_ns = Some(t_ns);
            self.held_ns = Some(t_ns);
            return false;
        }
        self.held_since_ns = None;
        if self.anchor.is_none() {
            self.anchor = Some(position_of(kf));
        }
        if since(last) < HAND_BOUND_INTERVAL_S {
            return false;
        }
        self.last_ns = Some(t_ns);
        let speed = since(held_at) >= HAND_BOUND_AFTER_S && kf.zero_velocity(sigma_mps).is_some();
        speed | self.within_reach(kf)
    }

    /// The position measured as the anchor's when an axis has drifted beyond the reach since
    /// it (each axis with its own variance, [`reach_variance`]). Returns whether it updated.
    fn within_reach(&self, kf: &mut Eskf) -> bool {
        let Some((anchor, anchor_var)) = self.anchor else {
            return false;
        };
        kf.propagate();
        let (_, var) = position_of(kf);
        let r2 = REACH_SIGMA_M * REACH_SIGMA_M;
        if (0..3).all(|i| var[i] - anchor_var[i] <= r2) {
            return false;
        }
        let measured = Vector3::from_fn(|i, _| {
            reach_variance(var[i], anchor_var[i], r2).unwrap_or(NO_INFORMATION * var[i].max(r2))
        });
        kf.position_update(anchor, measured).is_some()
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::eskf::{Imu, align};

    const G: f64 = 9.81;

    /// A level filter (the MPU-9250's densities, 0.05 m/s^2 of accelerometer bias 1-sigma) and
    /// the still sensor's sample whose accelerometer reads `bias_x` m/s^2 along x.
    fn filter(bias_x: f64) -> (Eskf, Imu) {
        let up = Vector3::new(0.0, 0.0, G);
        let (x, cov) = align(
            up,
            Vector3::zeros(),
            G,
            Vector3::repeat(0.05),
            Vector3::repeat(1e-4),
        );
        let m = Imu {
            f: up + Vector3::new(bias_x, 0.0, 0.0),
            w: Vector3::zeros(),
        };
        (Eskf::new(x, cov, G, crate::eskf::tests::noise(), m), m)
    }

    /// 150 s at 100 Hz of a still sensor whose accelerometer reads a bias of 0.05 m/s^2 along
    /// x that the alignment did not see (a hand that never rests: no zero-velocity update),
    /// with the bound at `sigma_mps` (0: off). Returns the end's horizontal distance from the
    /// start and the reported position 1-sigma along x, m.
    fn drift(sigma_mps: f64) -> (f64, f64) {
        let (mut kf, m) = filter(0.05);
        let mut bound = HandBound::default();
        for i in 1..=15_000u64 {
            kf.predict(m, 0.01);
            bound.update(&mut kf, i * 10_000_000, false, sigma_mps);
        }
        kf.propagate();
        (kf.x.p.xy().norm(), kf.position_sigma().x)
    }

    #[test]
    fn a_hand_that_never_rests_drifts_as_a_random_walk_not_with_the_square_of_time() {
        // Free integration: b t^2 / 2 = 562 m.
        let (free, _) = drift(0.0);
        assert!((free - 562.5).abs() < 5.0, "{free}");
        // Bounded: the velocity is held to the hand's scale and the bias is learned from it.
        let (bounded, sigma) = drift(HAND_SPEED_SIGMA_MPS);
        assert!(bounded < 0.1 * free, "{bounded} m");
        assert!(bounded <= 3.0 * sigma, "{bounded} m, 1-sigma {sigma} m");
    }

    #[test]
    fn the_reach_measurement_leaves_the_conditional_variance_of_anchor_plus_drift() {
        // Independent computation: p = a + d with a ~ N(0, pa) (the anchor's error) and
        // d ~ N(0, dv) (the drift since), observed as y = d + h with h ~ N(0, r2) (the reach);
        // Var(p | y) is the Schur complement of the joint covariance of (p, y).
        for (pa, dv, r2) in [(1e-6, 4.0, 1.0), (400.0, 30.0, 1.0), (2.0, 1.5, 1.0)] {
            let joint = nalgebra::Matrix2::new(pa + dv, dv, dv, dv + r2);
            let conditional = joint[(0, 0)] - joint[(0, 1)] * joint[(1, 0)] / joint[(1, 1)];
            let pp = pa + dv;
            let v = reach_variance(pp, pa, r2).expect("drifted beyond the reach");
            // A scalar Kalman update of variance pp by a measurement of variance v.
            let updated = pp * v / (pp + v);
            assert!(
                (updated - conditional).abs() <= 1e-9 * conditional,
                "{pa} {dv} {r2}"
            );
            assert!(updated >= pa);
        }
        assert_eq!(
            reach_variance(0.5, 0.6, 1.0),
            None,
            "no growth since the anchor"
        );
    }

    #[test]
    fn a_hand_that_never_rests_stays_within_reach_of_its_anchor() {
        // The same unseen bias: the velocity bound alone leaves a random walk of metres.
        let (bounded, sigma) = drift(HAND_SPEED_SIGMA_MPS);
        assert!(bounded <= 3.0 * sigma, "{bounded} m, 1-sigma {sigma} m");
        assert!(
            bounded < 2.0 * REACH_SIGMA_M,
            "{bounded} m from the anchor, 1-sigma {sigma} m"
        );
        // The 1-sigma stays at the reach's scale: not shrunk by repeating the measurement.
        assert!(
            sigma > 0.5 * REACH_SIGMA_M && sigma < 3.0 * REACH_SIGMA_M,
            "{sigma}"
        );
    }

    #[test]
    fn brief_rest_flags_in_a_motion_keep_the_anchor_of_the_last_rest() {
        // A rest of 1 s, then 150 s of motion with a held sample of 0.1 s every 3 s (a
        // detector's brief flags in a slow motion): the velocity bound never starts, and the
        // reach, anchored at the rest, holds the position the unseen bias would carry away.
        let (mut kf, m) = filter(0.05);
        let mut bound = HandBound::default();
        for i in 1..=15_100u64 {
            let t = i * 10_000_000;
            kf.predict(m, 0.01);
            let held = i <= 100 || i % 300 < 10;
            bound.update(&mut kf, t, held, HAND_SPEED_SIGMA_MPS);
        }
        kf.propagate();
        let (end, sigma) = (kf.x.p.xy().norm(), kf.position_sigma().x);
        assert!(end < 2.0 * REACH_SIGMA_M, "{end} m, 1-sigma {sigma} m");
        assert!(end <= 3.0 * sigma, "{end} m, 1-sigma {sigma} m");
    }

    #[test]
    fn a_rest_or_a_hint_restarts_the_interval_and_no_sigma_is_off() {
        let (mut kf, _) = filter(0.0);
        let mut bound = HandBound::default();
        let s = 1_000_000_000;
        assert!(!bound.update(&mut kf, 0, false, 1.0));
        assert!(!bound.update(&mut kf, s / 2, true, 1.0));
        // A reach: a few seconds after the rest, no bound yet (checked once a second).
        for t in [3 * s / 2, 5 * s / 2, 9 * s / 2] {
            assert!(!bound.update(&mut kf, t, false, 1.0), "{t} ns");
        }
        assert!(
            bound.update(&mut kf, 11 * s / 2, false, 1.0),
            "5 s after the rest"
        );
        assert!(
            !bound.update(&mut kf, 6 * s, false, 1.0),
            "0.5 s after the bound"
        );
        assert!(
            bound.update(&mut kf, 13 * s / 2, false, 1.0),
            "1 s after the bound"
        );
        assert!(!bound.update(&mut kf, 8 * s, false, 0.0), "off");
    }
}
