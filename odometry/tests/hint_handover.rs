//! A car that starts in motion with speed hints and no `--mount`, through the real
//! `mems-odometry offline` binary (`mems_sim`'s drive with no initial rest at car speeds, its
//! IMU upside down as the comma2k19 phone of docs/real-data.md, encoder hints from the
//! drive's truth): the filter aligns on a steady cruise with its velocity at zero for want of a
//! direction, and the speed hints wait for the forward axis (`odometry::cruise::ForwardAxis`).
//! When it is first trusted the velocity restarts from the hint along it, whatever its 1-sigma
//! has become meanwhile (the car accelerated past the cruise's speed, which set that 1-sigma),
//! and the IMU-only non-holonomic constraint has not estimated a mounting of its own from the
//! directionless velocity: the speed hints' innovations stay consistent with their 1-sigma and
//! the ends lie within the published 1-sigma's 68 % radius on two of three seeds (its 95 %
//! radius on all) and within 5 % of the distance driven. Before, the first speed update was linearized
//! about a velocity tens of m/s off, the tilt ran away and the speed hints' NIS per degree of
//! freedom was in the hundreds (as on the comma2k19 car).

mod common;

use common::{car_started_in_motion, offline_vehicle_json, scratch, write_drive_with_hints};

#[test]
fn a_car_starting_in_motion_takes_its_speed_hints_consistently_once_its_axis_is_known() {
    let dir = scratch("hint-handover");
    let mut covered = 0;
    for seed in [1, 2, 4] {
        let path = dir.join(format!("drive-{seed}.mcap"));
        let (raw, hints) = car_started_in_motion(seed);
        write_drive_with_hints(&path, &raw, hints);
        let v = offline_vehicle_json(env!("CARGO_BIN_EXE_mems-odometry"), &path, &[]);
        let a = |key: &str, i: usize| v[key][i].as_f64().unwrap();
        let speed = v["aligned_in_motion"]["speed_mps"].as_f64();
        assert!(speed.is_some_and(|s| s > 5.0), "not aligned in motion: {v}");
        let trusted = v["hints"]["forward_axis"]["trusted_at_s"].as_f64();
        assert!(trusted.is_some(), "forward axis never trusted: {v}");
        // The speed hints' innovations: NIS per degree of freedom near 1 for an honest
        // 1-sigma; within 3 here (the old hand-over gave hundreds).
        let nis = v["consistency"]["speed"]["nis_per_dof"].as_f64().unwrap();
        // Ends within its 1-sigma: the radius holding 68 % of a circular 2-D Gaussian with
        // the reported per-axis sigma (1.515 sigma, as bench.py) on at least two of the three
        // seeds, and every seed within the one holding 95 % (2.448 sigma). Each seed within its
        // 68 % radius would hold by chance on 31 % of honest runs.
        let error = a("truth_error_m", 0).hypot(a("truth_error_m", 1));
        let (sx, sy) = (a("sigma_m", 0), a("sigma_m", 1));
        let r68 = 1.515 * ((sx * sx + sy * sy) / 2.0).sqrt();
        let r95 = r68 * 2.448 / 1.515;
        let distance = v["truth_distance_m"].as_f64().unwrap();
        eprintln!(
            "seed {seed}: aligned at {:.1} m/s, axis trusted {:.1} s after, speed NIS/dof \
             {nis:.2}, end error {error:.2} m, r68 {r68:.2} m, distance {distance:.0} m",
            speed.unwrap(),
            trusted.unwrap() - v["aligned_at_s"].as_f64().unwrap()
        );
        assert!(nis < 3.0, "seed {seed}: {v}");
        assert!(error <= r95, "seed {seed}: {v}");
        // The wait's path becomes the position at the restart: where it was a measurement of
        // the filter's own position, which the restart's conditioning had left with a 1-sigma
        // of metres, it barely moved it, and seed 4 ended 97.9 m off (26 % of its distance).
        assert!(error <= 0.05 * distance, "seed {seed}: {v}");
        covered += usize::from(error <= r68);
    }
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(
        covered >= 2,
        "{covered} of 3 seeds within their 68 % radius"
    );
}
