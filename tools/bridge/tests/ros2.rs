//! `mems-bridge ros2` heard as a ROS 2 node on rmw_zenoh would hear it, by a listener built
//! from rmw_zenoh's design document alone (`tests/ros2_listen.py`: the `eclipse-zenoh` package
//! and a CDR decoder of its own): odometry states and corrected samples published here on
//! iceoryx2 arrive on `0/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_...` and
//! `0/imu/data/sensor_msgs::msg::dds_::Imu_/RIHS01_...`, each message what was sent (mapped as
//! docs/recording.md, "ROS 2", says), stamped with its sample time on one wall clock, with
//! consecutive sequence numbers, a source time taken while the test ran and its publisher's
//! GID; the node and both publishers have their liveliness tokens.
//!
//! Without the Python package the test fails in CI (`CI=true`; `.ci/run` installs it) and is
//! skipped loudly elsewhere.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use iceoryx2::prelude::PortFactory;
use integration_tests::{Proc, free_port, odometry_state, unique_namespace, wait_until};
use ipc_types::{CorrectedImuSample, OdometryState, Stamps, service};
use mems_ros2::msg::{Imu, Odometry, RosMessage};
use serde_json::Value;

const WAIT: Duration = Duration::from_secs(60);
const PACKAGE: &str = "eclipse-zenoh==1.10.2";
/// Messages the listener takes per topic.
const N: usize = 200;

fn unix_now_ns() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_nanos() as i64
}

/// A corrected sample numbered `seq`, sampled now, its values telling its number.
fn corrected(seq: u64) -> CorrectedImuSample {
    CorrectedImuSample {
        stamps: Stamps {
            sample_ns: ipc_types::clock::monotonic_ns(),
            ..Stamps::default()
        },
        seq,
        accel_mps2: [seq as f64 * 1e-3, -0.25, 9.75],
        gyro_rps: [0.5, seq as f64 * -1e-4, 0.125],
        ..CorrectedImuSample::default()
    }
}

#[test]
fn a_ros2_listener_hears_odom_and_imu_as_rmw_zenoh_lays_them_out() {
    let ns = unique_namespace("bridge-ros2");
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let args = [
        "ros2",
        "--service",
        "odometry",
        "--service",
        "corrected",
        "--listen",
        &endpoint,
        "--namespace",
        &ns,
        "--domain-id",
        "0",
    ];
    let bridge = Proc::spawn("mems-bridge", &args);
    let node = service::node().unwrap();
    let odom_svc =
        service::open::<OdometryState>(&node, &service::full_name(&ns, service::ODOMETRY)).unwrap();
    let imu_svc =
        service::open::<CorrectedImuSample>(&node, &service::full_name(&ns, service::CORRECTED))
            .unwrap();
    let (odom_pub, imu_pub) = (
        service::publisher(&odom_svc).unwrap(),
        service::publisher(&imu_svc).unwrap(),
    );
    wait_until(WAIT, "the bridge's subscribers", || {
        odom_svc.dynamic_config().number_of_subscribers() >= 1
            && imu_svc.dynamic_config().number_of_subscribers() >= 1
    });

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros2_listen.py");
    let report_path = std::env::temp_dir().join(format!("{ns}.json"));
    let mut listener = Command::new("python3")
        .args([script.to_str().unwrap(), &endpoint, "0", &N.to_string()])
        .arg(&report_path)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot run python3: install Python 3 (CI: .ci/run)");
    let start_ns = unix_now_ns();
    let (mut states, mut samples) = (Vec::new(), Vec::new());
    for seq in 0.. {
        if listener.try_wait().unwrap().is_some() || seq > 60_000 {
            break;
        }
        states.push(odometry_state(seq));
        odom_pub.send_copy(*states.last().unwrap()).unwrap();
        samples.push(corrected(seq));
        imu_pub.send_copy(*samples.last().unwrap()).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    let end_ns = unix_now_ns();
    let output = listener.wait_with_output().unwrap();
    bridge.signal(libc::SIGTERM);
    let (status, summary) = bridge.wait(WAIT);
    assert!(status.success(), "mems-bridge ros2: {status}\n{summary}");
    let stderr = String::from_utf8_lossy(&output.stderr);
    if output.status.code() == Some(3) {
        let why = format!("the Python package {PACKAGE} is missing:\n{stderr}");
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{why} (.ci/run installs it)"
        );
        eprintln!(
            "\n********************************************************************\n\
             SKIPPED: {why}Install it: python3 -m pip install {PACKAGE} (.ci/run does).\n\
             ********************************************************************\n"
        );
        return;
    }
    assert!(output.status.success(), "ros2_listen.py failed:\n{stderr}");
    let report: Value = serde_json::from_slice(&std::fs::read(&report_path).unwrap()).unwrap();
    std::fs::remove_file(&report_path).unwrap();

    let odom_key = format!(
        "0/odom/nav_msgs::msg::dds_::Odometry_/{}",
        Odometry::TYPE_HASH
    );
    let imu_key = format!("0/imu/data/sensor_msgs::msg::dds_::Imu_/{}", Imu::TYPE_HASH);
    let mut keys: Vec<&str> = report["keys"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_str().unwrap())
        .collect();
    keys.sort();
    assert_eq!(keys, [imu_key.as_str(), odom_key.as_str()]);

    let tokens = report["tokens"].as_array().unwrap();
    let node_token = tokens
        .iter()
        .map(|t| t["token"].as_str().unwrap())
        .find(|t| t.split('/').nth(5) == Some("NN"))
        .unwrap_or_else(|| panic!("no node token in {tokens:?}"));
    let zid = node_token.split('/').nth(2).unwrap().to_string();
    assert_eq!(
        node_token,
        format!("@ros2_lv/0/{zid}/0/0/NN/%/%/mems_bridge")
    );
    let publisher = |topic: &str, type_name: &str, hash: &str| {
        let suffix = format!("/MP/%/%/mems_bridge/{topic}/{type_name}/{hash}/::,10:,:,:,,");
        let t = tokens
            .iter()
            .find(|t| t["token"].as_str().unwrap().ends_with(&suffix))
            .unwrap_or_else(|| panic!("no publisher token ending {suffix} in {tokens:?}"));
        let text = t["token"].as_str().unwrap();
        assert!(text.starts_with(&format!("@ros2_lv/0/{zid}/0/")), "{text}");
        t["sha256_16"].as_str().unwrap().to_string()
    };
    let odom_gid = publisher(
        "%odom",
        "nav_msgs::msg::dds_::Odometry_",
        Odometry::TYPE_HASH,
    );
    let imu_gid = publisher("%imu%data", "sensor_msgs::msg::dds_::Imu_", Imu::TYPE_HASH);

    let offset = check_stream(&report["odom"], &odom_gid, (start_ns, end_ns), |m| {
        let x = m["position"][0].as_f64().unwrap();
        let s = &states[(x * 1e3).round() as usize];
        check_odometry(m, s);
        s.stamps.sample_ns
    });
    let imu_offset = check_stream(&report["imu/data"], &imu_gid, (start_ns, end_ns), |m| {
        let x = m["linear_acceleration"][0].as_f64().unwrap();
        let s = &samples[(x * 1e3).round() as usize];
        check_imu(m, s);
        s.stamps.sample_ns
    });
    assert_eq!(offset, imu_offset, "one wall clock for both topics");
    let ours = unix_now_ns() - ipc_types::clock::monotonic_ns() as i64;
    assert!(
        (offset - ours).abs() < 50_000_000,
        "stamps on the wall clock: {offset} vs {ours}"
    );
}

/// Checks a topic's messages (`check` each against what was sent, returning its sample time):
/// consecutive sequence numbers, source times within `window`, the publisher's GID; returns
/// the one offset from sample time to header stamp.
fn check_stream(
    messages: &Value,
    gid: &str,
    window: (i64, i64),
    check: impl Fn(&Value) -> u64,
) -> i64 {
    let messages = messages.as_array().unwrap();
    assert_eq!(messages.len(), N);
    let mut offsets = Vec::new();
    for (i, m) in messages.iter().enumerate() {
        let a = &m["attachment"];
        let first = messages[0]["attachment"]["sequence"].as_i64().unwrap();
        assert_eq!(
            a["sequence"].as_i64().unwrap(),
            first + i as i64,
            "consecutive"
        );
        let t = a["timestamp_ns"].as_i64().unwrap();
        assert!(
            t >= window.0 && t <= window.1,
            "source time {t} outside {window:?}"
        );
        assert_eq!(a["gid"].as_str().unwrap(), gid);
        let sample_ns = check(m);
        let h = &m["header"];
        let stamp = h["sec"].as_i64().unwrap() * 1_000_000_000 + h["nanosec"].as_i64().unwrap();
        offsets.push(stamp - sample_ns as i64);
    }
    assert!(
        offsets.windows(2).all(|w| w[0] == w[1]),
        "one offset: {offsets:?}"
    );
    offsets[0]
}

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// An aligned state at rest (`odometry_state`): position, identity attitude, position
/// variances, the rest unknown (1e6).
fn check_odometry(m: &Value, s: &OdometryState) {
    assert_eq!(m["header"]["frame_id"], "odom");
    assert_eq!(m["child_frame_id"], "base_link");
    assert_eq!(floats(&m["position"]), s.position_m);
    let [w, x, y, z] = s.attitude_wxyz;
    assert_eq!(floats(&m["orientation_xyzw"]), [x, y, z, w]);
    let mut pose = vec![0.0; 36];
    let mut twist = vec![0.0; 36];
    for i in 0..6 {
        pose[i * 7] = 1e6;
        twist[i * 7] = 1e6;
    }
    for i in 0..3 {
        pose[i * 7] = s.position_sigma_m[i] * s.position_sigma_m[i];
        twist[i * 7] = s.velocity_sigma_mps[i] * s.velocity_sigma_mps[i];
    }
    assert_eq!(floats(&m["pose_covariance"]), pose);
    assert_eq!(floats(&m["twist_covariance"]), twist);
    assert_eq!(floats(&m["linear"]), [0.0; 3]);
    assert_eq!(floats(&m["angular"]), [0.0; 3]);
}

fn check_imu(m: &Value, s: &CorrectedImuSample) {
    assert_eq!(m["header"]["frame_id"], "imu_link");
    assert_eq!(floats(&m["orientation_xyzw"]), [0.0, 0.0, 0.0, 1.0]);
    let mut orientation = vec![0.0; 9];
    orientation[0] = -1.0;
    assert_eq!(floats(&m["orientation_covariance"]), orientation);
    assert_eq!(floats(&m["angular_velocity"]), s.gyro_rps);
    assert_eq!(floats(&m["linear_acceleration"]), s.accel_mps2);
    assert_eq!(floats(&m["angular_velocity_covariance"]), [0.0; 9]);
    assert_eq!(floats(&m["linear_acceleration_covariance"]), [0.0; 9]);
}
