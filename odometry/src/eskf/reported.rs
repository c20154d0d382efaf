//! The variance the published position and velocity 1-sigma carry beyond the filter's own
//! covariance: what the run's innovations say the covariance misses ([`crate::consistency`]).
//!
//! Why the report and not the filter (covariance matching, Mehra 1972; Mohamed & Schwarz
//! 1999): when the normalized innovations average `lambda` times their degrees of freedom, the
//! data say the noise is `lambda` times what the filter assumes. A filter whose process noise,
//! measurement noise and prior were all `lambda` times larger has the same gains, hence the
//! same estimates, and `lambda` times the covariance. So the consistent covariance of the
//! same estimates is `lambda P`; where `lambda` changes with time, the variance a propagation
//! adds is multiplied by the factor in force while it was added (position variance
//! accumulates: a factor on the whole `P` would rescale the past), and an update shrinks the
//! extra in the proportion it shrinks the filter's own variance (as it shrinks `lambda P`).
//! The consider parameters' share (`crate::eskf`'s module documentation) is scaled with the
//! rest: a filter whose consider variances were also `lambda` times larger has the same
//! estimates too, and the innovations cannot tell a noise from a systematic error (their
//! NIS is taken against the innovation's whole predicted covariance, the consider share
//! included). Kept per navigation axis (the diagonal): exact for a constant factor, the
//! diagonal's share of the scaled covariance otherwise. Estimates and gains are untouched.
//!
//! Units: position m^2, velocity (m/s)^2, navigation frame (z up).

use nalgebra::Vector3;

/// The extra variance and the factor in force.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reported {
    /// Factor on the variance propagations add (>= 1; 1: the filter's covariance as is).
    pub lambda: f64,
    /// Extra position variance, m^2 per axis.
    pub p: Vector3<f64>,
    /// Extra velocity variance, (m/s)^2 per axis.
    pub v: Vector3<f64>,
    /// Position variance of motion the filter took for rest, m^2 per axis: uncorrelated with
    /// the state, so no update (none measures position) shrinks it.
    pub hidden: Vector3<f64>,
    /// Position variance of a systematic error the filter does not hold as a state (an
    /// estimated mounting's yaw, [`crate::hints::ForwardFit`]), m^2 per axis: set whole by
    /// its owner, never grown or shrunk here.
    pub systematic: Vector3<f64>,
}

impl Default for Reported {
    fn default() -> Self {
        Self {
            lambda: 1.0,
            p: Vector3::zeros(),
            v: Vector3::zeros(),
            hidden: Vector3::zeros(),
            systematic: Vector3::zeros(),
        }
    }
}

/// Position and velocity variances (the covariance's diagonal with the consider share), m^2
/// and (m/s)^2.
pub type Diagonal = (Vector3<f64>, Vector3<f64>);

impl Reported {
    /// A propagation took the filter's variances from `before` to `after`: the extra grows by
    /// `lambda - 1` times what they grew.
    pub fn propagated(&mut self, before: &Diagonal, after: &Diagonal) {
        let k = self.lambda - 1.0;
        if k <= 0.0 {
            return;
        }
        self.p += (after.0 - before.0).map(|d| d.max(0.0)) * k;
        self.v += (after.1 - before.1).map(|d| d.max(0.0)) * k;
    }

    /// An update took the filter's variances from `before` to `after`: the extra shrinks in
    /// the same proportion.
    pub fn updated(&mut self, before: &Diagonal, after: &Diagonal) {
        let ratio = |a: f64, b: f64| {
            if b > 0.0 {
                (a / b).clamp(0.0, 1.0)
            } else {
                1.0
            }
        };
        self.p
            .zip_apply(&before.0.zip_map(&after.0, |b, a| ratio(a, b)), |x, r| {
                *x *= r
            });
        self.v
            .zip_apply(&before.1.zip_map(&after.1, |b, a| ratio(a, b)), |x, r| {
                *x *= r
            });
    }

    /// Adds `p` (m^2, to [`Self::hidden`]) and `v` ((m/s)^2) to the horizontal axes (x, y):
    /// motion the filter took for rest ([`crate::consistency`]).
    pub fn widen_horizontal(&mut self, p: [f64; 2], v: [f64; 2]) {
        for i in 0..2 {
            self.hidden[i] += p[i].max(0.0);
            self.v[i] += v[i].max(0.0);
        }
    }

    /// The extra position variance, m^2 per axis.
    pub fn position(&self) -> Vector3<f64> {
        self.p + self.hidden + self.systematic
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With a constant factor the extra is `(lambda - 1)` times the filter's variance through
    /// any sequence of propagations and updates that scale it (the scaled filter's).
    #[test]
    fn a_constant_factor_scales_the_variance() {
        let mut r = Reported {
            lambda: 4.0,
            ..Default::default()
        };
        let mut var: Diagonal = (Vector3::zeros(), Vector3::zeros());
        for step in 0..50 {
            let before = var;
            var.0 += Vector3::repeat(0.01 * f64::from(step));
            var.1 += Vector3::repeat(0.02);
            r.propagated(&before, &var);
            if step % 7 == 0 {
                let before = var;
                var.1 *= 0.1;
                var.0 *= 0.9;
                r.updated(&before, &var);
            }
        }
        assert!((r.p - var.0 * 3.0).norm() < 1e-12 * var.0.norm());
        assert!((r.v - var.1 * 3.0).norm() < 1e-12 * var.1.norm());
    }

    /// The extra is what the variance grew by while the factor held, not the factor on the
    /// whole variance.
    #[test]
    fn a_factor_applies_to_the_variance_grown_while_it_held() {
        let mut r = Reported::default();
        let z = Vector3::zeros();
        r.propagated(&(z, z), &(Vector3::repeat(1.0), z));
        r.lambda = 3.0;
        r.propagated(&(Vector3::repeat(1.0), z), &(Vector3::repeat(1.5), z));
        assert_eq!(r.p, Vector3::repeat(1.0));
    }
}
