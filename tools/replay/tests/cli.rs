//! `mems-replay` as a real process against real MCAP files, with subscribers on the real
//! services in this process (or, to be SIGKILLed, in a process of their own): topic choice,
//! `--start`/`--end`, `--loop` with SIGTERM, a subscriber killed during the replay, and bad
//! arguments. What is expected is computed from the file read back (`read_all`).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use ipc_types::{
    CorrectedImuSample, OdometryState, RawImuSample, RobotHint, Stamps, corrected_flags,
    odometry_flags, raw_flags, service,
};
use recording::clock::WallClock;
use recording::mcap::{Contents, Writer, read_all};

fn namespace(test: &str) -> String {
    format!("c{}-{test}", std::process::id())
}

fn tmp(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("cli-{}-{name}", std::process::id()))
}

/// A recording as the recorder writes one (anchored): `n` raw samples at 1 kHz from 5 s, a
/// corrected sample and a state per sample, a revision of the state 20 samples back after
/// every 50th, a hint every 100 ms from 5.005 s.
fn write_run(path: &Path, n: u64) {
    let mut w = Writer::create(path).unwrap();
    w.anchor(WallClock::now()).unwrap();
    let (raw, corrected) = (w.add_channel().unwrap(), w.add_channel().unwrap());
    let (odometry, hint) = (w.add_channel().unwrap(), w.add_channel().unwrap());
    let t = |i: u64| 5_000_000_000 + i * 1_000_000;
    let stamps = |i: u64| Stamps {
        sample_ns: t(i),
        acquired_ns: t(i) + 300_000,
        calibrated_ns: t(i) + 400_000,
        odometry_ns: t(i) + 500_000,
    };
    for i in 0..n {
        if i % 100 == 5 {
            let h = RobotHint {
                stamps: Stamps {
                    acquired_ns: t(i),
                    ..Stamps::default()
                },
                seq: i / 100,
                forward_speed_mps: 0.1 * i as f64,
                ..RobotHint::default()
            };
            w.write(hint, &h, t(i)).unwrap();
        }
        let s = RawImuSample {
            stamps: stamps(i),
            seq: i,
            accel_g: [0.01 * (i % 7) as f64, 0.0, 1.0],
            gyro_dps: [0.5, -0.25, i as f64 * 1e-3],
            temp_c: 25.0,
            flags: raw_flags::GYRO_VALID | raw_flags::TEMP_VALID,
            ..RawImuSample::default()
        };
        w.write(raw, &s, t(i) + 300_000).unwrap();
        let c = CorrectedImuSample {
            stamps: stamps(i),
            seq: i,
            accel_mps2: [0.1, 0.2, 9.81 + i as f64 * 1e-6],
            ..CorrectedImuSample::default()
        };
        w.write(corrected, &c, t(i) + 400_000).unwrap();
        let state = |k: u64, flags| OdometryState {
            stamps: stamps(k),
            seq: k,
            position_m: [k as f64 * 1e-3, 0.5, -(i as f64)],
            flags,
            ..OdometryState::default()
        };
        w.write(odometry, &state(i, 0), t(i) + 500_000).unwrap();
        if i % 50 == 49 {
            let revision = state(i - 20, odometry_flags::REVISION);
            w.write(odometry, &revision, t(i) + 600_000).unwrap();
        }
    }
    w.finish().unwrap();
}

/// Subscribes to `base` in namespace `ns` in its own thread and node until `n` payloads
/// arrived (or 30 s passed).
fn subscribe<T: core::fmt::Debug + ZeroCopySend + Copy + Send + 'static>(
    ns: &str,
    base: &str,
    n: usize,
) -> thread::JoinHandle<Vec<T>> {
    let name = service::full_name(ns, base);
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let handle = thread::spawn(move || {
        let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
        let svc = service::open::<T>(&node, &name).unwrap();
        let sub = service::subscriber(&svc).unwrap();
        ready_tx.send(()).unwrap();
        let (start, mut got) = (Instant::now(), Vec::new());
        while got.len() < n && start.elapsed() < Duration::from_secs(30) {
            while let Some(s) = sub.receive().unwrap() {
                got.push(*s.payload());
            }
            thread::sleep(Duration::from_micros(200));
        }
        got
    });
    ready_rx.recv().unwrap();
    handle
}

fn mems_replay(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mems-replay"))
        .args(args)
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// The time of a recording's first replayable message, ns.
fn origin(c: &Contents) -> u64 {
    let raw = c.raw.iter().map(|s| s.stamps.sample_ns);
    let hints = c.hints.iter().map(|h| h.stamps.acquired_ns);
    let corrected = c.corrected.iter().map(|s| s.stamps.sample_ns);
    let states = c.odometry.iter().map(|s| s.stamps.sample_ns);
    raw.chain(hints)
        .chain(corrected)
        .chain(states)
        .min()
        .unwrap()
}

/// `--topics mems/odometry/state`: a subscriber on the state service receives exactly the
/// recorded states, revisions included, in recorded order; only `odometry_ns`, the
/// publisher's own stamp, is the publication time.
#[test]
fn the_chosen_topic_is_replayed_exactly_as_recorded() {
    let path = tmp("states.mcap");
    write_run(&path, 600);
    let recorded = read_all(&path).unwrap().odometry;
    assert_eq!(recorded.len(), 612);
    let ns = namespace("states");
    let sub = subscribe::<OdometryState>(&ns, service::ODOMETRY, recorded.len());
    let started_ns = ipc_types::clock::monotonic_ns();
    let args = [
        "--topics",
        "mems/odometry/state",
        "--max",
        "--wait-subscribers",
        "1",
    ];
    let out = mems_replay(&[&[path.to_str().unwrap()][..], &args, &["--namespace", &ns]].concat());
    std::fs::remove_file(&path).unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let got = sub.join().unwrap();
    assert_eq!(got.len(), recorded.len());
    for (g, r) in got.iter().zip(&recorded) {
        assert!(g.stamps.odometry_ns >= started_ns);
        let mut expected = *r;
        expected.stamps.odometry_ns = g.stamps.odometry_ns;
        assert_eq!(*g, expected);
    }
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("sent 612 of 612 samples in 1 pass"),
        "{stdout}"
    );
    assert!(stdout.contains("mems/odometry/state 612"), "{stdout}");
}

/// `--start 0.25 --end 0.5`: exactly the raw samples and hints whose times are within 0.25 to
/// 0.5 s of the first message, both ends included, and the final progress line.
#[test]
fn start_and_end_keep_exactly_the_messages_in_the_window() {
    let path = tmp("window.mcap");
    write_run(&path, 1000);
    let contents = read_all(&path).unwrap();
    let t0 = origin(&contents);
    let inside = |t: u64| (t0 + 250_000_000..=t0 + 500_000_000).contains(&t);
    let raw: Vec<u64> = contents
        .raw
        .iter()
        .filter(|s| inside(s.stamps.sample_ns))
        .map(|s| s.seq)
        .collect();
    let hints: Vec<RobotHint> = contents
        .hints
        .iter()
        .filter(|h| inside(h.stamps.acquired_ns))
        .copied()
        .collect();
    assert_eq!((raw.len(), hints.len()), (251, 2));
    let ns = namespace("window");
    let raw_sub = subscribe::<RawImuSample>(&ns, service::RAW, raw.len());
    let hint_sub = subscribe::<RobotHint>(&ns, service::HINT, hints.len());
    let args = [
        "--start",
        "0.25",
        "--end",
        "0.5",
        "--speed",
        "4",
        "--progress",
    ];
    let tail = ["--wait-subscribers", "1", "--namespace", &ns];
    let out = mems_replay(&[&[path.to_str().unwrap()][..], &args, &tail].concat());
    std::fs::remove_file(&path).unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let got: Vec<u64> = raw_sub.join().unwrap().iter().map(|s| s.seq).collect();
    assert_eq!(got, raw);
    assert_eq!(hint_sub.join().unwrap(), hints);
    let stdout = text(&out.stdout);
    assert!(stdout.contains("sent 253 of 253 samples"), "{stdout}");
    let stderr = text(&out.stderr);
    let last = stderr.lines().last().unwrap_or_default();
    assert!(last.starts_with("mems-replay: pass 1: "), "{stderr}");
    assert!(last.contains("s recorded, 253 messages sent"), "{stderr}");
}

/// `--loop` replays until SIGTERM: a subscriber sees the recording twice in a row, then the
/// replay exits 0 with its summary.
#[test]
fn loop_replays_until_sigterm_and_exits_cleanly() {
    let path = tmp("loop.mcap");
    write_run(&path, 100);
    let seqs: Vec<u64> = read_all(&path).unwrap().raw.iter().map(|s| s.seq).collect();
    let ns = namespace("loop");
    let sub = subscribe::<RawImuSample>(&ns, service::RAW, 2 * seqs.len());
    let child = Command::new(env!("CARGO_BIN_EXE_mems-replay"))
        .arg(&path)
        .args([
            "--loop",
            "--topics",
            "mems/imu/raw",
            "--wait-subscribers",
            "1",
        ])
        .args(["--namespace", &ns])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let got: Vec<u64> = sub.join().unwrap().iter().map(|s| s.seq).collect();
    // SAFETY: kill(2) on the child's pid; the child is not reaped before wait below.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let out = child.wait_with_output().unwrap();
    let status = out.status;
    std::fs::remove_file(&path).unwrap();
    let twice: Vec<u64> = seqs.iter().chain(&seqs).copied().collect();
    assert_eq!(
        got[..twice.len()],
        twice,
        "two passes, each the whole recording"
    );
    assert!(status.success(), "{status}: {}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("(stopped by signal)"), "{stdout}");
    let passes: u64 = stdout
        .split(" in ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no pass count in {stdout}"));
    assert!(passes >= 2, "{stdout}");
}

/// `--loop` of the corrected topic: the first sample of every pass after the first carries
/// `NEW_SESSION` (its seq and time start over), so that an odometry fed the corrected topic
/// directly starts a new session instead of refusing times that go back.
#[test]
fn a_looped_corrected_topic_marks_each_new_pass_as_a_new_session() {
    let path = tmp("loop-corrected.mcap");
    write_run(&path, 100);
    let n = read_all(&path).unwrap().corrected.len();
    let ns = namespace("loop-corrected");
    let sub = subscribe::<CorrectedImuSample>(&ns, service::CORRECTED, 2 * n);
    let child = Command::new(env!("CARGO_BIN_EXE_mems-replay"))
        .arg(&path)
        .args(["--loop", "--topics", "mems/imu/corrected"])
        .args(["--wait-subscribers", "1", "--namespace", &ns])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let got = sub.join().unwrap();
    // SAFETY: kill(2) on the child's pid; the child is not reaped before wait below.
    assert_eq!(unsafe { libc::kill(child.id() as i32, libc::SIGTERM) }, 0);
    let out = child.wait_with_output().unwrap();
    std::fs::remove_file(&path).unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    // The subscriber may have taken part of a third pass too.
    assert!(got.len() >= 2 * n, "{} of {}", got.len(), 2 * n);
    for (i, s) in got.iter().enumerate() {
        let first_of_a_later_pass = i > 0 && i % n == 0;
        assert_eq!(
            s.flags & corrected_flags::NEW_SESSION != 0,
            first_of_a_later_pass,
            "sample {i} (seq {}): only the first sample of a pass after the first is marked",
            s.seq
        );
    }
    assert_eq!(got[n].seq, got[0].seq, "the second pass starts over");
}

/// Environment variable that makes [`subscriber_process`] act: the namespace to subscribe in.
const SUBSCRIBER_ENV: &str = "MEMS_REPLAY_TEST_SUBSCRIBER";
/// Raw samples the subscriber process takes before it kills itself.
const TAKEN: usize = 100;

/// Not a test of its own (it returns at once): the subscriber process of
/// [`a_killed_subscriber_is_a_departure_that_the_replay_removes_itself`], this test binary run
/// again with [`SUBSCRIBER_ENV`] set. It subscribes to the raw samples, takes [`TAKEN`] of
/// them and SIGKILLs itself: a subscriber that dies without closing its port, at a known
/// point of the replay.
#[test]
fn subscriber_process() {
    let Ok(ns) = std::env::var(SUBSCRIBER_ENV) else {
        return;
    };
    let node = NodeBuilder::new().create::<ipc::Service>().unwrap();
    let name = service::full_name(&ns, service::RAW);
    let svc = service::open::<RawImuSample>(&node, &name).unwrap();
    let sub = service::subscriber(&svc).unwrap();
    let mut taken = 0;
    while taken < TAKEN {
        match sub.receive().unwrap() {
            Some(_) => taken += 1,
            None => thread::sleep(Duration::from_micros(100)),
        }
    }
    // SAFETY: kill(2) on this process.
    unsafe { libc::kill(libc::getpid(), libc::SIGKILL) };
    unreachable!("SIGKILL cannot be caught");
}

/// A subscriber killed with SIGKILL during a `--max` replay that then sends far more than a
/// subscriber buffer (the dead one's fills, and the lossless publisher would wait for it),
/// with nothing in the test removing its node: the replay removes it (unless another iceoryx2
/// process does first), takes its death for a departure and exits 0, counting and reporting every sample that did not reach it. It took
/// [`TAKEN`] samples and its buffer holds at most [`service::SUBSCRIBER_BUFFER`] more (and
/// the connection at times one or two beyond, see the replay tests), so at least the rest are
/// counted, whether as sent after it left or, had its node outlived the publisher's stall
/// timeout, as given up for it.
#[test]
fn a_killed_subscriber_is_a_departure_that_the_replay_removes_itself() {
    let path = tmp("killed.mcap");
    let n = TAKEN + service::SUBSCRIBER_BUFFER + 5000;
    write_run(&path, n as u64);
    let ns = namespace("killed");
    let mut subscriber = Command::new(std::env::current_exe().unwrap())
        .args(["subscriber_process", "--exact", "--test-threads", "1"])
        .env(SUBSCRIBER_ENV, &ns)
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let out = mems_replay(&[
        path.to_str().unwrap(),
        "--topics",
        "mems/imu/raw",
        "--max",
        "--wait-subscribers",
        "1",
        "--wait-timeout",
        "60",
        "--namespace",
        &ns,
    ]);
    let status = subscriber.wait().unwrap();
    std::fs::remove_file(&path).unwrap();
    assert_eq!(
        std::os::unix::process::ExitStatusExt::signal(&status),
        Some(libc::SIGKILL),
        "the subscriber killed itself"
    );
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{stdout}{}", text(&out.stderr));
    assert!(
        stdout.contains(&format!("sent {n} of {n} samples")),
        "{stdout}"
    );
    let count = |what: &str| {
        stdout
            .lines()
            .find(|l| l.contains(what))
            .and_then(|l| l.strip_prefix("mems-replay: "))
            .and_then(|l| l.split(' ').next())
            .map_or(0, |c| c.parse::<u64>().unwrap())
    };
    let departed = count("after one left") + count("given up");
    let least = (n - TAKEN - service::SUBSCRIBER_BUFFER - 2) as u64;
    assert!(
        (least..=(n - TAKEN) as u64).contains(&departed),
        "{departed} samples counted as departed, expected {least} to {}: {stdout}",
        n - TAKEN
    );
}

/// Bad arguments: a non-zero exit and a message that names the option (and for a topic that
/// is not replayable, the replayable ones).
#[test]
fn bad_arguments_are_refused_naming_the_option() {
    let path = tmp("bad.mcap");
    write_run(&path, 300);
    let file = path.to_str().unwrap();
    let ns = namespace("bad");
    let cases: [(&[&str], &str); 8] = [
        (
            &["--topics", "mems/odometry/pose"],
            "--topics mems/odometry/pose: not a replayable",
        ),
        (
            &["--topics", "mems/recorder/events"],
            "--topics mems/recorder/events",
        ),
        (
            &["--topics", "mems/imu/raw,mems/sim/truth"],
            "--topics mems/sim/truth",
        ),
        (&["--start=-1"], "--start -1"),
        (&["--start", "inf"], "--start inf"),
        (&["--end", "0.5"], "--end 0.5: past the recording's end"),
        (
            &["--start", "0.2", "--end", "0.1"],
            "--start 0.2 must be before --end 0.1",
        ),
        (
            &["--start", "0.1", "--end", "0.1"],
            "--start 0.1 must be before --end 0.1",
        ),
    ];
    for (args, expected) in cases {
        let out = mems_replay(&[&[file, "--namespace", &ns][..], args].concat());
        let stderr = text(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
    let out = mems_replay(&[file, "--topics", "mems/sim/truth", "--namespace", &ns]);
    let stderr = text(&out.stderr);
    for topic in [
        service::RAW,
        service::CORRECTED,
        service::ODOMETRY,
        service::HINT,
    ] {
        assert!(stderr.contains(topic), "{stderr}");
    }
    std::fs::remove_file(&path).unwrap();
}
