//! Dead-reckoning error model: the 1-sigma of the displacement obtained by integrating an
//! acceleration error twice from rest over `T` seconds, for the three error sources
//! `mems-eval static` accounts for. Units: m/s^2 in, seconds, metres out; each axis separately.
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
//! [`rrw_from_halves`] estimates `q` from data: the difference of the means of two consecutive
//! intervals of length `tau` has variance `2 sigma^2 / n` from white noise plus `2 q tau / 3`
//! (twice the Allan variance of a rate random walk).

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

/// Estimate of the rate-random-walk intensity `q` ((m/s^2)^2 per s) from the means of two
/// consecutive intervals of length `tau_s` with `n1`, `n2` samples of white-noise std
/// `sigma`: `q = 3 max(0, delta^2 - sigma^2 (1/n1 + 1/n2)) / (2 tau)`. One pair gives a
/// chi-square(1)-distributed estimate: unbiased, but with a relative standard deviation of
/// sqrt(2).
pub fn rrw_from_halves(delta: f64, sigma: f64, n1: usize, n2: usize, tau_s: f64) -> f64 {
    let white = sigma * sigma * (1.0 / n1 as f64 + 1.0 / n2 as f64);
    1.5 * (delta * delta - white).max(0.0) / tau_s
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

    #[test]
    fn bias_and_rrw_estimator() {
        assert_eq!(bias_sigma_m(0.01, 10.0), 0.5);
        // No excess over white noise: no drift.
        assert_eq!(rrw_from_halves(0.001, 0.05, 1000, 1000, 5.0), 0.0);
        // Pure drift: delta^2 = 2 q tau / 3.
        let q = 2e-6;
        let delta = (2.0 * q * 5.0 / 3.0f64).sqrt();
        assert!((rrw_from_halves(delta, 0.0, 10, 10, 5.0) - q).abs() < 1e-18);
    }
}
