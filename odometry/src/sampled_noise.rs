//! The error of integrating the samples as the stream shows it: how far each sample of the
//! specific force and the rate lies from the straight line through its two neighbours.
//!
//! The filter's prediction integrates the readings by the trapezoid rule, i.e. as if the
//! signal ran straight from one sample to the next ([`crate::eskf::Eskf::predict`]). Whatever
//! the samples do not resolve (a chassis's vibration, a motor's, the jolts of a car sliding
//! at 18-30 Hz) is an integration error the white noise of the part's datasheet does not
//! hold: on the F1TENTH car of docs/real-data.md the specific force scatters 1.1-3.5 m/s^2 per
//! sample while driving against 0.1-0.2 m/s^2 standing, a hundred times the MPU-9250
//! datasheet's density, and a filter that keeps the datasheet's figure believes its velocity
//! to a few centimetres per second while it is metres per second off.
//!
//! The measure: sample `k`'s deviation `r_k = x_k - ((1 - a) x_{k-1} + a x_{k+1})` from the
//! linear interpolation of its neighbours at its time (`a = (t_k - t_{k-1}) / (t_{k+1} -
//! t_{k-1})`, irregular steps allowed). For independent errors of variance `s^2` per sample,
//! `E[r_k^2] = s^2 (1 + (1 - a)^2 + a^2)` (1.5 `s^2` at equal steps: the mean square successive
//! difference, von Neumann et al., "Distribution of the ratio of the mean square successive
//! difference to the variance", Ann. Math. Statist. 12(4), 1941), so `r_k^2` over that factor
//! estimates `s^2` whatever the steps. A smooth motion leaves no residual: a turn's rate or a
//! braking's deceleration changing linearly over three samples is not counted. The per-axis
//! mean over the three axes of the last [`TIME_CONSTANT_S`] (exponential weights) is the
//! sample's standard deviation, and the prediction adds `s^2 dt^2` per sample to the velocity's
//! (and, for the rate, the attitude's) variance where that exceeds the datasheet's share
//! (`eskf::NoiseModel`; taken as the larger, not added, so the part's white noise, which the
//! residual also holds, is not counted twice).

use nalgebra::Vector3;

/// The exponential window's time constant, s: a second of driving, long enough to average a
/// 18 Hz stream's residuals and short enough to follow a stop.
pub const TIME_CONSTANT_S: f64 = 1.0;

/// One sample: time (ns), specific force (m/s^2) and rate (rad/s), sensor frame.
type Sample = (u64, Vector3<f64>, Vector3<f64>);

/// The running per-sample scatter of the specific force and the rate (see the module
/// documentation).
#[derive(Debug, Clone, Copy, Default)]
pub struct SampledNoise {
    /// The two samples before the newest one's predecessor, oldest first.
    older: Option<Sample>,
    newer: Option<Sample>,
    /// Exponentially weighted mean of the per-axis variance estimates, (m/s^2)^2 and
    /// (rad/s)^2; `None` before the first residual.
    var: Option<(f64, f64)>,
}

impl SampledNoise {
    /// Takes the next sample; the residual of the previous one (its neighbours now known)
    /// joins the running variances. Samples out of time order or at an equal time restart
    /// the neighbours.
    pub fn push(&mut self, t_ns: u64, f: &Vector3<f64>, w: &Vector3<f64>) {
        if self.newer.is_some_and(|(t, _, _)| t_ns <= t) {
            (self.older, self.newer) = (None, None);
        }
        if let (Some((t0, f0, w0)), Some((t1, f1, w1))) = (self.older, self.newer) {
            let span = (t_ns - t0) as f64;
            let a = (t1 - t0) as f64 / span;
            let factor = 1.0 + (1.0 - a).powi(2) + a * a;
            let per_axis = |x0: &Vector3<f64>, x1: &Vector3<f64>, x2: &Vector3<f64>| {
                (x1 - (x0 * (1.0 - a) + x2 * a)).norm_squared() / (3.0 * factor)
            };
            let (va, vw) = (per_axis(&f0, &f1, f), per_axis(&w0, &w1, w));
            let weight = ((t_ns - t1) as f64 * 1e-9 / TIME_CONSTANT_S).min(1.0);
            self.var = Some(match self.var {
                None => (va, vw),
                Some((a0, w0)) => (a0 + (va - a0) * weight, w0 + (vw - w0) * weight),
            });
        }
        (self.older, self.newer) = (self.newer, Some((t_ns, *f, *w)));
    }

    /// The per-sample standard deviation of the specific force (m/s^2) and of the rate
    /// (rad/s), per axis; zeros before the first residual.
    pub fn sd(&self) -> (f64, f64) {
        self.var.map_or((0.0, 0.0), |(a, w)| (a.sqrt(), w.sqrt()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Uniform in [-1, 1), from a seeded generator (deterministic).
    fn uniform(rng: &mut ChaCha8Rng) -> f64 {
        rng.random_range(-1.0..1.0)
    }

    #[test]
    fn a_smooth_motion_at_irregular_steps_leaves_no_scatter() {
        let mut n = SampledNoise::default();
        let mut state = ChaCha8Rng::seed_from_u64(7);
        let mut t = 0.0;
        for _ in 0..200 {
            // 18-30 Hz steps; specific force and rate changing linearly with time.
            t += 0.033 + 0.01 * uniform(&mut state);
            let f = Vector3::new(1.0 + 0.5 * t, -0.2 * t, 9.8);
            let w = Vector3::new(0.0, 0.0, 0.3 - 0.1 * t);
            n.push((t * 1e9) as u64, &f, &w);
        }
        let (a, w) = n.sd();
        assert!(a < 1e-6 && w < 1e-6, "{a} {w}");
    }

    #[test]
    fn independent_errors_give_their_standard_deviation_at_irregular_steps() {
        let mut n = SampledNoise::default();
        let mut state = ChaCha8Rng::seed_from_u64(11);
        let mut t = 0.0;
        // Uniform errors of half-width h: standard deviation h / sqrt(3).
        let (h_a, h_w) = (2.0, 0.1);
        let (mut sum_a, mut sum_w, mut k) = (0.0, 0.0, 0.0);
        for i in 0..20_000 {
            t += 0.04 + 0.015 * uniform(&mut state);
            let e =
                |h: f64, s: &mut ChaCha8Rng| Vector3::new(uniform(s), uniform(s), uniform(s)) * h;
            let f = Vector3::new(0.0, 0.0, 9.8) + e(h_a, &mut state);
            let w = Vector3::new(0.0, 0.0, 1.0) + e(h_w, &mut state);
            n.push((t * 1e9) as u64, &f, &w);
            if i > 100 {
                let (a, w) = n.sd();
                (sum_a, sum_w, k) = (sum_a + a * a, sum_w + w * w, k + 1.0);
            }
        }
        let (sd_a, sd_w) = ((sum_a / k).sqrt(), (sum_w / k).sqrt());
        let (want_a, want_w) = (h_a / 3f64.sqrt(), h_w / 3f64.sqrt());
        assert!((sd_a / want_a - 1.0).abs() < 0.03, "{sd_a} {want_a}");
        assert!((sd_w / want_w - 1.0).abs() < 0.03, "{sd_w} {want_w}");
    }

    #[test]
    fn a_repeated_time_restarts_the_neighbours() {
        let mut n = SampledNoise::default();
        let f = Vector3::new(0.0, 0.0, 9.8);
        for t in [1, 2, 2, 3] {
            n.push(t, &f, &Vector3::zeros());
        }
        assert_eq!(n.sd(), (0.0, 0.0));
    }
}
