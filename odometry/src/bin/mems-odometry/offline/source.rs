//! The inputs of an offline run: the recording's items read (an MCAP run streamed by a reader
//! thread, or a text recording in memory), then put in the order a live pipeline would have
//! received them (`odometry::arrival`), with the truth and the `--out` recording they feed
//! ([`Feed`]).

use odometry::diagnose::lag::LagShift;
use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use anyhow::Result;
use ipc_types::stream::range::Ranges;
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample};
use mems_stage::Either;
use odometry::arrival::Arrival;
use odometry::session::Input;
use recording::mcap::SegmentRead;
use recording::mcap::run::{Item, RawRun};

use super::OfflineArgs;
use super::truth::TruthQueue;
use crate::out::Out;

/// Items a reader thread sends at a time, and blocks in flight: what the streamed path holds
/// between the reader and the stages.
const BLOCK: usize = 4096;
const BLOCKS_IN_FLIGHT: usize = 4;

/// The recording's raw samples, truth and hints, in file order: an MCAP run streamed
/// ([`recording::mcap::run::RawRun`]) by a reader thread, so that decoding runs beside the
/// stages on a second core, or a text recording (or a repaired one) in memory.
pub enum Source {
    Stream {
        blocks: Receiver<recording::Result<Vec<Item>>>,
        block: std::vec::IntoIter<Item>,
        reader: Option<JoinHandle<Vec<SegmentRead>>>,
    },
    Memory(std::vec::IntoIter<Item>),
}

/// Reads the run at `path` in blocks of [`BLOCK`] items into `tx` until the end, an error
/// (sent as the last block) or the receiver's end; returns the files read.
fn read_run(
    path: &Path,
    hints: bool,
    tx: SyncSender<recording::Result<Vec<Item>>>,
) -> Vec<SegmentRead> {
    let mut run = match RawRun::open(path, hints) {
        Ok(run) => run,
        Err(e) => {
            let _ = tx.send(Err(e));
            return Vec::new();
        }
    };
    let mut block = Vec::with_capacity(BLOCK);
    for item in run.by_ref() {
        match item {
            Ok(item) => block.push(item),
            Err(e) => {
                let _ = tx.send(Err(e));
                return run.segments().to_vec();
            }
        }
        if block.len() == BLOCK {
            let full = std::mem::replace(&mut block, Vec::with_capacity(BLOCK));
            if tx.send(Ok(full)).is_err() {
                return run.segments().to_vec();
            }
        }
    }
    let _ = tx.send(Ok(block));
    run.segments().to_vec()
}

impl Source {
    /// Opens the input; also returns the log repairs of a text recording and the ranges its
    /// samples are marked clipped at (given, or inferred from a text recording's samples).
    pub fn open(args: &OfflineArgs) -> Result<(Self, recording::LogRepairs, Ranges)> {
        let is_mcap = recording::mcap::has_magic(&args.input)?;
        if is_mcap && !args.repair_torn_reads {
            let (tx, blocks) = sync_channel(BLOCKS_IN_FLIGHT);
            let (path, hints) = (args.input.clone(), !args.no_hints);
            let reader = std::thread::Builder::new()
                .name("mcap-reader".into())
                .spawn(move || read_run(&path, hints, tx))?;
            let source = Self::Stream {
                blocks,
                block: Vec::new().into_iter(),
                reader: Some(reader),
            };
            let ranges = args.ranges.ranges(None)?;
            return Ok((source, recording::LogRepairs::default(), ranges));
        }
        let policy = if args.strict_time {
            recording::LogPolicy::Strict
        } else {
            recording::LogPolicy::Repair
        };
        let mut recording = crate::load::load_recording(&args.input, policy)?;
        if args.repair_torn_reads {
            let report = calibrate::repair::repair_torn_reads(
                &mut recording.samples,
                &calibrate::repair::RepairConfig::default(),
            );
            tracing::info!(
                "{}: repaired torn reads in {} of {} samples (accelerometer x, y, \
                 z: {:?}; gyro: {:?})",
                args.input.display(),
                report.samples_repaired,
                recording.samples.len(),
                report.accel.map(|a| a.repaired),
                report.gyro.map(|g| g.map(|a| a.repaired))
            );
        }
        let ranges = args.ranges.ranges(Some(&recording.samples))?;
        // Hints first (the merge orders them by publication), then truth and samples by time.
        let mut items: Vec<Item> = if is_mcap && !args.no_hints {
            let hints = recording::mcap::read_all(&args.input)?.hints;
            hints.into_iter().map(Item::Hint).collect()
        } else {
            Vec::new()
        };
        let mut truth = recording.truth.take().unwrap_or_default();
        truth.sort_by_key(|t| t.t_ns);
        let mut truth = truth.into_iter().peekable();
        for raw in recording.samples {
            while let Some(t) = truth.next_if(|t| t.t_ns <= raw.stamps.sample_ns) {
                items.push(Item::Truth(t));
            }
            items.push(Item::Raw(raw));
        }
        items.extend(truth.map(Item::Truth));
        Ok((Self::Memory(items.into_iter()), recording.repairs, ranges))
    }

    fn next(&mut self) -> Option<recording::Result<Item>> {
        match self {
            Self::Stream { blocks, block, .. } => loop {
                if let Some(item) = block.next() {
                    return Some(Ok(item));
                }
                match blocks.recv() {
                    Ok(Ok(next)) => *block = next.into_iter(),
                    Ok(Err(e)) => return Some(Err(e)),
                    Err(_) => return None,
                }
            },
            Self::Memory(items) => items.next().map(Ok),
        }
    }

    /// The files a streamed run was read from, each with its truncation. A run stopped before
    /// the end of its file (a refusal) closes the channel first: the reader, blocked on a full
    /// channel, then stops and returns what it read instead of waiting for a receiver forever.
    pub fn segments(&mut self) -> Vec<SegmentRead> {
        match self {
            Self::Stream { reader, blocks, .. } => {
                drop(std::mem::replace(blocks, sync_channel(0).1));
                reader
                    .take()
                    .and_then(|r| r.join().ok())
                    .unwrap_or_default()
            }
            Self::Memory(_) => Vec::new(),
        }
    }
}

/// An input of the offline chain: a raw sample for the calibration stage, or a robot hint for
/// the odometry session.
pub type ChainInput = Either<RawImuSample, Input>;

/// What the offline driver's inputs and sink share (`mems_stage::offline::run_with`): the
/// source, its items put in live order ([`Arrival`]: hints at once, raw samples held back for
/// the hints logged after them), the truth read so far, and the `--out` recording, which gets
/// raw samples and hints as they leave and what the chain emits.
pub struct Feed {
    /// The recording read.
    pub source: Source,
    /// Raw samples held back for the hints logged after them.
    pub arrival: Arrival,
    /// Truth read and not yet passed by the states.
    pub truth: TruthQueue,
    /// The `--out` recording.
    pub out: Option<Out>,
    /// The first raw sample's time, ns.
    pub first_ns: Option<u64>,
    /// Whether the source has ended.
    ended: bool,
    /// The ranges raw samples are marked clipped at as they leave.
    ranges: Ranges,
    /// The accelerometer lag removed from the raw samples as they are read (`--accel-lag-s`).
    shift: Option<LagShift>,
}

impl Feed {
    /// Reads `source`, writing to `out`, marking raw samples clipped at `ranges`, removing the
    /// accelerometer lag `shift` from them.
    pub fn new(source: Source, out: Option<Out>, ranges: Ranges, shift: Option<LagShift>) -> Self {
        Self {
            source,
            arrival: Arrival::new(),
            truth: TruthQueue::default(),
            out,
            first_ns: None,
            ended: false,
            ranges,
            shift,
        }
    }

    /// The chain's next input, in the order a live pipeline receives them (`None`: the end).
    pub fn next_input(&mut self) -> Option<Result<ChainInput>> {
        loop {
            if let Some(mut raw) = self.arrival.release() {
                super::trust::mark(&mut raw, &self.ranges);
                if let Some(out) = self.out.as_mut() {
                    out.raw(&raw);
                }
                return Some(Ok(Either::First(raw)));
            }
            if self.ended {
                return None;
            }
            match self.source.next() {
                None => {
                    self.ended = true;
                    if let Some(shift) = self.shift.as_mut() {
                        shift.finish(|raw| self.arrival.raw(raw));
                    }
                    self.arrival.end();
                }
                Some(Err(e)) => return Some(Err(e.into())),
                Some(Ok(Item::Raw(raw))) => {
                    self.first_ns.get_or_insert(raw.stamps.sample_ns);
                    match self.shift.as_mut() {
                        Some(shift) => shift.push(raw, |r| self.arrival.raw(r)),
                        None => self.arrival.raw(raw),
                    }
                }
                Some(Ok(Item::Hint(h))) => {
                    if let Some(out) = self.out.as_mut() {
                        out.hint(&h);
                    }
                    self.arrival.hint(&h);
                    return Some(Ok(Either::Second(Input::Hint(h))));
                }
                Some(Ok(Item::Truth(t))) => self.truth.push(t),
            }
        }
    }

    /// Writes what the chain emits to `--out`: corrected samples and states (revisions
    /// included).
    pub fn write(&mut self, o: &Either<CorrectedImuSample, OdometryState>) {
        if let Some(out) = self.out.as_mut() {
            match o {
                Either::First(c) => out.corrected(c),
                Either::Second(s) => out.state(s),
            }
        }
    }
}
