//! Synthetic static records with known noise, and their exact Allan variance: the ground truth
//! for testing the analysis (and for any test that needs IMU noise with stated parameters).
//!
//! A rate series (unit `u`: m/s^2 or rad/s) is the sum of
//! - white noise of density `N` (u/sqrt(Hz)): per-sample variance `N^2 / tau0`;
//! - first-order Gauss-Markov processes (stationary AR(1), `x' = phi x + sqrt(1 - phi^2) s w`,
//!   `phi = exp(-tau0 / tau_c)`), which with log-spaced correlation times and equal variances
//!   approximate flicker noise (bias instability) between `1/(2 pi tau_c,max)` and
//!   `1/(2 pi tau_c,min)`: see [`flicker_approximation`];
//! - a random walk of density `K` (u sqrt(Hz)): increments of variance `K^2 tau0` per sample.
//!
//! The Allan variance of each part is known exactly for the discrete series, so a test can
//! define its truth without simulation ([`NoiseModel::avar`]).

use ipc_types::units::{AccelRange, GyroRange, quantize};
use ipc_types::{RawImuSample, raw_flags};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// A stationary first-order Gauss-Markov process.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaussMarkov {
    /// Stationary standard deviation, u.
    pub sigma: f64,
    /// Correlation time, s.
    pub tau_c_s: f64,
}

/// The noise of one axis.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NoiseModel {
    /// White noise density `N`, u/sqrt(Hz).
    pub white_density: f64,
    /// Gauss-Markov components (a flicker approximation, or any correlated bias).
    pub markov: Vec<GaussMarkov>,
    /// Rate random walk `K`, u sqrt(Hz).
    pub random_walk: f64,
}

/// Gauss-Markov components approximating flicker noise of bias instability `b` (u) between
/// correlation times `tau_min_s` and `tau_max_s`, `per_decade` of them per decade, all with
/// variance `b^2 ln(r) / pi` (`r` the ratio of neighbouring correlation times): the sum of their
/// Lorentzian spectra is then `b^2 / (2 pi f)` inside the band, IEEE Std 952's flicker
/// spectrum, whose Allan plateau is `(2 ln 2 / pi) b^2`. The plateau ripples by a few percent and
/// rolls off outside the band; use [`NoiseModel::avar`] for the exact curve.
pub fn flicker_approximation(
    b: f64,
    tau_min_s: f64,
    tau_max_s: f64,
    per_decade: usize,
) -> Vec<GaussMarkov> {
    let ratio = 10f64.powf(1.0 / per_decade as f64);
    let count = ((tau_max_s / tau_min_s).log10() * per_decade as f64).round() as usize + 1;
    let sigma = (b * b * ratio.ln() / std::f64::consts::PI).sqrt();
    (0..count)
        .map(|j| GaussMarkov {
            sigma,
            tau_c_s: tau_min_s * ratio.powi(j as i32),
        })
        .collect()
}

/// Half the variance of the sum of `t` consecutive samples of a unit-variance AR(1) process
/// with `phi = exp(-b)`: the structure function the Allan variance is made of.
fn markov_structure(t: f64, b: f64) -> f64 {
    let variance = if t * b < 1e-4 {
        // Series in b; the closed form below cancels catastrophically here.
        t * t - b * (t * t * t - t) / 3.0 + b * b * t * t * (t * t - 1.0) / 12.0
    } else {
        let one_minus_phi = -(-b).exp_m1();
        let phi = 1.0 - one_minus_phi;
        let one_minus_phi_t = -(-b * t).exp_m1();
        t * (1.0 + phi) / one_minus_phi
            - 2.0 * phi * one_minus_phi_t / (one_minus_phi * one_minus_phi)
    };
    variance / 2.0
}

impl NoiseModel {
    /// The exact Allan variance (u^2) of the discrete series at cluster size `m`, sample
    /// interval `tau0_s`: white `N^2 / (m tau0)`; random walk `K^2 tau0 (2 m^2 + 1) / (6 m)`;
    /// each Gauss-Markov part `(4 V(m) - V(2m)) / m^2` with `V(t)` half the variance of a sum
    /// of `t` samples.
    pub fn avar(&self, m: usize, tau0_s: f64) -> f64 {
        let mf = m as f64;
        let white = self.white_density.powi(2) / (mf * tau0_s);
        let walk = self.random_walk.powi(2) * tau0_s * (2.0 * mf * mf + 1.0) / (6.0 * mf);
        let markov: f64 = self
            .markov
            .iter()
            .map(|gm| {
                let b = tau0_s / gm.tau_c_s;
                gm.sigma.powi(2) * (4.0 * markov_structure(mf, b) - markov_structure(2.0 * mf, b))
                    / (mf * mf)
            })
            .sum();
        white + walk + markov
    }

    /// `len` samples of the series at interval `tau0_s` (the random walk starts at 0, the
    /// Gauss-Markov parts in their stationary distribution).
    pub fn generate(&self, len: usize, tau0_s: f64, rng: &mut impl Rng) -> Vec<f64> {
        let mut normal = || -> f64 { StandardNormal.sample(&mut *rng) };
        let white = self.white_density / tau0_s.sqrt();
        let step = self.random_walk * tau0_s.sqrt();
        let coefficients: Vec<(f64, f64)> = self
            .markov
            .iter()
            .map(|gm| {
                let phi = (-tau0_s / gm.tau_c_s).exp();
                (phi, gm.sigma * (1.0 - phi * phi).sqrt())
            })
            .collect();
        let mut states: Vec<f64> = self.markov.iter().map(|gm| gm.sigma * normal()).collect();
        let mut walk = 0.0;
        let mut out = Vec::with_capacity(len);
        for _ in 0..len {
            let mut value = white * normal() + walk;
            for (state, &(phi, drive)) in states.iter_mut().zip(&coefficients) {
                value += *state;
                *state = phi * *state + drive * normal();
            }
            walk += step * normal();
            out.push(value);
        }
        out
    }
}

/// A static recording, z up: specific force `(0, 0, 1 g)` plus each accelerometer axis' noise
/// (models in m/s^2, converted with `gravity_mps2`), and the gyro's noise (models in rad/s)
/// when given, every `tau0_s` seconds from time 0. Values are quantised to the +-2 g and
/// +-250 deg/s counts as the sensor would, and the counts are stored.
pub fn static_samples(
    accel: &[NoiseModel; 3],
    gyro: Option<&[NoiseModel; 3]>,
    len: usize,
    tau0_s: f64,
    gravity_mps2: f64,
    rng: &mut impl Rng,
) -> Vec<RawImuSample> {
    let accel_lsb = AccelRange::G2.lsb_per_g();
    let gyro_lsb = GyroRange::Dps250.lsb_per_dps();
    let accel_noise: Vec<Vec<f64>> = accel.iter().map(|m| m.generate(len, tau0_s, rng)).collect();
    let gyro_noise: Option<Vec<Vec<f64>>> =
        gyro.map(|g| g.iter().map(|m| m.generate(len, tau0_s, rng)).collect());
    (0..len)
        .map(|i| {
            let mut s = RawImuSample {
                seq: i as u64,
                ..Default::default()
            };
            s.stamps.sample_ns = (i as f64 * tau0_s * 1e9).round() as u64;
            for (axis, noise) in accel_noise.iter().enumerate() {
                let g = f64::from(u8::from(axis == 2)) + noise[i] / gravity_mps2;
                s.accel_counts[axis] = quantize(g * accel_lsb);
                s.accel_g[axis] = f64::from(s.accel_counts[axis]) / accel_lsb;
            }
            if let Some(noise) = &gyro_noise {
                for (axis, noise) in noise.iter().enumerate() {
                    s.gyro_counts[axis] = quantize(noise[i].to_degrees() * gyro_lsb);
                    s.gyro_dps[axis] = f64::from(s.gyro_counts[axis]) / gyro_lsb;
                }
                s.flags |= raw_flags::GYRO_VALID;
            }
            s
        })
        .collect()
}

/// A static recording of white noise alone ([`static_samples`]): density `accel_n`
/// (m/s^2/sqrt(Hz)) on each accelerometer axis and `gyro_n` (rad/s/sqrt(Hz)) on each gyro
/// axis, `len` samples every `tau0_s` s at local gravity `gravity_mps2`, drawn from a ChaCha8
/// generator seeded with `seed`: a record whose Allan analysis must find those densities.
pub fn white_static_samples(
    accel_n: f64,
    gyro_n: f64,
    len: usize,
    tau0_s: f64,
    gravity_mps2: f64,
    seed: u64,
) -> Vec<RawImuSample> {
    use rand::SeedableRng;
    let white = |density| NoiseModel {
        white_density: density,
        ..Default::default()
    };
    let (accel, gyro) = (white(accel_n), white(gyro_n));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    static_samples(
        &[accel.clone(), accel.clone(), accel],
        Some(&[gyro.clone(), gyro.clone(), gyro]),
        len,
        tau0_s,
        gravity_mps2,
        &mut rng,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::allan::overlapping_avar;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn structure_function_branches_agree() {
        // Direct sums of the AR(1) autocovariance against both branches.
        for (t, b) in [
            (1.0, 1e-6),
            (3.0, 1e-5),
            (10.0, 0.3),
            (100.0, 1e-3),
            (50.0, 2e-6),
        ] {
            let phi = f64::exp(-b);
            let ti = t as i64;
            let direct = (t + 2.0
                * (1..ti)
                    .map(|k| (t - k as f64) * phi.powi(k as i32))
                    .sum::<f64>())
                / 2.0;
            let value = markov_structure(t, b);
            assert!(
                (value / direct - 1.0).abs() < 1e-9,
                "t {t} b {b}: {value} vs {direct}"
            );
        }
    }

    #[test]
    fn simulated_avar_matches_the_exact_curve() {
        let tau0 = 0.01;
        // The Gauss-Markov part dominates from 0.05 to 3 s, white noise below.
        let model = NoiseModel {
            white_density: 2e-3,
            markov: vec![GaussMarkov {
                sigma: 0.01,
                tau_c_s: 0.5,
            }],
            random_walk: 1e-3,
        };
        // Average several records so the comparison is tight; compare where the average of
        // eight has a relative sigma of about 2% (m <= 300 of 100 000 samples).
        let len = 100_000;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let runs = 8;
        let curves: Vec<_> = (0..runs)
            .map(|_| {
                let values = model.generate(len, tau0, &mut rng);
                overlapping_avar(&values, std::slice::from_ref(&(0..len)), tau0)
            })
            .collect();
        for (i, p) in curves[0]
            .points
            .iter()
            .enumerate()
            .filter(|(_, p)| p.m <= 300)
        {
            let measured = curves.iter().map(|c| c.points[i].avar).sum::<f64>() / runs as f64;
            let exact = model.avar(p.m, tau0);
            assert!(
                (measured / exact - 1.0).abs() < 0.08,
                "m {}: simulated {measured} vs exact {exact}",
                p.m
            );
        }
    }

    #[test]
    fn flicker_plateau_is_the_bias_instability() {
        let b = 1e-3;
        let model = NoiseModel {
            markov: flicker_approximation(b, 0.1, 1e4, 3),
            ..Default::default()
        };
        // In the middle of the band the Allan variance is (2 ln2 / pi) b^2 within the ripple.
        for m in [1_000, 3_000, 10_000, 30_000] {
            let ratio = model.avar(m, 0.01) / (crate::fit::FLICKER_FACTOR * b * b);
            assert!((ratio - 1.0).abs() < 0.05, "m {m}: {ratio}");
        }
    }

    #[test]
    fn static_samples_are_quantised_and_consistent() {
        let quiet = [
            NoiseModel::default(),
            NoiseModel::default(),
            NoiseModel::default(),
        ];
        let noisy = NoiseModel {
            white_density: 0.01,
            ..Default::default()
        };
        let gyro = [noisy.clone(), noisy.clone(), noisy];
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let samples = static_samples(&quiet, Some(&gyro), 100, 0.005, 9.8, &mut rng);
        assert_eq!(samples.len(), 100);
        assert_eq!(samples[7].stamps.sample_ns, 35_000_000);
        assert_eq!(samples[7].accel_counts, [0, 0, 16384]);
        assert_eq!(samples[7].accel_g, [0.0, 0.0, 1.0]);
        assert!(samples.iter().all(|s| s.flags & raw_flags::GYRO_VALID != 0));
        assert!(samples.iter().any(|s| s.gyro_counts != [0, 0, 0]));
        for s in &samples {
            for axis in 0..3 {
                assert_eq!(s.gyro_dps[axis], f64::from(s.gyro_counts[axis]) / 131.0);
            }
        }
    }
}
