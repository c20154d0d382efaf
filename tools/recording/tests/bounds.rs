//! Values no sensor produces are refused at every reader, naming file, line (or message) and
//! field; a damaged MCAP length ends the read as a truncation instead of aborting the process.

mod common;

use common::{live_samples, tmp};
use ipc_types::{RawImuSample, limits};
use recording::mcap::run::{RawRun, RunReader};
use recording::{ErrorKind, LogPolicy, Position};

/// Writes `body` and returns the error `load_raw_with` gives for it.
fn csv_error(name: &str, body: &str, policy: LogPolicy) -> recording::Error {
    let path = tmp(name);
    std::fs::write(&path, body).unwrap();
    recording::load_raw_with(&path, policy).expect_err("the file holds an absurd value")
}

#[test]
fn a_csv_value_beyond_the_sensors_range_names_line_and_column() {
    for (i, (value, column)) in [("1e300", "ay_g"), ("100", "ay_g"), ("-20.5", "ay_g")]
        .into_iter()
        .enumerate()
    {
        let body = format!("t_s,ax_g,ay_g,az_g\n0,0,0,1\n0.001,0,{value},1\n0.002,0,0,1\n");
        for policy in [LogPolicy::Strict, LogPolicy::Repair] {
            let err = csv_error(&format!("range_{i}.csv"), &body, policy);
            assert_eq!(err.position, Some(Position::Line(3)), "{err}");
            assert_eq!(err.field.as_deref(), Some(column), "{err}");
            assert!(matches!(err.kind, ErrorKind::OutOfRange(_)), "{err}");
            assert!(
                err.to_string().contains("beyond the sensor's range"),
                "{err}"
            );
        }
    }
    let err = csv_error(
        "range_gyro.csv",
        "t_s,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps,temp_c\n0,0,0,1,0,0,3000,25\n",
        LogPolicy::Strict,
    );
    assert_eq!(err.field.as_deref(), Some("gz_dps"), "{err}");
    let err = csv_error(
        "range_temp.csv",
        "t_s,ax_g,ay_g,az_g,temp_c\n0,0,0,1,25\n0.001,0,0,1,500\n",
        LogPolicy::Strict,
    );
    assert_eq!(
        (err.position, err.field.as_deref()),
        (Some(Position::Line(3)), Some("temp_c"))
    );
    // The thesis format names its own columns.
    let err = csv_error(
        "range_thesis.csv",
        "time,x (g),y (g),z (g)\n0,0,0,1\n0.01,0,0,100\n",
        LogPolicy::Strict,
    );
    assert_eq!(
        (err.position, err.field.as_deref()),
        (Some(Position::Line(3)), Some("z (g)"))
    );
    // Full scale of the largest range reads.
    let path = tmp("range_full_scale.csv");
    std::fs::write(&path, "t_s,ax_g,ay_g,az_g\n0,-16,16,15.9995\n").unwrap();
    assert_eq!(recording::load_raw(&path).unwrap().samples.len(), 1);
}

#[test]
fn an_hour_long_step_is_refused_and_the_repair_of_small_steps_still_works() {
    let body = "t_s,ax_g,ay_g,az_g\n0,0,0.1,1\n0.001,0,0.2,1\n3600.001,0,0.3,1\n3600.002,0,0.4,1\n";
    for policy in [LogPolicy::Strict, LogPolicy::Repair] {
        let err = csv_error("gap_hour.csv", body, policy);
        assert_eq!(err.position, Some(Position::Line(4)), "{err}");
        assert_eq!(err.field.as_deref(), Some("t_s"), "{err}");
        assert!(matches!(err.kind, ErrorKind::TimeStep { .. }), "{err}");
        assert!(err.to_string().contains("3600.000000000 s ahead"), "{err}");
    }
    // A step just within the bound reads; so does a repaired repeat next to it.
    let path = tmp("gap_within.csv");
    let within = limits::MAX_STEP_S - 0.5;
    std::fs::write(
        &path,
        format!(
            "t_s,ax_g,ay_g,az_g\n0,0,0,1\n0.001,0,0.1,1\n0.001,0,0.2,1\n0.002,0,0.3,1\n{},0,0,1\n",
            0.002 + within
        ),
    )
    .unwrap();
    let rec = recording::load_raw_with(&path, LogPolicy::Repair).unwrap();
    assert_eq!(rec.samples.len(), 5);
    assert!(rec.repairs.times_rebuilt > 0);
}

#[test]
fn a_means_file_with_an_absurd_entry_names_line_and_column() {
    let header =
        "x_true (g),x_mean (g),x_std,y_true (g),y_mean (g),y_std,z_true (g),z_mean (g),z_std";
    let good = "0,0.01,0.002,0,0.02,0.002,1,0.99,0.004";
    for (i, (row, column)) in [
        ("0,0.01,0.002,0,1e300,0.002,1,0.99,0.004", "y_mean (g)"),
        ("0,0.01,0.002,0,0.02,-1,1,0.99,0.004", "y_std"),
        ("0,0.01,0.002,0,0.02,0.002,1,3.5,0.004", "x_mean (g)"),
        ("0,0.01,0.002,0,0.02,0.002,5,0.99,0.004", "x_true (g)"),
    ]
    .into_iter()
    .enumerate()
    {
        let path = tmp(&format!("means_{i}.csv"));
        std::fs::write(&path, format!("{header}\n{good}\n{row}\n")).unwrap();
        let err = recording::load_six_position(&path).expect_err("absurd pose");
        assert_eq!(err.position, Some(Position::Line(3)), "{err}");
        assert_eq!(err.field.as_deref(), Some(column), "{err}");
    }
}

/// Writes raw samples to an MCAP file the recorder's way.
fn write_mcap(name: &str, samples: &[RawImuSample]) -> std::path::PathBuf {
    let path = tmp(name);
    let mut writer = recording::mcap::Writer::create(&path).unwrap();
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    for s in samples {
        writer.write(raw, s, s.stamps.sample_ns).unwrap();
    }
    writer.finish().unwrap();
    path
}

#[test]
fn an_mcap_raw_sample_beyond_range_or_after_an_hour_names_its_message() {
    let mut samples = live_samples(50, 7);
    samples[20].accel_g[1] = 1e300;
    let path = write_mcap("range.mcap", &samples);
    let err = recording::mcap::read_all(&path).unwrap_err();
    assert_eq!(err.position, Some(Position::Message(21)), "{err}");
    assert_eq!(err.field.as_deref(), Some("mems/imu/raw: accel_g[1]"));
    assert!(matches!(err.kind, ErrorKind::OutOfRange(_)), "{err}");
    // Streamed, the same error after the 20 samples before it, and nothing after it.
    let items: Vec<_> = RawRun::open(&path, false).unwrap().collect();
    assert_eq!(items.len(), 21);
    let streamed = items[20].as_ref().unwrap_err();
    assert_eq!(streamed.to_string(), err.to_string());

    let mut samples = live_samples(50, 8);
    for s in &mut samples[30..] {
        s.stamps.sample_ns += 3_600_000_000_000;
    }
    let path = write_mcap("gap.mcap", &samples);
    let err = recording::load_raw(&path).unwrap_err();
    assert_eq!(err.position, Some(Position::Message(31)), "{err}");
    assert!(matches!(err.kind, ErrorKind::TimeStep { .. }), "{err}");
    let streamed = RawRun::open(&path, false).unwrap().find_map(Result::err);
    assert_eq!(streamed.map(|e| e.to_string()), Some(err.to_string()));

    // A raw stream that restarts (a second session) is refused when streamed, naming it.
    let mut samples = live_samples(50, 9);
    samples.extend(live_samples(10, 10));
    let path = write_mcap("restart.mcap", &samples);
    let err = RawRun::open(&path, false)
        .unwrap()
        .find_map(Result::err)
        .unwrap();
    assert_eq!(err.position, Some(Position::Message(51)), "{err}");
    assert!(
        matches!(err.kind, ErrorKind::SessionRestart { index: 50, .. }),
        "{err}"
    );
}

/// The messages a streamed read of `path` yields, and its file's truncation.
fn streamed(path: &std::path::Path) -> (usize, Option<recording::mcap::Truncation>) {
    let mut run = RunReader::open(path).unwrap();
    let mut n = 0;
    while let Some(m) = run.next() {
        m.unwrap();
        n += 1;
    }
    (n, run.segments()[0].truncation.clone())
}

/// Byte offsets of the uncompressed-size fields of the file's chunk headers (opcode 0x06,
/// then the body length, the start and end times, and the size).
fn chunk_size_fields(bytes: &[u8]) -> Vec<usize> {
    let mut at = 8;
    let mut found = Vec::new();
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        if bytes[at] == 0x06 {
            found.push(at + 9 + 16);
        }
        at += 9 + len;
    }
    found
}

#[test]
fn a_damaged_chunk_size_ends_the_read_as_a_truncation_without_aborting() {
    let samples = live_samples(3000, 9);
    let path = write_mcap("hostile.mcap", &samples);
    let clean = std::fs::read(&path).unwrap();
    let fields = chunk_size_fields(&clean);
    assert!(!fields.is_empty(), "the writer makes chunks");
    // The top byte of the first chunk's uncompressed size: 0x65 there asks for 7.3e18 bytes.
    let mut hostile = clean.clone();
    hostile[fields[0] + 7] = 0x65;
    std::fs::write(&path, &hostile).unwrap();
    let contents = recording::mcap::read_all(&path).unwrap();
    let cut = contents.truncation.expect("the damage is reported");
    assert_eq!(cut.messages_read, 0);
    assert!(cut.reason.contains("declares"), "{}", cut.reason);
    assert!(contents.raw.is_empty());
    // The streamed read walks the framing with seeks and stops at the same place.
    assert_eq!(streamed(&path), (0, Some(cut)));
    // A size a little too large for the data is the crate's own error: the chunk's framing
    // is intact, so it is skipped and reported, and the read goes on.
    let mut short = clean.clone();
    short[fields[0] + 1] ^= 0x01;
    std::fs::write(&path, &short).unwrap();
    let contents = recording::mcap::read_all(&path).unwrap();
    assert_eq!(contents.truncation, None);
    assert_eq!(
        contents.segments[0].damaged.len(),
        1,
        "{:?}",
        contents.segments
    );
    assert_eq!(streamed(&path), (contents.raw.len(), None));
}

/// A chunk with a changed data byte (its CRC fails) or a changed opcode is skipped and reported
/// with its offset and the messages it held, by both readers, and the read goes on after it.
#[test]
fn a_damaged_chunk_is_skipped_and_reported_with_what_it_held() {
    let samples = live_samples(3000, 11);
    let path = tmp("chunks.mcap");
    let mut writer = recording::mcap::Writer::create_tuned(&path, 0, 16 << 10).unwrap();
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    for s in &samples {
        writer.write(raw, s, s.stamps.sample_ns).unwrap();
    }
    writer.finish().unwrap();
    let clean = std::fs::read(&path).unwrap();
    let chunks: Vec<usize> = chunk_size_fields(&clean).iter().map(|f| f - 25).collect();
    assert!(chunks.len() > 3, "{} chunks", chunks.len());
    let at = chunks[1];
    for (name, spoil) in [("crc", at + 200), ("opcode", at)] {
        let mut bytes = clean.clone();
        bytes[spoil] ^= 0x55;
        let damaged = tmp(&format!("damaged-{name}.mcap"));
        std::fs::write(&damaged, &bytes).unwrap();

        let contents = recording::mcap::read_all(&damaged).unwrap();
        assert_eq!(
            contents.truncation, None,
            "{name}: read on after the damage"
        );
        let [segment] = &contents.segments[..] else {
            panic!("one file")
        };
        let [damage] = &segment.damaged[..] else {
            panic!("{name}: one damaged record, got {:?}", segment.damaged)
        };
        assert_eq!(damage.offset, at as u64, "{name}: {damage}");
        let lost = damage.messages_lost() as usize;
        assert!(lost > 0, "{name}: {damage}");
        assert_eq!(damage.lost[0].0, "mems/imu/raw", "{name}: {damage}");
        assert!(damage.log_time_ns.is_some(), "{name}: {damage}");
        assert_eq!(contents.raw.len() + lost, samples.len(), "{name}: {damage}");
        assert!(
            damage.to_string().contains(&format!("at byte {at}")),
            "{damage}"
        );

        let mut run = RunReader::open(&damaged).unwrap();
        let mut n = 0;
        while let Some(m) = run.next() {
            m.unwrap();
            n += 1;
        }
        assert_eq!(n + lost, samples.len(), "{name}: streamed");
        assert_eq!(
            run.segments()[0].damaged,
            segment.damaged,
            "{name}: streamed"
        );
    }
}
