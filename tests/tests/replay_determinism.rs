//! Replaying a recorded live run through real processes reproduces it bit for bit.
//!
//! Live: `mems-acquire` (simulated MPU-9250, datasheet preset, a drive that starts with 10 s of
//! rest) -> `mems-calibrate serve` -> `mems-odometry serve`, recorded by `mems-record`, with a
//! robot controller (the `publish_hints` example) saying "stationary" for the first 9 s (the
//! drive rests for 10 s; the odometry aligns after about 6, and counts hints from then on).
//! Replay, in a second namespace: `mems-replay LIVE.mcap --max` (raw samples and the recorded
//! hints) -> `mems-calibrate serve` -> `mems-odometry serve`, with the same calibration file,
//! recorded by a second `mems-record`.
//!
//! Every corrected sample and every odometry state (revisions included) of the replay equals
//! the live one field for field, floats compared bit for bit, except the wall-clock stamps:
//! `acquired_ns`, `calibrated_ns` and `odometry_ns` are when each process published, so they
//! must differ between the runs (the replay publishes at its own time), and `sample_ns` (the
//! sensor's time, replayed as recorded) must be equal.

use std::time::Duration;

use std::process::Command;

use integration_tests::{Proc, calibrate_sim_part, example, path_arg, unique_namespace};
use ipc_types::{CorrectedImuSample, OdometryState, Stamps};
use recording::mcap::{Contents, read_all};

/// Starts recorder, odometry and calibration (consumers first) in `ns`.
fn stages(ns: &str, calib: &str, rec: &str) -> [Proc; 3] {
    let ns_args = ["--namespace", ns];
    [
        Proc::spawn("mems-record", &[&["--out", rec][..], &ns_args].concat()),
        Proc::spawn(
            "mems-odometry",
            &[&["serve", "--calib", calib][..], &ns_args].concat(),
        ),
        Proc::spawn(
            "mems-calibrate",
            &[&["serve", "--calib", calib][..], &ns_args].concat(),
        ),
    ]
}

/// Lets the stages drain, stops them with SIGTERM (calibration first) and reads the recording.
fn stop(stages: [Proc; 3], rec: &std::path::Path) -> Contents {
    std::thread::sleep(Duration::from_millis(1000));
    let [record, odometry, calibrate] = stages;
    for p in [calibrate, odometry, record] {
        p.signal(libc::SIGTERM);
        let (status, _) = p.wait(Duration::from_secs(20));
        assert!(status.success(), "a stage failed: {status}");
    }
    let contents = read_all(rec).unwrap();
    assert_eq!(contents.truncation, None);
    contents
}

/// The stamps with the wall-clock fields zeroed (only `sample_ns` is the data's own time).
fn data_time(stamps: &Stamps) -> Stamps {
    Stamps {
        sample_ns: stamps.sample_ns,
        ..Stamps::default()
    }
}

/// A corrected sample as bits: every field, floats by their bit patterns, stamps without the
/// wall-clock fields.
fn corrected_bits(s: &CorrectedImuSample) -> (Stamps, Vec<u64>, [u64; 3]) {
    let floats = s
        .accel_mps2
        .iter()
        .chain(&s.gyro_rps)
        .chain([&s.temp_c])
        .chain(&s.zs_mean_mps2)
        .chain(&s.zs_std_mps2)
        .map(|v| v.to_bits())
        .collect();
    let ints = [
        s.seq,
        s.calib_id,
        (u64::from(s.flags) << 48) | (u64::from(s.raw_flags) << 32) | u64::from(s.settles),
    ];
    (data_time(&s.stamps), floats, ints)
}

/// An odometry state as bits, likewise.
fn state_bits(s: &OdometryState) -> (Stamps, Vec<u64>, Vec<u64>) {
    let floats = s
        .position_m
        .iter()
        .chain(&s.position_sigma_m)
        .chain(&s.velocity_mps)
        .chain(&s.velocity_sigma_mps)
        .chain(&s.gravity_sensor_mps2)
        .chain(&s.attitude_wxyz)
        .chain([&s.distance_m])
        .map(|v| v.to_bits())
        .collect();
    let ints = vec![
        s.seq,
        u64::from(s.flags),
        u64::from(s.reserved16),
        u64::from(s.rest_count),
        u64::from(s.hints_applied),
        u64::from(s.hint_disagreements),
    ];
    (data_time(&s.stamps), floats, ints)
}

#[test]
fn replay_through_the_processes_reproduces_the_live_run_bit_for_bit() {
    let ns = unique_namespace("determinism");
    let controller = example("ipc-types", "publish_hints");
    let replay_ns = format!("{ns}-replay");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 77);
    let calib = path_arg(&calib);
    let live_rec = dir.join("live.mcap");
    let replay_rec = dir.join("replay.mcap");

    // The live run: 12 s of the drive (10 s of rest for the alignment, then driving).
    let live = stages(&ns, calib, path_arg(&live_rec));
    std::thread::sleep(Duration::from_millis(1000));
    let acquire = Proc::spawn(
        "mems-acquire",
        &[
            "--rate",
            "1000",
            "--duration",
            "12",
            "--seed",
            "5",
            "--namespace",
            &ns,
        ],
    );
    // The controller starts with the acquisition and says "stationary" for 9 s of wall time:
    // the drive's first 9 s minus acquire's start-up, which covers the alignment (about 6 s of
    // sample time) even on a loaded machine, and never reaches the drive's motion at 10 s.
    let mut hints = Command::new(controller);
    hints
        .args(["9", "0"])
        .env(ipc_types::service::NAMESPACE_ENV, &ns);
    let hints = Proc::start("publish_hints", hints);
    let (status, _) = acquire.wait(Duration::from_secs(60));
    assert!(status.success(), "mems-acquire failed: {status}");
    let (status, _) = hints.wait(Duration::from_secs(20));
    assert!(status.success(), "publish_hints failed: {status}");
    let live = stop(live, &live_rec);

    // The replay, as fast as the stages take it (calibration and recorder subscribe to raw).
    let replay = stages(&replay_ns, calib, path_arg(&replay_rec));
    let (status, out) = Proc::spawn(
        "mems-replay",
        &[
            path_arg(&live_rec),
            "--max",
            "--wait-subscribers",
            "2",
            "--namespace",
            &replay_ns,
        ],
    )
    .wait(Duration::from_secs(60));
    assert!(status.success(), "mems-replay failed: {status}: {out}");
    let replayed = stop(replay, &replay_rec);

    // The hints are replayed exactly as recorded.
    assert!(
        live.hints.len() > 200,
        "{} hints recorded",
        live.hints.len()
    );
    assert_eq!(replayed.hints, live.hints);
    assert!(live.odometry.iter().any(|s| s.hints_applied > 0));

    // The raw input is the same (the replay re-stamps only acquired_ns).
    assert!(live.raw.len() > 11_000, "{} raw samples", live.raw.len());
    assert_eq!(replayed.raw.len(), live.raw.len());
    for (r, l) in replayed.raw.iter().zip(&live.raw) {
        assert_eq!((r.seq, r.stamps.sample_ns), (l.seq, l.stamps.sample_ns));
        assert_ne!(r.stamps.acquired_ns, l.stamps.acquired_ns);
    }

    assert_eq!(live.corrected.len(), live.raw.len(), "live: one per raw");
    assert_eq!(replayed.corrected.len(), live.corrected.len());
    for (r, l) in replayed.corrected.iter().zip(&live.corrected) {
        assert_eq!(
            corrected_bits(r),
            corrected_bits(l),
            "corrected seq {}",
            l.seq
        );
        assert_ne!(r.stamps.acquired_ns, l.stamps.acquired_ns);
        assert_ne!(r.stamps.calibrated_ns, l.stamps.calibrated_ns);
    }

    // One live state per sample (plus revisions, if a motion interval ended in the run).
    assert!(live.odometry.len() >= live.raw.len());
    assert_eq!(replayed.odometry.len(), live.odometry.len());
    for (r, l) in replayed.odometry.iter().zip(&live.odometry) {
        assert_eq!(state_bits(r), state_bits(l), "odometry seq {}", l.seq);
        assert_ne!(r.stamps.odometry_ns, l.stamps.odometry_ns);
        assert_ne!(r.stamps.calibrated_ns, l.stamps.calibrated_ns);
    }
    let last = live.odometry.last().unwrap();
    assert!(last.distance_m > 0.1, "moved {} m", last.distance_m);
    std::fs::remove_dir_all(&dir).unwrap();
}
