//! `mems-odometry offline --out F.mcap`: the offline run written as a live run's recording
//! (what `mems-record` writes of `mems-calibrate serve` and `mems-odometry serve`): the raw
//! samples and robot hints as read, every corrected sample, every odometry state (revisions
//! included) and the Foxglove messages derived from it (`recording::mcap::derived`: pose,
//! revised pose, transform, path). A recording has no receive times offline, so each
//! message's log time is its own publish time (the sample time; a hint's publication time).
//! The file is anchored to the input's wall clock (its `mems.clock` record, copied), so that
//! its log and publish times are the input's and the two line up in Foxglove; an input
//! without one (a CSV, an unanchored MCAP) gives an unanchored file, whose times are the
//! input's `CLOCK_MONOTONIC` stamps as they are.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use ipc_types::{CorrectedImuSample, OdometryState, RawImuSample, RobotHint};
use recording::clock::WallClock;
use recording::mcap::derived::DerivedChannels;
use recording::mcap::{Channel, Topic, Writer};

/// The MCAP file being written, its channels and the first write error (later writes are
/// skipped: the stages' emit callbacks cannot return one).
pub struct Out {
    path: PathBuf,
    writer: Writer,
    raw: Channel<RawImuSample>,
    corrected: Channel<CorrectedImuSample>,
    odometry: Channel<OdometryState>,
    derived: DerivedChannels,
    hint: Channel<RobotHint>,
    error: Option<recording::Error>,
}

impl Out {
    /// Starts the file at `path`, anchored to `clock` if given; an existing recording there
    /// is refused unless `force`. The file is private (0600) and appears at `path` only when
    /// [`Out::finish`] succeeds (replacing the recording there with `force`): a run that fails
    /// leaves none.
    pub fn create(path: &Path, force: bool, clock: Option<WallClock>) -> Result<Self> {
        // A replaced recording's successor segments would be read with the new file.
        for old in recording::segment::check_target(path, force)? {
            if old != path {
                std::fs::remove_file(&old)
                    .with_context(|| format!("cannot remove {}", old.display()))?;
            }
        }
        let mut writer = if force {
            Writer::create(path)?
        } else {
            Writer::create_new(path)?
        };
        if let Some(clock) = clock {
            writer.anchor(clock)?;
        }
        Ok(Self {
            path: path.to_path_buf(),
            raw: writer.add_channel()?,
            corrected: writer.add_channel()?,
            odometry: writer.add_channel()?,
            derived: DerivedChannels::add(&mut writer)?,
            hint: writer.add_channel()?,
            writer,
            error: None,
        })
    }

    /// The `--out` recording (`path`) of an offline run over `input`, anchored to the input's
    /// wall clock (none for an unanchored input); `None` without one.
    pub fn for_input(path: Option<&Path>, input: &Path, force: bool) -> Result<Option<Self>> {
        let Some(path) = path else {
            return Ok(None);
        };
        let clock = recording::mcap::run::clock_of(input)?;
        Ok(Some(Self::create(path, force, clock)?))
    }

    fn write<T: Topic>(&mut self, channel: Channel<T>, message: &T) {
        if self.error.is_none() {
            let log_ns = message.publish_time_ns();
            if let Err(e) = self.writer.write(channel, message, log_ns) {
                self.error = Some(e);
            }
        }
    }

    /// Writes a raw sample.
    pub fn raw(&mut self, s: &RawImuSample) {
        self.write(self.raw, s);
    }

    /// Writes a corrected sample.
    pub fn corrected(&mut self, c: &CorrectedImuSample) {
        self.write(self.corrected, c);
    }

    /// Writes an odometry state and what it derives.
    pub fn state(&mut self, s: &OdometryState) {
        self.write(self.odometry, s);
        if self.error.is_none()
            && let Err(e) = self.derived.write(&mut self.writer, s, s.stamps.sample_ns)
        {
            self.error = Some(e);
        }
    }

    /// Writes a robot hint.
    pub fn hint(&mut self, h: &RobotHint) {
        self.write(self.hint, h);
    }

    /// Writes the summary and footer; returns the first error met, if any.
    pub fn finish(self) -> Result<()> {
        if let Some(e) = self.error {
            return Err(e.into());
        }
        self.writer
            .finish()
            .with_context(|| format!("{}", self.path.display()))
    }
}
