//! The recorder's flushed file: an MCAP file that is whole at every instant, so that a
//! recorder killed at any point (SIGKILL, power kept) leaves a file every reader opens, the
//! official Python and Rust readers included, with every message flushed before the kill.
//!
//! The `mcap` crate writes a chunk by writing a placeholder header (its length `u64::MAX`) to
//! the file, the chunk's data after it, and seeking back to fill in the header when the chunk
//! closes; and it writes the data-end record, summary and footer only when the writer
//! finishes. A killed recorder's file therefore held an open chunk whose length is
//! `u64::MAX` and ended without a footer; the Python reader looks for the footer at the end
//! and raised on what it found there (`RecordLengthLimitExceeded`).
//!
//! [`DurableFile`] is the sink the `mcap` writer writes to instead: it keeps what the writer
//! writes in memory (the writer keeps each chunk in memory too, with seeking disabled) and
//! commits it at each flush, so the file ends with a data-end record, a footer without a
//! summary (readers then read the file from its start) and the closing magic after every
//! flush. A commit replaces the previous ending by the new records and a new ending in four
//! writes, each leaving a whole file behind it (module-level test `every_cut_reads`):
//!
//! 1. the new ending, past the end of the file;
//! 2. the length of the padding record that starts the old ending, made to skip up to the
//!    new ending (readers skip records of the private opcode [`PAD`], MCAP specification,
//!    "Opcodes");
//! 3. the new records, except their first 9 bytes, under that padding;
//! 4. the first 9 bytes (the first record's opcode and length), in place of the padding's.
//!
//! Writes 1, 2 and 4 are at most [`ENDING_LEN`] bytes within one page of the file (the ending
//! never straddles a page: a padding record moves it), which the kernel copies whole before a
//! SIGKILL takes effect; write 3 may be cut anywhere, under the padding.

use std::io::{self, Seek, SeekFrom, Write};
use std::os::unix::fs::FileExt;

use ::mcap::MAGIC;

/// Opcode of the padding records: the first of the private range (0x80-0xFF), which readers
/// skip.
pub const PAD: u8 = 0x80;
/// Length of the file's ending: a padding record without body (9 bytes), the data-end record
/// (13), the footer (29) and the magic (8).
pub const ENDING_LEN: u64 = 9 + 13 + 29 + 8;
/// The page size that writes 1, 2 and 4 stay within.
const PAGE: u64 = 4096;

/// A file written at given offsets (a [`std::fs::File`]; a log of writes in tests).
pub trait WriteAt {
    /// Writes all of `buf` at `offset`.
    fn write_all_at(&mut self, buf: &[u8], offset: u64) -> io::Result<()>;
}

impl WriteAt for std::fs::File {
    fn write_all_at(&mut self, buf: &[u8], offset: u64) -> io::Result<()> {
        FileExt::write_all_at(self, buf, offset)
    }
}

/// The sink of the recorder's flushed file (see the module documentation): what the `mcap`
/// writer writes is committed at each [`Write::flush`], and the file is whole between commits.
pub struct DurableFile<F> {
    file: F,
    /// What the writer wrote since the last commit.
    pending: Vec<u8>,
    /// The offset of the file's ending, where the pending records go.
    end: u64,
}

impl<F: WriteAt> DurableFile<F> {
    /// A sink on `file`, which is empty.
    pub fn new(file: F) -> Self {
        Self {
            file,
            pending: Vec::new(),
            end: 0,
        }
    }

    /// Writes the pending records to the file, which ends whole after each of the four
    /// writes (module documentation).
    fn commit(&mut self) -> io::Result<()> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let p = self.end;
        let records_end = p + self.pending.len() as u64;
        let q = ending_offset(records_end, if p == 0 { 0 } else { p + ENDING_LEN });
        if q > records_end {
            self.pending
                .extend_from_slice(&pad_header(q - records_end - 9));
            self.pending.resize((q - p) as usize, 0);
        }
        if p == 0 {
            // A new file: the magic and the header, with the ending, in one write.
            self.pending.extend_from_slice(&ending());
            self.file.write_all_at(&self.pending, 0)?;
        } else {
            self.file.write_all_at(&ending(), q)?;
            self.file.write_all_at(&pad_header(q - p - 9), p)?;
            self.file.write_all_at(&self.pending[9..], p + 9)?;
            self.file.write_all_at(&self.pending[..9], p)?;
        }
        self.pending.clear();
        self.end = q;
        Ok(())
    }

    /// The file, with every flushed record in it.
    pub fn into_inner(self) -> F {
        self.file
    }
}

/// Where the ending goes after records that end at `records_end`, no earlier than `earliest`
/// (past the old ending): there, if the ending fits in the rest of its page; otherwise after a
/// padding record (9 bytes and more), at the first offset from which it does.
fn ending_offset(records_end: u64, earliest: u64) -> u64 {
    let fits = |at: u64| at % PAGE + ENDING_LEN <= PAGE;
    if records_end >= earliest && fits(records_end) {
        return records_end;
    }
    let at = earliest.max(records_end + 9);
    if fits(at) {
        at
    } else {
        at.next_multiple_of(PAGE)
    }
}

/// A padding record's opcode and length (its body, `len` bytes, follows).
fn pad_header(len: u64) -> [u8; 9] {
    let mut header = [PAD; 9];
    header[1..].copy_from_slice(&len.to_le_bytes());
    header
}

/// The file's ending: an empty padding record, the data-end record (no data CRC), a footer
/// with no summary (no CRC) and the magic.
fn ending() -> [u8; ENDING_LEN as usize] {
    let mut out = [0u8; ENDING_LEN as usize];
    out[..9].copy_from_slice(&pad_header(0));
    out[9] = 0x0f;
    out[10..18].copy_from_slice(&4u64.to_le_bytes());
    // The data-end record's CRC (4 bytes) stays 0.
    out[22] = 0x02;
    out[23..31].copy_from_slice(&20u64.to_le_bytes());
    // The footer's summary start, summary-offset start and CRC (20 bytes) stay 0.
    out[51..].copy_from_slice(MAGIC);
    out
}

impl<F: WriteAt> Write for DurableFile<F> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.pending.extend_from_slice(buf);
        Ok(buf.len())
    }

    /// Commits what was written (see the module documentation).
    fn flush(&mut self) -> io::Result<()> {
        self.commit()
    }
}

impl<F: WriteAt> Seek for DurableFile<F> {
    /// Tells the position (the `mcap` writer asks for it); moving is not supported.
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let here = self.end + self.pending.len() as u64;
        match to {
            SeekFrom::Current(0) => Ok(here),
            SeekFrom::Start(at) if at == here => Ok(here),
            _ => Err(io::Error::new(
                io::ErrorKind::Unsupported,
                "the flushed file is written in order",
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every write made, in order.
    #[derive(Default)]
    struct Log(Vec<(u64, Vec<u8>)>);

    impl WriteAt for Log {
        fn write_all_at(&mut self, buf: &[u8], offset: u64) -> io::Result<()> {
            self.0.push((offset, buf.to_vec()));
            Ok(())
        }
    }

    /// The file after the first `n` writes, the last of them cut to `cut` bytes.
    fn file_after(log: &Log, n: usize, cut: usize) -> Vec<u8> {
        let mut file = Vec::new();
        for (i, (at, buf)) in log.0.iter().take(n).enumerate() {
            let buf = if i + 1 == n { &buf[..cut] } else { &buf[..] };
            let end = *at as usize + buf.len();
            if file.len() < end {
                file.resize(end, 0);
            }
            file[*at as usize..end].copy_from_slice(buf);
        }
        file
    }

    /// Messages the `mcap` crate's own reader reads from `bytes`, which must be whole.
    fn messages(bytes: &[u8]) -> usize {
        let mut count = 0;
        for message in ::mcap::MessageStream::new(bytes).expect("magic") {
            message.expect("a whole file");
            count += 1;
        }
        count
    }

    /// Writes `chunks` flushed chunks of `per_chunk` messages of `size` bytes each.
    fn record(chunks: usize, per_chunk: usize, size: usize) -> (Log, Vec<usize>) {
        let options = ::mcap::WriteOptions::new().disable_seeking(true);
        let mut writer = options.create(DurableFile::new(Log::default())).unwrap();
        let schema = writer.add_schema("s", "jsonschema", b"{}").unwrap();
        let channel = writer
            .add_channel(schema, "t", "json", &Default::default())
            .unwrap();
        writer.flush().unwrap();
        let mut flushed = vec![0];
        let data = vec![b'7'; size];
        for c in 0..chunks {
            for m in 0..per_chunk {
                let header = ::mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: m as u32,
                    log_time: (c * per_chunk + m) as u64,
                    publish_time: 0,
                };
                writer.write_to_known_channel(&header, &data).unwrap();
            }
            writer.flush().unwrap();
            flushed.push((c + 1) * per_chunk);
        }
        (writer.into_inner().into_inner(), flushed)
    }

    /// A file cut at any write, and inside the one write that may be cut, reads whole with the
    /// messages flushed before it.
    #[test]
    fn every_cut_reads() {
        for (per_chunk, size) in [(1, 10), (3, 1000), (40, 300), (2, 5000)] {
            let (log, flushed) = record(12, per_chunk, size);
            // The first commit is one write; each later one four.
            assert_eq!(log.0.len(), 1 + 4 * 12);
            for n in 1..=log.0.len() {
                // Write 1 is the first commit; then commit k is writes 4k-2 to 4k+1.
                let (k, step) = ((n + 2) / 4, (n + 2) % 4);
                let (at, last) = &log.0[n - 1];
                let cuts: Vec<usize> = if n > 1 && step == 2 {
                    (0..last.len()).step_by(97).chain([last.len()]).collect()
                } else {
                    let end = at + last.len() as u64 - 1;
                    assert_eq!(at / PAGE, end / PAGE, "write {n} is within one page");
                    vec![last.len()]
                };
                for cut in cuts {
                    let file = file_after(&log, n, cut);
                    let done = if step == 3 { k } else { k - 1 };
                    assert_eq!(messages(&file), flushed[done], "write {n} cut at {cut}");
                }
            }
        }
    }
}
