//! The MCAP writer: channels, typed and Foxglove messages, the recorder's flushed file
//! ([`super::durable`]) and its compact copy.

use std::any::Any;
use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use ::mcap::records::MessageHeader;
use ::mcap::{Compression, WriteOptions};

use super::codec::{MessageEncoding, Topic};
use super::durable;
use crate::clock::WallClock;
use crate::error::{Error, ErrorKind, Result};

/// A channel added to a [`Writer`], typed by the messages it carries.
pub struct Channel<T> {
    id: u16,
    message: PhantomData<fn(&T)>,
}

impl<T> Clone for Channel<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Channel<T> {}

/// A channel of one of Foxglove's messages ([`Writer::add_foxglove_channel`]).
pub struct FoxgloveChannel<M> {
    id: u16,
    message: PhantomData<fn(&M)>,
}

impl<M> Clone for FoxgloveChannel<M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M> Copy for FoxgloveChannel<M> {}

/// The `mcap` crate's writer on a file.
type McapWriter = ::mcap::Writer<Sink>;

/// Where an `mcap` writer writes: a buffered file, or the recorder's flushed file, which is
/// whole after every flush ([`durable`]).
enum Sink {
    Buffered(BufWriter<File>),
    Durable(durable::DurableFile<File>),
}

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self {
            Self::Buffered(w) => w.write(buf),
            Self::Durable(w) => w.write(buf),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Self::Buffered(w) => w.flush(),
            Self::Durable(w) => w.flush(),
        }
    }
}

impl Seek for Sink {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        match self {
            Self::Buffered(w) => w.seek(to),
            Self::Durable(w) => w.seek(to),
        }
    }
}

impl Sink {
    /// Flushes what is buffered and returns the file.
    fn into_file(self) -> std::io::Result<File> {
        match self {
            Self::Buffered(w) => w.into_inner().map_err(|e| e.into_error()),
            Self::Durable(w) => Ok(w.into_inner()),
        }
    }
}

/// zstd level of the compact copy a recorder writes beside its file
/// ([`Writer::create_new_compacting`]), measured on a 60 s, 1 kHz stack run (docs/recording.md,
/// "Size and write cost"): with [`COMPACT_CHUNK_BYTES`] it is 0.88 of the file flushed every
/// 50 ms at zstd's default level 3, and 0.96 of the same chunks at level 3; level 17 would
/// take 0.94 of level 9's bytes at 10 times its cost per message.
pub const COMPACT_LEVEL: u32 = 9;
/// Uncompressed size of the compact copy's chunks: 4 MiB (about 9 s of a 1 kHz run), 0.97 of
/// the size the `mcap` crate's default 1 MiB chunks take at [`COMPACT_LEVEL`].
pub const COMPACT_CHUNK_BYTES: u64 = 4 << 20;

/// Writes an MCAP recording to a file: zstd chunks, protobuf messages (or JSON, for files in
/// the older encoding: [`Writer::with_encoding`]).
///
/// Only [`Writer::finish`] completes the file: a writer dropped unfinished (a failed run)
/// leaves no file at its path, except the recorder's ([`Writer::create_new_compacting`]),
/// which holds what was flushed.
pub struct Writer {
    inner: McapWriter,
    /// The private temporary file renamed to the path at [`Writer::finish`]; `None` for the
    /// recorder's file, written in place.
    output: Option<mems_files::Output>,
    /// The compact copy of a recorder's file, if it writes one
    /// ([`Writer::create_new_compacting`]).
    compact: Option<Compact>,
    path: PathBuf,
    encoding: MessageEncoding,
    sequences: HashMap<u16, u32>,
    /// The encoded message being written, reused: a message allocates nothing once the
    /// buffer has grown to the largest one.
    buf: Vec<u8>,
    /// Each channel's protobuf message ([`Topic::Proto`]), reused in the same way.
    protos: HashMap<u16, Box<dyn Any>>,
    /// Shifts log and publish times to Unix time, once [`Writer::anchor`]ed.
    clock: Option<WallClock>,
}

impl Writer {
    /// Starts the file at `path`, which replaces any file there when finished (atomically:
    /// the file is written beside it and renamed; a symbolic link there is replaced, not
    /// followed), and writes the MCAP header.
    pub fn create(path: impl AsRef<Path>) -> Result<Self> {
        let replace = mems_files::Existing::Replace;
        Self::staged(path.as_ref(), replace, 0, DEFAULT_CHUNK_BYTES)
    }

    /// Starts the file at `path`, which must not exist (an existing file or symbolic link is
    /// never overwritten: the error names it and `--force`), as [`Writer::create`] does.
    pub fn create_new(path: impl AsRef<Path>) -> Result<Self> {
        let refuse = mems_files::Existing::Refuse;
        Self::staged(path.as_ref(), refuse, 0, DEFAULT_CHUNK_BYTES)
    }

    /// The recorder's file: created at `path`, which must not exist (0600), and written in
    /// place, each [`Writer::flush`] closing a chunk and leaving a whole MCAP file
    /// ([`durable`]), so that a killed recorder loses little and leaves a file every reader
    /// opens; and a compact copy beside it ([`compacting_path`]): the same records, in chunks
    /// of [`COMPACT_CHUNK_BYTES`] at zstd level [`COMPACT_LEVEL`], which [`Writer::flush`]
    /// leaves alone. [`Writer::finish`] finishes both and renames the copy over the file, so
    /// a finished recording is the compact one; a recorder killed before that leaves its
    /// flushed file (and a copy that [`remove_stale_copy`] removes).
    pub fn create_new_compacting(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let file = mems_files::create_new(path, None).map_err(|e| Error::io(path, e.io))?;
        let sink = Sink::Durable(durable::DurableFile::new(file));
        let mut writer = Self::on(path, sink, None, 0, DEFAULT_CHUNK_BYTES)?;
        // The header, committed: the file is whole from the start.
        writer.flush()?;
        let temp = compacting_path(path);
        let file = mems_files::create_new(&temp, None).map_err(|e| Error::io(&temp, e.io))?;
        let sink = Sink::Buffered(BufWriter::new(file));
        let copy = mcap_writer(&temp, sink, COMPACT_LEVEL, COMPACT_CHUNK_BYTES)?;
        writer.compact = Some(Compact {
            writer: Some(copy),
            temp,
        });
        Ok(writer)
    }

    /// Starts the file at `path` as [`Writer::create`] does, with chunks of `chunk_bytes`
    /// (uncompressed) compressed at zstd level `level` (0: zstd's default, 3): for measuring
    /// what they cost (`examples/encoding_cost.rs`).
    pub fn create_tuned(path: impl AsRef<Path>, level: u32, chunk_bytes: u64) -> Result<Self> {
        let replace = mems_files::Existing::Replace;
        Self::staged(path.as_ref(), replace, level, chunk_bytes)
    }

    /// A writer on a private temporary file renamed to `path` when finished.
    fn staged(
        path: &Path,
        existing: mems_files::Existing,
        level: u32,
        chunk_bytes: u64,
    ) -> Result<Self> {
        let mut output =
            mems_files::Output::create(path, None, existing).map_err(|e| Error::io(path, e.io))?;
        let file = output.file().try_clone().map_err(|e| Error::io(path, e))?;
        let sink = Sink::Buffered(BufWriter::new(file));
        Self::on(path, sink, Some(output), level, chunk_bytes)
    }

    /// Writes the MCAP header to `sink`, for chunks of `chunk_bytes` compressed at zstd level
    /// `level`.
    fn on(
        path: &Path,
        sink: Sink,
        output: Option<mems_files::Output>,
        level: u32,
        chunk_bytes: u64,
    ) -> Result<Self> {
        Ok(Self {
            inner: mcap_writer(path, sink, level, chunk_bytes)?,
            output,
            compact: None,
            path: path.to_path_buf(),
            encoding: MessageEncoding::Protobuf,
            sequences: HashMap::new(),
            buf: Vec::new(),
            protos: HashMap::new(),
            clock: None,
        })
    }

    /// Anchors the recording to the wall clock: writes `clock` as the metadata record
    /// [`crate::clock::METADATA_NAME`], and from now on every message's log and publish time
    /// is the Unix time (ns, UTC) of the monotonic time given for it
    /// ([`WallClock::unix_ns`]). The messages' own stamps stay `CLOCK_MONOTONIC`.
    pub fn anchor(&mut self, clock: WallClock) -> Result<()> {
        let metadata = ::mcap::records::Metadata {
            name: crate::clock::METADATA_NAME.into(),
            metadata: clock.metadata(),
        };
        self.each(|w| w.write_metadata(&metadata))?;
        self.clock = Some(clock);
        Ok(())
    }

    /// Writes the channels added from now on in `encoding` (protobuf unless told).
    pub fn with_encoding(mut self, encoding: MessageEncoding) -> Self {
        self.encoding = encoding;
        self
    }

    /// Adds the channel for messages of type `T` (its schema too, once). Adding the same type
    /// again returns the same channel.
    pub fn add_channel<T: Topic>(&mut self) -> Result<Channel<T>> {
        let schema = match self.encoding {
            MessageEncoding::Json => {
                serde_json::to_vec(&T::json_schema()).map_err(|e| self.fail(ErrorKind::Json(e)))?
            }
            MessageEncoding::Protobuf => T::proto_schema(),
        };
        let (schema_encoding, encoding) = (self.encoding.schema(), self.encoding.message());
        let schema_id = self.each(|w| w.add_schema(T::SCHEMA_NAME, schema_encoding, &schema))?;
        let id = self.each(|w| w.add_channel(schema_id, T::TOPIC, encoding, &BTreeMap::new()))?;
        if self.encoding == MessageEncoding::Protobuf {
            self.protos
                .entry(id)
                .or_insert_with(|| Box::new(T::Proto::default()));
        }
        Ok(Channel {
            id,
            message: PhantomData,
        })
    }

    /// Writes one message; `log_time_ns` is the MCAP log time (the recorder's receive time),
    /// the publish time is the message's own ([`Topic::publish_time_ns`]).
    ///
    /// On a JSON channel, errors if a float in the message is not finite (protobuf keeps
    /// every `f64` as it is).
    pub fn write<T: Topic>(
        &mut self,
        channel: Channel<T>,
        message: &T,
        log_time_ns: u64,
    ) -> Result<()> {
        let (publish_time, log_time_ns) = match &self.clock {
            Some(clock) => (
                clock.unix_ns(message.publish_time_ns()),
                clock.unix_ns(log_time_ns),
            ),
            None => (message.publish_time_ns(), log_time_ns),
        };
        self.buf.clear();
        match self.protos.get_mut(&channel.id) {
            Some(proto) => {
                let proto = proto
                    .downcast_mut::<T::Proto>()
                    .expect("a channel's protobuf message is its topic's");
                message.fill_proto(proto);
                prost::Message::encode(proto, &mut self.buf).expect("a Vec grows to any message");
            }
            None => {
                if !message.is_finite() {
                    let kind = ErrorKind::Invalid(format!(
                        "message at publish time {publish_time} ns holds NaN or infinity, which JSON cannot store"
                    ));
                    return Err(Error {
                        field: Some(T::TOPIC.to_owned()),
                        ..self.fail(kind)
                    });
                }
                serde_json::to_writer(&mut self.buf, message)
                    .map_err(|e| Error::file(&self.path, ErrorKind::Json(e)))?;
            }
        }
        self.write_buf(channel.id, publish_time, log_time_ns)
    }

    /// Writes the encoded message in `self.buf` on channel `id` with these times (already
    /// anchored).
    fn write_buf(&mut self, id: u16, publish_time: u64, log_time: u64) -> Result<()> {
        let sequence = self.sequences.entry(id).or_default();
        let header = MessageHeader {
            channel_id: id,
            sequence: *sequence,
            log_time,
            publish_time,
        };
        *sequence = sequence.wrapping_add(1);
        let buf = std::mem::take(&mut self.buf);
        let written = self.each(|w| w.write_to_known_channel(&header, &buf));
        self.buf = buf;
        written
    }

    /// Runs `f` on the file's writer, then on the compact copy's (which takes the same
    /// records in the same order, so the ids they return are the same); an error names the
    /// file it was met on.
    fn each<T>(
        &mut self,
        mut f: impl FnMut(&mut McapWriter) -> ::mcap::McapResult<T>,
    ) -> Result<T> {
        let out = f(&mut self.inner).map_err(|e| self.fail(ErrorKind::Mcap(e)))?;
        if let Some(c) = &mut self.compact
            && let Some(w) = &mut c.writer
        {
            f(w).map_err(|e| Error::file(&c.temp, ErrorKind::Mcap(e)))?;
        }
        Ok(out)
    }

    /// The wall clock the file is anchored to ([`Writer::anchor`]), if it is.
    pub fn clock(&self) -> Option<WallClock> {
        self.clock
    }

    /// Adds a protobuf channel on `topic` for one of Foxglove's messages `M` (its SDK's
    /// schema), written as it is: the derived topics of [`derived`](super::derived), which have no JSON form.
    pub fn add_foxglove_channel<M: foxglove::Encode>(
        &mut self,
        topic: &str,
    ) -> Result<FoxgloveChannel<M>> {
        let schema = M::get_schema().expect("Foxglove's messages have schemas");
        let schema_id =
            self.each(|w| w.add_schema(&schema.name, &schema.encoding, &schema.data))?;
        let id = self.each(|w| w.add_channel(schema_id, topic, "protobuf", &BTreeMap::new()))?;
        Ok(FoxgloveChannel {
            id,
            message: PhantomData,
        })
    }

    /// Writes one message on a Foxglove channel; `publish_time_ns` and `log_time_ns` are
    /// monotonic, anchored like [`Writer::write`]'s.
    pub fn write_foxglove<M: prost::Message>(
        &mut self,
        channel: FoxgloveChannel<M>,
        message: &M,
        publish_time_ns: u64,
        log_time_ns: u64,
    ) -> Result<()> {
        let (publish_time, log_time) = match &self.clock {
            Some(clock) => (clock.unix_ns(publish_time_ns), clock.unix_ns(log_time_ns)),
            None => (publish_time_ns, log_time_ns),
        };
        self.buf.clear();
        message
            .encode(&mut self.buf)
            .expect("a Vec grows to any message");
        self.write_buf(channel.id, publish_time, log_time)
    }

    /// Closes the current chunk and hands everything written so far to the operating system,
    /// so that a killed process loses nothing written before this call (the compact copy, if
    /// any, keeps its chunk open); the recorder's file is whole after it ([`durable`]).
    pub fn flush(&mut self) -> Result<()> {
        self.inner
            .flush()
            .map_err(|e| self.fail(ErrorKind::Mcap(e)))
    }

    /// Writes the summary and footer and renames the file to its path; the recorder's file
    /// gets its last chunk (it has no summary: readers read it from its start), and its
    /// compact copy is finished and renamed over it.
    pub fn finish(mut self) -> Result<()> {
        let closed = match self.output {
            Some(_) => self.inner.finish().map(drop),
            None => self.inner.flush(),
        };
        closed.map_err(|e| self.fail(ErrorKind::Mcap(e)))?;
        let (compact, output) = (self.compact.take(), self.output.take());
        let path = self.path.clone();
        self.inner
            .into_inner()
            .into_file()
            .map_err(|e| Error::io(&path, e))?;
        if let Some(output) = output {
            output.commit().map_err(|e| Error::io(&path, e.io))?;
        }
        compact.map_or(Ok(()), |c| c.finish(&path))
    }

    fn fail(&self, kind: ErrorKind) -> Error {
        Error::file(&self.path, kind)
    }
}

/// Uncompressed size of a chunk, unless a writer is tuned: the `mcap` crate's default (1 MiB).
const DEFAULT_CHUNK_BYTES: u64 = WriteOptions::DEFAULT_CHUNK_SIZE;

/// The `mcap` crate's writer of zstd chunks of `chunk_bytes` (uncompressed) at `level` on
/// `sink`, a new file at `path` (named in its error), with the MCAP header written. On the
/// recorder's flushed file ([`Sink::Durable`]) it keeps each chunk in memory until it closes.
fn mcap_writer(path: &Path, sink: Sink, level: u32, chunk_bytes: u64) -> Result<McapWriter> {
    let durable = matches!(sink, Sink::Durable(_));
    WriteOptions::new()
        .compression(Some(Compression::Zstd))
        .compression_level(level)
        .chunk_size(Some(chunk_bytes))
        .disable_seeking(durable)
        .create(sink)
        .map_err(|e| Error::file(path, ErrorKind::Mcap(e)))
}

/// The compact copy of a recorder's file ([`Writer::create_new_compacting`]): written at
/// `temp`, renamed over the file when finished, removed if dropped unfinished.
struct Compact {
    /// `None` once finished.
    writer: Option<McapWriter>,
    temp: PathBuf,
}

impl Compact {
    /// Finishes the copy, syncs it to disk and renames it over `target`, the file it copies.
    fn finish(mut self, target: &Path) -> Result<()> {
        let Some(mut writer) = self.writer.take() else {
            return Ok(());
        };
        writer
            .finish()
            .map_err(|e| Error::file(&self.temp, ErrorKind::Mcap(e)))?;
        let file = writer
            .into_inner()
            .into_file()
            .map_err(|e| Error::io(&self.temp, e))?;
        file.sync_all().map_err(|e| Error::io(&self.temp, e))?;
        std::fs::rename(&self.temp, target).map_err(|e| Error::io(target, e))
    }
}

impl Drop for Compact {
    fn drop(&mut self) {
        if self.writer.take().is_some() {
            // Unfinished: the flushed file is the recording. Best effort, as in any drop.
            let _ = std::fs::remove_file(&self.temp);
        }
    }
}

/// Where [`Writer::create_new_compacting`] writes the compact copy of `path`: `path` with
/// `.compacting` added (`run.mcap.compacting`), which no reader takes for a recording.
pub fn compacting_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".compacting");
    PathBuf::from(name)
}

/// Removes the compact copy a killed recorder left beside `path`, if there is one; whether
/// it did.
pub fn remove_stale_copy(path: &Path) -> Result<bool> {
    let copy = compacting_path(path);
    match std::fs::remove_file(&copy) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(Error::io(&copy, e)),
    }
}
