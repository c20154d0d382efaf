//! Values no platform could make: the plausibility test of the stream contract, beyond the
//! part's range ([`crate::limits`] bounds what a part can output; this bounds what the platform
//! it is mounted on can do).
//!
//! A calibrated sample (m/s^2, rad/s, sensor frame) is **implausible** when
//! - its specific force's magnitude exceeds the profile's peak `peak_force_mps2` (the
//!   hardest shock any platform of the profile gives the sensor), or its rate's magnitude
//!   `peak_rate_rps`: an isolated spike of 19.99 g on a vehicle; or
//! - the magnitude's deviation from gravity, averaged over `sustained_s` (an exponential mean
//!   with that time constant, of the samples that passed the peak test), exceeds
//!   `sustained_force_mps2`: a force held longer than any manoeuvre of the profile holds it.
//!   The test is causal: the first samples of such a stretch pass until the mean crosses.
//!
//! The odometry stage applies it with its profile's [`Envelope`], marks the sample
//! `corrected_flags::IMPLAUSIBLE` and counts it; its filter does not integrate the sample but
//! bridges its interval as unobserved.

/// What the platforms of a profile can do to the sensor (SI units, magnitudes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Envelope {
    /// Largest specific force magnitude, m/s^2.
    pub peak_force_mps2: f64,
    /// Largest angular rate magnitude, rad/s.
    pub peak_rate_rps: f64,
    /// Largest deviation of the specific force magnitude from gravity held over
    /// `sustained_s`, m/s^2.
    pub sustained_force_mps2: f64,
    /// Time constant of the mean the sustained test takes, s.
    pub sustained_s: f64,
}

/// Why a sample is implausible.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Implausible {
    /// The specific force's magnitude, m/s^2, beyond the peak.
    PeakForce(f64),
    /// The rate's magnitude, rad/s, beyond the peak.
    PeakRate(f64),
    /// The mean deviation from gravity, m/s^2, beyond the sustained bound.
    Sustained(f64),
}

impl std::fmt::Display for Implausible {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::PeakForce(v) => {
                write!(f, "specific force {v:.1} m/s^2 beyond the profile's peak")
            }
            Self::PeakRate(v) => write!(f, "rate {v:.1} rad/s beyond the profile's peak"),
            Self::Sustained(v) => write!(
                f,
                "specific force {v:.1} m/s^2 from gravity held longer than the profile holds one"
            ),
        }
    }
}

/// The test's state over one stream: the mean of the force magnitude.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plausibility {
    envelope: Envelope,
    gravity_mps2: f64,
    mean: Option<(u64, f64)>,
}

impl Plausibility {
    /// The test for `envelope` under local gravity `gravity_mps2`.
    pub fn new(envelope: Envelope, gravity_mps2: f64) -> Self {
        Self {
            envelope,
            gravity_mps2,
            mean: None,
        }
    }

    /// Tests the sample at `t_ns` with specific force `f` (m/s^2) and rate `w` (rad/s).
    pub fn check(&mut self, t_ns: u64, f: &[f64; 3], w: &[f64; 3]) -> Option<Implausible> {
        let e = &self.envelope;
        let norm = |v: &[f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let (force, rate) = (norm(f), norm(w));
        if force > e.peak_force_mps2 {
            return Some(Implausible::PeakForce(force));
        }
        if rate > e.peak_rate_rps {
            return Some(Implausible::PeakRate(rate));
        }
        let mean = match self.mean {
            Some((t0, m)) => {
                let dt = t_ns.saturating_sub(t0) as f64 * 1e-9;
                m + (force - m) * (dt / e.sustained_s).min(1.0)
            }
            None => force,
        };
        self.mean = Some((t_ns, mean));
        let deviation = (mean - self.gravity_mps2).abs();
        (deviation > e.sustained_force_mps2).then_some(Implausible::Sustained(deviation))
    }

    /// Forgets the mean (a new session).
    pub fn restart(&mut self) {
        self.mean = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const G: f64 = 9.81;

    fn envelope() -> Envelope {
        Envelope {
            peak_force_mps2: 16.0 * G,
            peak_rate_rps: 35.0,
            sustained_force_mps2: 8.0 * G,
            sustained_s: 0.5,
        }
    }

    #[test]
    fn a_spike_beyond_the_peak_is_implausible_and_leaves_the_mean_alone() {
        let mut p = Plausibility::new(envelope(), G);
        let rest = [0.0, 0.0, G];
        for k in 0..100u64 {
            assert_eq!(p.check(k * 5_000_000, &rest, &[0.0; 3]), None);
        }
        let spike = [19.99 * G, 0.0, G];
        assert!(matches!(
            p.check(500_000_000, &spike, &[0.0; 3]),
            Some(Implausible::PeakForce(_))
        ));
        assert_eq!(p.check(505_000_000, &rest, &[0.0; 3]), None);
        assert!(matches!(
            p.check(510_000_000, &rest, &[40.0, 0.0, 0.0]),
            Some(Implausible::PeakRate(_))
        ));
    }

    #[test]
    fn a_held_force_below_the_peak_is_implausible_once_the_mean_crosses() {
        let mut p = Plausibility::new(envelope(), G);
        let held = [12.0 * G, 0.0, 0.0];
        let flagged: Vec<bool> = (0..200u64)
            .map(|k| p.check(k * 5_000_000, &held, &[0.0; 3]).is_some())
            .collect();
        // The first sample sets the mean: 12 g is 11 g from gravity, beyond 8 g at once.
        assert!(flagged.iter().all(|f| *f));
        // A foot strike: 10 g for 20 ms, then rest: plausible.
        let mut p = Plausibility::new(envelope(), G);
        for k in 0..200u64 {
            let f = if (100..104).contains(&k) {
                [10.0 * G, 0.0, G]
            } else {
                [0.0, 0.0, G]
            };
            assert_eq!(p.check(k * 5_000_000, &f, &[0.0; 3]), None, "sample {k}");
        }
    }
}
