//! Size and write cost of a recording in each message encoding: reads every message of the
//! known topics of a recording (either encoding), then writes them all again, in the same
//! order with the same log times, once as JSON and once as protobuf, and prints each file's
//! size and the time spent writing (encoding, compressing and writing each message, then
//! finishing the file) per message.
//!
//!     cargo run --release -p recording --example encoding_cost -- run.mcap

use std::path::Path;
use std::time::Instant;

use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};
use recording::Truth;
use recording::mcap::run::RunReader;
use recording::mcap::{MessageEncoding, PoseInFrame, RecorderEvent, Writer};

/// One decoded message with its log time.
#[derive(Clone)]
enum Item {
    Raw(RawImuSample),
    Corrected(CorrectedImuSample),
    State(OdometryState),
    Pose(PoseInFrame),
    Hint(RobotHint),
    Truth(Truth),
    Event(RecorderEvent),
}

impl Item {
    /// The topic's index in the per-topic report.
    fn kind(&self) -> usize {
        match self {
            Item::Raw(_) => 0,
            Item::Corrected(_) => 1,
            Item::State(_) => 2,
            Item::Pose(_) => 3,
            Item::Hint(_) => 4,
            Item::Truth(_) => 5,
            Item::Event(_) => 6,
        }
    }
}

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
        } else if let Some(x) = m.decode::<PoseInFrame>() {
            Item::Pose(x?)
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

/// Writes `items` to `out` in `encoding`; the seconds it took.
fn write(items: &[(Item, u64)], out: &Path, encoding: MessageEncoding) -> recording::Result<f64> {
    let start = Instant::now();
    let mut w = Writer::create(out)?.with_encoding(encoding);
    let raw = w.add_channel::<RawImuSample>()?;
    let corrected = w.add_channel::<CorrectedImuSample>()?;
    let state = w.add_channel::<OdometryState>()?;
    let pose = w.add_channel::<PoseInFrame>()?;
    let hint = w.add_channel::<RobotHint>()?;
    let truth = w.add_channel::<Truth>()?;
    let event = w.add_channel::<RecorderEvent>()?;
    for (item, t) in items {
        match item {
            Item::Raw(x) => w.write(raw, x, *t)?,
            Item::Corrected(x) => w.write(corrected, x, *t)?,
            Item::State(x) => w.write(state, x, *t)?,
            Item::Pose(x) => w.write(pose, x, *t)?,
            Item::Hint(x) => w.write(hint, x, *t)?,
            Item::Truth(x) => w.write(truth, x, *t)?,
            Item::Event(x) => w.write(event, x, *t)?,
        }
    }
    w.finish()?;
    Ok(start.elapsed().as_secs_f64())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let input = std::env::args()
        .nth(1)
        .ok_or("usage: encoding_cost RECORDING.mcap")?;
    let items = read(Path::new(&input))?;
    println!("{input}: {} messages", items.len());
    let dir = std::env::temp_dir();
    for (name, encoding) in [
        ("json", MessageEncoding::Json),
        ("protobuf", MessageEncoding::Protobuf),
    ] {
        let out = dir.join(format!("encoding-cost-{}.{name}.mcap", std::process::id()));
        // The best of three, against a loaded machine.
        let mut best = f64::INFINITY;
        for _ in 0..3 {
            best = best.min(write(&items, &out, encoding)?);
        }
        let size = std::fs::metadata(&out)?.len();
        std::fs::remove_file(&out)?;
        println!(
            "{name:>8}: {size:>10} bytes ({:.1} bytes/message), written in {:.3} s ({:.2} us/message)",
            size as f64 / items.len() as f64,
            best,
            best * 1e6 / items.len() as f64
        );
    }
    // Each topic alone, protobuf.
    let kinds = [
        "raw",
        "corrected",
        "state",
        "pose",
        "hint",
        "truth",
        "event",
    ];
    for (k, kind) in kinds.iter().enumerate() {
        let alone: Vec<(Item, u64)> = items
            .iter()
            .filter(|(i, _)| i.kind() == k)
            .map(|(i, t)| (i.clone(), *t))
            .collect();
        if alone.is_empty() {
            continue;
        }
        let out = dir.join(format!("encoding-cost-{}.{kind}.mcap", std::process::id()));
        write(&alone, &out, MessageEncoding::Protobuf)?;
        let size = std::fs::metadata(&out)?.len();
        std::fs::remove_file(&out)?;
        println!(
            "{kind:>10} alone, protobuf: {size:>10} bytes ({} messages)",
            alone.len()
        );
    }
    Ok(())
}
