//! Double integration of acceleration to velocity and displacement with the trapezoid rule on
//! the recorded (irregular) sample times, as the thesis did (`cumulative_trapezoid` twice).
//!
//! Units: times in seconds, acceleration m/s^2, velocity m/s, displacement m; the integration
//! starts at rest (zero velocity and displacement at the first sample).

/// Streaming trapezoid double integrator (no allocation per sample).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DoubleIntegrator {
    last: Option<(f64, [f64; 3])>,
    velocity: [f64; 3],
    displacement: [f64; 3],
}

impl DoubleIntegrator {
    /// An integrator at rest with no sample yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the acceleration `a` (m/s^2) at time `t_s` (s, increasing). The first sample only
    /// sets the starting point.
    pub fn push(&mut self, t_s: f64, a: [f64; 3]) {
        if let Some((t0, a0)) = self.last {
            let dt = t_s - t0;
            for i in 0..3 {
                let v1 = self.velocity[i] + 0.5 * (a0[i] + a[i]) * dt;
                self.displacement[i] += 0.5 * (self.velocity[i] + v1) * dt;
                self.velocity[i] = v1;
            }
        }
        self.last = Some((t_s, a));
    }

    /// Velocity since the first sample, m/s.
    pub fn velocity(&self) -> [f64; 3] {
        self.velocity
    }

    /// Displacement since the first sample, m.
    pub fn displacement(&self) -> [f64; 3] {
        self.displacement
    }
}

/// Final displacement (m) of an acceleration series (m/s^2) at times `t_s` (s), starting at rest.
///
/// # Panics
/// If the slices differ in length.
pub fn displacement(t_s: &[f64], accel: &[[f64; 3]]) -> [f64; 3] {
    assert_eq!(t_s.len(), accel.len(), "one time per sample");
    let mut integ = DoubleIntegrator::new();
    for (t, a) in t_s.iter().zip(accel) {
        integ.push(*t, *a);
    }
    integ.displacement()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_acceleration_is_exact() {
        // The trapezoid rule is exact for linear velocity and, applied to it, gives
        // d = a T^2 / 2 exactly for a constant a, even on irregular times.
        let t: Vec<f64> = (0..200)
            .map(|k| 0.01 * k as f64 + 0.003 * ((k * 7) % 5) as f64)
            .collect();
        let a = vec![[0.5, -1.0, 2.0]; t.len()];
        let d = displacement(&t, &a);
        let tt = t[t.len() - 1] - t[0];
        for i in 0..3 {
            assert!((d[i] - 0.5 * a[0][i] * tt * tt).abs() < 1e-12);
        }
    }

    #[test]
    fn linear_acceleration_converges_with_second_order_error() {
        // a = t: d(T) = T^3 / 6. The trapezoid error halves twice per halving of dt.
        let err = |n: usize| {
            let t: Vec<f64> = (0..=n).map(|k| k as f64 / n as f64).collect();
            let a: Vec<[f64; 3]> = t.iter().map(|&x| [x, 0.0, 0.0]).collect();
            (displacement(&t, &a)[0] - 1.0 / 6.0).abs()
        };
        let (e1, e2) = (err(100), err(200));
        assert!(e1 > 0.0 && (e1 / e2 - 4.0).abs() < 0.1, "{e1} {e2}");
    }
}
