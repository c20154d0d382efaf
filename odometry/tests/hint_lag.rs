//! A wheeled robot whose speed hints lead its IMU, as the F1TENTH car's VESC speed leads its
//! IMU by 0.02-0.08 s (docs/real-data.md): a 25 Hz controller (a count over 40 ms windows)
//! whose hints are stamped 60 ms before the end of the window they count, on a car that
//! cruises at 1-3 m/s and changes speed at up to 3 m/s^2, through the real `mems-odometry
//! offline` binary with the mounting given. Taken at their stamps, the speed hints disagree
//! with the IMU by the time offset times the acceleration in every speed change; with that as
//! the speed's noise (`odometry::speed_lag`) the filter's speed-scale state ends within 0.02
//! of the encoders' true scale error (without it, 0.07 off: the scale state took the
//! disagreements up, as on the F1TENTH car), and the end within 2.5 % of the distance and
//! within the published 68 % radius. The scale state's own 1-sigma is not asserted: it still
//! ends several of its 1-sigmas from the truth here (docs/hints.md).

mod common;

use common::{Case, drive_with_hints, offline_drive_with_hints};
use mems_sim::hints::{HintParams, RestSource};

/// How much earlier than the motion's the hints' stamps are, ns.
const LEAD_NS: u64 = 60_000_000;

#[test]
fn hints_leading_the_imu_do_not_go_into_the_speed_scale() {
    let case = Case {
        duration_s: 240.0,
        rate_hz: 100.0,
        turns: true,
        cruise_speed_mps: [1.0, 3.0],
        peak_accel_mps2: 3.0,
        max_motion_s: 60.0,
        ..Case::straight()
    };
    let seed = 5;
    let params = HintParams {
        rate_hz: 25.0,
        ..HintParams::new(RestSource::Encoders)
    };
    let k_true = case.hints(seed, &params).speed_scale;
    let (raw, hints) = drive_with_hints(&case, seed, &params);
    // Hints describing the time before the first sample are dropped (the drive's clock starts
    // near zero).
    let hints = hints
        .into_iter()
        .filter(|h| h.stamps.sample_ns > LEAD_NS)
        .map(|mut h| {
            h.stamps.sample_ns -= LEAD_NS;
            h
        })
        .collect();
    let v = offline_drive_with_hints(
        env!("CARGO_BIN_EXE_mems-odometry"),
        "hint-lag",
        &raw,
        hints,
        &["--mount", "0,0,0"],
    );
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
    assert!((k - k_true).abs() < 0.02, "{v}");
    assert!(error < 0.025 * distance, "{v}");
    assert!(error <= r68, "{v}");
}
