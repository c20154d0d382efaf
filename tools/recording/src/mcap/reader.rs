//! The MCAP reader of one file: its messages in file order, up to a truncation, past damaged
//! records.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use ::mcap::MAGIC;

use super::codec::{MessageEncoding, Topic};
use super::scan;
use crate::error::{Error, ErrorKind, Result, Truncation};

/// Whether the file starts with the MCAP magic bytes.
pub fn has_magic(path: &Path) -> Result<bool> {
    let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut start = Vec::with_capacity(MAGIC.len());
    Read::by_ref(&mut file)
        .take(MAGIC.len() as u64)
        .read_to_end(&mut start)
        .map_err(|e| Error::io(path, e))?;
    Ok(start == MAGIC)
}

/// An MCAP file read into memory, to be scanned with [`Reader::messages`].
pub struct Reader {
    pub(super) path: PathBuf,
    bytes: Vec<u8>,
}

impl Reader {
    /// Reads the file; errors if it does not start with the MCAP magic bytes.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        if !bytes.starts_with(MAGIC) {
            let kind = ErrorKind::UnknownFormat("does not start with the MCAP magic bytes".into());
            return Err(Error::file(path, kind));
        }
        Ok(Self {
            path: path.to_path_buf(),
            bytes,
        })
    }

    /// The messages of all topics in file order. If the file ends early or is damaged, the
    /// last item is an [`ErrorKind::Truncated`] error after every message before the cut.
    ///
    /// Memory is bounded by the file: a chunk that declares more than
    /// [`scan::MAX_CHUNK_EXPANSION`] times its record's size uncompressed is damage, and
    /// reading stops before it; no record or string may be longer than what holds it (see
    /// [`scan`]).
    pub fn messages(&self) -> Result<Messages<'_>> {
        Ok(Messages {
            path: &self.path,
            stream: scan::Scanner::new(&self.bytes),
            read: 0,
            done: false,
        })
    }
}

/// Iterator over the messages of a [`Reader`].
pub struct Messages<'a> {
    path: &'a Path,
    stream: scan::Scanner<std::io::Cursor<&'a [u8]>>,
    read: u64,
    done: bool,
}

impl Messages<'_> {
    /// The damaged records skipped so far ([`scan::Damage`]).
    pub fn damaged(&self) -> &[scan::Damage] {
        self.stream.damaged()
    }
}

impl<'a> Iterator for Messages<'a> {
    type Item = Result<Recorded<'a>>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        match self.stream.next() {
            Some(Ok(message)) => {
                self.read += 1;
                Some(Ok(Recorded {
                    source: self.path,
                    index: self.read,
                    topic: message.channel.topic.clone(),
                    schema_name: message.channel.schema_name.clone(),
                    encoding: message.channel.encoding.clone(),
                    schema_encoding: message.channel.schema_encoding.clone(),
                    log_time_ns: message.log_time_ns,
                    publish_time_ns: message.publish_time_ns,
                    data: message.data,
                }))
            }
            Some(Err(reason)) => {
                self.done = true;
                let truncation = Truncation {
                    messages_read: self.read,
                    reason,
                };
                Some(Err(Error::file(
                    self.path,
                    ErrorKind::Truncated(truncation),
                )))
            }
            None => {
                self.done = true;
                None
            }
        }
    }
}

/// One message as stored in an MCAP file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recorded<'a> {
    source: &'a Path,
    /// 1-based index in the file, all topics counted.
    pub index: u64,
    /// The channel's topic.
    pub topic: String,
    /// The channel's schema name ("" without a schema).
    pub schema_name: String,
    /// The channel's message encoding.
    pub encoding: String,
    /// The encoding of the channel's schema ("" without a schema).
    pub schema_encoding: String,
    /// MCAP log time, ns (the recorder's receive time).
    pub log_time_ns: u64,
    /// MCAP publish time, ns (the message's own time).
    pub publish_time_ns: u64,
    /// The encoded message.
    pub data: Vec<u8>,
}

impl Recorded<'_> {
    /// Decodes the message as a `T`, or `None` if it is on another topic. Errors if the channel's
    /// encoding or schema name is not `T`'s, or the JSON does not decode.
    pub fn decode<T: Topic>(&self) -> Option<Result<T>> {
        if self.topic != T::TOPIC {
            return None;
        }
        Some(decode_as(
            self.source,
            self.index,
            &self.topic,
            &self.schema_name,
            MessageEncoding::of(&self.encoding, &self.schema_encoding)
                .ok_or((&self.encoding, &self.schema_encoding)),
            &self.data,
        ))
    }
}

/// Decodes message `index` of `path` (on `topic`, schema `schema_name`, in `encoding` or in
/// an encoding no decoder reads) as a `T`; errors name the message.
pub(crate) fn decode_as<T: Topic>(
    path: &Path,
    index: u64,
    topic: &str,
    schema_name: &str,
    encoding: std::result::Result<MessageEncoding, (&String, &String)>,
    data: &[u8],
) -> Result<T> {
    let fail = |kind| Error::message(path, index, Some(topic), kind);
    let encoding = match encoding {
        Ok(e) if schema_name == T::SCHEMA_NAME => e,
        Ok(_) | Err(_) => {
            let (message, schema) = encoding.err().map_or(("json", ""), |(m, s)| (m, s));
            let kind = ErrorKind::Invalid(format!(
                "channel has encoding {message:?} (schema encoding {schema:?}) and schema \
                 {schema_name:?}, expected \"protobuf\" or \"json\" and {:?}",
                T::SCHEMA_NAME
            ));
            return Err(fail(kind));
        }
    };
    encoding.decode(data).map_err(fail)
}

/// One file of a run as [`super::read_all`] read it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SegmentRead {
    /// The file.
    pub path: PathBuf,
    /// Set when the file ends early or its record framing is damaged.
    pub truncation: Option<Truncation>,
    /// Damaged records skipped (the read went on after each), with what they held.
    pub damaged: Vec<scan::Damage>,
}
