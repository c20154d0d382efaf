//! `mems-acquire` killed with SIGKILL mid-drive in a real, recorded `mems-stack` run (the
//! simulated MPU-9250 at 1 kHz on its drive, unique namespace): the stack restarts it, and the
//! restarted process continues the sensor session kept in the stack's work directory.
//!
//! Asserted: the recording holds one acquisition session (sequence numbers never go back, and
//! none is missing but what the read the kill interrupted numbered), whose one `RESUMED`
//! sample (flagged `GAP_BEFORE`) counts in `lost_before` the sample periods of the hole never
//! read, as the stack's status line does; the odometry saw one sensor
//! session (its summary says so, and no state after its alignment is unaligned: it did not
//! learn and align again); and its end position, against the simulated drive's truth (the
//! part's motion went on in wall time from the session's origin), is within 3 sigma of the
//! 1-sigma it reports, per horizontal axis.

use std::path::{Path, PathBuf};
use std::time::Duration;

use integration_tests::{
    Proc, child_named, missing_ranges, path_arg, unique_namespace, wait_until,
};
use ipc_types::{OdometryState, odometry_flags, raw_flags};
use mems_sim::scenario::{Drive, DriveParams, Scenario};
use nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};

const WAIT: Duration = Duration::from_secs(60);

/// The stack's work directory's session file, once the stack has made it.
fn session_file(stack: u32) -> Option<PathBuf> {
    let prefix = format!("mems-stack-{stack}-");
    std::fs::read_dir(std::env::temp_dir())
        .ok()?
        .flatten()
        .find(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.path().join("acquire.session"))
        .filter(|p| p.exists())
}

/// The session's origin, ns of `CLOCK_MONOTONIC` (the second word of the file,
/// `acquire::session`): the simulated part's power-on, from which its drive runs.
fn origin_ns(file: &Path) -> Option<u64> {
    let bytes = std::fs::read(file).ok()?;
    Some(u64::from_le_bytes(bytes.get(8..16)?.try_into().ok()?))
}

/// The newest raw sample's time in the growing recording, ns (0 before any).
fn newest_raw_ns(rec: &Path) -> u64 {
    recording::mcap::read_all(rec).map_or(0, |c| c.raw.last().map_or(0, |s| s.stamps.sample_ns))
}

/// The drive `mems-acquire --source sim --seed 1` simulates (`acquire::process::run`).
fn drive() -> Drive {
    let mut params = DriveParams::new(24.0 * 3600.0);
    params.turns = true;
    Drive::new(&params, 1).unwrap()
}

fn quat(wxyz: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]))
}

/// The end state's position error against the truth, m, in the odometry's frame: the truth's
/// frame turned by the heading difference at the first aligned state, from the truth position
/// there (as `mems-odometry offline` compares).
fn end_error(states: &[OdometryState], drive: &Drive, origin_ns: u64) -> Vector3<f64> {
    let truth = |s: &OdometryState| drive.truth((s.stamps.sample_ns - origin_ns) as f64 * 1e-9);
    let first = states
        .iter()
        .find(|s| s.flags & odometry_flags::ALIGNED != 0)
        .expect("the odometry aligned");
    let t0 = truth(first);
    let m = (quat(first.attitude_wxyz) * quat(t0.attitude_wxyz).inverse()).to_rotation_matrix();
    let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), m[(1, 0)].atan2(m[(0, 0)]));
    let end = states.last().unwrap();
    let t1 = truth(end);
    let expected = yaw * (Vector3::from(t1.position_m) - Vector3::from(t0.position_m));
    Vector3::from(end.position_m) - expected
}

#[test]
fn a_killed_acquisition_continues_the_sensor_session() {
    let ns = unique_namespace("acqresume");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let (rec, log) = (dir.join("run.mcap"), dir.join("stack.log"));
    let stack = Proc::spawn_logged(
        "mems-stack",
        &[
            "--duration",
            "40",
            "--record",
            path_arg(&rec),
            "--namespace",
            &ns,
        ],
        &log,
    );
    let mut file = None;
    wait_until(WAIT, "the acquisition's session file", || {
        file = session_file(stack.pid());
        file.as_deref().and_then(origin_ns).is_some_and(|o| o > 0)
    });
    let origin = origin_ns(file.as_deref().unwrap()).unwrap();
    // Mid-drive: at least 4 s after the 10 s initial rest, while the robot moves at speed.
    let drive = drive();
    wait_until(WAIT, "the robot driving", || {
        let t_s = newest_raw_ns(&rec).saturating_sub(origin) as f64 * 1e-9;
        t_s > 14.0 && Vector3::from(drive.truth(t_s).velocity_mps).norm() > 0.15
    });
    let acquire = child_named(stack.pid(), "mems-acquire").expect("acquire runs");
    // SAFETY: kill(2) on a process of this test's own stack; no memory is involved.
    assert_eq!(unsafe { libc::kill(acquire as i32, libc::SIGKILL) }, 0);
    wait_until(WAIT, "acquire restarted", || {
        child_named(stack.pid(), "mems-acquire").is_some_and(|new| new != acquire)
    });
    let (status, summary) = stack.wait(WAIT);
    let stderr = std::fs::read_to_string(&log).unwrap();
    assert!(
        status.success(),
        "mems-stack failed: {status}\n{summary}\n{stderr}"
    );
    assert!(summary.contains("acquire 1"), "{summary}");

    // One acquisition session with one resumed hole, counted.
    let c = recording::mcap::read_all(&rec).unwrap();
    assert_eq!(c.raw_sessions.len(), 1, "one acquisition session");
    let resumed: Vec<usize> = (0..c.raw.len())
        .filter(|&i| c.raw[i].flags & raw_flags::RESUMED != 0)
        .collect();
    assert_eq!(resumed.len(), 1, "one resumed sample");
    let (before, after) = (c.raw[resumed[0] - 1], c.raw[resumed[0]]);
    assert_ne!(after.flags & raw_flags::GAP_BEFORE, 0);
    // Numbered on across the restart. Only the read the kill interrupted (numbered and noted
    // in the session file, not all published) may be missing, just before the resumed sample.
    let seqs: Vec<u64> = c.raw.iter().map(|s| s.seq).collect();
    let missing = after.seq - before.seq - 1;
    let expected_gaps = if missing == 0 {
        vec![]
    } else {
        vec![(before.seq + 1, after.seq - 1)]
    };
    assert_eq!(
        missing_ranges(&seqs),
        expected_gaps,
        "numbered on across the restart"
    );
    assert!(
        missing < 40,
        "{missing} samples of one read (36 at most at 1 kHz)"
    );
    // The hole's sample periods, less the one the resumed sample takes, are those numbered
    // and lost with the kill and those never read (`lost_before`; 1 ms rounding).
    let hole_ms = (after.stamps.sample_ns - before.stamps.sample_ns) as f64 * 1e-6;
    let periods = hole_ms.round() as i64 - 1;
    let counted = i64::from(after.lost_before) + missing as i64;
    assert!(
        (counted - periods).abs() <= 1,
        "{counted} counted, {periods} periods"
    );
    let status_line = summary
        .lines()
        .find(|l| l.starts_with("sensor lost"))
        .unwrap();
    assert!(
        status_line.contains(&format!("+ {} across acquire restarts", after.lost_before)),
        "{status_line}"
    );
    eprintln!(
        "acquire restart: a hole of {hole_ms:.0} ms, {} samples lost",
        after.lost_before
    );

    // The odometry saw one sensor session: it said so, and never aligned again.
    assert!(
        stderr.contains("sessions 1,"),
        "the odometry's summary names one session:\n{stderr}"
    );
    let live: Vec<OdometryState> = c
        .odometry
        .iter()
        .filter(|s| s.flags & odometry_flags::REVISION == 0)
        .copied()
        .collect();
    let aligned_at = live
        .iter()
        .position(|s| s.flags & odometry_flags::ALIGNED != 0)
        .expect("aligned");
    assert!(
        live[aligned_at..]
            .iter()
            .all(|s| s.flags & odometry_flags::ALIGNED != 0),
        "the odometry aligned again after the restart"
    );

    // The end error within 3 sigma, per horizontal axis.
    let err = end_error(&live, &drive, origin);
    let end = live.last().unwrap();
    let t_end = (end.stamps.sample_ns - origin) as f64 * 1e-9;
    eprintln!(
        "end at {t_s:.1} s of drive, {:.2} m driven: error ({:.3}, {:.3}) m, 1-sigma ({:.3}, {:.3}) m",
        end.distance_m,
        err.x,
        err.y,
        end.position_sigma_m[0],
        end.position_sigma_m[1],
        t_s = t_end
    );
    for axis in 0..2 {
        assert!(
            err[axis].abs() <= 3.0 * end.position_sigma_m[axis],
            "axis {axis}: error {:.3} m beyond 3 x {:.3} m",
            err[axis],
            end.position_sigma_m[axis]
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
