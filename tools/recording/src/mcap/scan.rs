//! Bounded reading of an MCAP file's messages: nothing the reader allocates is larger than the
//! file or the largest chunk in it that passed [`ReadBounds`], whatever its length fields say.
//!
//! The `mcap` crate (0.26) decompresses chunks and frames records ([`LinearReader`], with a
//! `record_length_limit`), but its record parser reserves a string's or a byte array's declared
//! length before checking it against the record (a changed byte in a schema name asked for
//! 4 GB), and its `MessageStream` reads chunks with no limit at all (a changed byte in a chunk
//! header asked for 7.3e18 bytes and aborted the process). So the framing of chunks is checked
//! here ([`ReadBounds`]) and the three records that carry messages, Schema, Channel and Message,
//! are parsed here with every length checked against its record (MCAP specification,
//! "Records"): little-endian integers, a string is a `u32` length and UTF-8 bytes, a byte array
//! a `u32` length and bytes. Other records are skipped unparsed.
//!
//! A damaged record whose framing is intact (a chunk whose data does not decompress or fails
//! its CRC, a record whose opcode was changed, a record whose fields do not parse) is skipped
//! and reported ([`Damage`]: where it is, why, and what it held according to the message
//! indexes after it), and the read goes on after it; damage to the framing itself (a length
//! beyond the file) ends the read there, reported as a truncation.

use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::fs::File;
use std::io::{BufReader, Cursor, Read, Seek, SeekFrom, Take};
use std::rc::Rc;

use ::mcap::MAGIC;
use ::mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

/// Largest ratio of a chunk's declared uncompressed size to its record's size in the file.
/// Our recorder's zstd chunks of JSON expand 5-20 times; 1024 leaves room for any real
/// recording and caps what a damaged size field can make the reader allocate.
pub const MAX_CHUNK_EXPANSION: u64 = 1024;

/// MCAP opcodes (MCAP specification, "Records").
mod op {
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const METADATA: u8 = 0x0c;
    pub const DATA_END: u8 = 0x0f;
    /// The first opcode of the private range, which readers skip.
    pub const PRIVATE: u8 = 0x80;
}

/// A damaged record that was skipped, and what it cost.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Damage {
    /// Its offset in the file, bytes.
    pub offset: u64,
    /// Its length in the file, bytes.
    pub bytes: u64,
    /// What was wrong with it.
    pub reason: String,
    /// The messages it held, per topic, as the message indexes after it count them (none
    /// when they are missing: a record that was not a chunk, or a chunk without indexes).
    pub lost: Vec<(String, u64)>,
    /// The log times of its first and last message, ns, as its chunk header gives them.
    pub log_time_ns: Option<(u64, u64)>,
}

impl Damage {
    /// Messages lost, all topics.
    pub fn messages_lost(&self) -> u64 {
        self.lost.iter().map(|(_, n)| n).sum()
    }
}

impl fmt::Display for Damage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "damaged record of {} bytes at byte {} skipped ({}): ",
            self.bytes, self.offset, self.reason
        )?;
        if self.lost.is_empty() {
            write!(f, "no message index tells what it held")?;
        } else {
            let topics: Vec<String> = self.lost.iter().map(|(t, n)| format!("{t} {n}")).collect();
            write!(
                f,
                "{} messages lost ({})",
                self.messages_lost(),
                topics.join(", ")
            )?;
        }
        if let Some((start, end)) = self.log_time_ns {
            let span = end.saturating_sub(start) as f64 * 1e-9;
            write!(f, ", {span:.3} s of log time from {start} ns")?;
        }
        Ok(())
    }
}

/// What the reader may read and allocate for one MCAP file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadBounds {
    /// How many leading bytes of the file it reads.
    pub len: usize,
    /// Why it stops before the end (`None` when it reads the whole file).
    pub cut: Option<String>,
    /// The longest record (or chunk content) it accepts, bytes: the larger of the bytes read
    /// and the largest declared uncompressed size of a chunk among them.
    pub record_limit: usize,
}

impl ReadBounds {
    /// Walks the top-level record framing of `bytes` (an opcode byte, a `u64` body length, the
    /// body; a chunk's body starts with its message start and end times, then its uncompressed
    /// size as a `u64`) and stops before the first chunk whose uncompressed size exceeds
    /// [`MAX_CHUNK_EXPANSION`] times its record. A record that runs past the end of the file
    /// ends the walk; the reader reports that truncation itself.
    ///
    /// Hand-written because the crate checks record and chunk lengths only against one
    /// `record_length_limit`, and allocates up to it when a length field is damaged: a limit
    /// that fits every chunk of a real file is too loose to catch a damaged chunk among them.
    pub fn of(bytes: &[u8]) -> Self {
        Self::walk(bytes.len(), |at, out| {
            bytes
                .get(at..at + out.len())
                .map(|b| out.copy_from_slice(b))
                .is_some()
        })
    }

    /// [`Self::of`] for a file of `len` bytes read in place, its record headers read with
    /// seeks (a streaming reader does not hold the file). An I/O error ends the walk as the
    /// end of the file would; the reader then meets it itself.
    pub fn of_file(file: &mut File, len: u64) -> Self {
        let len = usize::try_from(len).unwrap_or(usize::MAX);
        Self::walk(len, |at, out| {
            file.seek(SeekFrom::Start(at as u64)).is_ok() && file.read_exact(out).is_ok()
        })
    }

    /// The walk of [`Self::of`] over `len` bytes, `read_at(offset, out)` filling `out` from
    /// `offset` (false past the end).
    fn walk(len: usize, mut read_at: impl FnMut(usize, &mut [u8]) -> bool) -> Self {
        let mut at = MAGIC.len().min(len);
        let mut largest_chunk = 0usize;
        let mut cut = None;
        let mut head = [0u8; 9 + 24];
        while at + 9 <= len && read_at(at, &mut head[..9]) {
            let opcode = head[0];
            let body_len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
            let body_start = at + 9;
            let Some(body_end) = usize::try_from(body_len)
                .ok()
                .and_then(|n| body_start.checked_add(n))
                .filter(|&end| end <= len)
            else {
                break;
            };
            if opcode == op::CHUNK && body_len >= 24 && read_at(body_start, &mut head[9..]) {
                let uncompressed = u64::from_le_bytes(head[9 + 16..].try_into().expect("8 bytes"));
                let record = 9 + body_len;
                if uncompressed > MAX_CHUNK_EXPANSION.saturating_mul(record) {
                    cut = Some(format!(
                        "the chunk at byte {at} declares {uncompressed} bytes uncompressed, more \
                         than {MAX_CHUNK_EXPANSION} times its {record} bytes (a damaged size)"
                    ));
                    break;
                }
                // Within the bound just checked, which is a fraction of the address space.
                largest_chunk = largest_chunk.max(uncompressed as usize);
            }
            at = body_end;
        }
        let len = if cut.is_some() { at } else { len };
        Self {
            len,
            cut,
            record_limit: len.max(largest_chunk),
        }
    }
}

/// A channel as its Channel record and its schema describe it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ChannelInfo {
    /// The topic.
    pub topic: String,
    /// The schema's name ("" without a schema).
    pub schema_name: String,
    /// The message encoding.
    pub encoding: String,
    /// The schema's encoding ("" without a schema).
    pub schema_encoding: String,
}

/// One message and its channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RawMessage {
    /// Its channel.
    pub channel: Rc<ChannelInfo>,
    /// Log time, ns.
    pub log_time_ns: u64,
    /// Publish time, ns.
    pub publish_time_ns: u64,
    /// The encoded message.
    pub data: Vec<u8>,
}

/// The messages of an MCAP file in file order, read from `R` (the file in memory, or the file
/// itself); damaged records are skipped and kept ([`Scanner::damaged`]); an error (a message
/// for the truncation) ends them.
pub struct Scanner<R> {
    input: Take<R>,
    reader: LinearReader,
    cut: Option<String>,
    /// Bytes of the file read ([`ReadBounds::len`]).
    len: u64,
    /// [`ReadBounds::record_limit`].
    record_limit: usize,
    /// Offset in the file of the next byte to hand to `reader`.
    fed: u64,
    /// Where the read last started over after a damaged record.
    restarted_at: u64,
    damaged: Vec<Damage>,
    catalog: Catalog,
    past_data_end: bool,
    done: bool,
}

/// What a file's records define for its messages.
#[derive(Default)]
struct Catalog {
    /// Name and encoding of each schema.
    schemas: HashMap<u16, (String, String)>,
    channels: HashMap<u16, Rc<ChannelInfo>>,
    /// The metadata records read so far: name and fields.
    metadata: Vec<(String, BTreeMap<String, String>)>,
}

impl<'a> Scanner<Cursor<&'a [u8]>> {
    /// A scanner over a whole file (magic included), within its [`ReadBounds`]; chunk CRCs
    /// are checked.
    pub fn new(bytes: &'a [u8]) -> Self {
        Self::with_bounds(Cursor::new(bytes), ReadBounds::of(bytes))
    }
}

impl Scanner<BufReader<File>> {
    /// A scanner reading `file` (`len` bytes, from its start) as it goes: what it holds at a
    /// time is one chunk, compressed and not, however long the file.
    pub fn stream(mut file: File, len: u64) -> std::io::Result<Self> {
        let bounds = ReadBounds::of_file(&mut file, len);
        file.seek(SeekFrom::Start(0))?;
        Ok(Self::with_bounds(
            BufReader::with_capacity(1 << 16, file),
            bounds,
        ))
    }
}

/// The `mcap` crate's reader of record framing: each chunk's CRC checked before any of its
/// records is read (a damaged chunk gives none of its messages), records up to `limit` bytes,
/// from the file's start (`from_start`: with the magic) or from a record.
fn linear_reader(limit: usize, from_start: bool) -> LinearReader {
    let options = LinearReaderOptions::default()
        .with_prevalidate_chunk_crcs(true)
        .with_record_length_limit(limit)
        .with_skip_start_magic(!from_start);
    LinearReader::new_with_options(options)
}

impl<R: Read + Seek> Scanner<R> {
    fn with_bounds(input: R, bounds: ReadBounds) -> Self {
        Self {
            input: input.take(bounds.len as u64),
            reader: linear_reader(bounds.record_limit, true),
            cut: bounds.cut,
            len: bounds.len as u64,
            record_limit: bounds.record_limit,
            fed: 0,
            restarted_at: 0,
            damaged: Vec::new(),
            catalog: Catalog::default(),
            past_data_end: false,
            done: false,
        }
    }

    /// The metadata records read so far (name and fields), in file order.
    pub fn metadata(&self) -> &[(String, BTreeMap<String, String>)] {
        &self.catalog.metadata
    }

    /// The damaged records skipped so far, in file order.
    pub fn damaged(&self) -> &[Damage] {
        &self.damaged
    }

    /// The next message into `data` (its storage reused: no allocation per message once it
    /// is as long as the longest), with its channel, log time and publish time; after the
    /// last, the reason the file was cut short, if it was (as [`Iterator::next`]).
    #[allow(clippy::type_complexity)]
    pub fn next_into(
        &mut self,
        data: &mut Vec<u8>,
    ) -> Option<Result<(Rc<ChannelInfo>, u64, u64), String>> {
        if self.done {
            return None;
        }
        match self.read_into(data) {
            Ok(Some(message)) => Some(Ok(message)),
            Ok(None) => {
                self.done = true;
                self.cut.take().map(Err)
            }
            Err(reason) => {
                self.done = true;
                Some(Err(self.cut.take().unwrap_or(reason)))
            }
        }
    }

    /// The next message into `data`, `Ok(None)` at the end of the data; a damaged record is
    /// skipped ([`Self::skip_damaged`]).
    fn read_into(
        &mut self,
        data: &mut Vec<u8>,
    ) -> Result<Option<(Rc<ChannelInfo>, u64, u64)>, String> {
        loop {
            let event = match self.reader.next_event() {
                None => return Ok(None),
                Some(Err(e)) => {
                    self.skip_damaged(e.to_string())?;
                    continue;
                }
                Some(Ok(event)) => event,
            };
            let (opcode, body) = match event {
                LinearReadEvent::ReadRequest(need) => {
                    let n = read_full(&mut self.input, self.reader.insert(need))
                        .map_err(|e| format!("reading failed: {e}"))?;
                    self.reader.notify_read(n);
                    self.fed += n as u64;
                    continue;
                }
                LinearReadEvent::Record { data, opcode } => (opcode, data),
            };
            let unknown = !(0x01..=op::DATA_END).contains(&opcode) && opcode < op::PRIVATE;
            let read = match opcode {
                _ if unknown => Err(format!("opcode {opcode:#04x} is no MCAP record's")),
                // The summary section repeats schemas and channels: not re-read.
                op::DATA_END => {
                    self.past_data_end = true;
                    Ok(None)
                }
                _ if self.past_data_end => Ok(None),
                _ => self.catalog.record(opcode, body, data),
            };
            match read {
                Ok(Some(message)) => return Ok(Some(message)),
                Ok(None) => {}
                Err(reason) if unknown => self.note_damaged(reason),
                Err(reason) => self.skip_damaged(reason)?,
            }
        }
    }

    /// Skips the top-level record that holds the last byte read, damaged for `reason`, if
    /// its framing is intact: notes it ([`Self::note_damaged`]) and reads on from the record
    /// after it. Errors with `reason` (the read ends there) otherwise.
    fn skip_damaged(&mut self, reason: String) -> Result<(), String> {
        let Some((_, end)) = self.record_holding(self.fed) else {
            return Err(reason);
        };
        if end <= self.restarted_at || end > self.len {
            return Err(reason);
        }
        self.note_damaged(reason);
        self.input
            .get_mut()
            .seek(SeekFrom::Start(end))
            .map_err(|e| format!("reading failed: {e}"))?;
        self.input.set_limit(self.len - end);
        self.reader = linear_reader(self.record_limit, false);
        (self.fed, self.restarted_at) = (end, end);
        Ok(())
    }

    /// Keeps the top-level record that holds the last byte read as damaged for `reason`, with
    /// what the message indexes after it say it held, then puts the input back where it was.
    fn note_damaged(&mut self, reason: String) {
        let Some((offset, end)) = self.record_holding(self.fed) else {
            return;
        };
        let mut lost: Vec<(String, u64)> = Vec::new();
        let mut at = end;
        let mut head = [0u8; 15];
        while at + 15 <= self.len && self.read_at(at, &mut head) && head[0] == op::MESSAGE_INDEX {
            let channel = u16::from_le_bytes([head[9], head[10]]);
            let entries = u64::from(u32::from_le_bytes(head[11..15].try_into().expect("4")) / 16);
            let topic = self
                .catalog
                .channels
                .get(&channel)
                .map_or_else(|| format!("channel {channel}"), |c| c.topic.clone());
            match lost.iter_mut().find(|(t, _)| *t == topic) {
                Some((_, n)) => *n += entries,
                None => lost.push((topic, entries)),
            }
            at = at.saturating_add(9 + u64::from_le_bytes(head[1..9].try_into().expect("8")));
        }
        // Only a chunk is followed by message indexes; its body starts with its log times.
        let mut times = [0u8; 16];
        let log_time_ns = (!lost.is_empty() && self.read_at(offset + 9, &mut times)).then(|| {
            let t = |i: usize| u64::from_le_bytes(times[i..i + 8].try_into().expect("8"));
            (t(0), t(8))
        });
        self.damaged.push(Damage {
            offset,
            bytes: end - offset,
            reason,
            lost,
            log_time_ns,
        });
        let _ = self.input.get_mut().seek(SeekFrom::Start(self.fed));
    }

    /// The top-level record (offset, end) that holds the byte before `pos`, by the file's
    /// record framing; `None` if the framing breaks before it.
    fn record_holding(&mut self, pos: u64) -> Option<(u64, u64)> {
        let last = pos.checked_sub(1)?;
        let mut at = MAGIC.len() as u64;
        let mut head = [0u8; 9];
        while at + 9 <= self.len && self.read_at(at, &mut head) {
            let len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
            let end = at.checked_add(9)?.checked_add(len)?;
            if last < end {
                let _ = self.input.get_mut().seek(SeekFrom::Start(self.fed));
                return (last >= at).then_some((at, end));
            }
            at = end;
        }
        let _ = self.input.get_mut().seek(SeekFrom::Start(self.fed));
        None
    }

    /// Fills `out` from offset `at` of the file (false if it cannot).
    fn read_at(&mut self, at: u64, out: &mut [u8]) -> bool {
        let input = self.input.get_mut();
        input.seek(SeekFrom::Start(at)).is_ok() && input.read_exact(out).is_ok()
    }
}

impl Catalog {
    /// Reads one record of the data section: a message (into `data`) or what messages need.
    fn record(
        &mut self,
        opcode: u8,
        body: &[u8],
        data: &mut Vec<u8>,
    ) -> Result<Option<(Rc<ChannelInfo>, u64, u64)>, String> {
        match opcode {
            op::SCHEMA => {
                let mut r = Fields::new(body, "schema");
                let id = r.u16()?;
                let name = r.string()?;
                let encoding = r.string()?;
                if id == 0 {
                    return Err("a schema record has the reserved id 0".into());
                }
                self.schemas.insert(id, (name, encoding));
            }
            op::CHANNEL => {
                let mut r = Fields::new(body, "channel");
                let id = r.u16()?;
                let schema_id = r.u16()?;
                let topic = r.string()?;
                let encoding = r.string()?;
                let (schema_name, schema_encoding) = match schema_id {
                    0 => (String::new(), String::new()),
                    id => self.schemas.get(&id).cloned().ok_or_else(|| {
                        format!("channel {topic:?} refers to schema {id}, not defined before it")
                    })?,
                };
                let info = ChannelInfo {
                    topic,
                    schema_name,
                    encoding,
                    schema_encoding,
                };
                self.channels.insert(id, Rc::new(info));
            }
            op::METADATA => {
                let mut r = Fields::new(body, "metadata");
                let name = r.string()?;
                let len = r.u32()? as usize;
                let mut map = Fields::new(r.take(len)?, "metadata");
                let mut fields = BTreeMap::new();
                while !map.body.is_empty() {
                    let key = map.string()?;
                    fields.insert(key, map.string()?);
                }
                self.metadata.push((name, fields));
            }
            op::MESSAGE => {
                let mut r = Fields::new(body, "message");
                let channel_id = r.u16()?;
                let _sequence = r.u32()?;
                let log_time_ns = r.u64()?;
                let publish_time_ns = r.u64()?;
                let channel = self.channels.get(&channel_id).cloned().ok_or_else(|| {
                    format!("a message on channel {channel_id}, not defined before it")
                })?;
                data.clear();
                data.extend_from_slice(r.rest());
                return Ok(Some((channel, log_time_ns, publish_time_ns)));
            }
            _ => {}
        }
        Ok(None)
    }
}

/// Reads into `buf` until it is full or the input ends; the bytes read.
fn read_full(input: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match input.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

impl<R: Read + Seek> Iterator for Scanner<R> {
    type Item = Result<RawMessage, String>;

    /// The next message; after the last, the reason the file was cut short, if it was.
    fn next(&mut self) -> Option<Self::Item> {
        let mut data = Vec::new();
        self.next_into(&mut data).map(|m| {
            m.map(|(channel, log_time_ns, publish_time_ns)| RawMessage {
                channel,
                log_time_ns,
                publish_time_ns,
                data,
            })
        })
    }
}

/// Reads a record's fields in order, every length checked against what is left.
struct Fields<'a> {
    body: &'a [u8],
    record: &'static str,
}

impl<'a> Fields<'a> {
    fn new(body: &'a [u8], record: &'static str) -> Self {
        Self { body, record }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if n > self.body.len() {
            return Err(format!(
                "a {} record is too short: a field needs {n} bytes, {} are left",
                self.record,
                self.body.len()
            ));
        }
        let (head, rest) = self.body.split_at(n);
        self.body = rest;
        Ok(head)
    }

    fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_le_bytes(
            self.take(2)?.try_into().expect("2 bytes"),
        ))
    }

    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }

    fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    fn string(&mut self) -> Result<String, String> {
        let len = self.u32()? as usize;
        let bytes = self.take(len)?;
        String::from_utf8(bytes.to_vec())
            .map_err(|_| format!("a {} record holds a string that is not UTF-8", self.record))
    }

    fn rest(self) -> &'a [u8] {
        self.body
    }
}
