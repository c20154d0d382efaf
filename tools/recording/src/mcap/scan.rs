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

use std::collections::HashMap;
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
    pub const DATA_END: u8 = 0x0f;
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
        let mut at = MAGIC.len().min(bytes.len());
        let mut largest_chunk = 0usize;
        let mut cut = None;
        while let Some(head) = bytes.get(at..at + 9) {
            let opcode = head[0];
            let body_len = u64::from_le_bytes(head[1..9].try_into().expect("8 bytes"));
            let body_start = at + 9;
            let Some(body) = usize::try_from(body_len)
                .ok()
                .and_then(|n| bytes.get(body_start..body_start.checked_add(n)?))
            else {
                break;
            };
            if opcode == op::CHUNK
                && let Some(size) = body.get(16..24)
            {
                let uncompressed = u64::from_le_bytes(size.try_into().expect("8 bytes"));
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
            at = body_start + body.len();
        }
        let len = if cut.is_some() { at } else { bytes.len() };
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

/// The messages of an MCAP file in file order; an error (a message for the truncation) ends
/// them.
pub struct Scanner<'a> {
    input: &'a [u8],
    reader: LinearReader,
    cut: Option<String>,
    schemas: HashMap<u16, String>,
    channels: HashMap<u16, Rc<ChannelInfo>>,
    past_data_end: bool,
    done: bool,
}

impl<'a> Scanner<'a> {
    /// A scanner over a whole file (magic included), within its [`ReadBounds`]; chunk CRCs
    /// are checked.
    pub fn new(bytes: &'a [u8]) -> Self {
        let bounds = ReadBounds::of(bytes);
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(bounds.record_limit);
        Self {
            input: &bytes[..bounds.len],
            reader: LinearReader::new_with_options(options),
            cut: bounds.cut,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            past_data_end: false,
            done: false,
        }
    }

    /// The next message, `Ok(None)` at the end of the data.
    fn next_message(&mut self) -> Result<Option<RawMessage>, String> {
        loop {
            let event = match self.reader.next_event() {
                None => return Ok(None),
                Some(Err(e)) => return Err(e.to_string()),
                Some(Ok(event)) => event,
            };
            let (opcode, body) = match event {
                LinearReadEvent::ReadRequest(need) => {
                    let n = need.min(self.input.len());
                    self.reader.insert(n).copy_from_slice(&self.input[..n]);
                    self.reader.notify_read(n);
                    self.input = &self.input[n..];
                    continue;
                }
                LinearReadEvent::Record { data, opcode } => (opcode, data),
            };
            // The summary section repeats schemas and channels: not re-read.
            match opcode {
                op::DATA_END => self.past_data_end = true,
                _ if self.past_data_end => {}
                op::SCHEMA => {
                    let mut r = Fields::new(body, "schema");
                    let id = r.u16()?;
                    let name = r.string()?;
                    if id == 0 {
                        return Err("a schema record has the reserved id 0".into());
                    }
                    self.schemas.insert(id, name);
                }
                op::CHANNEL => {
                    let mut r = Fields::new(body, "channel");
                    let id = r.u16()?;
                    let schema_id = r.u16()?;
                    let topic = r.string()?;
                    let encoding = r.string()?;
                    let schema_name = match schema_id {
                        0 => String::new(),
                        id => self.schemas.get(&id).cloned().ok_or_else(|| {
                            format!(
                                "channel {topic:?} refers to schema {id}, not defined before it"
                            )
                        })?,
                    };
                    let info = ChannelInfo {
                        topic,
                        schema_name,
                        encoding,
                    };
                    self.channels.insert(id, Rc::new(info));
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
                    return Ok(Some(RawMessage {
                        channel,
                        log_time_ns,
                        publish_time_ns,
                        data: r.rest().to_vec(),
                    }));
                }
                _ => {}
            }
        }
    }
}

impl Iterator for Scanner<'_> {
    type Item = Result<RawMessage, String>;

    /// The next message; after the last, the reason the file was cut short, if it was.
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.next_message() {
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
