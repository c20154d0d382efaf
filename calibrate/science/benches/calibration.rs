//! Timing of the label-free fit (36 poses) and throughput of the evaluation pipeline on a whole
//! recording. Run with `cargo bench -p calibrate`; plain timing (no harness): each figure is the
//! median of repeated runs.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use calibrate::model::{AccelModel, ModelKind};
use calibrate::repair::{RepairConfig, repair_torn_reads};
use calibrate_science::fit::{Pose, Weighting};
use calibrate_science::labelfree::fit_label_free;
use calibrate_science::static_eval::{StaticEvalConfig, evaluate_static};
use indicatif::ProgressBar;
use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// Median wall time of `runs` calls of `f`.
fn median_time(runs: usize, mut f: impl FnMut()) -> Duration {
    let mut t: Vec<Duration> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed()
        })
        .collect();
    t.sort();
    t[runs / 2]
}

fn label_free_36() {
    let s = Matrix3::new(1.01, 0.008, -0.012, 0.0, 0.985, 0.011, 0.0, 0.0, 1.022);
    let truth = AccelModel::new(ModelKind::Full, s, Vector3::new(0.09, 0.047, -0.25)).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let poses: Vec<Pose> = (0..36)
        .map(|_| {
            let d = Vector3::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal)).normalize();
            let e = Vector3::from_fn(|_, _| 3e-5 * rng.sample::<f64, _>(StandardNormal));
            Pose {
                truth_g: Vector3::zeros(),
                mean_g: truth.measure(&d) + e,
                std_g: Vector3::repeat(0.002),
                n: Some(5000),
            }
        })
        .collect();
    let t = median_time(200, || {
        black_box(fit_label_free(black_box(&poses), Weighting::PoseStd).unwrap());
    });
    println!(
        "label-free fit, 36 poses: {:.1} us (median of 200)",
        t.as_secs_f64() * 1e6
    );
}

fn evaluation_throughput() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/capstone/Six-Position-Test/data/trial_1");
    let (six_path, test_path) = (
        dir.join("six_position_data_1.csv"),
        dir.join("six_position_test_data_1.csv"),
    );
    if !test_path.is_file() {
        println!(
            "SKIPPED evaluation throughput: capstone data not found at {}",
            dir.display()
        );
        return;
    }
    let six = recording::load_six_position(&six_path).unwrap();
    let test = recording::load_raw(&test_path).unwrap();
    let n = test.samples.len();
    let cfg = StaticEvalConfig {
        align_s: 10.0,
        window_s: 45.0,
        step_s: 1.0,
        gravity_mps2: 9.797,
    };
    let t = median_time(20, || {
        black_box(
            evaluate_static(&six, &test, Vec::new(), None, &cfg, &ProgressBar::hidden()).unwrap(),
        );
    });
    println!(
        "mems-eval static on trial 1 ({n} samples, 5 windows): {:.2} ms, {:.1} M samples/s",
        t.as_secs_f64() * 1e3,
        n as f64 / t.as_secs_f64() / 1e6
    );
    let t = median_time(20, || {
        let mut s = test.samples.clone();
        black_box(repair_torn_reads(&mut s, &RepairConfig::default()));
    });
    println!(
        "torn-read repair alone: {:.2} ms, {:.1} M samples/s",
        t.as_secs_f64() * 1e3,
        n as f64 / t.as_secs_f64() / 1e6
    );
}

fn main() {
    label_free_36();
    evaluation_throughput();
}
