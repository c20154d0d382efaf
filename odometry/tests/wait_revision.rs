//! A car that starts in motion with speed hints and no `--mount` (`common::car_started_in_motion`,
//! its IMU upside down as the comma2k19 phone), through the real `mems-odometry offline`
//! binary: while the speed hints wait for the forward axis the filter's velocity has no
//! direction, so the states it publishes meanwhile stand still about the alignment point. Once
//! the axis is trusted, the wait's states are published again (`REVISION`) along the path the
//! hints' speeds and the attitude give (`odometry::handover::WaitRevision`), and the track of
//! the offline JSON (the last state published for each time) follows the car from the
//! alignment: its distance from the start is the truth's, and the heading that turns the
//! truth's first 10 m onto it (as tools/real-data/bench.py does for a truth without a heading)
//! is the one that turns its first 100 m.

mod common;

use common::{car_started_in_motion, offline_vehicle_json, scratch, write_drive_with_hints};
use nalgebra::Vector2;

/// The heading (rad) that best turns the truth's displacements from its position at `t0_s` onto
/// ours at the same times, over the truth's first `path_m` of path: `atan2(sum t x o, sum t . o)`
/// (bench.py's `track_heading`). `truth` and `ours` are (time s, x, y), ours from the alignment.
fn track_heading(truth: &[(f64, Vector2<f64>)], ours: &[(f64, Vector2<f64>)], path_m: f64) -> f64 {
    let t0 = ours[0].0;
    let at = |track: &[(f64, Vector2<f64>)], t: f64| {
        let i = track
            .partition_point(|p| p.0 <= t)
            .clamp(1, track.len() - 1);
        let ((ta, a), (tb, b)) = (track[i - 1], track[i]);
        a + (b - a) * ((t - ta) / (tb - ta)).clamp(0.0, 1.0)
    };
    let start = at(truth, t0);
    let (mut cross, mut dot, mut walked, mut last) = (0.0, 0.0, 0.0, start);
    for &(t, p) in truth.iter().filter(|p| p.0 > t0) {
        walked += (p - last).norm();
        last = p;
        let (d, o) = (p - start, at(ours, t));
        cross += d.x * o.y - d.y * o.x;
        dot += d.dot(&o);
        if walked >= path_m {
            break;
        }
    }
    cross.atan2(dot)
}

#[test]
fn the_path_driven_before_the_forward_axis_is_known_is_published_again() {
    let dir = scratch("wait-revision");
    let path = dir.join("drive.mcap");
    let (raw, hints) = car_started_in_motion(1);
    write_drive_with_hints(&path, &raw, hints);
    let v = offline_vehicle_json(env!("CARGO_BIN_EXE_mems-odometry"), &path, &[]);
    std::fs::remove_dir_all(&dir).unwrap();
    let first_ns = raw[0].0.stamps.sample_ns;
    let truth: Vec<(f64, Vector2<f64>)> = raw
        .iter()
        .map(|(r, t)| {
            let s = (r.stamps.sample_ns - first_ns) as f64 * 1e-9;
            (s, Vector2::new(t.position_m[0], t.position_m[1]))
        })
        .collect();
    let ours: Vec<(f64, Vector2<f64>)> = v["track"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let f = |i: usize| p[i].as_f64().unwrap();
            (f(0), Vector2::new(f(1), f(2)))
        })
        .collect();
    let aligned = v["aligned_at_s"].as_f64().unwrap();
    let trusted = v["hints"]["forward_axis"]["trusted_at_s"].as_f64().unwrap();
    assert!(
        v["aligned_in_motion"]["speed_mps"].as_f64().is_some(),
        "{v}"
    );
    assert!(trusted - aligned > 5.0, "no wait to revise: {v}");
    // Halfway through the wait: the track lies as far from the start as the truth does (the
    // published states stood within metres of it, at 0.1-2 m/s).
    let at = |track: &[(f64, Vector2<f64>)], t: f64| {
        track.iter().find(|p| p.0 >= t).map(|p| p.1).unwrap()
    };
    let mid = 0.5 * (aligned + trusted);
    let theirs = (at(&truth, mid) - at(&truth, aligned)).norm();
    let mine = at(&ours, mid).norm();
    eprintln!(
        "halfway through the wait, {mid:.1} s: {mine:.1} m from the start, truth {theirs:.1} m"
    );
    assert!(
        (mine - theirs).abs() < 0.1 * theirs,
        "{mine} against {theirs}: {v}"
    );
    // The heading that turns the truth's first 10 m onto ours is the one of its first 100 m.
    let short = track_heading(&truth, &ours, 10.0);
    let long = track_heading(&truth, &ours, 100.0);
    let pi = std::f64::consts::PI;
    let disagreement = ((short - long + pi).rem_euclid(2.0 * pi) - pi).to_degrees();
    eprintln!(
        "heading over 10 m {:.1} deg, over 100 m {:.1} deg",
        short.to_degrees(),
        long.to_degrees()
    );
    assert!(disagreement.abs() < 3.0, "{disagreement} deg: {v}");
}
