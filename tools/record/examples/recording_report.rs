//! Loss report of a recording, for long runs (the 10-minute 4 kHz stack benchmark and the
//! recorder-restart measurement in docs/acquisition.md): per topic the messages, the sequence
//! numbers missing between the first and the last, and the recorder's events; for raw samples
//! also what the sensor side flagged (FIFO overflows, samples lost before a sample) and the
//! longest stretch of sample time missing. A run recorded across recorder restarts is read
//! with all its segment files (`run.mcap`, `run.1.mcap`, ...), each file's cut reported.
//!
//! `cargo run --release -p mems-record --example recording_report -- FILE.mcap`
//!
//! Streams the file's messages (the whole file is read into memory, but not decoded into one
//! vector per topic), so a 1 GB recording needs about 1 GB of memory.

use anyhow::{Context, Result};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, odometry_flags, raw_flags};
use recording::mcap::{Reader, RecorderEvent};
use std::path::Path;

/// Sequence accounting of one topic.
#[derive(Default)]
struct SeqCount {
    messages: u64,
    first: Option<u64>,
    last: Option<u64>,
    missing: u64,
    restarts: u64,
}

impl SeqCount {
    /// Accounts for sequence number `seq` (numbers that do not increase start a new session).
    fn observe(&mut self, seq: u64) {
        self.messages += 1;
        match self.last {
            Some(last) if seq > last => self.missing += seq - last - 1,
            Some(_) => self.restarts += 1,
            None => self.first = Some(seq),
        }
        self.last = Some(seq);
    }

    fn line(&self, topic: &str) -> String {
        format!(
            "{topic}: {} messages, seq {:?}..={:?}, {} missing, {} restarts",
            self.messages, self.first, self.last, self.missing, self.restarts
        )
    }
}

fn main() -> Result<()> {
    let path = std::env::args()
        .nth(1)
        .context("usage: recording_report FILE.mcap")?;
    let (mut raw, mut corrected, mut odometry) = Default::default();
    let (raw, corrected, odometry): (&mut SeqCount, &mut SeqCount, &mut SeqCount) =
        (&mut raw, &mut corrected, &mut odometry);
    let (mut revisions, mut overflows, mut gap_flags, mut lost_before) = (0u64, 0u64, 0u64, 0u64);
    let (mut first_ns, mut last_ns) = (None, 0u64);
    let mut events: Vec<RecorderEvent> = Vec::new();
    let mut truncated = Vec::new();
    // Longest raw gap: (samples missing, ns between the samples either side).
    let mut longest_gap = (0u64, 0u64);
    let segments = recording::segment::existing(Path::new(&path));
    let readers = segments
        .iter()
        .map(Reader::open)
        .collect::<recording::Result<Vec<_>>>()?;
    if readers.is_empty() {
        Reader::open(&path)?;
    }
    for reader in &readers {
        for message in reader.messages()? {
            let message = match message {
                Ok(m) => m,
                Err(e) => {
                    truncated.push(e.to_string());
                    break;
                }
            };
            if let Some(s) = message.decode::<RawImuSample>() {
                let s = s?;
                if let Some(last) = raw.last
                    && s.seq > last + 1
                    && s.seq - last - 1 > longest_gap.0
                {
                    longest_gap = (s.seq - last - 1, s.stamps.sample_ns.saturating_sub(last_ns));
                }
                raw.observe(s.seq);
                first_ns.get_or_insert(s.stamps.sample_ns);
                last_ns = s.stamps.sample_ns;
                overflows += u64::from(s.flags & raw_flags::FIFO_OVERFLOW != 0);
                gap_flags += u64::from(s.flags & raw_flags::GAP_BEFORE != 0);
                lost_before += u64::from(s.lost_before);
            } else if let Some(s) = message.decode::<CorrectedImuSample>() {
                corrected.observe(s?.seq);
            } else if let Some(s) = message.decode::<OdometryState>() {
                let s = s?;
                if s.flags & odometry_flags::REVISION != 0 {
                    revisions += 1;
                } else {
                    odometry.observe(s.seq);
                }
            } else if let Some(e) = message.decode::<RecorderEvent>() {
                events.push(e?);
            }
        }
    }

    let span_s = first_ns.map_or(0.0, |f| (last_ns - f) as f64 * 1e-9);
    println!("{path}: raw sample times span {span_s:.1} s");
    println!(
        "{}; longest gap {} samples, {:.0} ms between the samples around it",
        raw.line("mems/imu/raw"),
        longest_gap.0,
        longest_gap.1 as f64 * 1e-6
    );
    println!("{}", corrected.line("mems/imu/corrected"));
    println!(
        "{} (+ {revisions} revisions)",
        odometry.line("mems/odometry/state")
    );
    println!(
        "sensor side: {overflows} FIFO overflows, {gap_flags} samples flagged GAP_BEFORE, \
         {lost_before} samples lost at the sensor (lost_before)"
    );
    println!("recorder events: {}", events.len());
    for e in &events {
        println!(
            "  {:?} on {} seq {:?}..={:?}",
            e.kind, e.service, e.from_seq, e.to_seq
        );
    }
    println!("files: {}", segments.len());
    for t in truncated {
        println!("truncated: {t}");
    }
    Ok(())
}
