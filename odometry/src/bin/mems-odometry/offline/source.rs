//! The inputs of an offline run: the recording's items read (an MCAP run streamed by a reader
//! thread, or a text recording in memory), then put in the order a live pipeline would have
//! received them ([`Inputs`]).

use std::cell::RefCell;
use std::collections::VecDeque;
use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use anyhow::Result;
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample};
use mems_stage::Either;
use odometry::session::Input;
use recording::mcap::SegmentRead;
use recording::mcap::run::{Item, RawRun};

use super::OfflineArgs;
use super::summary::TruthQueue;
use crate::out::Out;

/// How long a raw sample is held back for the robot hints recorded after it, ns: a hint
/// recorded later than this after its publication reaches the stage late (counted).
pub const HINT_WINDOW_NS: u64 = 2_000_000_000;

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
    /// Opens the input; also returns the log repairs of a text recording.
    pub fn open(args: &OfflineArgs) -> Result<(Self, recording::LogRepairs)> {
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
            return Ok((source, recording::LogRepairs::default()));
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
        Ok((Self::Memory(items.into_iter()), recording.repairs))
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

    /// The files a streamed run was read from (after its end), each with its truncation.
    pub fn segments(&mut self) -> Vec<SegmentRead> {
        match self {
            Self::Stream { reader, .. } => reader
                .take()
                .and_then(|r| r.join().ok())
                .unwrap_or_default(),
            Self::Memory(_) => Vec::new(),
        }
    }
}

/// An input of the offline chain: a raw sample for the calibration stage, or a robot hint for
/// the odometry session.
pub type ChainInput = Either<RawImuSample, Input>;

/// The source's items as the chain's inputs, in the order a live pipeline receives them: a
/// hint as soon as it is read (the session orders hints by publication), a raw sample held
/// back [`HINT_WINDOW_NS`] of sample time, so that the hints recorded after it but published
/// before it reach the session first. Truth goes to `truth`; raw samples and hints are
/// written to `out` as they leave.
pub struct Inputs<'a> {
    pub source: &'a mut Source,
    pub truth: &'a RefCell<TruthQueue>,
    pub out: &'a RefCell<Option<Out>>,
    held: VecDeque<RawImuSample>,
    /// Time of the newest raw sample read, ns (`None` at the end of the input).
    newest_ns: Option<u64>,
    /// Time of the last raw sample released, ns.
    released_ns: Option<u64>,
    /// The first raw sample's time, ns.
    pub first_ns: Option<u64>,
    /// Hints read, and those recorded too late for their place (see [`HINT_WINDOW_NS`]).
    pub hints_seen: u64,
    pub hints_late: u64,
}

impl<'a> Inputs<'a> {
    pub fn new(
        source: &'a mut Source,
        truth: &'a RefCell<TruthQueue>,
        out: &'a RefCell<Option<Out>>,
    ) -> Self {
        Self {
            source,
            truth,
            out,
            held: VecDeque::new(),
            newest_ns: Some(0),
            released_ns: None,
            first_ns: None,
            hints_seen: 0,
            hints_late: 0,
        }
    }

    /// The oldest held raw sample, once the input has passed its time by the window (or
    /// ended).
    fn due(&mut self) -> Option<RawImuSample> {
        let newest = self.newest_ns;
        let front = self.held.front()?;
        if newest.is_some_and(|n| front.stamps.sample_ns + HINT_WINDOW_NS > n) {
            return None;
        }
        let raw = self.held.pop_front()?;
        self.released_ns = Some(raw.stamps.sample_ns);
        if let Some(out) = self.out.borrow_mut().as_mut() {
            out.raw(&raw);
        }
        Some(raw)
    }
}

impl Iterator for Inputs<'_> {
    type Item = Result<ChainInput>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(raw) = self.due() {
                return Some(Ok(Either::First(raw)));
            }
            self.newest_ns?;
            match self.source.next() {
                None => self.newest_ns = None,
                Some(Err(e)) => return Some(Err(e.into())),
                Some(Ok(Item::Raw(raw))) => {
                    self.newest_ns = Some(raw.stamps.sample_ns);
                    self.first_ns.get_or_insert(raw.stamps.sample_ns);
                    self.held.push_back(raw);
                }
                Some(Ok(Item::Hint(h))) => {
                    if let Some(out) = self.out.borrow_mut().as_mut() {
                        out.hint(&h);
                    }
                    self.hints_seen += 1;
                    self.hints_late +=
                        u64::from(self.released_ns.is_some_and(|r| h.stamps.acquired_ns <= r));
                    return Some(Ok(Either::Second(Input::Hint(h))));
                }
                Some(Ok(Item::Truth(t))) => self.truth.borrow_mut().push(t),
            }
        }
    }
}

/// What the chain emits, written to `out`: corrected samples and states (revisions included).
pub fn write(out: &RefCell<Option<Out>>, o: &Either<CorrectedImuSample, OdometryState>) {
    if let Some(out) = out.borrow_mut().as_mut() {
        match o {
            Either::First(c) => out.corrected(c),
            Either::Second(s) => out.state(s),
        }
    }
}
