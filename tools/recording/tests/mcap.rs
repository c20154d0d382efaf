//! MCAP recordings: bit-exact round trips, truncated files read up to the cut, clear errors.

mod common;

use std::path::Path;

use common::{any_truth, any_within, live_samples, sample_bits, tmp, truth_bits};
use ipc_types::{RawImuSample, limits};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use recording::mcap::{MessageEncoding, Reader, Topic, Writer, read_all};
use recording::{ErrorKind, Format, Position, Truth};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// Samples with arbitrary floats within the sensor's range (all such bit patterns), to check
/// exactness.
fn arbitrary_samples(n: usize, seed: u64) -> Vec<RawImuSample> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut samples = live_samples(n, seed);
    for (i, s) in samples.iter_mut().enumerate() {
        s.accel_g = [0.0; 3].map(|_| any_within(&mut rng, limits::ACCEL_LIMIT_G));
        s.gyro_dps = [0.0; 3].map(|_| any_within(&mut rng, limits::GYRO_LIMIT_DPS));
        s.temp_c = any_within(&mut rng, limits::TEMP_MAX_C);
        s.stamps.acquired_ns = s.stamps.sample_ns + 1000 + i as u64;
        s.stamps.calibrated_ns = u64::MAX - i as u64;
        s.seq = 1_000_000 + 3 * i as u64;
        s.undelivered = i as u32;
    }
    samples[0].accel_g[0] = -0.0;
    samples
}

/// Log time the test writer uses for sample `i` (distinct from the publish time).
fn log_time(i: usize) -> u64 {
    7_000_000_000 + 1_000 * i as u64
}

/// Writes samples (and truth), flushing every `flush_every` samples; returns the file length
/// after each flush (the byte offset where every message written so far is complete).
fn write(path: &Path, samples: &[RawImuSample], truth: &[Truth], flush_every: usize) -> Vec<u64> {
    write_in(path, samples, truth, flush_every, MessageEncoding::Protobuf)
}

/// [`write`] in `encoding`.
fn write_in(
    path: &Path,
    samples: &[RawImuSample],
    truth: &[Truth],
    flush_every: usize,
    encoding: MessageEncoding,
) -> Vec<u64> {
    let mut writer = Writer::create(path).unwrap().with_encoding(encoding);
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    let truth_channel = writer.add_channel::<Truth>().unwrap();
    for (i, sample) in samples.iter().enumerate() {
        writer.write(raw, sample, log_time(i)).unwrap();
        writer
            .write(truth_channel, &truth[i], log_time(i) + 1)
            .unwrap();
        if (i + 1) % flush_every == 0 {
            writer.flush().unwrap();
        }
    }
    writer.finish().unwrap();
    flush_boundaries(&std::fs::read(path).unwrap())
}

/// Where each chunk's message indexes end in the MCAP file `bytes` (the file is written
/// beside its path and renamed when finished: these are the lengths it had after each flush).
fn flush_boundaries(bytes: &[u8]) -> Vec<u64> {
    let (mut at, mut in_chunk, mut ends) = (8, false, Vec::new());
    while at + 9 <= bytes.len() {
        let opcode = bytes[at];
        if in_chunk && opcode != 0x07 {
            ends.push(at as u64);
            in_chunk = false;
        }
        if opcode == 0x0f {
            break;
        }
        in_chunk |= opcode == 0x06;
        at += 9 + u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
    }
    ends
}

/// In both encodings (protobuf as written now, JSON as in older recordings).
#[test]
fn messages_round_trip_bit_for_bit_with_their_times() {
    round_trip(MessageEncoding::Protobuf, "protobuf");
    round_trip(MessageEncoding::Json, "json");
}

fn round_trip(encoding: MessageEncoding, name: &str) {
    let samples = arbitrary_samples(400, 11);
    let truth = any_truth(&samples, 12);
    let path = tmp(&format!("roundtrip-{name}.mcap"));
    write_in(&path, &samples, &truth, 64, encoding);

    let reader = Reader::open(&path).unwrap();
    let mut raw_read = 0;
    for (n, message) in reader.messages().unwrap().enumerate() {
        let message = message.unwrap();
        let i = n / 2;
        assert_eq!(message.index, n as u64 + 1);
        if n % 2 == 0 {
            assert_eq!(message.topic, "mems/imu/raw");
            assert_eq!(message.schema_name, "mems.RawImuSample");
            assert_eq!(message.encoding, name);
            assert_eq!(message.schema_encoding, encoding.schema());
            assert_eq!(message.log_time_ns, log_time(i));
            assert_eq!(message.publish_time_ns, samples[i].stamps.sample_ns);
            assert!(message.decode::<Truth>().is_none());
            let sample: RawImuSample = message.decode().unwrap().unwrap();
            assert_eq!(sample, samples[i]);
            assert_eq!(sample_bits(&sample), sample_bits(&samples[i]));
            raw_read += 1;
        } else {
            assert_eq!(message.topic, "mems/sim/truth");
            assert_eq!(message.log_time_ns, log_time(i) + 1);
            assert_eq!(message.publish_time_ns, truth[i].t_ns);
            let t: Truth = message.decode().unwrap().unwrap();
            assert_eq!(truth_bits(&t), truth_bits(&truth[i]));
            assert_eq!(t, truth[i]);
        }
    }
    assert_eq!(raw_read, samples.len());

    let contents = read_all(&path).unwrap();
    assert_eq!(contents.truncation, None);
    assert_eq!(contents.raw, samples);
    assert_eq!(contents.truth, truth);
    assert_eq!(contents.other_messages, 0);

    let rec = recording::load_raw(&path).unwrap();
    assert_eq!(rec.format, Format::Mcap);
    assert_eq!(rec.samples, samples);
    assert_eq!(rec.truth.as_deref(), Some(&truth[..]));
    assert_eq!(rec.truncation, None);
}

#[test]
fn truncated_file_yields_every_message_before_the_cut() {
    let samples = live_samples(300, 21);
    let truth = any_truth(&samples, 22);
    let path = tmp("full.mcap");
    let per_chunk = 25;
    let boundaries = write(&path, &samples, &truth, per_chunk);
    let bytes = std::fs::read(&path).unwrap();
    let data_end = *boundaries.last().unwrap();
    assert!(
        data_end < bytes.len() as u64,
        "summary and footer follow the data"
    );

    // (cut offset, samples complete before it): at each flush boundary, every sample written
    // before that flush; halfway to the next boundary (inside the next chunk, whose compressed
    // messages are far larger than the message indexes that follow it), still only those; in
    // the summary, all of them.
    let mut cuts: Vec<(u64, usize)> = vec![(8, 0), (boundaries[0] / 2, 0)];
    for (k, &boundary) in boundaries.iter().enumerate() {
        let complete = per_chunk * (k + 1);
        cuts.push((boundary, complete));
        if let Some(&next) = boundaries.get(k + 1) {
            cuts.push(((boundary + next) / 2, complete));
        }
    }
    cuts.push((
        data_end + (bytes.len() as u64 - data_end) / 2,
        samples.len(),
    ));

    for (cut, complete) in cuts {
        let cut_path = tmp("cut.mcap");
        std::fs::write(&cut_path, &bytes[..cut as usize]).unwrap();
        let contents = read_all(&cut_path).unwrap();
        assert_eq!(contents.raw, samples[..complete], "cut at {cut}");
        assert_eq!(contents.truth, truth[..complete], "cut at {cut}");
        let truncation = contents
            .truncation
            .expect("a cut file is reported as truncated");
        assert_eq!(
            truncation.messages_read,
            2 * complete as u64,
            "cut at {cut}"
        );
        assert!(!truncation.reason.is_empty());

        // Through load_raw as well, and via the iterator: the last item reports the cut.
        let rec = recording::load_raw(&cut_path).unwrap();
        assert_eq!(rec.samples.len(), complete);
        assert_eq!(rec.truncation.as_ref(), Some(&truncation));
        let reader = Reader::open(&cut_path).unwrap();
        let last = reader.messages().unwrap().last().unwrap();
        let err = last.expect_err("the iterator ends with the truncation");
        assert!(matches!(err.kind, ErrorKind::Truncated(_)));
        assert!(
            err.to_string()
                .contains(&format!("after {} complete messages", 2 * complete)),
            "{err}"
        );
    }
}

#[test]
fn any_cut_yields_a_prefix_bounded_by_the_flushes() {
    let samples = live_samples(200, 23);
    let truth = any_truth(&samples, 24);
    let path = tmp("full_for_cuts.mcap");
    let per_chunk = 20;
    let boundaries = write(&path, &samples, &truth, per_chunk);
    let bytes = std::fs::read(&path).unwrap();
    for cut in (0..=bytes.len()).step_by(251).chain([bytes.len()]) {
        let cut_path = tmp("any_cut.mcap");
        std::fs::write(&cut_path, &bytes[..cut]).unwrap();
        if cut < 8 {
            // Not even the magic: not recognisable as MCAP.
            assert!(read_all(&cut_path).is_err());
            continue;
        }
        let contents = read_all(&cut_path).unwrap();
        let flushed = boundaries.iter().filter(|&&b| b <= cut as u64).count();
        let lower = per_chunk * flushed;
        let upper = (lower + per_chunk).min(samples.len());
        let n = contents.raw.len();
        assert!(
            (lower..=upper).contains(&n),
            "cut at {cut}: {n} samples, expected {lower}..={upper}"
        );
        assert_eq!(contents.raw, samples[..n]);
        assert_eq!(contents.truth, truth[..contents.truth.len()]);
        assert_eq!(
            contents.truncation.is_some(),
            cut < bytes.len(),
            "cut at {cut}"
        );
    }
}

#[test]
fn garbage_files_give_clear_errors_naming_the_file() {
    let path = tmp("garbage.mcap");
    std::fs::write(&path, b"\x00\x01garbage, not an MCAP file\xff\xfe").unwrap();
    let err = read_all(&path).unwrap_err();
    assert!(matches!(err.kind, ErrorKind::UnknownFormat(_)), "{err}");
    assert_eq!(
        err.to_string(),
        format!(
            "{}: not a recognised recording: does not start with the MCAP magic bytes",
            path.display()
        )
    );
    assert!(
        recording::load_raw(&path)
            .unwrap_err()
            .to_string()
            .starts_with(&path.display().to_string())
    );

    // The magic followed by garbage: nothing readable, reported as damaged, not silently empty.
    let mut bytes = b"\x89MCAP0\r\n".to_vec();
    bytes.extend_from_slice(&[0xAB; 100]);
    std::fs::write(&path, &bytes).unwrap();
    let contents = read_all(&path).unwrap();
    assert!(contents.raw.is_empty());
    assert_eq!(contents.truncation.unwrap().messages_read, 0);

    let missing = tmp("does_not_exist.mcap");
    let err = read_all(&missing).unwrap_err();
    assert!(matches!(err.kind, ErrorKind::Io(_)));
    assert!(err.to_string().starts_with(&missing.display().to_string()));
}

/// JSON cannot hold them (protobuf can: see the crate's unit tests).
#[test]
fn non_finite_values_are_refused_when_writing_json() {
    let path = tmp("nan.mcap");
    let mut writer = Writer::create(&path)
        .unwrap()
        .with_encoding(MessageEncoding::Json);
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    let mut sample = live_samples(1, 31)[0];
    sample.gyro_dps[1] = f64::INFINITY;
    let err = writer.write(raw, &sample, 0).unwrap_err();
    assert_eq!(err.field.as_deref(), Some("mems/imu/raw"));
    assert!(err.to_string().contains("NaN or infinity"), "{err}");
}

#[test]
fn raw_sample_times_must_increase() {
    let mut samples = live_samples(3, 41);
    samples[2].stamps.sample_ns = samples[0].stamps.sample_ns;
    let path = tmp("backwards.mcap");
    let mut writer = Writer::create(&path).unwrap();
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    for s in &samples {
        writer.write(raw, s, 0).unwrap();
    }
    writer.finish().unwrap();
    let err = read_all(&path).unwrap_err();
    assert_eq!(err.position, Some(Position::Message(3)));
    assert!(matches!(err.kind, ErrorKind::TimeBackwards { .. }), "{err}");
}

/// A raw stream that restarts inside one file (a replay recorded twice, whose times start
/// over; then a restarted acquisition, whose times go on) is split into its sessions, each
/// read back bit for bit; `load_raw`, which returns one time-ordered session, refuses the file
/// naming the first restart.
#[test]
fn restarted_raw_streams_are_split_into_sessions() {
    let first = live_samples(300, 51);
    let second = live_samples(200, 52); // seq from 0 again, times from the same origin
    let mut third = live_samples(100, 53);
    let last_ns = second.last().unwrap().stamps.sample_ns;
    for s in &mut third {
        s.stamps.sample_ns += last_ns; // later than everything before: a live restart
    }
    assert!(second[0].stamps.sample_ns < first.last().unwrap().stamps.sample_ns);
    let path = tmp("sessions.mcap");
    let mut writer = Writer::create(&path).unwrap();
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    for s in first.iter().chain(&second).chain(&third) {
        writer.write(raw, s, s.stamps.sample_ns).unwrap();
    }
    writer.finish().unwrap();

    let contents = read_all(&path).unwrap();
    assert_eq!(contents.raw_sessions, [0..300, 300..500, 500..600]);
    for (i, want) in [&first, &second, &third].into_iter().enumerate() {
        let got = contents.raw_session(i);
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(want.iter()) {
            assert_eq!(sample_bits(g), sample_bits(w));
        }
    }

    let err = recording::load_raw(&path).unwrap_err();
    assert!(
        matches!(
            err.kind,
            ErrorKind::SeveralSessions {
                sessions: 3,
                index: 300,
                previous_seq: 299,
                seq: 0
            }
        ),
        "{err}"
    );
    let message = err.to_string();
    assert!(
        message.contains("sessions.mcap") && message.contains("299 -> 0"),
        "{message}"
    );

    // One session: no split, and load_raw accepts it.
    let path = tmp("one-session.mcap");
    write(&path, &first, &any_truth(&first, 1), 100);
    let sessions = read_all(&path).unwrap().raw_sessions;
    assert_eq!((sessions.len(), &sessions[0]), (1, &(0..300)));
    assert_eq!(recording::load_raw(&path).unwrap().samples.len(), 300);
}

/// A message type defined outside the crate: implementing `Topic` (its JSON Schema, its
/// protobuf message and descriptor) is all it takes to record it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Hint {
    t_ns: u64,
    speed_mps: f64,
}

/// The protobuf form of [`Hint`].
#[derive(Clone, PartialEq, prost::Message)]
struct HintProto {
    #[prost(uint64, tag = 1)]
    t_ns: u64,
    #[prost(double, tag = 2)]
    speed_mps: f64,
}

impl Topic for Hint {
    const TOPIC: &'static str = "mems/test/hint";
    const SCHEMA_NAME: &'static str = "test.Hint";
    type Proto = HintProto;

    fn proto_schema() -> Vec<u8> {
        use prost_types::field_descriptor_proto::Type;
        let field = |name: &str, number, ty: Type| prost_types::FieldDescriptorProto {
            name: Some(name.into()),
            number: Some(number),
            r#type: Some(ty as i32),
            ..Default::default()
        };
        let file = prost_types::FileDescriptorProto {
            name: Some("test.proto".into()),
            package: Some("test".into()),
            syntax: Some("proto3".into()),
            message_type: vec![prost_types::DescriptorProto {
                name: Some("Hint".into()),
                field: vec![
                    field("t_ns", 1, Type::Uint64),
                    field("speed_mps", 2, Type::Double),
                ],
                ..Default::default()
            }],
            ..Default::default()
        };
        prost::Message::encode_to_vec(&prost_types::FileDescriptorSet { file: vec![file] })
    }

    fn fill_proto(&self, p: &mut HintProto) {
        p.t_ns = self.t_ns;
        p.speed_mps = self.speed_mps;
    }

    fn from_proto(p: HintProto) -> Result<Self, String> {
        Ok(Self {
            t_ns: p.t_ns,
            speed_mps: p.speed_mps,
        })
    }

    fn json_schema() -> Value {
        json!({
            "type": "object",
            "properties": {"t_ns": {"type": "integer"}, "speed_mps": {"type": "number"}},
        })
    }

    fn publish_time_ns(&self) -> u64 {
        self.t_ns
    }

    fn is_finite(&self) -> bool {
        self.speed_mps.is_finite()
    }
}

#[test]
fn further_channels_take_one_call_and_are_counted_by_read_all() {
    let samples = live_samples(4, 51);
    let path = tmp("extra_channel.mcap");
    let mut writer = Writer::create(&path).unwrap();
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    let hint = writer.add_channel::<Hint>().unwrap();
    let hints: Vec<Hint> = (0..3)
        .map(|i| Hint {
            t_ns: i,
            speed_mps: 0.1 * i as f64,
        })
        .collect();
    for (s, h) in samples.iter().zip(&hints) {
        writer.write(raw, s, 5).unwrap();
        writer.write(hint, h, 5).unwrap();
    }
    writer.write(raw, &samples[3], 5).unwrap();
    writer.finish().unwrap();

    let contents = read_all(&path).unwrap();
    assert_eq!(contents.raw, samples);
    assert_eq!(contents.other_messages, 3);
    let reader = Reader::open(&path).unwrap();
    let decoded: Vec<Hint> = reader
        .messages()
        .unwrap()
        .filter_map(|m| m.unwrap().decode::<Hint>())
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(decoded, hints);
}

/// Checks a JSON value against the subset of JSON Schema the crate's schemas use.
fn conforms(value: &Value, schema: &Value, at: &str) {
    match schema["type"].as_str().unwrap() {
        "object" => {
            let object = value
                .as_object()
                .unwrap_or_else(|| panic!("{at}: not an object"));
            let properties = schema["properties"].as_object().unwrap();
            let mut names: Vec<&String> = object.keys().collect();
            let mut declared: Vec<&String> = properties.keys().collect();
            names.sort();
            declared.sort();
            assert_eq!(names, declared, "{at}: fields differ from the schema");
            let required: Vec<&str> = schema["required"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_str().unwrap())
                .collect();
            assert_eq!(
                required.len(),
                declared.len(),
                "{at}: every field is required"
            );
            for (name, field) in object {
                conforms(field, &properties[name], &format!("{at}.{name}"));
            }
        }
        "array" => {
            let items = value
                .as_array()
                .unwrap_or_else(|| panic!("{at}: not an array"));
            assert_eq!(
                Some(items.len() as u64),
                schema["minItems"].as_u64(),
                "{at}"
            );
            assert_eq!(
                Some(items.len() as u64),
                schema["maxItems"].as_u64(),
                "{at}"
            );
            for item in items {
                conforms(item, &schema["items"], at);
            }
        }
        "integer" => {
            let ok = match (value.as_i64(), value.as_u64()) {
                (Some(v), _) => {
                    schema["minimum"].as_i64().is_none_or(|min| v >= min)
                        && schema["maximum"].as_i64().is_none_or(|max| v <= max)
                }
                (None, Some(v)) => schema["maximum"].as_u64().is_some_and(|max| v <= max),
                _ => false,
            };
            assert!(ok, "{at}: {value} is not an integer in the schema's range");
            assert!(schema["description"].is_string(), "{at}: no description");
        }
        "number" => {
            assert!(value.is_f64(), "{at}: {value} is not a float");
            assert!(schema["description"].is_string(), "{at}: no description");
        }
        "boolean" => assert!(value.is_boolean(), "{at}"),
        other => panic!("{at}: unexpected schema type {other}"),
    }
}

#[test]
fn schemas_describe_the_json_the_writer_produces() {
    let mut sample = arbitrary_samples(1, 61)[0];
    sample.accel_counts = [i16::MIN, i16::MAX, 0];
    sample.stamps.odometry_ns = u64::MAX;
    sample.lost_before = u32::MAX;
    conforms(
        &serde_json::to_value(sample).unwrap(),
        &RawImuSample::json_schema(),
        "RawImuSample",
    );
    let truth = any_truth(&[sample], 62)[0];
    conforms(
        &serde_json::to_value(truth).unwrap(),
        &Truth::json_schema(),
        "Truth",
    );
}

/// A run recorded across a recorder restart: the first file cut mid-chunk (a killed
/// recorder), its successor written whole. `read_all` of the first file reads both as one run,
/// names each file with its own truncation, and `load_raw` gives one session.
#[test]
fn a_run_continues_in_its_successor_segment() {
    use recording::mcap::{EventKind, RecorderEvent};
    use recording::segment;
    let samples = live_samples(300, 31);
    let truth = any_truth(&samples, 32);
    let base = tmp("segmented.mcap");
    let second = segment::path(&base, 1);
    let _ = std::fs::remove_file(segment::path(&base, 2));
    // The first 100 samples reach the file (flushed), then the recorder dies mid-chunk.
    let boundaries = write(&base, &samples[..150], &truth[..150], 100);
    let bytes = std::fs::read(&base).unwrap();
    std::fs::write(&base, &bytes[..boundaries[0] as usize + 20]).unwrap();
    // The restarted recorder missed samples 100..120.
    let mut writer = Writer::create_new(&second).unwrap();
    let events = writer.add_channel::<RecorderEvent>().unwrap();
    let raw = writer.add_channel::<RawImuSample>().unwrap();
    let split = RecorderEvent {
        kind: EventKind::Segment,
        service: String::new(),
        from_seq: Some(1),
        to_seq: Some(1),
        t_ns: 1,
    };
    writer.write(events, &split, 1).unwrap();
    for (i, s) in samples.iter().enumerate().skip(120) {
        writer.write(raw, s, log_time(i)).unwrap();
    }
    writer.finish().unwrap();
    assert!(
        Writer::create_new(&second).is_err(),
        "an existing segment is never overwritten"
    );

    let contents = read_all(&base).unwrap();
    let expected: Vec<RawImuSample> = samples[..100]
        .iter()
        .chain(&samples[120..])
        .copied()
        .collect();
    assert_eq!(contents.raw, expected);
    assert_eq!(contents.raw_sessions, vec![0..expected.len()]);
    assert_eq!(contents.events, vec![split]);
    assert_eq!(contents.segments.len(), 2);
    assert_eq!(contents.segments[0].path, base);
    assert!(contents.segments[0].truncation.is_some(), "first file cut");
    assert_eq!(contents.segments[1].path, second);
    assert_eq!(contents.segments[1].truncation, None);
    assert_eq!(
        contents.truncation, None,
        "the run ends with a finished file"
    );
    let rec = recording::load_raw(&base).unwrap();
    assert_eq!(rec.samples, expected);
    let last = recording::mcap::last_seqs(&base).unwrap();
    assert_eq!(last, vec![(ipc_types::service::RAW, samples[99].seq)]);

    // A file that only has a successor's name (no segment event first) is not part of the run.
    let third = segment::path(&base, 2);
    write(&third, &samples[..10], &truth[..10], 10);
    let contents = read_all(&base).unwrap();
    assert_eq!(contents.segments.len(), 2);
    assert_eq!(contents.raw, expected);
    for p in [&base, &second, &third] {
        std::fs::remove_file(p).unwrap();
    }
}

/// The streaming reader (`RawRun`, behind `mems-odometry offline`, `mems-replay` and
/// `mems-info`) reads a JSON recording (the older encoding) and a protobuf one, written by the
/// real writer, to the same samples and truth, bit for bit; each message names its encoding.
#[test]
fn the_streaming_reader_reads_both_encodings() {
    use recording::mcap::run::{Item, RawRun, RunReader};
    let samples = live_samples(500, 71);
    let truth = any_truth(&samples, 72);
    let mut read = Vec::new();
    for (encoding, name) in [
        (MessageEncoding::Json, "json"),
        (MessageEncoding::Protobuf, "protobuf"),
    ] {
        let path = tmp(&format!("stream-{name}.mcap"));
        write_in(&path, &samples, &truth, 100, encoding);
        let mut run = RunReader::open(&path).unwrap();
        while let Some(m) = run.next() {
            let m = m.unwrap();
            assert_eq!(m.encoding, Some(encoding), "{name}");
            assert_eq!(m.channel.encoding, name);
        }
        let items: Vec<Item> = RawRun::open(&path, false)
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        let raw: Vec<RawImuSample> = items
            .iter()
            .filter_map(|i| match i {
                Item::Raw(s) => Some(*s),
                _ => None,
            })
            .collect();
        let t: Vec<Truth> = items
            .iter()
            .filter_map(|i| match i {
                Item::Truth(t) => Some(*t),
                _ => None,
            })
            .collect();
        assert_eq!(raw, samples, "{name}");
        let bits: Vec<_> = raw.iter().map(sample_bits).collect();
        assert_eq!(bits, samples.iter().map(sample_bits).collect::<Vec<_>>());
        assert_eq!(
            t.iter().map(truth_bits).collect::<Vec<_>>(),
            truth.iter().map(truth_bits).collect::<Vec<_>>()
        );
        read.push(std::fs::metadata(&path).unwrap().len());
    }
    assert!(
        read[1] < read[0],
        "protobuf {} bytes, JSON {}",
        read[1],
        read[0]
    );
}
