//! The displacement floor: how far double integration of a static record drifts from noise
//! alone once the bias is removed perfectly, predicted from the noise parameters and measured
//! on a record.
//!
//! Removing the record's own mean specific force `abar` over `[0, T]` and integrating twice
//! gives `p(T) = int_0^T (T/2 - t) a(t) dt` (the weight integrates to zero, so any constant
//! bias cancels). Its variance for the three noise terms (two-sided spectra
//! `N^2`, `B^2 / (2 pi f)`, and `K^2 / (2 pi f)^2`) is
//! - white: `N^2 int (T/2 - t)^2 dt = N^2 T^3 / 12`;
//! - flicker: `B^2 T^4 int |F(u)|^2 / (2 pi |u|) du = B^2 T^4 / (16 pi)`, where
//!   `|F(u)|^2 = ((sin x - x cos x) / x^2)^2 / 4`, `x = pi u`, is the weight's spectrum on a
//!   unit interval and `int_0^inf (sin x - x cos x)^2 / x^5 dx = 1/4`;
//! - random walk: `K^2 int_0^T (t (T - t) / 2)^2 dt = K^2 T^5 / 120`.
//!
//! The terms are independent, so the variances add. Units: `N` in m/s^2/sqrt(Hz), `B` in m/s^2,
//! `K` in m/s^3/sqrt(Hz), `T` in s, the result in m (1-sigma, per axis).

use ipc_types::RawImuSample;

/// 1-sigma displacement (m) after `t_s` seconds of double integration of a static record
/// whose mean over those seconds was removed, for white noise `n`, bias instability `b` and
/// rate random walk `k` (see the module documentation for units).
pub fn static_displacement_sigma(n: f64, b: f64, k: f64, t_s: f64) -> f64 {
    let white = n * n * t_s.powi(3) / 12.0;
    let flicker = b * b * t_s.powi(4) / (16.0 * std::f64::consts::PI);
    let walk = k * k * t_s.powi(5) / 120.0;
    (white + flicker + walk).sqrt()
}

/// Displacement (m) at the end of a series of specific force `values` (m/s^2) at `times_s`,
/// after removing its time-weighted mean and integrating twice with the trapezoid rule on the
/// given times (which need not be uniform). Needs at least two samples.
pub fn detrended_displacement(times_s: &[f64], values: &[f64]) -> f64 {
    assert_eq!(times_s.len(), values.len(), "one time per value");
    displacement(|i| times_s[i], values)
}

/// [`detrended_displacement`] with times in integer nanoseconds (any origin).
pub fn detrended_displacement_ns(times_ns: &[u64], values: &[f64]) -> f64 {
    assert_eq!(times_ns.len(), values.len(), "one time per value");
    let t0 = times_ns[0];
    displacement(|i| (times_ns[i] - t0) as f64 * 1e-9, values)
}

/// The work of [`detrended_displacement`], times given by index.
fn displacement(time: impl Fn(usize) -> f64, values: &[f64]) -> f64 {
    let n = values.len();
    assert!(n >= 2, "at least two samples");
    let duration = time(n - 1) - time(0);
    let area: f64 = (1..n)
        .map(|i| 0.5 * (values[i - 1] + values[i]) * (time(i) - time(i - 1)))
        .sum();
    let mean = area / duration;
    let (mut velocity, mut position) = (0.0, 0.0);
    for i in 1..n {
        let dt = time(i) - time(i - 1);
        let next = velocity + 0.5 * ((values[i - 1] - mean) + (values[i] - mean)) * dt;
        position += 0.5 * (velocity + next) * dt;
        velocity = next;
    }
    position
}

/// [`detrended_displacement`] of each accelerometer axis of a recording (sensor frame, m), with
/// `gravity_mps2` converting g to m/s^2.
pub fn measured_static_displacement(samples: &[RawImuSample], gravity_mps2: f64) -> [f64; 3] {
    let t0 = samples.first().map_or(0, |s| s.stamps.sample_ns);
    let times: Vec<f64> = samples
        .iter()
        .map(|s| (s.stamps.sample_ns - t0) as f64 * 1e-9)
        .collect();
    std::array::from_fn(|axis| {
        let values: Vec<f64> = samples
            .iter()
            .map(|s| s.accel_g[axis] * gravity_mps2)
            .collect();
        detrended_displacement(&times, &values)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::flicker_approximation;

    /// The weights `w` of `p = sum_n w_n a_n`, by linearity: the response to unit impulses.
    fn weights(times: &[f64]) -> Vec<f64> {
        let mut impulse = vec![0.0; times.len()];
        (0..times.len())
            .map(|n| {
                impulse[n] = 1.0;
                let w = detrended_displacement(times, &impulse);
                impulse[n] = 0.0;
                w
            })
            .collect()
    }

    #[test]
    fn removes_any_constant_bias() {
        let times: Vec<f64> = (0..500)
            .map(|i| i as f64 * 0.01 + (i % 3) as f64 * 1e-3)
            .collect();
        let values: Vec<f64> = times.iter().map(|t| 0.3 + (7.0 * t).sin()).collect();
        let shifted: Vec<f64> = values.iter().map(|v| v + 12.5).collect();
        let a = detrended_displacement(&times, &values);
        let b = detrended_displacement(&times, &shifted);
        assert!((a - b).abs() < 1e-12, "{a} {b}");
    }

    #[test]
    fn predicted_sigma_matches_the_exact_variance_of_each_noise() {
        // The exact variance of the discrete functional for each noise, computed from the
        // weights in the time domain, against the closed forms.
        let tau0 = 0.05;
        let len = 1_201; // T = 60 s
        let times: Vec<f64> = (0..len).map(|i| i as f64 * tau0).collect();
        let t = times[len - 1];
        let w = weights(&times);

        // White: per-sample variance N^2 / tau0.
        let n = 2e-3;
        let white: f64 = w.iter().map(|w| w * w).sum::<f64>() * n * n / tau0;
        let predicted = static_displacement_sigma(n, 0.0, 0.0, t).powi(2);
        assert!(
            (white / predicted - 1.0).abs() < 0.01,
            "{white} {predicted}"
        );

        // Random walk: a_n = sum_{j<=n} e_j, Var e = K^2 tau0; p = sum_j e_j W_j with W_j the
        // tail sums of the weights.
        let k = 1e-4;
        let mut tail = 0.0;
        let mut walk = 0.0;
        for &wn in w.iter().rev() {
            tail += wn;
            walk += tail * tail;
        }
        walk *= k * k * tau0;
        let predicted = static_displacement_sigma(0.0, 0.0, k, t).powi(2);
        assert!((walk / predicted - 1.0).abs() < 0.01, "{walk} {predicted}");

        // Flicker as a wide sum of Gauss-Markov processes: sum_{n,m} w_n w_m v phi^|n-m| by
        // forward and backward exponential filters.
        let b = 1e-3;
        let mut flicker = 0.0;
        for gm in flicker_approximation(b, tau0 / 3.0, 1e4 * t, 4) {
            let phi = (-tau0 / gm.tau_c_s).exp();
            let mut forward = vec![0.0; len];
            let mut acc = 0.0;
            for (f, &wn) in forward.iter_mut().zip(&w) {
                acc = acc * phi + wn;
                *f = acc;
            }
            let mut backward = 0.0;
            let mut total = 0.0;
            for i in (0..len).rev() {
                total += w[i] * (forward[i] + backward);
                backward = (backward + w[i]) * phi;
            }
            flicker += gm.sigma * gm.sigma * total;
        }
        let predicted = static_displacement_sigma(0.0, b, 0.0, t).powi(2);
        assert!(
            (flicker / predicted - 1.0).abs() < 0.05,
            "{flicker} {predicted}"
        );
    }
}
