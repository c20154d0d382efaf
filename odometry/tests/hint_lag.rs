//! A wheeled robot whose speed hints lead its IMU: a 20 Hz controller (a count over 50 ms
//! windows) whose hints are stamped 50 ms before the motion they describe ends (a stamp taken
//! before the speed is read, as the F1TENTH car's VESC speed leads its IMU by 0.02-0.08 s in
//! docs/real-data.md), through the real `mems-odometry offline` binary with the mounting
//! given. The speed hints are taken at their stamps, so in every acceleration and braking
//! they disagree with the IMU by the lag times the acceleration; the filter carries that as
//! the speed's noise (`odometry::speed_lag`), so its speed-scale state ends within three of
//! its 1-sigmas of the encoders' true scale error and the end within the published 68 %
//! radius.

mod common;

use std::process::Command;

use common::{Case, drive_with_hints, scratch, write_drive_with_hints};
use mems_sim::hints::{HintParams, RestSource};

/// How much earlier than the motion's the hints' stamps are, ns.
const LEAD_NS: u64 = 50_000_000;

#[test]
fn hints_leading_the_imu_leave_the_scale_and_the_sigma_honest() {
    let case = Case {
        duration_s: 240.0,
        rate_hz: 100.0,
        turns: true,
        ..Case::straight()
    };
    let seed = 5;
    let params = HintParams {
        rate_hz: 20.0,
        ..HintParams::new(RestSource::Encoders)
    };
    let k_true = case.hints(seed, &params).speed_scale;
    let (raw, hints) = drive_with_hints(&case, seed, &params);
    let hints = hints
        .into_iter()
        .map(|mut h| {
            h.stamps.sample_ns -= LEAD_NS;
            h
        })
        .collect();
    let dir = scratch("hint-lag");
    let path = dir.join("drive.mcap");
    write_drive_with_hints(&path, &raw, hints);
    let out = Command::new(env!("CARGO_BIN_EXE_mems-odometry"))
        .args([
            "offline",
            "--json",
            "--profile",
            "vehicle",
            "--mount",
            "0,0,0",
        ])
        .arg("--input")
        .arg(&path)
        .output()
        .unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "offline failed: {err}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let scale = &v["hints"]["speed_scale"];
    let (k, sigma) = (
        scale["k"].as_f64().unwrap(),
        scale["sigma"].as_f64().unwrap(),
    );
    let e = |i: usize| v["truth_error_m"][i].as_f64().unwrap();
    let s = |i: usize| v["sigma_m"][i].as_f64().unwrap();
    let error = e(0).hypot(e(1));
    let r68 = 1.515 * ((s(0).powi(2) + s(1).powi(2)) / 2.0).sqrt();
    let distance = v["truth_distance_m"].as_f64().unwrap();
    eprintln!(
        "scale {k:.4} +- {sigma:.4}, true {k_true:.4}; end error {error:.3} m of {distance:.1} m, \
         r68 {r68:.3} m"
    );
    assert!((k - k_true).abs() <= 3.0 * sigma, "{v}");
    assert!(error <= r68, "{v}");
}
