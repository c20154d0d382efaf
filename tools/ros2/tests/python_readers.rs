//! A real recording (a simulated drive run through the pipeline's stages by
//! `mems-odometry offline --out`) exported by `mems-ros2 export`, then read back by two
//! independent ROS 2 readers, `rosbags` and `mcap` with `mcap-ros2-support`
//! (`tests/read_bag.py`): both must decode every message, with the definitions the bag carries,
//! to the same values, and those must be, field by field, what our own reader
//! (`recording::mcap::run::RunReader`) gives for the recording's corrected samples and states,
//! mapped as docs/recording.md ("ROS 2") says: computed here independently of the crate, the
//! velocity's rotation into the body frame and its covariance to within float rounding, every
//! other value exactly. The types the bag defines are the ROS 2 interfaces' (Jazzy and Humble
//! fields), with the RIHS01 hashes `mems_ros2::msg` states.
//!
//! Without the Python packages the test fails in CI (`CI=true`; `.ci/run` installs them) and is
//! skipped loudly elsewhere.

use std::path::Path;
use std::process::Command;

use integration_tests::{path_arg, run_ok, unique_namespace};
use ipc_types::{CorrectedImuSample, OdometryState, odometry_flags};
use mems_ros2::msg::{Imu, Odometry, RosMessage, TfMessage};
use recording::clock::WallClock;
use recording::mcap::run::RunReader;
use serde_json::{Value, json};

const PACKAGES: &str = "rosbags==0.11.9 mcap-ros2-support==0.6.0";
const UNKNOWN: f64 = 1e6;

#[test]
fn rosbags_and_mcap_ros2_read_every_message_as_our_reader_does() {
    let dir = std::env::temp_dir().join(unique_namespace("ros2-export"));
    std::fs::create_dir_all(&dir).unwrap();
    let (drive, states, bag) = (
        dir.join("drive.mcap"),
        dir.join("states.mcap"),
        dir.join("bag.mcap"),
    );
    run_ok(
        "mems-sim",
        &[
            "drive",
            "--duration",
            "40",
            "--turns",
            "on",
            "--rate",
            "200",
            "--seed",
            "3",
            "--out",
            path_arg(&drive),
        ],
    );
    run_ok(
        "mems-odometry",
        &[
            "offline",
            "--input",
            path_arg(&drive),
            "--out",
            path_arg(&states),
        ],
    );
    let export = Command::new(env!("CARGO_BIN_EXE_mems-ros2"))
        .args(["export", path_arg(&states), "--out", path_arg(&bag)])
        .output()
        .unwrap();
    assert!(
        export.status.success(),
        "{}",
        String::from_utf8_lossy(&export.stderr)
    );
    let Some(report) = read_bag(&bag) else {
        return;
    };
    let expected = expected(&states);

    assert_eq!(report["profile"], "ros2");
    for (type_name, hash) in [
        (Imu::TYPE_NAME, Imu::TYPE_HASH),
        (Odometry::TYPE_NAME, Odometry::TYPE_HASH),
        (TfMessage::TYPE_NAME, TfMessage::TYPE_HASH),
    ] {
        assert_eq!(report["types"][type_name], hash, "{type_name}'s RIHS01");
    }
    for (topic, type_name) in [
        ("/imu/data", "sensor_msgs/msg/Imu"),
        ("/odom", "nav_msgs/msg/Odometry"),
        ("/odom/revised", "nav_msgs/msg/Odometry"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
    ] {
        assert_eq!(
            report["channels"][topic],
            json!([type_name, "cdr"]),
            "{topic}"
        );
        assert_eq!(report["schemas"][type_name], "ros2msg", "{type_name}");
        let ours = &expected[topic];
        assert!(!ours.is_empty(), "the drive gives no {topic}");
        let mcap_ros2 = rows(&report["mcap_ros2"][topic]);
        compare(topic, ours, &mcap_ros2);
        let rosbags = rows(&report["rosbags"][topic]);
        assert!(
            rosbags.windows(2).all(|w| w[0].0 <= w[1].0),
            "{topic}: rosbags reads in log time order"
        );
        assert_eq!(
            sorted(rosbags),
            sorted(mcap_ros2),
            "{topic}: rosbags and mcap_ros2 differ"
        );
    }
    let live = expected["/odom"].len();
    let aligned = expected["/tf"]
        .iter()
        .filter(|(_, _, leaves)| leaves.len() > 11)
        .count();
    assert!(aligned > live / 2, "{aligned} of {live} states aligned");
    assert!(
        expected["/odom/revised"].len() > 100,
        "the drive revises states"
    );
    assert_eq!(expected["/tf"].len(), live);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// One message: log time, publish time and its leaves (dotted path, value) in declaration order.
type Row = (u64, u64, Vec<(String, Value)>);

/// A reader's table of one topic as rows.
fn rows(table: &Value) -> Vec<Row> {
    let fields: Vec<String> = serde_json::from_value(table["fields"].clone()).unwrap();
    let rows = table["rows"].as_array().unwrap();
    rows.iter()
        .map(|row| {
            let row = row.as_array().unwrap();
            let leaves = fields
                .iter()
                .cloned()
                .zip(row[2..].iter().cloned())
                .collect();
            (row[0].as_u64().unwrap(), row[1].as_u64().unwrap(), leaves)
        })
        .collect()
}

/// Rows in an order that does not depend on how ties of log time were read.
fn sorted(mut rows: Vec<Row>) -> Vec<Row> {
    rows.sort_by_cached_key(|(log, _, leaves)| (*log, serde_json::to_string(leaves).unwrap()));
    rows
}

/// Compares a reader's rows (file order) with ours, field by field.
fn compare(topic: &str, ours: &[Row], theirs: &[Row]) {
    assert_eq!(ours.len(), theirs.len(), "{topic}: messages");
    for (i, (a, b)) in ours.iter().zip(theirs).enumerate() {
        assert_eq!((a.0, a.1), (b.0, b.1), "{topic} #{i}: log and publish time");
        let names = |r: &Row| r.2.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
        assert_eq!(names(a), names(b), "{topic} #{i}: fields");
        for ((name, x), (_, y)) in a.2.iter().zip(&b.2) {
            let tolerance = if name.starts_with("twist.") {
                1e-12
            } else {
                0.0
            };
            assert!(
                same(x, y, tolerance),
                "{topic} #{i} {name}: ours {x}, read {y}"
            );
        }
    }
}

/// Equal values; numbers within `tolerance` relative to their size (at least 1).
fn same(a: &Value, b: &Value, tolerance: f64) -> bool {
    match (a, b) {
        (Value::Array(a), Value::Array(b)) => {
            a.len() == b.len() && a.iter().zip(b).all(|(a, b)| same(a, b, tolerance))
        }
        (Value::Number(_), Value::Number(_)) => {
            let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
            (a - b).abs() <= tolerance * a.abs().max(1.0)
        }
        _ => a == b,
    }
}

/// Runs tests/read_bag.py on `bag`; `None` when a package is missing outside CI.
fn read_bag(bag: &Path) -> Option<Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/read_bag.py");
    let output = Command::new("python3")
        .arg(script)
        .arg(bag)
        .output()
        .expect("cannot run python3: install Python 3 (CI: .ci/run)");
    let stderr = String::from_utf8_lossy(&output.stderr);
    if output.status.code() == Some(3) {
        let why = format!("the Python packages {PACKAGES} are missing:\n{stderr}");
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "{why} (.ci/run installs them)"
        );
        eprintln!(
            "\n********************************************************************\n\
             SKIPPED: {why}\
             Install them: python3 -m pip install {PACKAGES} (.ci/run does).\n\
             ********************************************************************\n"
        );
        return None;
    }
    assert!(output.status.success(), "read_bag.py failed:\n{stderr}");
    Some(serde_json::from_slice(&output.stdout).unwrap())
}

/// Each topic's messages as our reader gives the recording, mapped here.
fn expected(states: &Path) -> std::collections::HashMap<&'static str, Vec<Row>> {
    let mut out = std::collections::HashMap::from([
        ("/imu/data", Vec::new()),
        ("/odom", Vec::new()),
        ("/odom/revised", Vec::new()),
        ("/tf", Vec::new()),
    ]);
    let mut reader = RunReader::open(states).unwrap();
    while let Some(message) = reader.next() {
        let message = message.unwrap();
        let log = message.log_time_ns;
        let sample = message.decode::<CorrectedImuSample>().map(Result::unwrap);
        let state = message.decode::<OdometryState>().map(Result::unwrap);
        let clock = reader
            .clock()
            .expect("an offline run keeps the drive's anchor");
        let mut push = |topic, leaves| out.get_mut(topic).unwrap().push((log, log, leaves));
        if let Some(s) = sample {
            push("/imu/data", imu(&s, &clock));
        } else if let Some(s) = state {
            if s.flags & odometry_flags::REVISION != 0 {
                push("/odom/revised", odometry(&s, &clock));
            } else {
                push("/odom", odometry(&s, &clock));
                push("/tf", tf(&s, &clock));
            }
        }
    }
    out
}

fn stamp(prefix: &str, clock: &WallClock, sample_ns: u64, frame: &str) -> Vec<(String, Value)> {
    let t = clock.unix_ns(sample_ns);
    vec![
        (
            format!("{prefix}header.stamp.sec"),
            json!(t / 1_000_000_000),
        ),
        (
            format!("{prefix}header.stamp.nanosec"),
            json!(t % 1_000_000_000),
        ),
        (format!("{prefix}header.frame_id"), json!(frame)),
    ]
}

fn xyz(prefix: &str, v: [f64; 3]) -> Vec<(String, Value)> {
    ["x", "y", "z"]
        .iter()
        .zip(v)
        .map(|(axis, v)| (format!("{prefix}.{axis}"), json!(v)))
        .collect()
}

/// (x, y, z, w) of our (w, x, y, z).
fn xyzw(prefix: &str, [w, x, y, z]: [f64; 4]) -> Vec<(String, Value)> {
    ["x", "y", "z", "w"]
        .iter()
        .zip([x, y, z, w])
        .map(|(axis, v)| (format!("{prefix}.{axis}"), json!(v)))
        .collect()
}

fn imu(s: &CorrectedImuSample, clock: &WallClock) -> Vec<(String, Value)> {
    let mut orientation_covariance = [0.0; 9];
    orientation_covariance[0] = -1.0;
    let mut leaves = stamp("", clock, s.stamps.sample_ns, "imu_link");
    leaves.extend(xyzw("orientation", [1.0, 0.0, 0.0, 0.0]));
    leaves.push((
        "orientation_covariance".into(),
        json!(orientation_covariance),
    ));
    leaves.extend(xyz("angular_velocity", s.gyro_rps));
    leaves.push((
        "angular_velocity_covariance".into(),
        json!([0.0f64; 9].to_vec()),
    ));
    leaves.extend(xyz("linear_acceleration", s.accel_mps2));
    leaves.push((
        "linear_acceleration_covariance".into(),
        json!([0.0f64; 9].to_vec()),
    ));
    leaves
}

/// The rotation matrix (sensor to navigation frame) of a state's attitude, normalised.
fn rotation(s: &OdometryState) -> [[f64; 3]; 3] {
    let n = s.attitude_wxyz.iter().map(|v| v * v).sum::<f64>().sqrt();
    let [w, x, y, z] = s.attitude_wxyz.map(|v| v / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// 6x6 row-major with `block` upper left, [`UNKNOWN`] on the rest of the diagonal.
fn covariance(block: Option<[[f64; 3]; 3]>) -> Vec<f64> {
    let mut c = vec![0.0; 36];
    for i in 0..6 {
        c[i * 7] = UNKNOWN;
    }
    for (i, row) in block.iter().flatten().enumerate() {
        for (j, v) in row.iter().enumerate() {
            c[i * 6 + j] = *v;
        }
    }
    c
}

fn odometry(s: &OdometryState, clock: &WallClock) -> Vec<(String, Value)> {
    let aligned = s.flags & odometry_flags::ALIGNED != 0;
    let r = rotation(s);
    // v_body = R^T v_nav; its covariance R^T diag(sigma^2) R.
    let body: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| r[k][i] * s.velocity_mps[k]).sum());
    let var = s.velocity_sigma_mps.map(|v| v * v);
    let twist_block: [[f64; 3]; 3] = std::array::from_fn(|i| {
        std::array::from_fn(|j| (0..3).map(|k| r[k][i] * var[k] * r[k][j]).sum())
    });
    let p = s.position_sigma_m.map(|v| v * v);
    let pose_block = [[p[0], 0.0, 0.0], [0.0, p[1], 0.0], [0.0, 0.0, p[2]]];
    let mut leaves = stamp("", clock, s.stamps.sample_ns, "odom");
    leaves.push(("child_frame_id".into(), json!("base_link")));
    leaves.extend(xyz("pose.pose.position", s.position_m));
    leaves.extend(xyzw("pose.pose.orientation", s.attitude_wxyz));
    leaves.push((
        "pose.covariance".into(),
        json!(covariance(aligned.then_some(pose_block))),
    ));
    leaves.extend(xyz("twist.twist.linear", body));
    leaves.extend(xyz("twist.twist.angular", [0.0; 3]));
    leaves.push((
        "twist.covariance".into(),
        json!(covariance(aligned.then_some(twist_block))),
    ));
    leaves
}

fn tf(s: &OdometryState, clock: &WallClock) -> Vec<(String, Value)> {
    let mut frames = vec![];
    if s.flags & odometry_flags::ALIGNED != 0 {
        frames.push(("odom", "base_link", s.position_m, s.attitude_wxyz));
    }
    frames.push(("base_link", "imu_link", [0.0; 3], [1.0, 0.0, 0.0, 0.0]));
    let mut leaves = vec![];
    for (i, (parent, child, translation, rotation)) in frames.into_iter().enumerate() {
        let at = format!("transforms[{i}].");
        leaves.extend(stamp(&at, clock, s.stamps.sample_ns, parent));
        leaves.push((format!("{at}child_frame_id"), json!(child)));
        leaves.extend(xyz(&format!("{at}transform.translation"), translation));
        leaves.extend(xyzw(&format!("{at}transform.rotation"), rotation));
    }
    leaves
}
