//! A ROS 2 bag in one MCAP file, as rosbag2's MCAP storage writes it and reads it without a
//! `metadata.yaml`: profile `ros2`; per message type a schema named `pkg/msg/Type`, encoding
//! `ros2msg`, holding its complete definition ([`crate::msg::Definition::complete`]); per
//! topic a channel with message encoding `cdr`; zstd chunks with message indexes and the
//! statistics record (rosbag2 takes its message counts from it).
//!
//! Channels carry no `offered_qos_profiles`, so `ros2 bag play` offers its default QoS
//! (reliable, volatile), which every subscriber of these topics accepts.

use std::collections::{BTreeMap, HashMap};
use std::fs::{File, OpenOptions};
use std::io::BufWriter;
use std::marker::PhantomData;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};

use crate::cdr;
use crate::msg::RosMessage;

/// A topic of the bag, carrying `M`.
pub struct Topic<M> {
    id: u16,
    message: PhantomData<M>,
}

impl<M> Clone for Topic<M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M> Copy for Topic<M> {}

/// A ROS 2 bag being written (see the module documentation). Dropping it leaves an unfinished
/// file; call [`Bag::finish`].
pub struct Bag {
    writer: mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    /// Each channel's next sequence number.
    sequences: HashMap<u16, u32>,
    /// The encoded message, reused.
    buf: Vec<u8>,
}

impl Bag {
    /// Creates the bag at `path`, which must not exist (a symbolic link is not followed: its
    /// name is taken, and the creation fails), readable and writable by its owner only.
    pub fn create_new(path: &Path) -> Result<Self> {
        let file = OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .custom_flags(libc::O_NOFOLLOW)
            .open(path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        let writer = WriteOptions::new()
            .profile("ros2")
            .library(concat!("mems-ros2 ", env!("CARGO_PKG_VERSION")))
            .compression(Some(Compression::Zstd))
            .create(BufWriter::new(file))
            .with_context(|| format!("{}: cannot write the MCAP header", path.display()))?;
        Ok(Self {
            writer,
            path: path.to_path_buf(),
            sequences: HashMap::new(),
            buf: Vec::new(),
        })
    }

    /// Adds topic `name` (e.g. `/odom`) of message type `M`, its schema with it (once per type).
    pub fn add_topic<M: RosMessage>(&mut self, name: &str) -> Result<Topic<M>> {
        let definition = M::DEFINITION.complete();
        let schema = self
            .writer
            .add_schema(M::TYPE_NAME, "ros2msg", definition.as_bytes())
            .with_context(|| format!("{}: schema {}", self.path.display(), M::TYPE_NAME))?;
        let id = self
            .writer
            .add_channel(schema, name, "cdr", &BTreeMap::new())
            .with_context(|| format!("{}: channel {name}", self.path.display()))?;
        Ok(Topic {
            id,
            message: PhantomData,
        })
    }

    /// Writes `message` on `topic` received at `log_time_ns` (also its publish time).
    pub fn write<M: RosMessage>(
        &mut self,
        topic: Topic<M>,
        message: &M,
        log_time_ns: u64,
    ) -> Result<()> {
        if let Err(e) = cdr::encode(message, &mut self.buf) {
            bail!(
                "{}: cannot encode a {}: {e}",
                self.path.display(),
                M::TYPE_NAME
            );
        }
        let sequence = self.sequences.entry(topic.id).or_default();
        let header = MessageHeader {
            channel_id: topic.id,
            sequence: *sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        *sequence = sequence.wrapping_add(1);
        self.writer
            .write_to_known_channel(&header, &self.buf)
            .with_context(|| format!("{}: cannot write a {}", self.path.display(), M::TYPE_NAME))
    }

    /// Writes the summary and footer and closes the file.
    pub fn finish(mut self) -> Result<()> {
        let path = self.path.display().to_string();
        self.writer
            .finish()
            .with_context(|| format!("{path}: cannot finish the MCAP file"))?;
        self.writer
            .into_inner()
            .into_inner()
            .map_err(|e| e.into_error())
            .with_context(|| format!("{path}: cannot write"))?;
        Ok(())
    }
}
