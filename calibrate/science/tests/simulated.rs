//! Monte Carlo checks of the fits on simulated pose means with known parameters: the reported
//! 1-sigma must cover the true parameter at the advertised rate.
//!
//! Pose means are drawn directly from the model, `mean = S a + b + e`, with `e` white noise
//! averaged over `n` samples (standard error `std / sqrt(n)`): exactly the data the fits see
//! from a real session, at a fraction of the cost of simulating every sample.

use calibrate::model::{AccelModel, ModelKind, N_PARAMS};
use calibrate_science::fit::{CovarianceMode, Pose, Weighting, fit_labelled};
use calibrate_science::labelfree::fit_label_free;
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal, StandardNormal};

/// A sensor like the thesis's: 0.25 g z bias, 2% z scale, ~1% cross terms.
fn thesis_like() -> AccelModel {
    let s = Matrix3::new(
        1.0001, 0.0080, 0.0090, -0.0064, 1.0004, 0.0106, -0.0102, -0.0044, 1.0220,
    );
    AccelModel::new(ModelKind::Full, s, Vector3::new(0.0916, 0.0473, -0.2502)).unwrap()
}

const STD_G: [f64; 3] = [0.0021, 0.0021, 0.0037];
const N_SAMPLES: usize = 5400;

fn noisy_pose(
    model: &AccelModel,
    truth: Vector3<f64>,
    rng: &mut ChaCha8Rng,
    n: Option<usize>,
) -> Pose {
    let std = Vector3::from(STD_G);
    let sem = std / (N_SAMPLES as f64).sqrt();
    let e = Vector3::from_fn(|i, _| sem[i] * rng.sample::<f64, _>(StandardNormal));
    Pose {
        truth_g: truth,
        mean_g: model.measure(&truth) + e,
        std_g: std,
        n,
    }
}

fn six_positions() -> Vec<Vector3<f64>> {
    vec![
        Vector3::z(),
        -Vector3::z(),
        Vector3::y(),
        -Vector3::y(),
        Vector3::x(),
        -Vector3::x(),
    ]
}

/// Fraction of (seed, parameter) pairs with |estimate - truth| <= k sigma, per parameter.
fn coverage(
    seeds: u64,
    kind: ModelKind,
    k: f64,
    mut fit: impl FnMut(&mut ChaCha8Rng) -> (AccelModel, [f64; N_PARAMS]),
    truth: &AccelModel,
) -> Vec<f64> {
    let mut inside = [0usize; N_PARAMS];
    for seed in 0..seeds {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (m, sigma) = fit(&mut rng);
        let (p, t) = (m.params(), truth.params());
        for j in 0..N_PARAMS {
            if (p[j] - t[j]).abs() <= k * sigma[j] {
                inside[j] += 1;
            }
        }
    }
    (0..N_PARAMS)
        .filter(|&j| kind.is_free(j))
        .map(|j| inside[j] as f64 / seeds as f64)
        .collect()
}

fn sigma_array(cov: &calibrate::model::ParamCovariance) -> [f64; N_PARAMS] {
    std::array::from_fn(|j| cov[(j, j)].sqrt())
}

/// Weighted fit with known sample counts (absolute sigmas), six positions: every parameter's
/// 1-sigma covers the truth 68% +- 5% of the time. 2000 seeds make the binomial spread of each
/// fraction 1%, so the +-5% band is a real test.
#[test]
fn weighted_fit_sigmas_cover_at_68_percent() {
    let truth = thesis_like();
    for kind in ModelKind::ALL {
        let truth_k = match kind {
            ModelKind::Full => truth,
            ModelKind::Scale => AccelModel::new(
                kind,
                Matrix3::from_diagonal(&truth.scale().diagonal()),
                *truth.bias_g(),
            )
            .unwrap(),
            ModelKind::Bias => AccelModel::new(kind, Matrix3::identity(), *truth.bias_g()).unwrap(),
        };
        let cov = coverage(
            2000,
            kind,
            1.0,
            |rng| {
                let poses: Vec<Pose> = six_positions()
                    .into_iter()
                    .map(|a| noisy_pose(&truth_k, a, rng, Some(N_SAMPLES)))
                    .collect();
                let f = fit_labelled(&poses, kind, Weighting::PoseStd).unwrap();
                assert_eq!(f.covariance_mode, CovarianceMode::Absolute);
                (f.model, sigma_array(&f.covariance))
            },
            &truth_k,
        );
        for c in &cov {
            assert!((c - 0.6827).abs() < 0.05, "{kind}: coverage {cov:?}");
        }
    }
}

/// Unweighted fits estimate the noise from the residuals (curve_fit's default). With 24 poses
/// (the six positions, each re-placed four times) the residual variance has 20 degrees of
/// freedom and the coverage is Student-t's P(|t_20| < 1) = 0.671. With the thesis's six poses
/// it has 2 and the coverage drops to P(|t_2| < 1) = 0.577: the 1-sigma of an unweighted
/// six-position fit is optimistic, as this test documents.
#[test]
fn unweighted_fit_coverage_follows_student_t() {
    let truth = thesis_like();
    for (repeats, expect) in [(4usize, 0.671), (1, 0.577)] {
        let cov = coverage(
            2000,
            ModelKind::Full,
            1.0,
            |rng| {
                let poses: Vec<Pose> = (0..repeats)
                    .flat_map(|_| six_positions())
                    .map(|a| noisy_pose(&truth, a, rng, None))
                    .collect();
                let f = fit_labelled(&poses, ModelKind::Full, Weighting::Unweighted).unwrap();
                (f.model, sigma_array(&f.covariance))
            },
            &truth,
        );
        for c in &cov {
            assert!(
                (c - expect).abs() < 0.05,
                "{repeats} placements: coverage {cov:?}, expected {expect}"
            );
        }
    }
}

/// Uniformly distributed random directions.
fn random_direction(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    let n = Normal::new(0.0, 1.0).unwrap();
    Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng)).normalize()
}

/// The label-free model is identifiable only up to a rotation, so its truth is the
/// upper-triangular form of the thesis-like sensor: T = R of the QR decomposition of S^-1
/// (with a positive diagonal), S = T^-1.
fn upper_triangular_truth() -> AccelModel {
    let qr = thesis_like().scale_inv().qr();
    let mut r = qr.r();
    for i in 0..3 {
        if r[(i, i)] < 0.0 {
            r.row_mut(i).neg_mut();
        }
    }
    AccelModel::new(
        ModelKind::Full,
        r.try_inverse().unwrap(),
        *thesis_like().bias_g(),
    )
    .unwrap()
}

/// Label-free fit from 12 random orientations: over 1000 seeds, every parameter falls within
/// 2-sigma 95.4% +- 2% of the time and within 1-sigma 68% +- 5% (binomial spreads 0.66% and
/// 1.5%: the linearised covariance is accurate at this noise level), and no seed is refused.
#[test]
fn label_free_recovers_s_and_b_within_two_sigma() {
    let truth = upper_triangular_truth();
    // Measured sensor: rotating the true frame does not change magnitudes, so poses are
    // generated from the upper-triangular truth directly.
    let mut within = [[0usize; N_PARAMS]; 2];
    let seeds = 1000u64;
    for seed in 0..seeds {
        let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
        let poses: Vec<Pose> = (0..12)
            .map(|_| {
                let a = random_direction(&mut rng);
                noisy_pose(&truth, a, &mut rng, Some(N_SAMPLES))
            })
            .collect();
        let fit = fit_label_free(&poses, Weighting::PoseStd)
            .unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        let (p, t) = (fit.model.params(), truth.params());
        for j in 0..N_PARAMS {
            let s = fit.covariance[(j, j)].sqrt();
            if s == 0.0 {
                // The structurally zero lower triangle of S.
                assert!(p[j].abs() < 1e-15 && t[j].abs() < 1e-12);
                continue;
            }
            for (k, w) in within.iter_mut().enumerate() {
                if (p[j] - t[j]).abs() <= (k + 1) as f64 * s {
                    w[j] += 1;
                }
            }
        }
    }
    let free: Vec<usize> = (0..N_PARAMS)
        .filter(|&j| !matches!(j, 6 | 9 | 10))
        .collect();
    assert_eq!(free.len(), 9);
    for &j in &free {
        let one = within[0][j] as f64 / seeds as f64;
        let two = within[1][j] as f64 / seeds as f64;
        assert!(
            (two - 0.9545).abs() < 0.015,
            "parameter {j}: within 2 sigma {two}"
        );
        assert!(
            (one - 0.6827).abs() < 0.05,
            "parameter {j}: within 1 sigma {one}"
        );
    }
}

/// The same sensor seen through a rotated frame gives the same label-free model: only the
/// upper-triangular part is estimated, the rotation is left to alignment.
#[test]
fn label_free_result_does_not_depend_on_the_mounting_rotation() {
    let truth = upper_triangular_truth();
    let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.9);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let dirs: Vec<Vector3<f64>> = (0..15).map(|_| random_direction(&mut rng)).collect();
    let clean = |a: &Vector3<f64>| Pose {
        truth_g: Vector3::zeros(),
        mean_g: truth.measure(a),
        std_g: Vector3::from(STD_G),
        n: Some(N_SAMPLES),
    };
    let plain: Vec<Pose> = dirs.iter().map(clean).collect();
    let rotated: Vec<Pose> = dirs.iter().map(|a| clean(&(rot * a))).collect();
    let f1 = fit_label_free(&plain, Weighting::Unweighted).unwrap_or_else(|e| panic!("{e}"));
    let f2 = fit_label_free(&rotated, Weighting::Unweighted).unwrap_or_else(|e| panic!("{e}"));
    assert!((f1.model.params() - truth.params()).norm() < 1e-8);
    assert!((f2.model.params() - truth.params()).norm() < 1e-8);
}
