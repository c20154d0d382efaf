//! The recorder's compact copy (`Writer::create_new_compacting`): a finished recording is the
//! copy, with every record of the flushed file and far fewer chunks; an unfinished one is the
//! flushed file, with the copy removed.

mod common;

use std::path::Path;

use ::mcap::Summary;
use ipc_types::RawImuSample;
use recording::clock::WallClock;
use recording::mcap::{Writer, compacting_path, read_all, remove_stale_copy, run::RunReader};

/// Every message of the file: topic, log time, publish time and encoded bytes, in file order.
fn messages(path: &Path) -> Vec<(String, u64, u64, Vec<u8>)> {
    let mut reader = RunReader::one(path).unwrap();
    let mut out = Vec::new();
    while let Some(m) = reader.next() {
        let m = m.unwrap();
        out.push((
            m.channel.topic.clone(),
            m.log_time_ns,
            m.publish_time_ns,
            m.data.to_vec(),
        ));
    }
    out
}

/// Chunks in the file's summary, and its metadata record names.
fn chunks_and_metadata(path: &Path) -> (usize, Vec<String>) {
    let bytes = std::fs::read(path).unwrap();
    let summary = Summary::read(&bytes).unwrap().expect("a summary");
    let names = summary
        .metadata_indexes
        .iter()
        .map(|m| m.name.clone())
        .collect();
    (summary.chunk_indexes.len(), names)
}

/// Writes `samples` on the raw topic at 1 ms of log time each, flushing every 50 as the
/// recorder does; `compacting` chooses the writer.
fn write(path: &Path, samples: &[RawImuSample], compacting: bool) -> Writer {
    let mut w = if compacting {
        Writer::create_new_compacting(path).unwrap()
    } else {
        Writer::create_new(path).unwrap()
    };
    w.anchor(WallClock {
        realtime_ns: 1_700_000_000_000_000_000,
        monotonic_ns: 0,
    })
    .unwrap();
    let raw = w.add_channel::<RawImuSample>().unwrap();
    for (i, s) in samples.iter().enumerate() {
        w.write(raw, s, 1_000_000 * i as u64).unwrap();
        if i % 50 == 49 {
            w.flush().unwrap();
        }
    }
    w
}

#[test]
fn a_finished_recording_is_the_compact_copy_with_every_record() {
    let samples = common::live_samples(5000, 7);
    let flushed = common::tmp("compact-reference.mcap");
    write(&flushed, &samples, false).finish().unwrap();
    let path = common::tmp("compact-finished.mcap");
    let writer = write(&path, &samples, true);
    assert!(
        compacting_path(&path).exists(),
        "the copy is written beside the file"
    );
    writer.finish().unwrap();

    assert!(
        !compacting_path(&path).exists(),
        "the copy was renamed over the file"
    );
    assert_eq!(messages(&path), messages(&flushed));
    assert_eq!(read_all(&path).unwrap().raw, samples);
    let (chunks, metadata) = chunks_and_metadata(&path);
    let (flushed_chunks, flushed_metadata) = chunks_and_metadata(&flushed);
    assert_eq!(metadata, flushed_metadata);
    assert_eq!(metadata, ["mems.clock"]);
    assert_eq!(flushed_chunks, 100, "one chunk per flush");
    assert!(chunks < 5, "{chunks} chunks in the compact copy");
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    assert!(size(&path) < size(&flushed));
}

#[test]
fn an_unfinished_recording_is_the_flushed_file() {
    let samples = common::live_samples(1000, 8);
    let path = common::tmp("compact-unfinished.mcap");
    let writer = write(&path, &samples, true);
    // Dropped without finishing (an error in the recorder's loop): the copy goes, the flushed
    // file stays with everything written.
    drop(writer);
    assert!(!compacting_path(&path).exists());
    assert_eq!(read_all(&path).unwrap().raw, samples);
}

#[test]
fn a_stale_copy_is_removed_once() {
    let path = common::tmp("compact-stale.mcap");
    std::fs::write(compacting_path(&path), b"left by a killed recorder").unwrap();
    assert!(remove_stale_copy(&path).unwrap());
    assert!(!compacting_path(&path).exists());
    assert!(!remove_stale_copy(&path).unwrap());
}
