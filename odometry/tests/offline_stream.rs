//! `mems-odometry offline` as a process on real MCAP files of a simulated drive with truth and
//! robot hints (each hint recorded 40 ms after its publication, so after samples it precedes
//! in publication order): the streamed run split across two segments (a recorder restarted
//! with `--continue`) gives exactly the single file's result.

mod common;

use std::path::Path;
use std::process::Command;

use common::{Case, drive_with_encoder_hints, offline_json, scratch};
use ipc_types::{OdometryState, RawImuSample, RobotHint};
use recording::Truth;
use recording::mcap::{EventKind, RecorderEvent, Writer, quantum};

/// How long after its publication the recorder receives a hint, ns.
const HINT_LATENCY_NS: u64 = 40_000_000;

/// One message of the recording, in the order the recorder writes them.
enum Message {
    Raw(RawImuSample, Truth),
    Hint(RobotHint),
}

/// A drive with turns at 200 Hz and its encoder hints, in recorder order (by receive time).
fn drive() -> Vec<Message> {
    let case = Case {
        duration_s: 120.0,
        turns: true,
        ..Case::straight()
    };
    let (raw, hints) = drive_with_encoder_hints(&case, 3);
    let mut hints = hints.into_iter().peekable();
    let mut messages = Vec::new();
    for (r, t) in raw {
        while let Some(h) =
            hints.next_if(|h| h.stamps.acquired_ns + HINT_LATENCY_NS <= r.stamps.sample_ns)
        {
            messages.push(Message::Hint(h));
        }
        messages.push(Message::Raw(r, t));
    }
    messages.extend(hints.map(Message::Hint));
    messages
}

/// Writes `messages` to `path`; a successor segment (`segment` > 0) starts with its event.
fn write(path: &Path, segment: u64, messages: &[Message]) {
    let mut w = Writer::create(path).unwrap();
    let events = w.add_channel::<RecorderEvent>().unwrap();
    let raw = w.add_channel::<RawImuSample>().unwrap();
    let truth = w.add_channel::<Truth>().unwrap();
    let hint = w.add_channel::<RobotHint>().unwrap();
    if segment > 0 {
        let event = RecorderEvent {
            kind: EventKind::Segment,
            service: String::new(),
            from_seq: Some(segment),
            to_seq: Some(segment),
            t_ns: 0,
        };
        w.write(events, &event, 0).unwrap();
    }
    for m in messages {
        match m {
            Message::Raw(r, t) => {
                w.write(raw, r, r.stamps.sample_ns).unwrap();
                w.write(truth, t, r.stamps.sample_ns).unwrap();
            }
            Message::Hint(h) => w
                .write(hint, h, h.stamps.acquired_ns + HINT_LATENCY_NS)
                .unwrap(),
        }
    }
    w.finish().unwrap();
}

fn offline(input: &Path, extra: &[&str]) -> serde_json::Value {
    offline_json(env!("CARGO_BIN_EXE_mems-odometry"), input, extra)
}

#[test]
fn a_segmented_run_streams_to_the_single_files_result() {
    let dir = scratch("offline-stream");
    let messages = drive();
    let single = dir.join("single.mcap");
    write(&single, 0, &messages);
    let run = dir.join("run.mcap");
    let half = messages.len() / 2;
    write(&run, 0, &messages[..half]);
    write(&dir.join("run.1.mcap"), 1, &messages[half..]);

    let whole = offline(&single, &[]);
    let segmented = offline(&run, &[]);
    std::fs::remove_dir_all(&dir).unwrap();

    // The hints were used, and the drive was navigated against its truth.
    assert!(whole["hints"]["applied"].as_u64().unwrap() > 0, "{whole}");
    assert!(
        whole["hints"]["in_recording"].as_u64().unwrap() > 1000,
        "{whole}"
    );
    assert_eq!(whole["hints"]["late"], 0, "{whole}");
    assert!(
        whole["truth_distance_m"].as_f64().unwrap() > 10.0,
        "{whole}"
    );
    assert!(
        whole["rest_intervals"].as_array().unwrap().len() > 2,
        "{whole}"
    );
    // serde_json's Value compares f64 exactly.
    assert_eq!(segmented, whole);
}

/// `--out` writes the run as a live run's recording: the raw samples and hints read, one
/// corrected sample per raw sample, a state per sample (revisions besides), each live state
/// with its pose, the last live state is the one the report gives and the report's track is the
/// live states' positions every 100 ms. An existing file is refused
/// unless `--force`.
#[test]
fn offline_writes_its_run_as_a_recording() {
    // Not under `scratch("offline-stream")`, which the other test removes when it ends.
    let dir = std::env::temp_dir().join(format!("offline-out-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let messages = drive();
    let input = dir.join("drive.mcap");
    write(&input, 0, &messages);
    let out = dir.join("states.mcap");
    let out_arg = out.to_str().unwrap();
    let report = offline(&input, &["--out", out_arg]);

    let read = recording::mcap::read_all(&out).unwrap();
    let raw: Vec<RawImuSample> = messages
        .iter()
        .filter_map(|m| match m {
            Message::Raw(r, _) => Some(*r),
            Message::Hint(_) => None,
        })
        .collect();
    assert_eq!(read.raw, raw);
    let hints = messages.len() - raw.len();
    assert_eq!(read.hints.len(), hints);
    assert_eq!(read.corrected.len(), raw.len());
    let live: Vec<_> = read
        .odometry
        .iter()
        .filter(|s| s.flags & ipc_types::odometry_flags::REVISION == 0)
        .collect();
    assert_eq!(live.len(), raw.len());
    assert!(read.odometry.len() > live.len(), "revisions are kept");
    // The pose of the first live state in each 20 ms of sample time; revised poses (likewise
    // thinned), transforms (one per pose) and the path are on their own topics, which
    // read_all counts without decoding.
    let shown = displayed(live.iter().copied());
    assert_eq!(read.poses.len(), shown.len());
    for (pose, state) in read.poses.iter().zip(&shown) {
        let p = pose.pose.position;
        assert_eq!([p.x, p.y, p.z], state.position_m);
    }
    let revisions = read
        .odometry
        .iter()
        .filter(|s| s.flags & ipc_types::odometry_flags::REVISION != 0);
    let revised = displayed(revisions).len() as u64;
    let path = read.other_messages - revised - shown.len() as u64;
    assert!(path >= 1, "{path} path messages");
    // The recorded end equals the report's f64 end rounded to the recording's quantum.
    let end = live.last().unwrap();
    let reported: Vec<f64> = report["end_displacement_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| quantum::recorded(v.as_f64().unwrap(), quantum::POSITION_M))
        .collect();
    assert_eq!(reported, end.position_m);
    // The report's track: the aligned live states thinned to one per 100 ms of sample time
    // from the first, times from the first sample, each at its position as last published: a
    // revised state puts the points after the revised state before it (within 100 ms) and up
    // to its own time on the line between the two, as the recording holds them in order.
    let first_ns = raw[0].stamps.sample_ns;
    let mut expected = Vec::new();
    for s in live
        .iter()
        .filter(|s| s.flags & ipc_types::odometry_flags::ALIGNED != 0)
    {
        if expected
            .last()
            .is_none_or(|&(t, _)| s.stamps.sample_ns >= t + 100_000_000)
        {
            expected.push((s.stamps.sample_ns, s.position_m));
        }
    }
    revise(&mut expected, &read.odometry);
    let track = report["track"].as_array().unwrap();
    assert!(track.len() > 100, "{}", track.len());
    assert_eq!(track.len(), expected.len());
    for (point, (t_ns, p)) in track.iter().zip(&expected) {
        let v: Vec<f64> = point
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert!(
            (v[0] - (t_ns - first_ns) as f64 * 1e-9).abs() < 1e-9,
            "{point}"
        );
        // Interpolated between recorded (rounded) positions: within two quanta.
        for (x, e) in v[1..].iter().zip(p) {
            assert!(
                (x - e).abs() <= 2.0 * quantum::POSITION_M,
                "{point} against {p:?}"
            );
        }
    }
    assert_eq!(track[0][0], report["aligned_at_s"], "{report}");

    let refused = Command::new(env!("CARGO_BIN_EXE_mems-odometry"))
        .args(["offline", "--input"])
        .arg(&input)
        .args(["--out", out_arg])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(
        !refused.status.success() && err.contains("--force"),
        "{err}"
    );
    offline(&input, &["--out", out_arg, "--force"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The states the Foxglove topics show: the first of each 20 ms of sample time.
fn displayed<'a>(states: impl Iterator<Item = &'a OdometryState>) -> Vec<&'a OdometryState> {
    let mut step = None;
    states
        .filter(|s| {
            let this = s.stamps.sample_ns / 20_000_000;
            step.replace(this) != Some(this)
        })
        .collect()
}

/// A run the session refuses midway (robot hints published far ahead of the samples they
/// precede, more than the session's hint queue holds) ends with that refusal as the error and a
/// non-zero exit, instead of waiting on the reader thread still streaming the rest of the file.
#[test]
fn a_refused_streamed_run_fails_instead_of_hanging() {
    let dir = std::env::temp_dir().join(format!("offline-refused-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ahead_ns = 1_000_000_000_000;
    let messages: Vec<Message> = drive()
        .into_iter()
        .map(|m| match m {
            Message::Hint(mut h) => {
                h.stamps.sample_ns += ahead_ns;
                h.stamps.acquired_ns += ahead_ns;
                Message::Hint(h)
            }
            raw => raw,
        })
        .collect();
    let hints = messages
        .iter()
        .filter(|m| matches!(m, Message::Hint(_)))
        .count();
    assert!(hints > odometry::session::HINT_QUEUE, "{hints} hints");
    let input = dir.join("ahead.mcap");
    write(&input, 0, &messages);
    let mut child = Command::new(env!("CARGO_BIN_EXE_mems-odometry"))
        .args(["offline", "--json", "--input"])
        .arg(&input)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    // A generous bound: the run takes well under a second; a hang is the failure looked for.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(300);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if std::time::Instant::now() > deadline {
            child.kill().unwrap();
            panic!("mems-odometry offline still runs after 300 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(!status.success(), "{err}");
    assert!(err.contains("hints already wait"), "{err}");
}

/// Moves the track's points `track` (sample time ns, position m) as the revised states among
/// `states` (in their recorded order) revise them: the points after the previous revised
/// state, when it is at most 100 ms older, and up to this one's time, onto the line between
/// the two; the point at its time alone otherwise.
fn revise(track: &mut [(u64, [f64; 3])], states: &[OdometryState]) {
    use ipc_types::odometry_flags::{ALIGNED, REVISION};
    let mut previous: Option<(u64, [f64; 3])> = None;
    for s in states.iter().filter(|s| s.flags & REVISION != 0) {
        if s.flags & ALIGNED == 0 {
            previous = None;
            continue;
        }
        let (t, p) = (s.stamps.sample_ns, s.position_m);
        let (t0, p0) = match previous.replace((t, p)) {
            Some((t0, p0)) if t0 < t && t - t0 <= 100_000_000 => (t0, p0),
            _ => (t - 1, p),
        };
        for (tk, pk) in track.iter_mut().filter(|(tk, _)| *tk > t0 && *tk <= t) {
            let f = (*tk - t0) as f64 / (t - t0) as f64;
            *pk = std::array::from_fn(|i| p0[i] + (p[i] - p0[i]) * f);
        }
    }
}
