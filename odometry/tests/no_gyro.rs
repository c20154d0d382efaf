//! Samples without a gyroscope (an accelerometer-only sensor mode, the MPU-9250 at 4 kHz) with
//! the real `mems-odometry serve` in a unique namespace: it cannot track attitude, so every
//! state says `NO_GYRO`, none is `ALIGNED` or has a position, and the process says so once on
//! stderr. The same samples with the gyroscope are navigated (the control that shows the input
//! would give a position).

mod common;

use std::io::Read;
use std::process::{Command, Stdio};
use std::time::Duration;

use common::{unique_namespace, wait_until};

use iceoryx2::port::update_connections::UpdateConnections as _;
use iceoryx2::service::port_factory::PortFactory as _;
use ipc_types::{
    CorrectedImuSample, OdometryState, Stamps, corrected_flags, odometry_flags, raw_flags, service,
};

const G: f64 = 9.80665;
const RATE_HZ: u64 = 1000;

/// 3 s at rest, level (flagged rest by a ready detector), then 2 s of 0.5 m/s^2 along x.
fn samples(gyro: bool) -> Vec<CorrectedImuSample> {
    (0..5 * RATE_HZ)
        .map(|k| {
            let moving = k >= 3 * RATE_HZ;
            let mut flags = corrected_flags::DETECTOR_READY;
            if !moving {
                flags |= corrected_flags::ZERO_STATE;
            }
            CorrectedImuSample {
                stamps: Stamps {
                    sample_ns: 1_000_000_000 + k * 1_000_000_000 / RATE_HZ,
                    ..Stamps::default()
                },
                seq: k,
                accel_mps2: [if moving { 0.5 } else { 0.0 }, 0.0, G],
                flags,
                raw_flags: if gyro { raw_flags::GYRO_VALID } else { 0 },
                ..CorrectedImuSample::default()
            }
        })
        .collect()
}

/// Runs `mems-odometry serve` on `samples`; returns its live states and its stderr.
fn serve(tag: &str, samples: &[CorrectedImuSample]) -> (Vec<OdometryState>, String) {
    let namespace = unique_namespace(tag);
    let dir = std::env::temp_dir().join(&namespace);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = dir.join("calib.toml");
    calibrate::calibfile::CalibrationFile::identity(G)
        .save(&calib)
        .unwrap();

    let node = service::node().unwrap();
    let corrected = service::open::<CorrectedImuSample>(
        &node,
        &service::full_name(&namespace, service::CORRECTED),
    )
    .unwrap();
    let odometry =
        service::open::<OdometryState>(&node, &service::full_name(&namespace, service::ODOMETRY))
            .unwrap();
    let states_sub = service::subscriber(&odometry).unwrap();
    let sample_pub = service::publisher(&corrected).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_mems-odometry"))
        .args(["serve", "--calib", calib.to_str().unwrap()])
        .env(service::NAMESPACE_ENV, &namespace)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start mems-odometry serve");
    wait_until(Duration::from_secs(10), "serve's subscriber", || {
        corrected.dynamic_config().number_of_subscribers() >= 1
    });
    sample_pub.update_connections().unwrap();
    std::thread::sleep(Duration::from_millis(300));

    let mut states = Vec::new();
    let drain = |states: &mut Vec<OdometryState>| {
        while let Some(s) = states_sub.receive().unwrap() {
            if s.flags & odometry_flags::REVISION == 0 {
                states.push(*s.payload());
            }
        }
    };
    for s in samples {
        sample_pub.send_copy(*s).unwrap();
        drain(&mut states);
    }
    wait_until(Duration::from_secs(20), "a state per sample", || {
        drain(&mut states);
        states.len() >= samples.len()
    });
    let term = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(term.success());
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    assert!(child.wait().unwrap().success(), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
    (states, stderr)
}

#[test]
fn serve_estimates_no_position_without_gyro_and_says_so() {
    let without = samples(false);
    let (states, stderr) = serve("no-gyro", &without);
    assert_eq!(states.len(), without.len(), "one state per sample");
    for (s, o) in without.iter().zip(&states) {
        assert_eq!(o.seq, s.seq);
        assert_ne!(o.flags & odometry_flags::NO_GYRO, 0, "seq {}", o.seq);
        assert_eq!(o.flags & odometry_flags::ALIGNED, 0, "seq {}", o.seq);
        assert_eq!(o.position_m, [0.0; 3], "seq {}", o.seq);
        assert_eq!(o.velocity_mps, [0.0; 3], "seq {}", o.seq);
    }
    assert_eq!(
        stderr.matches("has no gyroscope").count(),
        1,
        "one message, once:\n{stderr}"
    );

    // Control: with the gyroscope the same motion is navigated, 0.5 m/s^2 for 2 s = 1 m.
    let with = samples(true);
    let (states, stderr) = serve("with-gyro", &with);
    assert!(!stderr.contains("has no gyroscope"), "{stderr}");
    assert!(
        states
            .iter()
            .all(|o| o.flags & odometry_flags::NO_GYRO == 0)
    );
    let last = states.last().unwrap();
    assert_ne!(last.flags & odometry_flags::ALIGNED, 0);
    assert!(
        (last.position_m[0] - 1.0).abs() < 0.05,
        "x {}",
        last.position_m[0]
    );
}
