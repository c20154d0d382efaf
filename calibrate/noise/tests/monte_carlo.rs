//! Monte Carlo: on simulated static records with known white noise, bias instability and rate
//! random walk, the fitted parameters fall within their reported 1-sigma of the truth at the
//! 1-sigma rate (68.3%), and the Allan deviation's 1-sigma intervals cover the exact curve at
//! that rate.
//!
//! The truth: bias instability is simulated as a sum of Gauss-Markov processes (log-spaced
//! correlation times, equal variances: a 1/f spectrum over the band), whose Allan variance is
//! known exactly; the reference values of N, B and K are the fit of the three-term model to
//! that exact curve, on the same cluster times (what the estimator converges to with unlimited
//! data). 200 records of 2^17 samples at 100 Hz; runs in about 5 s in release
//! (`cargo test --release -p noise --test monte_carlo`), too slow for an unoptimised build.

use noise::allan::{AllanCurve, AllanPoint, overlapping_avar};
use noise::fit::{CovarianceBasis, Term, fit_with};
use noise::synth::{NoiseModel, flicker_approximation};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const TRIALS: usize = 200;
const LEN: usize = 1 << 17;
const TAU0: f64 = 0.01;
/// The 1-sigma coverage of a Gaussian estimate.
const ONE_SIGMA: f64 = 0.682_689_492_137_086;

/// N = 2e-3 m/s^2/sqrt(Hz), B = 1.5e-3 m/s^2, K = 6e-4 m/s^3/sqrt(Hz): white noise dominates
/// below ~2 s, bias instability from ~2 to ~30 s, the random walk beyond (the cluster times
/// reach 328 s), so that every term is resolved in every record.
fn model() -> NoiseModel {
    NoiseModel {
        white_density: 2e-3,
        markov: flicker_approximation(1.5e-3, 0.1, 100.0 * LEN as f64 * TAU0, 4),
        random_walk: 6e-4,
    }
}

/// Per trial: `Some((value, sigma))` for N, B, K when resolved, and how many Allan deviation
/// intervals covered the exact curve out of how many.
type Outcome = ([Option<(f64, f64)>; 3], usize, usize);

fn trial(seed: u64, basis: &CovarianceBasis, model: &NoiseModel) -> Outcome {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let values = model.generate(LEN, TAU0, &mut rng);
    let curve = overlapping_avar(&values, std::slice::from_ref(&(0..LEN)), TAU0);
    let fit = fit_with(&curve, basis).expect("a long record fits");
    let terms = [&fit.white, &fit.bias_instability, &fit.random_walk].map(Term::resolved);
    let covered = fit
        .points
        .iter()
        .zip(&curve.points)
        .filter(|(p, c)| {
            let exact = model.avar(c.m, TAU0).sqrt();
            p.adev_low <= exact && exact <= p.adev_high
        })
        .count();
    (terms, covered, fit.points.len())
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "Monte Carlo of 200 long records: run in release (cargo test --release)"
)]
fn fitted_parameters_cover_the_truth_at_the_one_sigma_rate() {
    let model = model();
    // The grid of cluster times, from any record of this length.
    let grid = overlapping_avar(&vec![0.0; LEN], std::slice::from_ref(&(0..LEN)), TAU0);
    let exact = AllanCurve {
        points: grid
            .points
            .iter()
            .map(|p| AllanPoint {
                avar: model.avar(p.m, TAU0),
                ..*p
            })
            .collect(),
        ..grid
    };
    let basis = CovarianceBasis::for_curve(&exact);
    let reference = fit_with(&exact, &basis).expect("the exact curve fits");
    let truth = reference.coefficients.map(f64::sqrt);
    // The flicker approximation is close to the model the fit assumes: the reference values
    // are near the generating ones.
    for (k, (t, generating)) in truth.iter().zip([2e-3, 1.5e-3, 6e-4]).enumerate() {
        assert!(
            (t / generating - 1.0).abs() < 0.1,
            "term {k}: reference {t} vs generating {generating}"
        );
    }

    let outcomes: Vec<Outcome> = std::thread::scope(|scope| {
        let halves: Vec<_> = [0..TRIALS / 2, TRIALS / 2..TRIALS]
            .into_iter()
            .map(|seeds| {
                let (model, basis) = (&model, &basis);
                scope.spawn(move || {
                    seeds
                        .map(|seed| trial(seed as u64, basis, model))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        halves
            .into_iter()
            .flat_map(|h| h.join().expect("trials do not panic"))
            .collect()
    });

    // Binomial tolerance: 3 standard deviations of the coverage over TRIALS records.
    let tolerance = 3.0 * (ONE_SIGMA * (1.0 - ONE_SIGMA) / TRIALS as f64).sqrt();
    for (k, name) in ["N", "B", "K"].iter().enumerate() {
        let resolved: Vec<(f64, f64)> = outcomes.iter().filter_map(|o| o.0[k]).collect();
        assert_eq!(resolved.len(), TRIALS, "{name} unresolved in some records");
        let inside = resolved
            .iter()
            .filter(|(value, sigma)| (value - truth[k]).abs() <= *sigma)
            .count();
        let rate = inside as f64 / TRIALS as f64;
        println!(
            "{name}: reference {:.4e}, within 1 sigma in {rate:.3} of {TRIALS}",
            truth[k]
        );
        assert!(
            (rate - ONE_SIGMA).abs() <= tolerance,
            "{name}: truth within 1 sigma in {rate:.3} of {TRIALS} records, expected \
             {ONE_SIGMA:.3} +- {tolerance:.3}"
        );
    }
    // The intervals of one record are correlated, so this rate is not binomial over all
    // points; it still must be close to 68%.
    let covered: usize = outcomes.iter().map(|o| o.1).sum();
    let total: usize = outcomes.iter().map(|o| o.2).sum();
    let rate = covered as f64 / total as f64;
    println!("Allan deviation 1-sigma intervals cover the exact curve at {rate:.3}");
    assert!(
        (rate - ONE_SIGMA).abs() < 0.05,
        "Allan deviation intervals cover the exact curve at {rate:.3}"
    );
}
