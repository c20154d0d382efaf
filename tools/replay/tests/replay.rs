//! The replay loop against a real subscriber in another thread (its own iceoryx2 node), and the
//! `mems-replay` command line on bad input.

use std::process::Command;
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use ipc_types::clock::monotonic_ns;
use ipc_types::{RawImuSample, RobotHint, Stamps, hint_flags, raw_flags, service};
use mems_replay::source::Recording;
use mems_replay::topics::{Payload, Replayable};
use mems_replay::{LINGER, Pace, ReplayError, ReplayOptions, ReplaySummary, SETTLE, replay};

fn namespace(test: &str) -> String {
    format!("t{}-{test}", std::process::id())
}

/// `n` samples at `rate_hz` whose every field differs from the defaults.
fn samples(n: u64, rate_hz: u64) -> Vec<RawImuSample> {
    (0..n)
        .map(|i| RawImuSample {
            stamps: Stamps {
                sample_ns: 1_000_000_000 + i * (1_000_000_000 / rate_hz),
                acquired_ns: 17,
                calibrated_ns: 0,
                odometry_ns: 0,
            },
            seq: 100 + i,
            // Within the sensor's range (readers refuse beyond 20 g).
            accel_g: [0.1 * (i % 150) as f64, -1.0 / 3.0, 1.0 + 1e-9 * i as f64],
            gyro_dps: [-250.0, 0.5, f64::MIN_POSITIVE],
            temp_c: 21.0 + i as f64 / 333.87,
            accel_counts: [i as i16, -(i as i16), 16384],
            gyro_counts: [-32768, 65, 0],
            temp_counts: i as i16,
            flags: raw_flags::GYRO_VALID | raw_flags::TEMP_VALID,
            lost_before: (i % 3) as u32,
            undelivered: 0,
        })
        .collect()
}

/// Subscribes in its own thread and node; returns each sample with its receive time once `n`
/// arrived (or what arrived within 10 s). `stall_every` makes it pause 2 ms every that many
/// samples, to be slower than the publisher.
fn subscribe(
    ns: &str,
    n: usize,
    stall_every: Option<usize>,
) -> thread::JoinHandle<Vec<(RawImuSample, u64)>> {
    let name = service::full_name(ns, service::RAW);
    thread::spawn(move || {
        let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
        let svc = service::open::<RawImuSample>(&node, &name).unwrap();
        let sub = service::subscriber(&svc).unwrap();
        let start = Instant::now();
        let mut got = Vec::new();
        while got.len() < n && start.elapsed() < Duration::from_secs(10) {
            while let Some(s) = sub.receive().unwrap() {
                got.push((*s.payload(), monotonic_ns()));
                if stall_every.is_some_and(|k| got.len() % k == 0) {
                    thread::sleep(Duration::from_millis(2));
                }
            }
            thread::sleep(Duration::from_micros(100));
        }
        got
    })
}

/// Replays `samples` and `hints` (held in memory) as `mems-replay` would.
fn replay_in_memory(
    ns: &str,
    samples: &[RawImuSample],
    hints: &[RobotHint],
    options: &ReplayOptions,
) -> Result<ReplaySummary, ReplayError> {
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
    let payloads = hints
        .iter()
        .map(|h| Payload::Hint(*h))
        .chain(samples.iter().map(|s| Payload::Raw(*s)))
        .collect();
    let topics: &[Replayable] = if hints.is_empty() {
        &[Replayable::Raw]
    } else {
        &[Replayable::Hint, Replayable::Raw]
    };
    let recording = Recording::Memory(payloads);
    replay(&node, ns, &recording, topics, None, options, &mut |_| {})
}

fn run(ns: &str, samples: &[RawImuSample], pace: Pace) -> ReplaySummary {
    let options = ReplayOptions {
        pace,
        wait_subscribers: 1,
        wait_timeout: Duration::from_secs(5),
        looping: false,
    };
    replay_in_memory(ns, samples, &[], &options).unwrap()
}

/// Payloads arrive as recorded except `acquired_ns`, which is the publish time.
fn assert_same_but_acquired(got: &[(RawImuSample, u64)], sent: &[RawImuSample]) {
    assert_eq!(got.len(), sent.len());
    for ((g, received_ns), s) in got.iter().zip(sent) {
        let mut expected = *s;
        expected.stamps.acquired_ns = g.stamps.acquired_ns;
        assert_eq!(*g, expected);
        assert_eq!(g.temp_c.to_bits(), s.temp_c.to_bits());
        assert!(
            g.stamps.acquired_ns <= *received_ns,
            "stamped before it was received"
        );
    }
}

/// At speed 2, samples 1 ms apart are published 0.5 ms apart: none before its recorded offset
/// from the first, halved (counted from the first's publication: the pacer's clock starts
/// after it). Only lower bounds: a loaded machine may publish any of them late (when each is
/// due is `Pacer`'s unit tests).
#[test]
fn real_time_pace_follows_the_sample_times_scaled_by_speed() {
    let ns = namespace("pace");
    let sent = samples(400, 1000);
    let sub = subscribe(&ns, sent.len(), None);
    let started = Instant::now();
    let summary = run(&ns, &sent, Pace::RealTime { speed: 2.0 });
    assert!(
        started.elapsed() >= LINGER,
        "the publisher lingers after the last sample"
    );
    let got = sub.join().unwrap();
    assert_same_but_acquired(&got, &sent);
    assert_eq!(summary.total_sent(), 400);
    assert!(!summary.interrupted);
    assert_eq!(summary.short_deliveries, 0);

    let a0 = got[0].0.stamps.acquired_ns;
    for (g, _) in &got {
        let due = (g.stamps.sample_ns - sent[0].stamps.sample_ns) / 2;
        let at = g.stamps.acquired_ns - a0;
        assert!(at >= due, "seq {} published {} ns early", g.seq, due - at);
    }
    // 399 intervals of 0.5 ms.
    let elapsed = summary.elapsed.as_secs_f64();
    assert!(elapsed >= 0.1995, "took {elapsed} s");
    assert!((summary.rate_hz() - 399.0 / elapsed).abs() < 1e-6);
}

/// Two sessions whose sample times start over (two replays in one recording): pacing starts
/// over with the second, which is published at the recorded spacing, not all at once.
#[test]
fn real_time_pace_starts_over_with_a_new_session() {
    let ns = namespace("sessions");
    let first = samples(200, 1000);
    let mut second = samples(200, 1000);
    for s in &mut second {
        s.seq -= 100; // counts from 0 again
    }
    let sent: Vec<RawImuSample> = first.iter().chain(&second).copied().collect();
    let sub = subscribe(&ns, sent.len(), None);
    let summary = run(&ns, &sent, Pace::RealTime { speed: 1.0 });
    let got = sub.join().unwrap();
    assert_same_but_acquired(&got, &sent);
    // Each session spans 199 ms; the second starts when the first has ended.
    let published = |i: usize| got[i].0.stamps.acquired_ns;
    let second_span_ms = (published(399) - published(200)) as f64 / 1e6;
    assert!(
        second_span_ms >= 199.0,
        "second session spans {second_span_ms} ms"
    );
    let elapsed = summary.elapsed.as_secs_f64();
    assert!(elapsed >= 0.398, "took {elapsed} s");
}

/// As fast as possible, with a subscriber slower than the publisher and more samples than its
/// buffer: nothing is lost, the order is kept, the publisher was held back.
#[test]
fn max_pace_is_lossless_with_a_slow_subscriber() {
    let ns = namespace("max");
    let n = service::SUBSCRIBER_BUFFER + 2000;
    let sent = samples(n as u64, 4000);
    let sub = subscribe(&ns, n, Some(500));
    let summary = run(&ns, &sent, Pace::Max);
    let got = sub.join().unwrap();
    assert_same_but_acquired(&got, &sent);
    assert_eq!(summary.total_sent(), n as u64);
    assert_eq!(summary.short_deliveries, 0);
    // The last sample fits in the subscriber's queue only once it has taken n - buffer samples
    // (2000), and it stalls 2 ms after every 500 it takes: the stalls after 500, 1000 and 1500
    // come before that point (the one after 2000 does not delay the publisher), so the
    // publisher waited at least 3 x 2 ms.
    let stalls = ((n - service::SUBSCRIBER_BUFFER) / 500 - 1) as f64 * 0.002;
    assert!(
        summary.elapsed.as_secs_f64() >= stalls,
        "{:?}",
        summary.elapsed
    );
}

/// Recorded hints are published exactly as recorded (both stamps kept), each just before the
/// first raw sample taken at or after its publication time; a hint published after the last
/// sample follows it. Samples 50 ms apart at real-time pace leave no doubt about the order
/// in which a subscriber polling every 0.1 ms sees them.
#[test]
fn hints_are_published_as_recorded_among_the_raw_samples_in_time_order() {
    let ns = namespace("hints");
    let sent = samples(20, 20);
    let t = |i: usize| sent[i].stamps.sample_ns;
    // Published 1 ms after sample 2, exactly at sample 5, 30 ms after sample 5, 30 ms after
    // the last.
    let hint_times = [
        t(2) + 1_000_000,
        t(5),
        t(5) + 30_000_000,
        t(19) + 30_000_000,
    ];
    let hints: Vec<RobotHint> = hint_times
        .iter()
        .zip(0..)
        .map(|(&acquired_ns, seq)| RobotHint {
            stamps: Stamps {
                sample_ns: acquired_ns - 4_000_000,
                acquired_ns,
                ..Stamps::default()
            },
            seq,
            forward_speed_mps: 0.5 + seq as f64,
            forward_speed_sigma_mps: 0.02,
            flags: hint_flags::SPEED_VALID,
            ..RobotHint::default()
        })
        .collect();
    // Raw samples received before each hint.
    let expected_before = [3, 5, 6, 20];

    let (raw_name, hint_name) = (
        service::full_name(&ns, service::RAW),
        service::full_name(&ns, service::HINT),
    );
    let (ready_tx, ready_rx) = mpsc::channel();
    let sub = thread::spawn(move || {
        let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
        let raw_svc = service::open::<RawImuSample>(&node, &raw_name).unwrap();
        let hint_svc = service::open::<RobotHint>(&node, &hint_name).unwrap();
        let raw = service::subscriber(&raw_svc).unwrap();
        let hint = service::subscriber(&hint_svc).unwrap();
        ready_tx.send(()).unwrap();
        let (mut raw_count, mut got) = (0, Vec::new());
        let start = Instant::now();
        while got.len() < 4 && start.elapsed() < Duration::from_secs(10) {
            while let Some(h) = hint.receive().unwrap() {
                got.push((*h.payload(), raw_count));
            }
            while raw.receive().unwrap().is_some() {
                raw_count += 1;
            }
            thread::sleep(Duration::from_micros(100));
        }
        (raw_count, got)
    });
    ready_rx.recv().unwrap();
    let options = ReplayOptions {
        pace: Pace::RealTime { speed: 1.0 },
        wait_subscribers: 1,
        wait_timeout: Duration::from_secs(5),
        looping: false,
    };
    let summary = replay_in_memory(&ns, &sent, &hints, &options).unwrap();
    let (raw_count, got) = sub.join().unwrap();
    let (hints_sent, raw_sent) = (
        summary.sent[Replayable::Hint.index()],
        summary.sent[Replayable::Raw.index()],
    );
    assert_eq!((raw_sent, hints_sent), (20, 4));
    assert_eq!(raw_count, 20);
    let received: Vec<RobotHint> = got.iter().map(|(h, _)| *h).collect();
    assert_eq!(received, hints, "as recorded, stamps included");
    let before: Vec<usize> = got.iter().map(|(_, n)| *n).collect();
    assert_eq!(before, expected_before);
}

/// A subscriber that does not call `receive` for a while after the publisher appeared is not
/// connected: iceoryx2 queues one buffer for it and drops the rest. The replay counts exactly
/// those samples, so the loss is never silent.
#[test]
fn samples_dropped_for_an_unconnected_subscriber_are_counted() {
    let ns = namespace("unconnected");
    let n = service::SUBSCRIBER_BUFFER + 1500;
    let sent = samples(n as u64, 4000);
    let name = service::full_name(&ns, service::RAW);
    let (ready_tx, ready_rx) = mpsc::channel();
    // Created before the publisher exists, then silent for longer than the replay's SETTLE but
    // not past its LINGER (a subscriber that wakes after the publisher left gets nothing).
    let sub = thread::spawn(move || {
        let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
        let svc = service::open::<RawImuSample>(&node, &name).unwrap();
        let sub = service::subscriber(&svc).unwrap();
        ready_tx.send(()).unwrap();
        thread::sleep(SETTLE + LINGER / 2);
        let mut got = Vec::new();
        let start = Instant::now();
        while start.elapsed() < Duration::from_millis(300) {
            while let Some(s) = sub.receive().unwrap() {
                got.push(s.seq);
            }
            thread::sleep(Duration::from_millis(1));
        }
        got
    });
    ready_rx.recv().unwrap();
    let summary = run(&ns, &sent, Pace::Max);
    let got = sub.join().unwrap();
    assert_eq!(
        got.len(),
        service::SUBSCRIBER_BUFFER,
        "one buffer was queued"
    );
    assert_eq!(got, (100..100 + got.len() as u64).collect::<Vec<_>>());
    assert_eq!(summary.short_deliveries, (n - got.len()) as u64);
}

/// A subscriber that leaves during a replay is a departure, not a loss: the samples sent after
/// it left are counted apart, none is counted as short, and the subscriber that stays gets
/// every sample. The one that stays holds the replay (lossless back-pressure on a full buffer)
/// until the other has left, so at least `n - SUBSCRIBER_BUFFER - 2` samples follow the
/// departure: its buffer and the sample it took hold `SUBSCRIBER_BUFFER + 1`, and one more
/// was seen taken before the departure in a full-suite run (4,098: the connection holds a
/// sample beyond the buffer at times), so the bound allows it.
#[test]
fn a_subscriber_that_leaves_is_counted_apart_and_the_others_get_everything() {
    let ns = namespace("leaves");
    let n = service::SUBSCRIBER_BUFFER + 1000;
    let sent = samples(n as u64, 4000);
    let name = service::full_name(&ns, service::RAW);
    let (ready_tx, ready_rx) = mpsc::channel();
    let (left_tx, left_rx) = mpsc::channel::<()>();
    let leaving = {
        let (name, ready_tx) = (name.clone(), ready_tx.clone());
        thread::spawn(move || {
            let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
            let svc = service::open::<RawImuSample>(&node, &name).unwrap();
            let sub = service::subscriber(&svc).unwrap();
            ready_tx.send(()).unwrap();
            let mut got = 0;
            while got < 100 {
                while got < 100 && sub.receive().unwrap().is_some() {
                    got += 1;
                }
                thread::sleep(Duration::from_micros(100));
            }
            // Leaves: the port is deregistered when dropped.
            drop(sub);
            drop(svc);
            drop(node);
            left_tx.send(()).unwrap();
        })
    };
    let staying = thread::spawn(move || {
        let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
        let svc = service::open::<RawImuSample>(&node, &name).unwrap();
        let sub = service::subscriber(&svc).unwrap();
        ready_tx.send(()).unwrap();
        // Connected by its first receive of a sample (an unconnected subscriber is not waited
        // for: see the test above), then silent until the other has left.
        let mut got = Vec::new();
        while got.is_empty() {
            if let Some(s) = sub.receive().unwrap() {
                got.push(s.seq);
            }
            thread::sleep(Duration::from_micros(100));
        }
        left_rx.recv().unwrap();
        let start = Instant::now();
        while got.len() < n && start.elapsed() < Duration::from_secs(60) {
            while let Some(s) = sub.receive().unwrap() {
                got.push(s.seq);
            }
            thread::sleep(Duration::from_micros(100));
        }
        got
    });
    ready_rx.recv().unwrap();
    ready_rx.recv().unwrap();
    let options = ReplayOptions {
        pace: Pace::Max,
        wait_subscribers: 2,
        wait_timeout: Duration::from_secs(60),
        looping: false,
    };
    let summary = replay_in_memory(&ns, &sent, &[], &options).unwrap();
    leaving.join().unwrap();
    let got = staying.join().unwrap();
    assert_eq!(got, (100..100 + n as u64).collect::<Vec<_>>());
    assert_eq!(summary.total_sent(), n as u64);
    assert_eq!(summary.short_deliveries, 0);
    assert!(
        summary.after_subscriber_left >= (n - service::SUBSCRIBER_BUFFER - 2) as u64
            && summary.after_subscriber_left <= (n - 100) as u64,
        "{summary:?}"
    );
}

#[test]
fn too_few_subscribers_is_an_error_naming_the_service() {
    let ns = namespace("nosub");
    let options = ReplayOptions {
        pace: Pace::Max,
        wait_subscribers: 2,
        wait_timeout: Duration::from_millis(50),
        looping: false,
    };
    let err = replay_in_memory(&ns, &samples(3, 100), &[], &options).unwrap_err();
    assert!(matches!(
        err,
        ReplayError::NoSubscribers {
            connected: 0,
            wanted: 2,
            ..
        }
    ));
    let text = err.to_string();
    assert!(text.contains(&format!("{ns}/mems/imu/raw")), "{text}");
    assert!(text.contains("only 0 of 2 subscribers"), "{text}");
}

#[test]
fn a_speed_that_is_not_positive_is_refused() {
    for speed in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let options = ReplayOptions {
            pace: Pace::RealTime { speed },
            wait_subscribers: 0,
            wait_timeout: Duration::ZERO,
            looping: false,
        };
        let err = replay_in_memory("unused", &samples(2, 100), &[], &options).unwrap_err();
        assert!(matches!(err, ReplayError::BadSpeed(_)), "{speed}: {err}");
    }
}

/// The command line reports a malformed recording with its file, line and field.
#[test]
fn a_bad_csv_line_is_reported_with_file_line_and_field() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
    let path = dir.join(format!("replay-bad-{}.csv", std::process::id()));
    std::fs::write(&path, "t_s,ax_g,ay_g,az_g\n0.0,0,0,1\n0.001,0,x,1\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_mems-replay"))
        .arg(&path)
        .args(["--namespace", &namespace("badcsv")])
        .output()
        .unwrap();
    std::fs::remove_file(&path).unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let expected = format!("{}:3: field \"ay_g\"", path.display());
    assert!(stderr.contains(&expected), "{stderr}");
}

/// A run recorded across a recorder restart (its first file and the successor segment, which
/// misses what the recorder lost) is replayed by `mems-replay FIRST.mcap` as one run: every
/// recorded sample, in order, once.
#[test]
fn a_run_in_two_segment_files_is_replayed_as_one() {
    use recording::mcap::{EventKind, RecorderEvent, Writer};
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));
    let base = dir.join(format!("replay-segments-{}.mcap", std::process::id()));
    let second = recording::segment::path(&base, 1);
    let sent = samples(1000, 1000);
    for (n, (path, part)) in [(&base, &sent[..400]), (&second, &sent[450..])]
        .into_iter()
        .enumerate()
    {
        let mut writer = Writer::create(path).unwrap();
        if n > 0 {
            // What a restarted recorder writes first.
            let events = writer.add_channel::<RecorderEvent>().unwrap();
            let split = RecorderEvent {
                kind: EventKind::Segment,
                service: String::new(),
                from_seq: Some(n as u64),
                to_seq: Some(n as u64),
                t_ns: 0,
            };
            writer.write(events, &split, 0).unwrap();
        }
        let raw = writer.add_channel::<RawImuSample>().unwrap();
        for s in part {
            writer.write(raw, s, s.stamps.sample_ns).unwrap();
        }
        writer.finish().unwrap();
    }
    let expected: Vec<RawImuSample> = sent[..400].iter().chain(&sent[450..]).copied().collect();
    let ns = namespace("segments");
    let sub = subscribe(&ns, expected.len(), None);
    let out = Command::new(env!("CARGO_BIN_EXE_mems-replay"))
        .arg(&base)
        .args(["--max", "--namespace", &ns, "--wait-subscribers", "1"])
        .output()
        .unwrap();
    for p in [&base, &second] {
        std::fs::remove_file(p).unwrap();
    }
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = sub.join().unwrap();
    assert_same_but_acquired(&got, &expected);
}
