//! `mems-ros2 export` on hand-made recordings: a run split across a recorder restart is read
//! as one, each file's messages stamped on its own wall clock; `--out` is never overwritten
//! without `--force`, never the input, never followed through a symbolic link, and is created
//! with mode 0600; a recording without corrected samples or states is refused, leaving no file.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use integration_tests::{path_arg, unique_namespace};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, Stamps, odometry_flags};
use recording::clock::WallClock;
use recording::mcap::{EventKind, RecorderEvent, Writer};

const CLOCKS: [WallClock; 2] = [
    WallClock {
        realtime_ns: 1_795_935_601_000_000_000,
        monotonic_ns: 1_000_000_000_000,
    },
    // The restarted recorder read its clocks 2 s later, and the wall clock had been stepped.
    WallClock {
        realtime_ns: 1_795_935_700_000_000_000,
        monotonic_ns: 1_002_000_000_000,
    },
];
const PERIOD_NS: u64 = 1_000_000;

fn export(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mems-ros2"))
        .arg("export")
        .args(args)
        .output()
        .unwrap()
}

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(unique_namespace(tag));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Segment `n` of a run: 5 corrected samples and 5 aligned states from sequence number 5 n,
/// anchored to `CLOCKS[n]`; a successor starts with its segment event.
fn write_segment(path: &Path, n: u64) {
    let mut writer = Writer::create_new(path).unwrap();
    writer.anchor(CLOCKS[n as usize]).unwrap();
    let t0 = CLOCKS[0].monotonic_ns;
    if n > 0 {
        let events = writer.add_channel::<RecorderEvent>().unwrap();
        let event = RecorderEvent {
            kind: EventKind::Segment,
            service: String::new(),
            from_seq: Some(n),
            to_seq: Some(n),
            t_ns: t0,
        };
        writer.write(events, &event, t0).unwrap();
    }
    let corrected = writer.add_channel::<CorrectedImuSample>().unwrap();
    let odometry = writer.add_channel::<OdometryState>().unwrap();
    for seq in 5 * n..5 * n + 5 {
        let stamps = Stamps {
            sample_ns: t0 + 2_000_000_000 * n + seq * PERIOD_NS,
            ..Stamps::default()
        };
        let sample = CorrectedImuSample {
            stamps,
            seq,
            accel_mps2: [0.0, 0.0, 9.81],
            ..CorrectedImuSample::default()
        };
        writer.write(corrected, &sample, stamps.sample_ns).unwrap();
        let state = OdometryState {
            stamps,
            seq,
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            flags: odometry_flags::ALIGNED,
            ..OdometryState::default()
        };
        writer.write(odometry, &state, stamps.sample_ns).unwrap();
    }
    writer.finish().unwrap();
}

/// (topic, log time, header stamp in ns) of every message of the bag, in file order.
fn stamps(bag: &Path) -> Vec<(String, u64, u64)> {
    let bytes = std::fs::read(bag).unwrap();
    let stream = mcap::MessageStream::new(&bytes).unwrap();
    stream
        .map(|m| {
            let m = m.unwrap();
            // CDR: the 4-byte encapsulation header, then the first header's stamp (a TFMessage
            // starts with its transforms' count).
            let at = if m.channel.topic == "/tf" { 8 } else { 4 };
            let word = |i: usize| u32::from_le_bytes(m.data[i..i + 4].try_into().unwrap());
            let stamp = u64::from(word(at)) * 1_000_000_000 + u64::from(word(at + 4));
            (m.channel.topic.clone(), m.log_time, stamp)
        })
        .collect()
}

#[test]
fn a_split_run_is_read_whole_each_file_on_its_own_clock() {
    let dir = temp_dir("ros2-split");
    let (run, bag) = (dir.join("run.mcap"), dir.join("bag.mcap"));
    write_segment(&run, 0);
    write_segment(&dir.join("run.1.mcap"), 1);
    let out = export(&[path_arg(&run), "--out", path_arg(&bag)]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "/imu/data sensor_msgs/msg/Imu 10\n/odom nav_msgs/msg/Odometry 10\n\
         /odom/revised nav_msgs/msg/Odometry 0\n/tf tf2_msgs/msg/TFMessage 10\n"
    );
    let messages = stamps(&bag);
    assert_eq!(messages.len(), 30);
    let t0 = CLOCKS[0].monotonic_ns;
    for (i, (topic, log, stamp)) in messages.iter().enumerate() {
        let seq = (i / 3) as u64;
        let n = seq / 5;
        let sample_ns = t0 + 2_000_000_000 * n + seq * PERIOD_NS;
        let unix = CLOCKS[n as usize].unix_ns(sample_ns);
        assert_eq!((*stamp, *log), (unix, unix), "{topic} of seq {seq}");
    }
    let mode = std::fs::metadata(&bag).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o600);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn out_is_replaced_only_with_force_and_never_through_a_link_or_over_the_input() {
    let dir = temp_dir("ros2-out");
    let (run, bag) = (dir.join("run.mcap"), dir.join("bag.mcap"));
    write_segment(&run, 0);
    std::fs::write(&bag, "old").unwrap();
    let out = export(&[path_arg(&run), "--out", path_arg(&bag)]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("exists: give --force"));
    assert_eq!(std::fs::read_to_string(&bag).unwrap(), "old");
    assert!(
        export(&[path_arg(&run), "--out", path_arg(&bag), "--force"])
            .status
            .success()
    );
    assert_eq!(stamps(&bag).len(), 15);

    let input = std::fs::read(&run).unwrap();
    let out = export(&[path_arg(&run), "--out", path_arg(&run), "--force"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("is the input's file"));
    assert_eq!(
        std::fs::read(&run).unwrap(),
        input,
        "the input is untouched"
    );

    let (target, link) = (dir.join("target"), dir.join("link.mcap"));
    std::fs::write(&target, "kept").unwrap();
    std::os::unix::fs::symlink(&target, &link).unwrap();
    assert!(
        !export(&[path_arg(&run), "--out", path_arg(&link)])
            .status
            .success()
    );
    assert!(
        export(&[path_arg(&run), "--out", path_arg(&link), "--force"])
            .status
            .success()
    );
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "kept");
    assert!(!std::fs::symlink_metadata(&link).unwrap().is_symlink());
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_raw_recording_is_refused_without_leaving_a_file() {
    let dir = temp_dir("ros2-raw");
    let (raw, bag) = (dir.join("raw.mcap"), dir.join("bag.mcap"));
    let mut writer = Writer::create_new(&raw).unwrap();
    let channel = writer.add_channel::<RawImuSample>().unwrap();
    writer.write(channel, &RawImuSample::default(), 0).unwrap();
    writer.finish().unwrap();
    let out = export(&[path_arg(&raw), "--out", path_arg(&bag)]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("no corrected samples and no odometry states"),
        "{stderr}"
    );
    assert!(stderr.contains("mems-odometry offline"), "{stderr}");
    assert!(!bag.exists());
    std::fs::remove_dir_all(&dir).unwrap();
}
