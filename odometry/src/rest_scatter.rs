//! The gyroscope's scatter at rest as the rests show it, for the zero-rate update's sigma.
//!
//! The zero-rate update takes a rest window's mean angular rate as a measurement of the gyro
//! bias. With the datasheet's white noise as its sigma it holds only where the part stands in
//! its own noise. A car standing with its engine running shakes its sensor in rotation too:
//! wid-car-06's gyroscope scatters 0.37-0.53 deg/s per sample and axis at its stop (120 Hz),
//! against 0.11 deg/s for the MPU-9250 datasheet's density at that rate (0.01 deg/s/sqrt(Hz),
//! InvenSense PS-MPU-9250A-01 rev. 1.1, "Gyroscope specifications", the profile's figure for a
//! recording without a noise table). Gated at 5 of those 0.11 deg/s, the update took the
//! 40 % of the samples that lay near the bias it already held and refused the others, and that
//! selection walked the bias state's z from 0.27 to 0.33 deg/s over the stop (from 0.06 to
//! 0.24 over the standing at the start) while the readings there averaged 0.01 deg/s, with
//! a 1-sigma of 0.002 deg/s: the heading turned 13 deg in the stop's 35 s. With the rests'
//! own scatter as its sigma every sample is taken, the bias comes back towards the readings'
//! mean (0.24 to 0.19 over the stop) and the heading turns 2 deg.
//!
//! On wheeled platforms, and on any platform until `--profile auto` has recognized it
//! ([`crate::config::OdometryConfig::rest_rate_scatter`]); not on a foot or a hand: on the
//! real-data bench's feet and hand-held phones the rests' scatter, taken as the sigma, moved
//! the errors the wrong way (foot median 0.42 to 0.58 % of distance). Before recognition the
//! same selection acts on the standing before the first motion: wid-car-06, recognized as
//! wheeled only after 10 s of motion, stands 1.2-10.5 s before its drive with its corrected
//! rates averaging 0.00 +- 0.05 deg/s per axis (0.25 s means), yet the datasheet-sigma update
//! walked the bias state from (-0.06, -0.10, +0.04) to (-0.30, -0.33, +0.27) deg/s (1-sigma
//! 0.004). The attitude integrates that error; a calibrated prior's zero-velocity updates pull
//! the tilt back, but under the uncalibrated prior (0.98 m/s^2 across gravity, as likely as
//! 5.7 deg of tilt) the bias across gravity absorbs it, and the pitch walked -0.2 to +6.4 deg
//! with the bias following (`mems-odometry offline --input wid-car-06.csv --uncalibrated`,
//! identity calibration). With the scatter the bias stays within 0.001 deg/s of the readings'
//! mean, the pitch at -0.2 deg, and the stop after the drive is a rest again.
//!
//! [`RestScatter`] keeps the per-sample variance of the rest samples' rate about the filter's
//! bias, per axis averaged over the three, in (rad/s)^2 (sensor frame; no sign convention
//! involved), exponentially weighted over the last [`TIME_CONSTANT_S`] of rest samples. The
//! zero-rate update's per-sample sigma is the larger of that scatter's and the datasheet's.

use nalgebra::Vector3;

/// The exponential window's time constant over rest samples, s: a second, the span over
/// which an engine's idle is steady.
pub const TIME_CONSTANT_S: f64 = 1.0;

/// Exponentially weighted variance of the rest samples' rate about the bias.
#[derive(Debug, Clone, Copy, Default)]
pub struct RestScatter {
    /// Weighted mean of the squared deviation, (rad/s)^2 per axis.
    var: f64,
    /// Sum of the weights (1 once the window is full), for the start's bias correction.
    weight: f64,
}

impl RestScatter {
    /// Adds one rest sample: `deviation` is its rate less the filter's bias, rad/s, `dt_s` its
    /// interval.
    pub fn push(&mut self, deviation: &Vector3<f64>, dt_s: f64) {
        let a = (dt_s / TIME_CONSTANT_S).clamp(0.0, 1.0);
        self.var += a * (deviation.norm_squared() / 3.0 - self.var);
        self.weight += a * (1.0 - self.weight);
    }

    /// The per-sample standard deviation, rad/s, or 0 before any rest sample.
    pub fn sd(&self) -> f64 {
        if self.weight > 0.0 {
            (self.var / self.weight).sqrt()
        } else {
            0.0
        }
    }

    /// The per-sample standard deviation the zero-rate update takes under `cfg`, rad/s:
    /// [`Self::sd`] where `cfg.rest_rate_scatter` says the platform's rests may shake, else 0.
    pub fn taken_sd(&self, cfg: &crate::config::OdometryConfig) -> f64 {
        if cfg.rest_rate_scatter {
            self.sd()
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against the sample standard deviation of a sequence computed directly: alternating
    /// +-s on every axis has a variance of s^2 per axis about a zero bias.
    #[test]
    fn alternating_rate_gives_its_amplitude() {
        let s = 0.008;
        let mut r = RestScatter::default();
        for k in 0..1200 {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            r.push(&Vector3::repeat(sign * s), 1.0 / 120.0);
        }
        assert!((r.sd() - s).abs() < 1e-9 * s.max(1.0), "{}", r.sd());
        assert_eq!(RestScatter::default().sd(), 0.0);
    }
}
