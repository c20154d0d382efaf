//! The speed hints' unknown time against the IMU's, as noise of the speed they give.
//!
//! A wheel speed is not an instant's: a count of encoder ticks over the controller's window is
//! the mean speed over that window (its centre half a window before its stamp), a motor
//! controller's speed is filtered, and a stamp taken on receipt (a ROS driver's) adds the
//! transport. The speed a hint gives therefore describes the motion at a time known only to
//! about one hint period `T` of its stamp: on the F1TENTH car of docs/real-data.md the VESC's
//! speed leads its IMU's forward acceleration by 0.02-0.08 s at a period of 0.041 s, and a
//! counting encoder lags by `T / 2` by construction. A time error `tau` makes the speed wrong
//! by `tau a`, `a` the forward acceleration (first order), which the hint's own 1-sigma (its
//! per-hint white part: quantisation, slip) leaves out; and since the scale state `k` is
//! learnt from the speed's changes (`crate::eskf`), errors that grow with the acceleration
//! are the ones the scale takes up. So each speed hint's forward variance gets `T^2 a^2` with
//! `T` the hints' own period: a time uncertainty turned into a measurement uncertainty through
//! the measurement's rate of change, as for the aperture jitter of a sampled signal (W. Kester,
//! "Aperture Time, Aperture Jitter, Aperture Delay Time - Removing the Confusion", Analog
//! Devices tutorial MT-007, 2009: the error is the signal's slope times the time error).
//! White hint by hint, this still takes an offset that lasts a whole speed change for
//! independent errors; the offset as a state of the filter (M. Li and A. I. Mourikis,
//! "Online temporal calibration for camera-IMU systems", IJRR 33(7), 2014) would not.
//!
//! The acceleration is the hints' own, their speed's change over the two latest periods; its
//! squared estimate has the changes' white noise taken out (its expected share,
//! `(sigma_k^2 + sigma_{k-2}^2) / dt^2`, as for the regression dilution of
//! `crate::cruise::ForwardAxis`), so hints read at rest or cruise add nothing. Units: s, m/s,
//! m/s^2; the speed is the body's forward one, as the hints give it.

/// The latest speed hints' times and speeds, for [`LagNoise::variance`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LagNoise {
    /// The two speed hints before the newest: (time, ns; speed, m/s; its 1-sigma, m/s), the
    /// older first.
    previous: [Option<(u64, f64, f64)>; 2],
}

impl LagNoise {
    /// Takes a speed hint (`t_ns` the time it describes, `speed` and its 1-sigma `sigma`,
    /// m/s) and returns the variance its unknown time adds to its speed, (m/s)^2: `T^2 a^2`
    /// with `T` the mean period over the two latest intervals and `a^2` the squared
    /// acceleration over them less its expected noise (module documentation). Zero for the
    /// first two hints, and after a gap longer than `max_gap_ns` (the hints went stale: the
    /// acceleration over it is not the motion's at the hint's time).
    pub fn variance(&mut self, t_ns: u64, speed: f64, sigma: f64, max_gap_ns: u64) -> f64 {
        let [older, newer] = self.previous;
        let recent = |p: Option<(u64, f64, f64)>, t: u64| {
            p.filter(|(tp, _, _)| *tp < t && t - tp <= max_gap_ns)
        };
        let var = match (recent(older, newer.map_or(0, |n| n.0)), recent(newer, t_ns)) {
            (Some((t0, s0, sigma0)), Some(_)) => {
                let span_s = (t_ns - t0) as f64 * 1e-9;
                let a = (speed - s0) / span_s;
                let noise = (sigma * sigma + sigma0 * sigma0) / (span_s * span_s);
                let period_s = 0.5 * span_s;
                period_s * period_s * (a * a - noise).max(0.0)
            }
            _ => 0.0,
        };
        self.previous = match recent(newer, t_ns) {
            Some(n) => [Some(n), Some((t_ns, speed, sigma))],
            None => [None, Some((t_ns, speed, sigma))],
        };
        var
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn a_steady_acceleration_adds_its_change_over_a_period() {
        // 40 ms apart, accelerating at 2 m/s^2, noiseless (sigma tiny): T a = 0.08 m/s.
        let mut lag = LagNoise::default();
        let mut last = 0.0;
        for i in 0..5u64 {
            let t = 1000 * MS + i * 40 * MS;
            last = lag.variance(t, 1.0 + 2.0 * (i as f64) * 0.04, 1e-9, 250 * MS);
            if i < 2 {
                assert_eq!(last, 0.0);
            }
        }
        assert!((last.sqrt() - 0.08).abs() < 1e-6, "{}", last.sqrt());
    }

    #[test]
    fn noise_alone_and_a_gap_add_nothing() {
        let mut lag = LagNoise::default();
        // A cruise read with noise smaller than its 1-sigma: the change is within its noise.
        let speeds = [1.0, 1.03, 0.98, 1.02, 0.99];
        for (i, s) in speeds.iter().enumerate() {
            let t = 1000 * MS + i as u64 * 40 * MS;
            assert_eq!(lag.variance(t, *s, 0.05, 250 * MS), 0.0);
        }
        // A jump after a gap beyond the maximum: no acceleration taken over the gap.
        assert_eq!(lag.variance(5000 * MS, 3.0, 0.001, 250 * MS), 0.0);
        assert_eq!(lag.variance(5040 * MS, 3.0, 0.001, 250 * MS), 0.0);
        assert!(lag.variance(5080 * MS, 3.2, 0.001, 250 * MS) > 0.0);
    }
}
