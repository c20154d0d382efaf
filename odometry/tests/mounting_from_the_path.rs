//! A small robot driving off from rest at 0.15-0.25 m/s with its IMU yawed 90 degrees on it
//! (as the corpus's TurtleBot navX, sensor -y forward), through the real `mems-odometry
//! offline` binary with no `--mount`: the forward axis comes from the path the filter
//! integrates from the rest against the speed hints' distance (`odometry::velocity_axis`),
//! within a second or two of driving off, where the speed-change fit
//! (`odometry::cruise::ForwardAxis`) needs at least six intervals of 0.5 s of motion. On the
//! corpus's TurtleBot the fit was never trusted on four of five runs (docs/hints.md), and
//! those runs took no speed hint at all.
//!
//! Offline, the run is then made a second time with that axis from the start
//! (`HintConfig::mounting_fit`): the JSON reports when the first pass trusted it, and
//! `from_start`.

mod common;

use common::{Case, offline_vehicle_json, scratch, write_drive_with_encoder_hints};
use ipc_types::odometry_flags;
use nalgebra::{UnitQuaternion, Vector3};

/// The speed-change fit's least excitation: six intervals of 0.5 s in motion, s.
const FIT_LEAST_S: f64 = 3.0;

/// A 40 s drive at 50 Hz with turns, the IMU yawed 90 degrees on the robot and white samples,
/// with `case`'s other settings.
fn yawed_robot(case: Case) -> Case {
    Case {
        duration_s: 40.0,
        rate_hz: 50.0,
        turns: true,
        mounting: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 90f64.to_radians()),
        dlpf: None,
        ..case
    }
}

/// `mems-odometry offline` (vehicle profile, no `--mount`) on `case`'s drive at `seed` with
/// encoder hints, written to a scratch directory `tag`: the JSON summary.
fn run(tag: &str, case: &Case, seed: u64) -> serde_json::Value {
    let dir = scratch(tag);
    let path = dir.join("drive.mcap");
    write_drive_with_encoder_hints(&path, case, seed);
    let v = offline_vehicle_json(env!("CARGO_BIN_EXE_mems-odometry"), &path, &[]);
    std::fs::remove_dir_all(&dir).unwrap();
    v
}

#[test]
fn a_slow_robot_takes_its_forward_axis_from_the_path_of_its_first_seconds() {
    for seed in [1, 2] {
        let case = yawed_robot(Case {
            initial_rest_s: 3.0,
            cruise_speed_mps: [0.15, 0.25],
            ..Case::straight()
        });
        let v = run("mounting-from-the-path", &case, seed);
        let forward = &v["hints"]["forward_axis"];
        let trusted_s = forward["trusted_at_s"].as_f64().unwrap();
        let yaw = v["hints"]["mounting_rpy_deg"][2].as_f64().unwrap();
        let sigma = forward["yaw_sigma_deg"].as_f64().unwrap();
        let a = |key: &str, i: usize| v[key][i].as_f64().unwrap();
        let error = a("truth_error_m", 0).hypot(a("truth_error_m", 1));
        let distance = v["truth_distance_m"].as_f64().unwrap();
        eprintln!(
            "seed {seed}: forward axis trusted at {trusted_s:.2} s (driving off at {:.1} s), \
             yaw {yaw:.2} +- {sigma:.2} deg; end error {error:.3} m after {distance:.1} m",
            case.initial_rest_s
        );
        assert!(trusted_s < case.initial_rest_s + FIT_LEAST_S, "{v}");
        // The path gave it; a later speed-change fit is fused with it.
        let source = forward["source"].as_str().unwrap();
        assert!(["path", "fused"].contains(&source), "{v}");
        assert!((yaw - 90.0).abs() < 3.0 * sigma.max(0.5), "{v}");
        assert!(v["hints"]["speed_updates"].as_u64().unwrap() > 0, "{v}");
        assert!(error < 0.05 * distance, "{v}");
    }
}

/// The corpus's TurtleBot starts gently and then keeps its speed: 0.05 m/s^2 to 0.15-0.2 m/s
/// after 2 s of rest, legs of 15-20 s. From such a start the path's direction is known to
/// 10-20 degrees only (the filter's velocity 1-sigma grows about as fast as the distance),
/// and with so few speed changes the speed-change fit may not come: the coarse path axis is
/// then taken once the hints have counted `odometry::velocity_axis::COARSE_WAIT_M` since it,
/// and the speed hints apply from there on (on seed 2 the fit never comes: without the coarse
/// axis no speed hint applied). Asserted for each drive: the forward axis trusted, its yaw
/// within three of its 1-sigmas of the truth, speed hints applied, and the end within three
/// of its published 1-sigmas per axis and within 35 % of the distance (the second pass takes
/// the axis from the start, and seed 2's, 17 degrees off, turns the whole track by 30 %; the
/// IMU-only constraint with its own mounting ends 3-4 times the distance off on the corpus's
/// TurtleBot).
#[test]
fn a_gentle_start_takes_a_coarse_path_axis_when_the_fit_does_not_come() {
    let mut failures = Vec::new();
    for seed in [1, 2, 3] {
        let case = yawed_robot(Case {
            initial_rest_s: 2.0,
            cruise_speed_mps: [0.15, 0.2],
            peak_accel_mps2: 0.05,
            leg_s: [15.0, 20.0],
            max_motion_s: 40.0,
            ..Case::straight()
        });
        let v = run("mounting-from-a-gentle-start", &case, seed);
        let forward = &v["hints"]["forward_axis"];
        let a = |key: &str, i: usize| v[key][i].as_f64().unwrap();
        let error = a("truth_error_m", 0).hypot(a("truth_error_m", 1));
        let sigma_m = a("sigma_m", 0).hypot(a("sigma_m", 1)) / 2f64.sqrt();
        let distance = v["truth_distance_m"].as_f64().unwrap();
        let yaw = v["hints"]["mounting_rpy_deg"][2]
            .as_f64()
            .unwrap_or(f64::NAN);
        let sigma = forward["yaw_systematic_sigma_deg"]
            .as_f64()
            .unwrap_or(f64::NAN);
        eprintln!(
            "seed {seed}: forward axis {forward}, yaw {yaw:.2} deg; end error {error:.3} m \
             (1-sigma per axis {sigma_m:.3} m) after {distance:.2} m"
        );
        let ok = (yaw - 90.0).abs() < 3.0 * sigma
            && v["hints"]["speed_updates"].as_u64().unwrap() > 0
            && error < 0.35 * distance
            && error < 3.0 * sigma_m;
        if !ok {
            failures.push(seed);
        }
    }
    assert!(failures.is_empty(), "seeds {failures:?} (above)");
}

/// Offline, the slow robot's second pass takes the first pass's axis from the start: its
/// states (`--out`, read back) carry speed updates (`HINT_SPEED`) from before the first pass
/// trusted the axis, the JSON says so (`from_start`, the first pass's time and source), and
/// the end stays within three of its published 1-sigmas per axis.
#[test]
fn offline_takes_the_first_pass_axis_from_the_start() {
    let case = yawed_robot(Case {
        initial_rest_s: 3.0,
        cruise_speed_mps: [0.15, 0.25],
        ..Case::straight()
    });
    let dir = scratch("mounting-from-the-start");
    let (path, out) = (dir.join("drive.mcap"), dir.join("states.mcap"));
    write_drive_with_encoder_hints(&path, &case, 1);
    let out_arg = out.to_str().unwrap();
    let v = offline_vehicle_json(
        env!("CARGO_BIN_EXE_mems-odometry"),
        &path,
        &["--out", out_arg],
    );
    let states = recording::mcap::read_all(&out).unwrap().odometry;
    std::fs::remove_dir_all(&dir).unwrap();
    let forward = &v["hints"]["forward_axis"];
    assert_eq!(forward["from_start"], true, "{v}");
    assert!(
        ["path", "fused"].contains(&forward["source"].as_str().unwrap()),
        "{v}"
    );
    let first_ns = states.first().unwrap().stamps.sample_ns;
    let trusted_s = forward["trusted_at_s"].as_f64().unwrap();
    let first_speed_s = states
        .iter()
        .find(|s| s.flags & odometry_flags::HINT_SPEED != 0)
        .map(|s| (s.stamps.sample_ns - first_ns) as f64 * 1e-9)
        .unwrap();
    eprintln!(
        "first pass trusted the axis at {trusted_s:.2} s; speed updates from {first_speed_s:.2} s"
    );
    assert!(first_speed_s < trusted_s - 0.5, "{v}");
    let a = |key: &str, i: usize| v[key][i].as_f64().unwrap();
    for i in 0..2 {
        assert!(a("truth_error_m", i).abs() < 3.0 * a("sigma_m", i), "{v}");
    }
}
