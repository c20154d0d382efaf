//! `mems-info` on runs written by the recording crate's MCAP writer (the recorder's own): its
//! counts against the official Python MCAP reader's, and a two-segment run whose second
//! file was cut (a killed recorder) with its sequence gap, revisions and events, and the
//! wall-clock start and end of an anchored run.

use std::path::{Path, PathBuf};
use std::process::Command;

use ipc_types::{
    CorrectedImuSample, OdometryState, RawImuSample, Stamps, odometry_flags, raw_flags,
};
use recording::mcap::{EventKind, PoseInFrame, RecorderEvent, Writer};
use serde_json::Value;

/// The official reader's version, as `.ci/run` installs it.
const PYTHON_MCAP: &str = "mcap==1.6.0";
const CALIB_ID: u64 = 0x0c11_c160_99d2_0acc;

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mems-info-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn stamps(seq: u64) -> Stamps {
    Stamps {
        sample_ns: 1_000_000_000 + seq * 1_000_000,
        acquired_ns: 1_000_100_000 + seq * 1_000_000,
        ..Stamps::default()
    }
}

fn raw(seq: u64) -> RawImuSample {
    RawImuSample {
        stamps: stamps(seq),
        seq,
        accel_g: [0.0, 0.0, 1.0],
        flags: raw_flags::GYRO_VALID,
        lost_before: u32::from(seq == 40) * 3,
        undelivered: u32::try_from(seq / 50).unwrap(),
        ..RawImuSample::default()
    }
}

/// Writes raw, corrected and odometry messages for `seqs` (each odometry state with its pose,
/// and a revision of the previous state every tenth sample) to `writer`.
fn write_samples(writer: &mut Writer, seqs: impl Iterator<Item = u64>) {
    let raw_ch = writer.add_channel::<RawImuSample>().unwrap();
    let cor_ch = writer.add_channel::<CorrectedImuSample>().unwrap();
    let odo_ch = writer.add_channel::<OdometryState>().unwrap();
    let pose_ch = writer.add_channel::<PoseInFrame>().unwrap();
    for seq in seqs {
        let log_ns = 1_000_200_000 + seq * 1_000_000;
        writer.write(raw_ch, &raw(seq), log_ns).unwrap();
        let corrected = CorrectedImuSample {
            stamps: stamps(seq),
            seq,
            calib_id: CALIB_ID,
            ..CorrectedImuSample::default()
        };
        writer.write(cor_ch, &corrected, log_ns).unwrap();
        let mut states = vec![OdometryState {
            stamps: stamps(seq),
            seq,
            attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
            ..OdometryState::default()
        }];
        if seq % 10 == 0 && seq > 0 {
            states.push(OdometryState {
                flags: odometry_flags::REVISION,
                ..states[0]
            });
            states[1].seq -= 1;
        }
        for state in &states {
            writer.write(odo_ch, state, log_ns).unwrap();
            writer
                .write(pose_ch, &PoseInFrame::from_state(state), log_ns)
                .unwrap();
        }
    }
}

fn mems_info(path: &Path) -> Value {
    let output = Command::new(env!("CARGO_BIN_EXE_mems-info"))
        .arg(path)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "mems-info failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap()
}

/// Messages per topic as the official Python reader counts them; fails (does not skip) when
/// the `mcap` package is missing.
fn python_counts(path: &Path) -> Value {
    let script = "import json, sys\n\
        try:\n    from mcap.reader import make_reader\n\
        except ImportError:\n    sys.exit(3)\n\
        counts = {}\n\
        with open(sys.argv[1], 'rb') as f:\n\
        \x20   for _schema, channel, _message in make_reader(f).iter_messages():\n\
        \x20       counts[channel.topic] = counts.get(channel.topic, 0) + 1\n\
        print(json.dumps(counts))\n";
    let output = Command::new("python3")
        .args(["-c", script])
        .arg(path)
        .output()
        .expect("cannot run python3: install Python 3 (CI: .ci/run)");
    assert!(
        output.status.code() != Some(3),
        "the Python package `mcap` is not installed: run .ci/run or `python3 -m pip install \
         {PYTHON_MCAP}`"
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).unwrap()
}

#[test]
fn counts_match_the_official_reader() {
    let dir = temp_dir("counts");
    let path = dir.join("run.mcap");
    let mut writer = Writer::create(&path).unwrap();
    // 1.2 s: a rate is given over a span of at least a second.
    write_samples(&mut writer, 0..1200);
    writer.finish().unwrap();

    let info = mems_info(&path);
    let official = python_counts(&path);
    let topics = info["topics"].as_object().unwrap();
    assert_eq!(topics.len(), official.as_object().unwrap().len(), "{info}");
    for (topic, count) in official.as_object().unwrap() {
        assert_eq!(topics[topic]["count"], *count, "{topic}");
    }
    let raw = &topics["mems/imu/raw"];
    assert_eq!(raw["count"], 1200);
    assert!(
        (raw["rate_hz"].as_f64().unwrap() - 1000.0).abs() < 1e-6,
        "{raw}"
    );
    assert_eq!(
        info["raw"]["sample_rate_hz"].as_f64().unwrap().round(),
        1000.0
    );
    assert_eq!(info["raw"]["lost_at_sensor"], 3);
    assert_eq!(
        info["raw"]["undelivered"], 23,
        "the last running total (seq 1199 / 50)"
    );
    assert_eq!(info["raw"]["gyro"], true);
    assert_eq!(topics["mems/odometry/state"]["revisions"], 119);
    assert_eq!(
        topics["mems/odometry/state"]["seq_gaps"], 0,
        "revisions are no gaps"
    );
    assert_eq!(topics["mems/odometry/pose"]["sequenced"], false);
    assert_eq!(
        info["calib_ids"],
        serde_json::json!([format!("{CALIB_ID:016x}")])
    );
    assert_eq!(info["files"][0]["truncated"], Value::Null);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A recorder killed in its second segment: the run is read across both files, the cut is
/// reported with the messages before it counted, and the split's gap shows twice, in the
/// sequence numbers and in the recorder's event.
#[test]
fn a_cut_two_segment_run_reads_as_one() {
    let dir = temp_dir("segments");
    let base = dir.join("run.mcap");
    let mut first = Writer::create(&base).unwrap();
    write_samples(&mut first, 0..100);
    first.finish().unwrap();

    let second_path = recording::segment::path(&base, 1);
    let mut second = Writer::create(&second_path).unwrap();
    let events = second.add_channel::<RecorderEvent>().unwrap();
    let event = |kind, service: &str, from, to| RecorderEvent {
        kind,
        service: service.into(),
        from_seq: Some(from),
        to_seq: Some(to),
        t_ns: 1_100_000_000,
    };
    second
        .write(events, &event(EventKind::Segment, "", 1, 1), 1_100_000_000)
        .unwrap();
    second
        .write(
            events,
            &event(EventKind::Gap, "mems/imu/raw", 100, 104),
            1_100_000_000,
        )
        .unwrap();
    write_samples(&mut second, 105..150);
    second.finish().unwrap();
    // Cut the footer and summary off, as a SIGKILL before the clean finish leaves the file.
    let bytes = std::fs::read(&second_path).unwrap();
    let messages_end = bytes.len() * 3 / 4;
    std::fs::write(&second_path, &bytes[..messages_end]).unwrap();

    let info = mems_info(&base);
    let files = info["files"].as_array().unwrap();
    assert_eq!(files.len(), 2, "{info}");
    assert_eq!(files[0]["truncated"], Value::Null);
    assert!(files[1]["truncated"].is_string(), "{info}");
    let raw = &info["topics"]["mems/imu/raw"];
    let raw_count = raw["count"].as_u64().unwrap();
    assert!(
        (100..150).contains(&raw_count) && raw_count > 100,
        "the first file's 100 and some of the cut second's: {raw}"
    );
    assert_eq!(raw["seq_gaps"], 1, "{raw}");
    assert_eq!(raw["seq_missing"], 5, "{raw}");
    assert_eq!(raw["seq_restarts"], 0, "{raw}");
    assert_eq!(info["raw"]["sessions"], 1);
    assert_eq!(info["events"]["segment"], 1);
    assert_eq!(info["events"]["gap"], 1);
    assert_eq!(info["events"]["gap_missing"], 5);
    let total: u64 = files.iter().map(|f| f["messages"].as_u64().unwrap()).sum();
    assert_eq!(info["messages"], total);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_file_that_is_not_mcap_is_named() {
    let dir = temp_dir("bad");
    let path = dir.join("notes.mcap");
    std::fs::write(&path, "not an mcap file\n").unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_mems-info"))
        .arg(&path)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("notes.mcap") && stderr.contains("MCAP"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A recording anchored to the wall clock: `mems-info` prints its start and end as UTC dates
/// (the anchor's realtime reading is 2026-11-25T05:00:01Z, `date -u -d @1795582801`), with the
/// anchor; an older, monotonic-only recording has none.
#[test]
fn an_anchored_run_has_wall_clock_start_and_end() {
    let dir = temp_dir("clock");
    let path = dir.join("run.mcap");
    let mut writer = Writer::create(&path).unwrap();
    // Monotonic 0.5 s before the first message's log time (write_samples: 1_000_200_000).
    let clock = recording::clock::WallClock {
        realtime_ns: 1_795_582_801_000_000_000,
        monotonic_ns: 1_000_200_000 - 500_000_000,
    };
    writer.anchor(clock).unwrap();
    write_samples(&mut writer, 0..100);
    writer.finish().unwrap();
    let info = mems_info(&path);
    let wall = &info["wall_clock"];
    assert_eq!(
        wall["start_utc"], "2026-11-25T05:00:01.500000000Z",
        "{info}"
    );
    // The last sample (seq 99) is received 99 ms later.
    assert_eq!(wall["end_utc"], "2026-11-25T05:00:01.599000000Z", "{info}");
    assert_eq!(
        wall["offset_ns"].as_i64().unwrap(),
        1_795_582_801_000_000_000 - 500_200_000
    );
    assert_eq!(info["start_ns"].as_u64(), Some(1_795_582_801_500_000_000));

    let old = dir.join("old.mcap");
    let mut writer = Writer::create(&old).unwrap();
    write_samples(&mut writer, 0..10);
    writer.finish().unwrap();
    assert!(mems_info(&old)["wall_clock"].is_null());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Two messages 20 us apart (a burst of revised poses) have no rate: `-` in the table, null in
/// JSON, where a rate over their span would be 50 000 Hz.
#[test]
fn a_topic_without_a_second_of_span_has_no_rate() {
    let dir = temp_dir("no-rate");
    let path = dir.join("run.mcap");
    let mut writer = Writer::create(&path).unwrap();
    let raw_ch = writer.add_channel::<RawImuSample>().unwrap();
    for seq in 0..1200 {
        writer
            .write(raw_ch, &raw(seq), 1_000_200_000 + seq * 1_000_000)
            .unwrap();
    }
    let pose_ch = writer.add_channel::<PoseInFrame>().unwrap();
    let state = OdometryState {
        attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
        ..OdometryState::default()
    };
    for log_ns in [2_000_000_000, 2_000_020_000] {
        writer
            .write(pose_ch, &PoseInFrame::from_state(&state), log_ns)
            .unwrap();
    }
    writer.finish().unwrap();

    let info = mems_info(&path);
    assert_eq!(info["topics"]["mems/odometry/pose"]["count"], 2);
    assert_eq!(info["topics"]["mems/odometry/pose"]["rate_hz"], Value::Null);
    let table = Command::new(env!("CARGO_BIN_EXE_mems-info"))
        .arg(&path)
        .output()
        .unwrap();
    let table = String::from_utf8(table.stdout).unwrap();
    let pose = table
        .lines()
        .find(|l| l.contains("mems/odometry/pose"))
        .unwrap_or_else(|| panic!("{table}"));
    assert!(pose.contains("msgs         - Hz"), "{pose}");
    let raw = table.lines().find(|l| l.contains("mems/imu/raw")).unwrap();
    assert!(raw.contains("msgs    1000.0 Hz"), "{raw}");
    std::fs::remove_dir_all(&dir).unwrap();
}
