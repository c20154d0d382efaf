//! Throughput of the whole `allan` analysis on 10 million samples (issue: at most 2 s).
//!
//! `cargo bench -p noise --bench allan [-- SAMPLES]` builds a static recording of SAMPLES
//! (default 10 000 000) accelerometer + gyro samples at 1 kHz with white noise and rate random
//! walk (not timed), then times, best of three: torn-read repair, the Allan curves of all six
//! axes, the fits, and the whole [`noise::analyze`] (which includes the others plus the
//! displacement floor), with the CPU time it used (on a loaded machine the wall time grows, the
//! CPU time much less). Reading the file is not included: it depends on the format and disk.

use std::time::{Duration, Instant};

use ipc_types::units::STANDARD_GRAVITY_MPS2;
use noise::allan::overlapping_avar;
use noise::analysis::{Options, analyze};
use noise::fit::fit;
use noise::repair::{RepairConfig, repair_torn_reads};
use noise::series::{self, GapPolicy};
use noise::synth::{NoiseModel, static_samples};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// User plus system CPU time of the process so far, all threads.
fn cpu_time() -> Duration {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::zeroed();
    // SAFETY: getrusage fills the struct it is given; RUSAGE_SELF is always valid.
    let usage = unsafe {
        libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr());
        usage.assume_init()
    };
    let time = |t: libc::timeval| Duration::new(t.tv_sec as u64, t.tv_usec as u32 * 1000);
    time(usage.ru_utime) + time(usage.ru_stime)
}

fn best_of<T>(runs: usize, mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut best = Duration::MAX;
    let mut last = None;
    for _ in 0..runs {
        let start = Instant::now();
        let value = f();
        best = best.min(start.elapsed());
        last = Some(value);
    }
    (best, last.expect("at least one run"))
}

fn main() {
    let samples: usize = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with('-'))
        .map_or(10_000_000, |a| a.parse().expect("SAMPLES is a count"));
    let tau0 = 1e-3;
    let accel = NoiseModel {
        white_density: 2.5e-3,
        random_walk: 1e-4,
        ..Default::default()
    };
    let gyro = NoiseModel {
        white_density: 1.7e-4,
        random_walk: 1e-5,
        ..Default::default()
    };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let build = Instant::now();
    let recording = static_samples(
        &[accel.clone(), accel.clone(), accel],
        Some(&[gyro.clone(), gyro.clone(), gyro]),
        samples,
        tau0,
        STANDARD_GRAVITY_MPS2,
        &mut rng,
    );
    println!(
        "{samples} samples (accelerometer + gyro) built in {:.1} s (not timed below)",
        build.elapsed().as_secs_f64()
    );

    // The clone each run needs is not timed.
    let mut repair_times = Vec::new();
    for _ in 0..3 {
        let mut copy = recording.clone();
        let start = Instant::now();
        repair_torn_reads(&mut copy, &RepairConfig::default());
        repair_times.push(start.elapsed());
    }
    let repair = repair_times.into_iter().min().expect("three runs");

    let timing = series::timing(&recording, &GapPolicy::default()).expect("valid recording");
    let channels = series::channels(&recording, STANDARD_GRAVITY_MPS2).expect("finite values");
    let segments = timing.segment_ranges();
    let (curve_time, curves) = best_of(3, || {
        channels
            .iter()
            .map(|c| overlapping_avar(&c.values, &segments, timing.mean_interval_s))
            .collect::<Vec<_>>()
    });
    let (fit_time, _) = best_of(3, || {
        curves
            .iter()
            .map(|c| fit(c).expect("fit"))
            .collect::<Vec<_>>()
    });

    let mut whole = Vec::new();
    for _ in 0..3 {
        let mut copy = recording.clone();
        let (start, cpu) = (Instant::now(), cpu_time());
        let report = analyze(&mut copy, "bench", &Options::default()).expect("analysis");
        whole.push((start.elapsed(), cpu_time() - cpu));
        assert_eq!(report.channels.len(), 6);
    }
    let (whole, whole_cpu) = whole.into_iter().min().expect("three runs");

    println!(
        "cluster times per axis: {}, largest {:.0} s",
        curves[0].points.len(),
        curves[0].points.last().map_or(0.0, |p| p.tau_s)
    );
    println!(
        "torn-read repair, 6 axes:          {:>7.3} s",
        repair.as_secs_f64()
    );
    println!(
        "Allan curves, 6 axes, one thread:  {:>7.3} s",
        curve_time.as_secs_f64()
    );
    println!(
        "fits, 6 axes:                      {:>7.3} s",
        fit_time.as_secs_f64()
    );
    println!(
        "whole analysis (axes in parallel on {} threads): {:.3} s wall, {:.3} s CPU (best of 3)",
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        whole.as_secs_f64(),
        whole_cpu.as_secs_f64()
    );
}
