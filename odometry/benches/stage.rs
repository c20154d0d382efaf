//! Cost of the odometry stage per sample, and the longest single sample (a rest withdrawn in
//! hindsight replays up to `2 rest_hindsight_s + motion_confirm_s` of inputs, spread over
//! calls). Plain timing (no harness): `cargo bench -p odometry --bench stage`.
//!
//! Input: a simulated 10-minute drive with turns at 1 kHz (the live pipeline's rate), its rest
//! flags from the calibration stage's zero-state detector (GLRT, the live defaults) on the raw
//! samples, so the withdrawals happen where the live pipeline has them. The corrected samples
//! are computed first; only `OdometryStage::process` is timed, per call, into a histogram.
//! Each configuration runs on the calibration stage's output as it leaves it (provisional
//! flags, settled one batch later) and on the same output with its final flags (through a
//! `Settler`), which shows what navigating on provisional flags costs.

#[path = "../tests/common/mod.rs"]
mod common;

use mems_stage::Stage;
use std::hint::black_box;
use std::time::Instant;

use calibrate::stage::Settler;
use common::{Case, Simulation, live_calibration_stage, live_detector};
use hdrhistogram::Histogram;
use ipc_types::CorrectedImuSample;
use mems_sim::model::G_MPS2;
use odometry::config::OdometryConfig;
use odometry::stage::OdometryStage;

fn corrected_drive() -> Vec<CorrectedImuSample> {
    let c = Case {
        rate_hz: 1000.0,
        turns: true,
        ..Case::straight()
    };
    let mut sim = Simulation::new(&c, 1);
    sim.session();
    let mut calibration = live_calibration_stage(live_detector());
    let mut out = Vec::new();
    sim.drive_raw(|raw, _| {
        calibration
            .process(raw, &mut |c| out.push(*c))
            .expect("valid raw samples");
    });
    calibration.finish(&mut |_| {});
    out
}

fn run(label: &str, cfg: OdometryConfig, samples: &[CorrectedImuSample]) {
    let mut stage = OdometryStage::new(cfg);
    let mut hist = Histogram::<u64>::new_with_bounds(1, 1_000_000_000, 3).expect("bounds");
    let mut states = 0u64;
    let start = Instant::now();
    for s in samples {
        let t0 = Instant::now();
        stage
            .process(s, &mut |o| {
                black_box(o);
                states += 1;
            })
            .expect("valid samples");
        // A call descheduled for longer than the histogram's 1 s counts as 1 s.
        hist.saturating_record(t0.elapsed().as_nanos().max(1) as u64);
    }
    let total = start.elapsed();
    println!(
        "{label}: {} samples, {states} states ({} revised), {} rest flags withdrawn; mean {:.2} us/sample (wall incl. timing), p50 {:.1} us, p99 {:.1} us, p99.9 {:.1} us, max {:.0} us",
        samples.len(),
        stage.revisions_emitted(),
        stage.withdrawn_rest_samples(),
        total.as_secs_f64() * 1e6 / samples.len() as f64,
        hist.value_at_quantile(0.5) as f64 / 1e3,
        hist.value_at_quantile(0.99) as f64 / 1e3,
        hist.value_at_quantile(0.999) as f64 / 1e3,
        hist.max() as f64 / 1e3,
    );
}

/// `samples` with their final flags: held by a `Settler` until their batch is decided.
fn settled(samples: &[CorrectedImuSample]) -> Vec<CorrectedImuSample> {
    let mut settler = Settler::default();
    let mut out = Vec::with_capacity(samples.len());
    for s in samples {
        settler.push(s, &mut |s| out.push(*s));
    }
    settler.finish(&mut |s| out.push(*s));
    out
}

fn main() {
    let provisional = corrected_drive();
    let final_flags = settled(&provisional);
    let cfg = OdometryConfig::mpu9250(G_MPS2);
    let no_hindsight = OdometryConfig {
        rest_hindsight_s: 0.0,
        ..cfg
    };
    for _ in 0..2 {
        run(
            "hindsight 0.5 s (default), provisional flags",
            cfg,
            &provisional,
        );
        run("hindsight 0.5 s (default), final flags", cfg, &final_flags);
        run(
            "no hindsight, provisional flags",
            no_hindsight,
            &provisional,
        );
        run("no hindsight, final flags", no_hindsight, &final_flags);
    }
}
