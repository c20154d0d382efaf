//! What the filter does with input it cannot take at its word (the rules:
//! `ipc_types::stream::range` and `ipc_types::stream::plausible`):
//!
//! - An **implausible** sample (`corrected_flags::IMPLAUSIBLE`) is not a measurement: the
//!   filter holds the previous sample's reading across it and bridges its interval as
//!   unobserved, as a gap (`Eskf::unobserved`: a run of them ends as wide as one gap of its
//!   length).
//! - A **clipped** axis (`corrected_flags::CLIPPED`, which axes: `raw_flags::SATURATED_AXES`)
//!   read less than the truth, by an amount not seen: the reading is integrated (the least the
//!   platform did) and the unseen excess widens the 1-sigma (`Eskf::clipped`), with a
//!   1-sigma of what the profile's manoeuvre (`OdometryConfig::manoeuvre`: `accel` m/s^2,
//!   `rate` rad/s) reaches beyond the reading, and at least a quarter of the reading (a part's
//!   ranges step by factors of two). The excess persists through a clip, so the widening is
//!   that of a fully correlated error: after `n` clipped samples the unseen velocity (or
//!   rotation) has the 1-sigma `n excess dt`. A gyroscope clip on a foot turns it about a
//!   horizontal axis: a tilt error that the next rest's gravity shows, and the rest's updates
//!   take back through the widened covariance. A gyroscope clip is also reconstructed once
//!   the rest after it has measured it ([`crate::clip`]).
//!
//! The state of every sample where either happened carries `odometry_flags::UNTRUSTED_INPUT`.
//! `OdometryConfig::trust_untrusted` integrates both as measured (for comparison).

use ipc_types::{CorrectedImuSample, corrected_flags, raw_flags};

use crate::config::OdometryConfig;
use crate::eskf::{Eskf, Imu};

/// What a sample's flags say about its trust.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Verdict {
    /// Not a measurement.
    pub implausible: bool,
    /// `raw_flags::SATURATED_AXES` bits of the clipped axes.
    pub clipped: u16,
}

impl Verdict {
    /// The verdict on `s` under `cfg` (nothing when `cfg.trust_untrusted`).
    pub fn of(s: &CorrectedImuSample, cfg: &OdometryConfig) -> Self {
        if cfg.trust_untrusted {
            return Self::default();
        }
        let clipped = if s.flags & corrected_flags::CLIPPED != 0 {
            // A clipped sample from a source that did not say which axes: all of them.
            match s.raw_flags & raw_flags::SATURATED_AXES {
                0 => raw_flags::SATURATED_AXES,
                bits => bits,
            }
        } else {
            0
        };
        Self {
            implausible: s.flags & corrected_flags::IMPLAUSIBLE != 0,
            clipped,
        }
    }

    /// Whether the sample is not taken at its word.
    pub fn untrusted(&self) -> bool {
        self.implausible || self.clipped != 0
    }
}

/// The untrusted stretches in progress.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Untrusted {
    /// Length of the current run of implausible samples, s.
    unobserved_s: f64,
    /// Consecutive clipped samples per axis (accelerometer x, y, z, gyroscope x, y, z).
    run: [u32; 6],
}

impl Untrusted {
    /// Widens `kf` for the sample just predicted (reading `m`, interval `dt` s) as `v` says;
    /// returns whether the sample was untrusted.
    pub fn widen(
        &mut self,
        kf: &mut Eskf,
        m: &Imu,
        dt: f64,
        v: Verdict,
        cfg: &OdometryConfig,
    ) -> bool {
        if v.implausible {
            let t0 = self.unobserved_s;
            self.unobserved_s += dt;
            kf.unobserved(t0, self.unobserved_s, &cfg.manoeuvre);
        } else {
            self.unobserved_s = 0.0;
        }
        let mut var = [0.0; 6];
        for (i, (run, var)) in self.run.iter_mut().zip(&mut var).enumerate() {
            if v.implausible || v.clipped & raw_flags::saturated_axis(i) == 0 {
                *run = 0;
                continue;
            }
            *run += 1;
            let (reading, reach) = if i < 3 {
                (m.f[i].abs(), cfg.manoeuvre.accel)
            } else {
                (m.w[i - 3].abs(), cfg.manoeuvre.rate)
            };
            // Fully correlated through the clip: the n-th sample takes the variance from
            // ((n - 1) excess dt)^2 to (n excess dt)^2.
            let excess = (reach - reading).max(reading / 4.0);
            *var = f64::from(2 * *run - 1) * (excess * dt).powi(2);
        }
        if v.clipped != 0 && !v.implausible {
            kf.clipped(&var);
        }
        v.untrusted()
    }
}
