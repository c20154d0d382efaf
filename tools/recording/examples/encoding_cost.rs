//! Size and write cost of a recording's layout: reads every message of the known topics of a
//! recording (either encoding, older layouts too), then writes them all again, in the same
//! order with the same log times:
//! - as JSON, the form older recorders wrote (raw, corrected, state, a pose per live state,
//!   hints, truth, events);
//! - as protobuf, as the recorder writes now (the Foxglove topics derived from the states by
//!   `recording::mcap::derived`, at their display rate): its flushed file (a chunk closed
//!   every 50 ms of log time, what a killed recorder leaves), its compact copy (whole chunks
//!   at `recording::mcap::COMPACT_LEVEL`, what a finished recording is), and other levels;
//!
//! and prints each file's size and the time spent writing it (deriving, encoding,
//! compressing and writing each message, then finishing the file) per message written, the
//! best of three; then what each topic adds to a finished recording.
//!
//!     cargo run --release -p recording --example encoding_cost -- run.mcap

use std::path::Path;
use std::time::Instant;

use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};
use recording::Truth;
use recording::mcap::derived::{
    Derived, Out, PATH_TOPIC, POSE_TOPIC, REVISED_POSE_TOPIC, TF_TOPIC,
};
use recording::mcap::run::RunReader;
use recording::mcap::{
    COMPACT_CHUNK_BYTES, COMPACT_LEVEL, MessageEncoding, PoseInFrame, RecorderEvent, Topic, Writer,
};

/// One decoded message with its log time (the recording's own Foxglove topics are not read:
/// they are derived again from the states).
#[derive(Clone)]
enum Item {
    Raw(RawImuSample),
    Corrected(CorrectedImuSample),
    State(OdometryState),
    Hint(RobotHint),
    Truth(Truth),
    Event(RecorderEvent),
}

/// The topics, in the per-topic report's order.
const TOPICS: [&str; 10] = [
    RawImuSample::TOPIC,
    CorrectedImuSample::TOPIC,
    OdometryState::TOPIC,
    POSE_TOPIC,
    REVISED_POSE_TOPIC,
    TF_TOPIC,
    PATH_TOPIC,
    RobotHint::TOPIC,
    Truth::TOPIC,
    RecorderEvent::TOPIC,
];

fn read(path: &Path) -> recording::Result<Vec<(Item, u64)>> {
    let mut run = RunReader::open(path)?;
    let mut items = Vec::new();
    while let Some(m) = run.next() {
        let m = m?;
        let item = if let Some(x) = m.decode::<RawImuSample>() {
            Item::Raw(x?)
        } else if let Some(x) = m.decode::<CorrectedImuSample>() {
            Item::Corrected(x?)
        } else if let Some(x) = m.decode::<OdometryState>() {
            Item::State(x?)
        } else if let Some(x) = m.decode::<RobotHint>() {
            Item::Hint(x?)
        } else if let Some(x) = m.decode::<Truth>() {
            Item::Truth(x?)
        } else if let Some(x) = m.decode::<RecorderEvent>() {
            Item::Event(x?)
        } else {
            continue;
        };
        items.push((item, m.log_time_ns));
    }
    Ok(items)
}

/// How a rewrite is written.
#[derive(Clone, Copy)]
struct Layout {
    encoding: MessageEncoding,
    level: u32,
    /// Uncompressed bytes at which a chunk is closed.
    chunk_bytes: u64,
    /// Every topic but this one, or all.
    without: Option<&'static str>,
    /// Closes the chunk when its first message is this much log time old, as the recorder
    /// does (`mems_record::FLUSH_PERIOD`, 50 ms), or never.
    flush_ns: Option<u64>,
}

/// Writes `items` to `out` as `layout` says; the seconds it took and the messages written.
fn write(items: &[(Item, u64)], out: &Path, layout: Layout) -> recording::Result<(f64, u64)> {
    let start = Instant::now();
    let mut w =
        Writer::create_tuned(out, layout.level, layout.chunk_bytes)?.with_encoding(layout.encoding);
    let raw = w.add_channel::<RawImuSample>()?;
    let corrected = w.add_channel::<CorrectedImuSample>()?;
    let state = w.add_channel::<OdometryState>()?;
    let hint = w.add_channel::<RobotHint>()?;
    let truth = w.add_channel::<Truth>()?;
    let event = w.add_channel::<RecorderEvent>()?;
    let json = layout.encoding == MessageEncoding::Json;
    let json_pose = w.add_channel::<PoseInFrame>()?;
    let pose = w.add_foxglove_channel(POSE_TOPIC)?;
    let revised = w.add_foxglove_channel(REVISED_POSE_TOPIC)?;
    let tf = w.add_foxglove_channel(TF_TOPIC)?;
    let path = w.add_foxglove_channel(PATH_TOPIC)?;
    let mut derived = Derived::new(None);
    let wanted = |topic: &str| layout.without != Some(topic);
    let mut n = 0u64;
    let mut chunk_start = None;
    for (item, t) in items {
        if let Some(period) = layout.flush_ns {
            let start = *chunk_start.get_or_insert(*t);
            if *t >= start + period {
                w.flush()?;
                chunk_start = Some(*t);
            }
        }
        let mut put = |topic: &str| {
            let yes = wanted(topic);
            n += u64::from(yes);
            yes
        };
        match item {
            Item::Raw(x) if put(RawImuSample::TOPIC) => w.write(raw, x, *t)?,
            Item::Corrected(x) if put(CorrectedImuSample::TOPIC) => w.write(corrected, x, *t)?,
            Item::State(x) => {
                if put(OdometryState::TOPIC) {
                    w.write(state, x, *t)?;
                }
                let live = x.flags & ipc_types::odometry_flags::REVISION == 0;
                if json && live && put(POSE_TOPIC) {
                    w.write(json_pose, &PoseInFrame::from_state(x), *t)?;
                }
                if !json {
                    let p = x.stamps.sample_ns;
                    derived.state(x, |out| match out {
                        Out::Pose(m) if put(POSE_TOPIC) => w.write_foxglove(pose, m, p, *t),
                        Out::RevisedPose(m) if put(REVISED_POSE_TOPIC) => {
                            w.write_foxglove(revised, m, p, *t)
                        }
                        Out::Tf(m) if put(TF_TOPIC) => w.write_foxglove(tf, m, p, *t),
                        Out::Path(m) if put(PATH_TOPIC) => w.write_foxglove(path, m, p, *t),
                        _ => Ok(()),
                    })?;
                }
            }
            Item::Hint(x) if put(RobotHint::TOPIC) => w.write(hint, x, *t)?,
            Item::Truth(x) if put(Truth::TOPIC) => w.write(truth, x, *t)?,
            Item::Event(x) if put(RecorderEvent::TOPIC) => w.write(event, x, *t)?,
            _ => {}
        }
    }
    w.finish()?;
    Ok((start.elapsed().as_secs_f64(), n))
}

/// Writes `items` as `layout` says, three times; the file's size, the messages written and
/// the best time.
fn measure(
    items: &[(Item, u64)],
    layout: Layout,
    runs: usize,
) -> Result<(u64, u64, f64), Box<dyn std::error::Error>> {
    let out = std::env::temp_dir().join(format!("encoding-cost-{}.mcap", std::process::id()));
    let mut best = f64::INFINITY;
    let mut n = 0;
    for _ in 0..runs {
        let (seconds, written) = write(items, &out, layout)?;
        best = best.min(seconds);
        n = written;
    }
    let size = std::fs::metadata(&out)?.len();
    std::fs::remove_file(&out)?;
    Ok((size, n, best))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let input = std::env::args()
        .nth(1)
        .ok_or("usage: encoding_cost RECORDING.mcap")?;
    let items = read(Path::new(&input))?;
    println!(
        "{input}: {} messages read (Foxglove topics derived again)",
        items.len()
    );
    // What the recorder leaves: its flushed file (a chunk closed every 50 ms of log time)
    // if it is killed, the compact copy (whole chunks at COMPACT_LEVEL) if it finishes.
    let flushed = Layout {
        encoding: MessageEncoding::Protobuf,
        level: 0,
        chunk_bytes: 1 << 20,
        without: None,
        flush_ns: Some(50_000_000),
    };
    let compact = Layout {
        level: COMPACT_LEVEL,
        chunk_bytes: COMPACT_CHUNK_BYTES,
        flush_ns: None,
        ..flushed
    };
    let layouts = [
        (
            "json, flushed every 50 ms",
            Layout {
                encoding: MessageEncoding::Json,
                ..flushed
            },
        ),
        (
            "protobuf, flushed every 50 ms (a killed recorder's file)",
            flushed,
        ),
        (
            "protobuf, 4 MiB chunks, zstd level 3",
            Layout {
                level: 0,
                ..compact
            },
        ),
        (
            "protobuf, 1 MiB chunks, zstd level 9",
            Layout {
                chunk_bytes: 1 << 20,
                ..compact
            },
        ),
        (
            "protobuf, 4 MiB chunks, zstd level 9 (a finished recording)",
            compact,
        ),
        (
            "protobuf, 4 MiB chunks, zstd level 17",
            Layout {
                level: 17,
                ..compact
            },
        ),
    ];
    println!("| layout | bytes | messages | bytes/message | write, us/message |");
    println!("|---|---|---|---|---|");
    for (name, layout) in layouts {
        let (size, n, best) = measure(&items, layout, 3)?;
        println!(
            "| {name} | {size} | {n} | {:.1} | {:.2} |",
            size as f64 / n as f64,
            best * 1e6 / n as f64
        );
    }
    // What each topic adds: the file without it, against the file with every topic (a
    // finished recording's layout).
    let (all, _, _) = measure(&items, compact, 1)?;
    println!("| topic | messages | bytes it adds |");
    println!("|---|---|---|");
    for topic in TOPICS {
        let (size, n, _) = measure(
            &items,
            Layout {
                without: Some(topic),
                ..compact
            },
            1,
        )?;
        let (_, everything, _) = measure(&items, compact, 1)?;
        if n < everything {
            println!("| {topic} | {} | {} |", everything - n, all - size);
        }
    }
    Ok(())
}
