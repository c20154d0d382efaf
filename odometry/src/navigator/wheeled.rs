//! The navigator's checks of a wheeled platform without speed hints (`crate::nonholonomic`):
//! a rest flag the filter's velocity contradicts, and the along-track drift's share of the
//! published 1-sigma.

use ipc_types::{hint_flags, odometry_flags};

use super::Navigator;
use super::hint_state::{HintDecision, HintSample};

/// A rest flag is refused when the filter's horizontal velocity lies beyond this many of its
/// published 1-sigma (with the zero-velocity update's) from zero: the hints' fallback gate
/// (`HintConfig::fallback_zupt_gate_sigma`'s default). At 3, a simulated car on a level road
/// (docs/detectors.md, "Short rests", seed 1) had its real stops refused while the filter held
/// its speed far off, and drove on for kilometres.
pub const REST_GATE_SIGMA: f64 = 5.0;

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
        let Some(kf) = self.kf.as_ref() else {
            return false;
        };
        let sigma = kf.velocity_sigma();
        let moving =
            (0..2).any(|i| kf.x.v[i].abs() > REST_GATE_SIGMA * sigma[i].hypot(self.zupt_sigma_mps));
        if moving {
            hs.flags |= odometry_flags::REST_MOVING;
        }
        moving
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
