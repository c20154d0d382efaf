//! Dead-reckoning error model: the 1-sigma of the displacement obtained by integrating an
//! acceleration error twice from rest over `T` seconds, for the three error sources
//! `mems-eval static` accounts for (plus the flicker term). Units: m/s^2 in, seconds, metres out; each axis separately.
//!
//! - White noise of per-sample std `sigma` at sample interval `dt`: velocity random walk with
//!   variance `sigma^2 dt t`, displacement variance `sigma^2 dt T^3 / 3`.
//! - A constant bias error of std `sigma_b` (e.g. the error of a mean used as reference):
//!   displacement `b T^2 / 2`.
//! - A random-walk bias (rate random walk, increments of variance `q` per second) referenced to
//!   its mean over an alignment interval of length `A` that ends when integration starts:
//!   the reference error `B(0) - mean B` has variance `q A / 3`, and the bias wanders on
//!   afterwards, giving displacement variance `q (A T^4 / 12 + T^5 / 20)`.
//!
//! - Flicker bias (bias instability `B`, two-sided spectrum `B^2 / (2 pi f)`) referenced to its
//!   mean over the alignment interval: see [`flicker_sigma_m`].
//!
//! `q` is `K^2` of the noise parameters (`noise::NoiseParams`).

/// Displacement 1-sigma (m) from white noise of per-sample std `sigma_mps2` at interval
/// `dt_s`, integrated over `t_s`.
pub fn white_sigma_m(sigma_mps2: f64, dt_s: f64, t_s: f64) -> f64 {
    sigma_mps2 * (dt_s * t_s.powi(3) / 3.0).sqrt()
}

/// Displacement 1-sigma (m) from a constant bias error of std `sigma_b_mps2` over `t_s`.
pub fn bias_sigma_m(sigma_b_mps2: f64, t_s: f64) -> f64 {
    0.5 * sigma_b_mps2 * t_s * t_s
}

/// Displacement 1-sigma (m) from a random-walk bias of intensity `q` ((m/s^2)^2 per s)
/// referenced to its mean over an alignment interval of `align_s`, integrated over `t_s`.
pub fn rrw_sigma_m(q: f64, align_s: f64, t_s: f64) -> f64 {
    (q * (align_s * t_s.powi(4) / 12.0 + t_s.powi(5) / 20.0))
        .max(0.0)
        .sqrt()
}

/// Displacement 1-sigma (m) from a flicker bias of bias instability `b_mps2` (m/s^2; spectrum
/// `b^2 / (2 pi f)`, Allan floor `0.664 b`) referenced to its mean over an alignment interval
/// of `align_s` that ends when the double integration over `t_s` starts.
///
/// The end displacement is `p = int w(t) b(t) dt` with `w = T - t` on `[0, T]` and
/// `-T^2 / (2 A)` on `[-A, 0]` (the reference subtracted; `w` integrates to zero, so a constant
/// bias cancels). Its variance is `(b^2 / pi) int_0^inf |W(f)|^2 / f df`, `W` the Fourier
/// transform of `w` (closed form below). Flicker noise is scale free, so the integral is
/// `T^4 c(A / T)`; it is evaluated numerically over `ln f` (Simpson, 40 000 intervals for
/// `f T` in `[1e-6, 100]`, the oscillation there below 0.3 rad per step) plus the
/// high-frequency tail, where `|W|^2` averages `(J_0^2 + J_A^2) / (2 pi f)^2` with `J` the
/// weight's jumps at `0` and `-A`. No library integrates this oscillatory, scale-free integrand
/// directly, hence the hand-written quadrature.
pub fn flicker_sigma_m(b_mps2: f64, align_s: f64, t_s: f64) -> f64 {
    use nalgebra::Complex;
    assert!(
        align_s > 0.0 && t_s > 0.0,
        "alignment and integration times must be positive"
    );
    // Work with T = 1 (scale free): a = A / T.
    let a = align_s / t_s;
    let transform = |f: f64| -> Complex<f64> {
        let w = 2.0 * std::f64::consts::PI * f;
        let iw = Complex::new(0.0, w);
        let e_t = Complex::new(0.0, -w).exp();
        let i1 = (Complex::new(1.0, 0.0) - e_t) / iw;
        let i2 = -e_t / iw + i1 / iw;
        let on_window = i1 - i2;
        let on_align = -(Complex::new(0.0, w * a).exp() - 1.0) / iw * (0.5 / a);
        on_window + on_align
    };
    let (lo, hi, n) = (1e-6_f64.ln(), 100_f64.ln(), 40_000);
    let h = (hi - lo) / n as f64;
    let mut sum = 0.0;
    for k in 0..=n {
        let weight = if k == 0 || k == n {
            1.0
        } else if k % 2 == 1 {
            4.0
        } else {
            2.0
        };
        sum += weight * transform((lo + k as f64 * h).exp()).norm_sqr();
    }
    let body = sum * h / 3.0;
    let (j0, ja) = (1.0 + 0.5 / a, 0.5 / a);
    let f_hi = hi.exp();
    let tail = (j0 * j0 + ja * ja) / (8.0 * std::f64::consts::PI.powi(2) * f_hi * f_hi);
    b_mps2 * t_s * t_s * ((body + tail) / std::f64::consts::PI).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::DoubleIntegrator;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Monte Carlo check of the formulas against the trapezoid integrator itself.
    #[test]
    fn formulas_match_monte_carlo() {
        let (dt, t, align) = (0.01, 20.0, 5.0);
        let n = (t / dt) as usize;
        let na = (align / dt) as usize;
        let (sigma, q): (f64, f64) = (0.02, 1e-6);
        let runs = 600;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let white = Normal::new(0.0, sigma).unwrap();
        let step = Normal::new(0.0, (q * dt).sqrt()).unwrap();
        let (mut s2_white, mut s2_rrw) = (0.0, 0.0);
        for _ in 0..runs {
            // White noise only.
            let mut integ = DoubleIntegrator::new();
            for k in 0..=n {
                integ.push(k as f64 * dt, [white.sample(&mut rng), 0.0, 0.0]);
            }
            s2_white += integ.displacement()[0].powi(2);
            // Random-walk bias, referenced to its alignment-interval mean.
            let mut b = 0.0;
            let mut align_sum = 0.0;
            for _ in 0..na {
                b += step.sample(&mut rng);
                align_sum += b;
            }
            let reference = align_sum / na as f64;
            let mut integ = DoubleIntegrator::new();
            for k in 0..=n {
                integ.push(k as f64 * dt, [b - reference, 0.0, 0.0]);
                b += step.sample(&mut rng);
            }
            s2_rrw += integ.displacement()[0].powi(2);
        }
        let mc_white = (s2_white / runs as f64).sqrt();
        let mc_rrw = (s2_rrw / runs as f64).sqrt();
        // 600 runs: the sample sigma is good to about 3% (1-sigma); allow 4 sigma.
        assert!(
            (mc_white / white_sigma_m(sigma, dt, t) - 1.0).abs() < 0.12,
            "{mc_white}"
        );
        assert!(
            (mc_rrw / rrw_sigma_m(q, align, t) - 1.0).abs() < 0.12,
            "{mc_rrw}"
        );
    }

    /// The flicker term against a time-domain computation: flicker as a sum of Gauss-Markov
    /// components (the noise crate's approximation, correlation times far beyond both ends of
    /// the weight), the variance `sum_ij w_i w_j R(t_i - t_j) dt^2` summed exactly per
    /// component with a forward and a backward exponential filter.
    #[test]
    fn flicker_term_matches_a_gauss_markov_sum_in_the_time_domain() {
        let (b, align, t): (f64, f64, f64) = (1.5e-3, 10.0, 45.0);
        let components = noise::synth::flicker_approximation(b, 1e-3, 1e5, 8);
        let dt: f64 = 2e-3;
        let n = ((align + t) / dt).round() as usize;
        let w: Vec<f64> = (0..n)
            .map(|i| {
                let time = (i as f64 + 0.5) * dt - align;
                if time < 0.0 {
                    -t * t / (2.0 * align)
                } else {
                    t - time
                }
            })
            .collect();
        let mut var = 0.0;
        for c in &components {
            let decay = (-dt / c.tau_c_s).exp();
            let mut forward = vec![0.0; n];
            let mut acc = 0.0;
            for i in 0..n {
                acc = acc * decay + w[i];
                forward[i] = acc;
            }
            let mut backward = 0.0;
            let mut total = 0.0;
            for i in (0..n).rev() {
                backward = backward * decay + w[i];
                total += w[i] * (forward[i] + backward - w[i]);
            }
            var += c.sigma * c.sigma * total * dt * dt;
        }
        let direct = var.sqrt();
        let closed = flicker_sigma_m(b, align, t);
        // The Gauss-Markov sum ripples by a few percent about the 1/f spectrum.
        assert!(
            (direct / closed - 1.0).abs() < 0.03,
            "time domain {direct} m, closed form {closed} m"
        );
        // Scale free: doubling both times quadruples the sigma.
        let doubled = flicker_sigma_m(b, 2.0 * align, 2.0 * t);
        assert!((doubled / closed - 4.0).abs() < 1e-9, "{doubled} {closed}");
    }

    #[test]
    fn bias_term() {
        assert_eq!(bias_sigma_m(0.01, 10.0), 0.5);
    }
}
