//! Round trips of every recorded type through the writer and the reader, and the schemas
//! against the messages.

use std::path::PathBuf;

use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint, Stamps};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{Value, json};

use super::*;

fn stamps(rng: &mut ChaCha8Rng) -> Stamps {
    Stamps {
        sample_ns: rng.random(),
        acquired_ns: rng.random(),
        calibrated_ns: rng.random(),
        odometry_ns: rng.random(),
    }
}

/// Any finite f64 bit pattern (subnormals, -0.0 and extremes included).
fn finite(rng: &mut ChaCha8Rng) -> f64 {
    loop {
        let v = f64::from_bits(rng.random());
        if v.is_finite() {
            return v;
        }
    }
}

fn corrected(rng: &mut ChaCha8Rng) -> CorrectedImuSample {
    CorrectedImuSample {
        stamps: stamps(rng),
        seq: rng.random(),
        accel_mps2: [(); 3].map(|_| finite(rng)),
        gyro_rps: [(); 3].map(|_| finite(rng)),
        temp_c: finite(rng),
        zs_mean_mps2: [(); 3].map(|_| finite(rng)),
        zs_std_mps2: [(); 3].map(|_| finite(rng)),
        calib_id: rng.random(),
        flags: rng.random(),
        raw_flags: rng.random(),
        settles: rng.random(),
        refined_accel_mps2: [(); 3].map(|_| finite(rng)),
        refined_gyro_rps: [(); 3].map(|_| finite(rng)),
    }
}

fn odometry(rng: &mut ChaCha8Rng) -> OdometryState {
    OdometryState {
        stamps: stamps(rng),
        seq: rng.random(),
        position_m: [(); 3].map(|_| finite(rng)),
        position_sigma_m: [(); 3].map(|_| finite(rng)),
        velocity_mps: [(); 3].map(|_| finite(rng)),
        velocity_sigma_mps: [(); 3].map(|_| finite(rng)),
        gravity_sensor_mps2: [(); 3].map(|_| finite(rng)),
        attitude_wxyz: [(); 4].map(|_| finite(rng)),
        distance_m: finite(rng),
        flags: rng.random(),
        reserved16: 0,
        rest_count: rng.random(),
        hints_applied: rng.random(),
        hint_disagreements: rng.random(),
    }
}

fn hint(rng: &mut ChaCha8Rng) -> RobotHint {
    RobotHint {
        stamps: stamps(rng),
        seq: rng.random(),
        forward_speed_mps: finite(rng),
        forward_speed_sigma_mps: finite(rng),
        yaw_rate_rps: finite(rng),
        yaw_rate_sigma_rps: finite(rng),
        flags: rng.random(),
        reserved16: 0,
        reserved: 0,
    }
}

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("recording-unit-{}-{name}", std::process::id()))
}

/// Every message type the recorder writes reads back bit for bit, each on its own topic,
/// in both encodings.
#[test]
fn recorder_topics_round_trip_bit_exact() {
    round_trip(MessageEncoding::Protobuf);
    round_trip(MessageEncoding::Json);
}

fn round_trip(encoding: MessageEncoding) {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let corrected: Vec<_> = (0..50).map(|_| corrected(&mut rng)).collect();
    let odometry: Vec<_> = (0..50).map(|_| odometry(&mut rng)).collect();
    // Foxglove's timestamps hold whole seconds as u32 (up to 2106).
    let poses: Vec<_> = odometry
        .iter()
        .map(|s| {
            let mut s = *s;
            s.stamps.sample_ns %= u64::from(u32::MAX) * 1_000_000_000;
            PoseInFrame::from_state(&s)
        })
        .collect();
    let hints: Vec<_> = (0..50).map(|_| hint(&mut rng)).collect();
    let events = vec![
        RecorderEvent {
            kind: EventKind::Gap,
            service: ipc_types::service::CORRECTED.into(),
            from_seq: Some(10),
            to_seq: Some(19),
            t_ns: 5,
        },
        RecorderEvent {
            kind: EventKind::PublisherLost,
            service: ipc_types::service::RAW.into(),
            from_seq: None,
            to_seq: None,
            t_ns: u64::MAX,
        },
    ];
    let path = tmp(&format!("topics-{encoding:?}.mcap"));
    let mut writer = Writer::create(&path).unwrap().with_encoding(encoding);
    let c = writer.add_channel::<CorrectedImuSample>().unwrap();
    let o = writer.add_channel::<OdometryState>().unwrap();
    let p = writer.add_channel::<PoseInFrame>().unwrap();
    let e = writer.add_channel::<RecorderEvent>().unwrap();
    let h = writer.add_channel::<RobotHint>().unwrap();
    for i in 0..50 {
        writer.write(c, &corrected[i], i as u64).unwrap();
        writer.write(o, &odometry[i], i as u64).unwrap();
        writer.write(p, &poses[i], i as u64).unwrap();
        writer.write(h, &hints[i], i as u64).unwrap();
    }
    for event in &events {
        writer.write(e, event, event.t_ns).unwrap();
    }
    writer.finish().unwrap();

    let contents = read_all(&path).unwrap();
    // Protobuf records corrected samples and states at their quanta; JSON as they are.
    let (corrected, odometry): (Vec<_>, Vec<_>) = match encoding {
        MessageEncoding::Protobuf => (
            corrected.iter().map(Topic::as_recorded).collect(),
            odometry.iter().map(Topic::as_recorded).collect(),
        ),
        MessageEncoding::Json => (corrected, odometry),
    };
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(contents.corrected.len(), 50);
    for (a, b) in contents.corrected.iter().zip(&corrected) {
        assert_eq!(bits(&a.accel_mps2), bits(&b.accel_mps2));
        assert_eq!(bits(&a.zs_std_mps2), bits(&b.zs_std_mps2));
        assert_eq!(bits(&a.refined_accel_mps2), bits(&b.refined_accel_mps2));
        assert_eq!(bits(&a.refined_gyro_rps), bits(&b.refined_gyro_rps));
    }
    for (a, b) in contents.odometry.iter().zip(&odometry) {
        assert_eq!(bits(&a.position_m), bits(&b.position_m));
        assert_eq!(bits(&a.attitude_wxyz), bits(&b.attitude_wxyz));
    }
    assert_eq!(contents.hints.len(), 50);
    for (a, b) in contents.hints.iter().zip(&hints) {
        let fields = |x: &RobotHint| {
            bits(&[
                x.forward_speed_mps,
                x.forward_speed_sigma_mps,
                x.yaw_rate_rps,
                x.yaw_rate_sigma_rps,
            ])
        };
        assert_eq!(fields(a), fields(b));
    }
    // PartialEq on f64 treats -0.0 == 0.0; the bit comparisons above catch that case.
    assert_eq!(contents.corrected, corrected);
    assert_eq!(contents.odometry, odometry);
    assert_eq!(contents.hints, hints);
    assert_eq!(contents.poses, poses);
    assert_eq!(contents.events, events);
    assert!(contents.raw.is_empty() && contents.truncation.is_none());
    assert_eq!(contents.other_messages, 0);

    // publish_time is each message's own time.
    let reader = Reader::open(&path).unwrap();
    for m in reader.messages().unwrap() {
        let m = m.unwrap();
        let expected = if let Some(s) = m.decode::<CorrectedImuSample>() {
            s.unwrap().stamps.sample_ns
        } else if let Some(s) = m.decode::<OdometryState>() {
            s.unwrap().stamps.sample_ns
        } else if let Some(s) = m.decode::<PoseInFrame>() {
            s.unwrap().timestamp.to_ns()
        } else if let Some(s) = m.decode::<RobotHint>() {
            s.unwrap().stamps.sample_ns
        } else {
            m.decode::<RecorderEvent>().unwrap().unwrap().t_ns
        };
        assert_eq!(m.publish_time_ns, expected, "{}", m.topic);
    }
    std::fs::remove_file(&path).unwrap();
}

/// The pose is the state's position and attitude in Foxglove's JSON layout: quaternion
/// reordered from (w, x, y, z) to {x, y, z, w}, time split into sec and nsec.
#[test]
fn pose_has_foxglove_layout() {
    let state = OdometryState {
        stamps: Stamps {
            sample_ns: 12_345_678_901,
            ..Stamps::default()
        },
        position_m: [1.5, -2.0, 0.25],
        attitude_wxyz: [0.5, -0.5, 0.5, -0.5],
        ..OdometryState::default()
    };
    let json = serde_json::to_value(PoseInFrame::from_state(&state)).unwrap();
    assert_eq!(
        json,
        json!({
            "timestamp": {"sec": 12, "nsec": 345_678_901},
            "frame_id": "nav",
            "pose": {
                "position": {"x": 1.5, "y": -2.0, "z": 0.25},
                "orientation": {"x": -0.5, "y": 0.5, "z": -0.5, "w": 0.5},
            },
        })
    );
}

/// Collects, for every object in `schema`, the path and its required property names.
fn schema_objects(schema: &Value, at: &str, out: &mut Vec<(String, Vec<String>)>) {
    if let Some(properties) = schema["properties"].as_object() {
        let required = schema["required"].as_array().unwrap();
        let mut names: Vec<String> = required
            .iter()
            .map(|r| r.as_str().unwrap().into())
            .collect();
        names.sort();
        out.push((at.to_owned(), names));
        for (name, sub) in properties {
            schema_objects(sub, &format!("{at}.{name}"), out);
        }
    }
}

/// The same for a JSON value.
fn value_objects(value: &Value, at: &str, out: &mut Vec<(String, Vec<String>)>) {
    if let Some(map) = value.as_object() {
        let mut names: Vec<String> = map.keys().cloned().collect();
        names.sort();
        out.push((at.to_owned(), names));
        for (name, sub) in map {
            value_objects(sub, &format!("{at}.{name}"), out);
        }
    }
}

fn assert_schema_describes<T: Topic>(message: &T) {
    let mut from_schema = Vec::new();
    schema_objects(&T::json_schema(), "", &mut from_schema);
    let mut from_value = Vec::new();
    value_objects(&serde_json::to_value(message).unwrap(), "", &mut from_value);
    from_schema.sort();
    from_value.sort();
    assert_eq!(from_schema, from_value, "{}", T::SCHEMA_NAME);
    assert_eq!(T::json_schema()["title"], T::SCHEMA_NAME);
}

/// Each schema names exactly the fields serde writes, at every nesting level.
#[test]
fn schemas_describe_the_serialized_messages() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let state = odometry(&mut rng);
    assert_schema_describes(&corrected(&mut rng));
    assert_schema_describes(&state);
    assert_schema_describes(&PoseInFrame::from_state(&state));
    assert_schema_describes(&hint(&mut rng));
    assert_schema_describes(&RecorderEvent {
        kind: EventKind::SeqReset,
        service: "s".into(),
        from_seq: Some(1),
        to_seq: Some(0),
        t_ns: 0,
    });
}

/// Event kinds serialize to the strings the schema's enum lists.
#[test]
fn event_kinds_match_the_schema_enum() {
    let kinds = [
        EventKind::Gap,
        EventKind::SeqReset,
        EventKind::PublisherLost,
        EventKind::PublisherBack,
        EventKind::Segment,
    ];
    let written: Vec<Value> = kinds
        .iter()
        .map(|k| serde_json::to_value(k).unwrap())
        .collect();
    let schema = RecorderEvent::json_schema();
    assert_eq!(
        &written,
        schema["properties"]["kind"]["enum"].as_array().unwrap()
    );
}

/// Protobuf keeps NaN and infinity: a raw sample's values bit for bit (they are not what
/// the counts give, so they are written as `double`s), a state's as `float`s.
#[test]
fn protobuf_keeps_non_finite_values() {
    let path = tmp("nan-protobuf.mcap");
    let mut writer = Writer::create(&path).unwrap();
    let r = writer.add_channel::<RawImuSample>().unwrap();
    let o = writer.add_channel::<OdometryState>().unwrap();
    let nan = f64::from_bits(0x7ff8_0000_dead_beef);
    let raw = RawImuSample {
        accel_g: [nan, f64::INFINITY, -0.0],
        temp_c: f64::NEG_INFINITY,
        ..RawImuSample::default()
    };
    writer.write(r, &raw, 0).unwrap();
    let state = OdometryState {
        distance_m: nan,
        position_m: [f64::INFINITY, f64::NEG_INFINITY, -0.0],
        ..OdometryState::default()
    };
    writer.write(o, &state, 0).unwrap();
    writer.finish().unwrap();
    let reader = Reader::open(&path).unwrap();
    let mut messages = reader.messages().unwrap().map(Result::unwrap);
    let back = messages
        .next()
        .unwrap()
        .decode::<RawImuSample>()
        .unwrap()
        .unwrap();
    assert_eq!(
        back.accel_g.map(f64::to_bits),
        raw.accel_g.map(f64::to_bits)
    );
    assert_eq!(back.temp_c, f64::NEG_INFINITY);
    let back = messages
        .next()
        .unwrap()
        .decode::<OdometryState>()
        .unwrap()
        .unwrap();
    assert!(back.distance_m.is_nan());
    let bits = back.position_m.map(f64::to_bits);
    assert_eq!(bits, state.position_m.map(f64::to_bits));
    std::fs::remove_file(&path).unwrap();
}

/// On a JSON channel, NaN in a corrected sample or an odometry state is refused, naming
/// the topic.
#[test]
fn non_finite_values_are_refused() {
    let path = tmp("nan.mcap");
    let mut writer = Writer::create(&path)
        .unwrap()
        .with_encoding(MessageEncoding::Json);
    let o = writer.add_channel::<OdometryState>().unwrap();
    let state = OdometryState {
        distance_m: f64::NAN,
        ..OdometryState::default()
    };
    let err = writer.write(o, &state, 0).unwrap_err();
    assert!(err.to_string().contains("mems/odometry/state"), "{err}");
    let h = writer.add_channel::<RobotHint>().unwrap();
    let hint = RobotHint {
        forward_speed_sigma_mps: f64::INFINITY,
        ..RobotHint::default()
    };
    let err = writer.write(h, &hint, 0).unwrap_err();
    assert!(err.to_string().contains("mems/robot/hint"), "{err}");
    drop(writer);
    assert!(!path.exists(), "an unfinished writer leaves no file");
}
