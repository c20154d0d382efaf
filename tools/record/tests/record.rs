//! `mems-record` as a real process: a round trip through `mems-replay`, a SIGKILLed recorder,
//! a SIGKILLed publisher, and every service recorded with the derived pose.

mod common;

use std::time::Duration;

use common::*;
use ipc_types::clock::monotonic_ns;
use ipc_types::service;
use recording::mcap::{EventKind, Reader, RecorderEvent, Writer, read_all};

const WAIT: Duration = Duration::from_secs(10);

/// Raw sample count in the (possibly still growing) recording at `path`.
fn raw_in(path: &std::path::Path) -> usize {
    read_all(path).map_or(0, |c| c.raw.len())
}

/// Events in the (possibly still growing) recording at `path`.
fn events_in(path: &std::path::Path) -> Vec<RecorderEvent> {
    read_all(path).map_or_else(|_| Vec::new(), |c| c.events)
}

/// A CSV replayed with `mems-replay --max` arrives in the recording complete and bit-exact
/// (but for `acquired_ns`, the publish time), with no gap; the replay's clean exit (its
/// publisher announces that it leaves) is no lost publisher, and SIGTERM finishes the file with
/// its summary.
#[test]
fn csv_replayed_at_max_speed_is_recorded_bit_exact() {
    let ns = namespace("roundtrip");
    let csv = tmp("roundtrip.csv");
    let mcap = tmp("roundtrip.mcap");
    recording::csv::write_raw(&csv, &raw_samples(8000, 0, 4000), None).unwrap();
    // What the replay publishes: the CSV as the recording crate reads it.
    let expected = recording::load_raw(&csv).unwrap().samples;

    let recorder = spawn(
        &mems_record(),
        &["--out", mcap.to_str().unwrap(), "--namespace", &ns],
    );
    let before_ns = monotonic_ns();
    let replay = spawn(
        &mems_replay(),
        &[
            csv.to_str().unwrap(),
            "--max",
            "--namespace",
            &ns,
            "--wait-subscribers",
            "1",
            "--wait-timeout",
            "5",
        ],
    );
    let (status, stdout) = replay.wait(WAIT);
    let after_ns = monotonic_ns();
    assert!(status.success(), "mems-replay failed: {stdout}");
    assert!(stdout.contains("sent 8000 of 8000 samples"), "{stdout}");
    wait_until(WAIT, "all samples in the file", || raw_in(&mcap) == 8000);
    // Five publisher checks after the replay left: a loss would be in the file by now (a slow
    // machine can only make this pass without a check, never fail).
    std::thread::sleep(5 * mems_record::PUBLISHER_CHECK_PERIOD);
    recorder.signal(libc::SIGTERM);
    let (status, stdout) = recorder.wait(WAIT);
    assert!(status.success(), "mems-record failed: {stdout}");
    assert!(stdout.contains("stopped by signal"), "{stdout}");

    let contents = read_all(&mcap).unwrap();
    assert_eq!(contents.truncation, None, "SIGTERM must finish the file");
    assert_eq!(contents.raw.len(), expected.len());
    for (got, want) in contents.raw.iter().zip(&expected) {
        assert!(same_but_acquired(got, want), "{got:?} != {want:?}");
    }
    let acquired: Vec<u64> = contents.raw.iter().map(|s| s.stamps.acquired_ns).collect();
    assert!(
        acquired.windows(2).all(|w| w[0] < w[1]),
        "publish times increase"
    );
    assert!(
        acquired[0] > before_ns && acquired[7999] < after_ns,
        "stamped at publication"
    );
    assert_eq!(contents.events, [], "a clean stop is no loss");

    // log_time is the receive time (after publication), publish_time the sample time, both
    // shifted to Unix time by the clock in the file's metadata.
    let mut run = recording::mcap::run::RunReader::open(&mcap).unwrap();
    run.next().unwrap().unwrap();
    let clock = run
        .clock()
        .expect("the recorder anchors its file to the wall clock");
    let reader = Reader::open(&mcap).unwrap();
    for m in reader.messages().unwrap() {
        let m = m.unwrap();
        if let Some(sample) = m.decode::<ipc_types::RawImuSample>() {
            let sample = sample.unwrap();
            assert_eq!(m.publish_time_ns, clock.unix_ns(sample.stamps.sample_ns));
            assert!(
                m.log_time_ns >= clock.unix_ns(sample.stamps.acquired_ns)
                    && m.log_time_ns < clock.unix_ns(after_ns + 1_000_000_000)
            );
        }
    }
    assert!(!service_exists(&ns, service::RAW), "no service left behind");
}

/// The count on `mems-replay`'s summary line that contains `what`, if there is one.
fn replay_count(stdout: &str, what: &str) -> Option<u64> {
    let line = stdout.lines().find(|l| l.contains(what))?;
    let count = line.strip_prefix("mems-replay: ")?.split(' ').next()?;
    Some(
        count
            .parse()
            .unwrap_or_else(|_| panic!("no count in {line:?}")),
    )
}

/// A recorder killed with SIGKILL leaves a whole file (no truncation) that lost at most the
/// last 100 ms; the replay feeding it takes its death for a departure
/// (exit 0, what was sent after it reported), removing the dead node itself unless another
/// process does first; the killed node's shared memory is gone afterwards.
#[test]
fn sigkilled_recorder_loses_at_most_100_ms() {
    let ns = namespace("sigkill");
    let csv = tmp("sigkill.csv");
    let mcap = tmp("sigkill.mcap");
    // 2 s at 2 kHz: fewer samples than a subscriber buffer, so the replay never waits for the
    // dead recorder (nothing is given up as stalled); the recorder is killed early in it.
    recording::csv::write_raw(&csv, &raw_samples(4000, 0, 2000), None).unwrap();
    let expected = recording::load_raw(&csv).unwrap().samples;

    let recorder = spawn(
        &mems_record(),
        &["--out", mcap.to_str().unwrap(), "--namespace", &ns],
    );
    let replay = spawn(
        &mems_replay(),
        &[
            csv.to_str().unwrap(),
            "--speed",
            "1",
            "--namespace",
            &ns,
            "--wait-subscribers",
            "1",
        ],
    );
    wait_until(WAIT, "the first samples in the file", || raw_in(&mcap) > 0);
    std::thread::sleep(Duration::from_millis(400));
    let kill_ns = monotonic_ns();
    recorder.signal(libc::SIGKILL);
    let (status, _) = recorder.wait(WAIT);
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&status),
        Some(libc::SIGKILL)
    );
    // Nothing here removes the dead recorder's node: the replay does (any other iceoryx2
    // process creating a node on the machine meanwhile may do it first). Either way the replay
    // counts what reached no subscriber after the recorder left, and succeeds.
    let (status, stdout) = replay.wait(WAIT);
    assert!(status.success(), "mems-replay failed: {stdout}");
    assert!(stdout.contains("sent 4000 of 4000 samples"), "{stdout}");
    let departed = replay_count(&stdout, "after one left").unwrap_or(0);
    assert_eq!(replay_count(&stdout, "given up"), None, "{stdout}");

    let recording = recording::load_raw(&mcap).unwrap();
    assert_eq!(
        recording.truncation, None,
        "a killed recorder's file is whole (every flush leaves one)"
    );
    let got = &recording.samples;
    assert!(
        !got.is_empty() && got.len() < expected.len(),
        "{} samples",
        got.len()
    );
    for (g, w) in got.iter().zip(&expected) {
        assert!(same_but_acquired(g, w), "{g:?} != {w:?}");
    }
    let last_ns = got.last().unwrap().stamps.acquired_ns;
    assert!(
        kill_ns.saturating_sub(last_ns) <= 100_000_000,
        "the last recorded sample was published {} ms before the kill",
        (kill_ns - last_ns) as f64 / 1e6
    );
    // Killed early in the replay, its node removed within 0.25 s: what was sent once it was
    // gone is counted, and none of what it recorded.
    assert!(
        departed > 0 && departed <= (expected.len() - got.len()) as u64,
        "{departed} samples after the recorder left, {} recorded: {stdout}",
        got.len()
    );

    // The dead recorder's node is gone (removed by the replay or by another process; the
    // cleanup here would remove it otherwise), and with it the services it held.
    let node = node();
    node.try_cleanup_dead_nodes();
    drop(node);
    for base in [service::RAW, service::CORRECTED, service::ODOMETRY] {
        assert!(
            !service_exists(&ns, base),
            "{base} left behind after the cleanup"
        );
    }
}

/// A publisher killed with SIGKILL and replaced by one further along the sequence shows in the
/// recording as: publisher lost, publisher back, and the gap of the numbers never sent; the
/// second one's clean end is no loss.
#[test]
fn sigkilled_publisher_shows_as_lost_back_and_gap() {
    let ns = namespace("gap");
    let first = tmp("gap-first.mcap");
    let second = tmp("gap-second.mcap");
    let mcap = tmp("gap-recording.mcap");
    // MCAP keeps sequence numbers as recorded (CSV would number rows from 0).
    let write = |path: &std::path::Path, samples: &[ipc_types::RawImuSample]| {
        let mut w = Writer::create(path).unwrap();
        let raw = w.add_channel::<ipc_types::RawImuSample>().unwrap();
        for s in samples {
            w.write(raw, s, s.stamps.sample_ns).unwrap();
        }
        w.finish().unwrap();
    };
    let second_samples = raw_samples(400, 6000, 4000);
    write(&first, &raw_samples(4000, 0, 4000));
    write(&second, &second_samples);
    let replay_bin = mems_replay();

    let recorder = spawn(
        &mems_record(),
        &["--out", mcap.to_str().unwrap(), "--namespace", &ns],
    );
    let replay = spawn(
        &replay_bin,
        &[
            first.to_str().unwrap(),
            "--namespace",
            &ns,
            "--wait-subscribers",
            "1",
        ],
    );
    wait_until(WAIT, "samples of the first replay", || raw_in(&mcap) >= 400);
    replay.signal(libc::SIGKILL);
    let _ = replay.wait(WAIT);
    wait_until(WAIT, "the lost publisher noticed", || {
        events_in(&mcap)
            .iter()
            .any(|e| e.kind == EventKind::PublisherLost)
    });
    // The first replay is dead: what it delivered is all in the file.
    let delivered = raw_in(&mcap);
    let replay = spawn(
        &replay_bin,
        &[
            second.to_str().unwrap(),
            "--max",
            "--namespace",
            &ns,
            "--wait-subscribers",
            "1",
        ],
    );
    let (status, stdout) = replay.wait(WAIT);
    assert!(status.success(), "second mems-replay failed: {stdout}");
    // The second replay ends cleanly and announces its departure: no loss is recorded for it.
    wait_until(WAIT, "the second replay's samples", || {
        raw_in(&mcap) >= delivered + 400
    });
    recorder.signal(libc::SIGINT);
    let (status, stdout) = recorder.wait(WAIT);
    assert!(status.success(), "mems-record failed: {stdout}");

    let contents = read_all(&mcap).unwrap();
    assert_eq!(contents.truncation, None);
    let seqs: Vec<u64> = contents.raw.iter().map(|s| s.seq).collect();
    let k = *seqs.iter().take_while(|&&s| s < 6000).last().unwrap();
    let want: Vec<u64> = (0..=k).chain(6000..6400).collect();
    assert_eq!(
        seqs, want,
        "the first replay's prefix, then the second replay"
    );
    let summary: Vec<(EventKind, Option<u64>, Option<u64>)> = contents
        .events
        .iter()
        .map(|e| (e.kind, e.from_seq, e.to_seq))
        .collect();
    assert_eq!(
        summary,
        [
            (EventKind::PublisherLost, Some(k), Some(k)),
            (EventKind::PublisherBack, Some(k), Some(k)),
            (EventKind::Gap, Some(k + 1), Some(5999)),
        ]
    );
    assert!(contents.events.iter().all(|e| e.service == service::RAW));
    assert!(contents.events.windows(2).all(|w| w[0].t_ns <= w[1].t_ns));
    assert!(
        !service_exists(&ns, service::RAW),
        "the killed replay's node was cleaned up"
    );
}

/// `--duration` ends the recording by itself with a finished (summarised) file.
#[test]
fn duration_ends_the_recording_cleanly() {
    let ns = namespace("duration");
    let mcap = tmp("duration.mcap");
    let started = std::time::Instant::now();
    let recorder = spawn(
        &mems_record(),
        &[
            "--out",
            mcap.to_str().unwrap(),
            "--namespace",
            &ns,
            "--duration",
            "0.3",
        ],
    );
    let (status, stdout) = recorder.wait(WAIT);
    assert!(status.success(), "{stdout}");
    assert!(started.elapsed() >= Duration::from_millis(300));
    assert!(!stdout.contains("stopped by signal"), "{stdout}");
    let contents = read_all(&mcap).unwrap();
    assert_eq!(contents.truncation, None);
    assert!(contents.raw.is_empty() && contents.events.is_empty());

    let bad = spawn(
        &mems_record(),
        &["--out", mcap.to_str().unwrap(), "--duration", "-1"],
    );
    let (status, _) = bad.wait(WAIT);
    assert!(!status.success(), "a negative duration is refused");
}

/// A recorder killed with SIGKILL and started again with `--continue` on the same file writes
/// the run's next segment: read as one run, the recording holds every sample but one range,
/// which the new segment names in a `gap` event after its `segment` event; the first file is
/// left as the killed recorder wrote it. A recorder started without `--continue` or `--force`
/// refuses the existing run, naming it, and changes nothing.
#[test]
fn a_restarted_recorder_continues_the_run_in_the_next_segment() {
    let ns = namespace("segment");
    let csv = tmp("segment.csv");
    let mcap = tmp("segment.mcap");
    let second = recording::segment::path(&mcap, 1);
    let _ = std::fs::remove_file(&second);
    // 3 s at 1 kHz: fewer samples than a subscriber buffer, so the replay never blocks on the
    // dead recorder.
    recording::csv::write_raw(&csv, &raw_samples(3000, 0, 1000), None).unwrap();
    let expected = recording::load_raw(&csv).unwrap().samples;
    let record = || {
        spawn(
            &mems_record(),
            &[
                "--out",
                mcap.to_str().unwrap(),
                "--continue",
                "--namespace",
                &ns,
            ],
        )
    };
    let first = record();
    let replay = spawn(
        &mems_replay(),
        &[
            csv.to_str().unwrap(),
            "--speed",
            "1",
            "--namespace",
            &ns,
            "--wait-subscribers",
            "1",
        ],
    );
    wait_until(WAIT, "samples in the first file", || raw_in(&mcap) > 300);
    first.signal(libc::SIGKILL);
    first.wait(WAIT);
    let cut = std::fs::read(&mcap).unwrap();

    let refused = spawn(
        &mems_record(),
        &["--out", mcap.to_str().unwrap(), "--namespace", &ns],
    );
    let (status, _) = refused.wait(WAIT);
    assert!(!status.success(), "an existing run is refused");
    assert_eq!(std::fs::read(&mcap).unwrap(), cut, "and left as it was");

    let restarted = record();
    // The first recorder's death is a departure, not a replay failure (what reached no
    // recorder while none ran is reported).
    let (status, stdout) = replay.wait(WAIT);
    assert!(status.success(), "mems-replay failed: {stdout}");
    assert!(stdout.contains("sent 3000 of 3000 samples"), "{stdout}");
    // Wait for the split's gap event: the previous segment is scanned in the background.
    wait_until(WAIT, "the gap across the split", || {
        events_in(&second).iter().any(|e| e.kind == EventKind::Gap)
    });
    restarted.signal(libc::SIGTERM);
    let (status, stdout) = restarted.wait(WAIT);
    assert!(status.success(), "{stdout}");
    assert!(stdout.contains("segment 1 of the run"), "{stdout}");
    assert_eq!(std::fs::read(&mcap).unwrap(), cut, "the first file is kept");

    let contents = read_all(&mcap).unwrap();
    assert_eq!(contents.segments.len(), 2);
    assert_eq!(
        contents.truncation, None,
        "the run ends with a finished file"
    );
    let seqs: Vec<u64> = contents.raw.iter().map(|s| s.seq).collect();
    let missing: Vec<(u64, u64)> = seqs
        .windows(2)
        .filter(|w| w[1] > w[0] + 1)
        .map(|w| (w[0] + 1, w[1] - 1))
        .collect();
    assert_eq!(
        missing.len(),
        1,
        "one range lost across the split: {missing:?}"
    );
    assert_eq!(*seqs.last().unwrap(), expected.last().unwrap().seq);
    for g in &contents.raw {
        assert!(same_but_acquired(g, &expected[g.seq as usize]));
    }
    let (from, to) = missing[0];
    let split: Vec<(EventKind, String, Option<u64>, Option<u64>)> = contents
        .events
        .iter()
        .map(|e| (e.kind, e.service.clone(), e.from_seq, e.to_seq))
        .collect();
    assert_eq!(
        split[..2],
        [
            (EventKind::Segment, String::new(), Some(1), Some(1)),
            (
                EventKind::Gap,
                service::RAW.to_string(),
                Some(from),
                Some(to)
            ),
        ],
        "{split:?}"
    );
    for p in [&mcap, &second] {
        std::fs::remove_file(p).unwrap();
    }
}
