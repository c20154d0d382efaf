//! The checks of a raw stream as it is read, shared by [`super::read_all`] and
//! [`super::run::RawRun`].

use std::path::Path;

use ipc_types::{RawImuSample, limits};

use crate::error::{Error, ErrorKind, Result};

/// Refuses a raw sample whose values the sensor cannot produce ([`limits::check_raw`]; the
/// gyroscope and temperature when their flags mark them valid).
fn check_raw_values(path: &Path, index: u64, topic: &str, sample: &RawImuSample) -> Result<()> {
    let gyro = sample.flags & ipc_types::raw_flags::GYRO_VALID != 0;
    let temp = sample.flags & ipc_types::raw_flags::TEMP_VALID != 0;
    limits::check_raw(
        &sample.accel_g,
        gyro.then_some(&sample.gyro_dps),
        temp.then_some(sample.temp_c),
    )
    .map_err(|bad| {
        let field = format!("{topic}: {}", bad.field);
        Error::message(path, index, Some(&field), ErrorKind::OutOfRange(bad))
    })
}

/// The checks of the raw stream as it is read: values the sensor can produce, and within a
/// session (a run of increasing sequence numbers) times that strictly increase by at most
/// [`limits::MAX_STEP_S`]. Public for readers that stream a run's raw samples themselves
/// (`mems-replay`), so that they refuse what [`read_all`](super::read_all) refuses.
#[derive(Debug, Clone, Copy, Default)]
pub struct RawChecks {
    /// The previous sample's sequence number and time.
    pub(super) previous: Option<(u64, u64)>,
}

impl RawChecks {
    /// The sequence number of the last sample checked.
    pub fn previous_seq(&self) -> Option<u64> {
        self.previous.map(|(seq, _)| seq)
    }

    /// Checks `sample`, message `index` of `path` on `topic`; whether it starts a new session
    /// (the first sample, or a sequence number that does not increase).
    pub fn check(
        &mut self,
        path: &Path,
        index: u64,
        topic: &str,
        sample: &RawImuSample,
    ) -> Result<bool> {
        check_raw_values(path, index, topic, sample)?;
        let previous = self.previous.replace((sample.seq, sample.stamps.sample_ns));
        let Some((_, previous_ns)) = previous.filter(|(seq, _)| sample.seq > *seq) else {
            return Ok(true);
        };
        let t_ns = sample.stamps.sample_ns;
        let kind = if t_ns < previous_ns {
            ErrorKind::TimeBackwards { t_ns, previous_ns }
        } else if t_ns == previous_ns {
            ErrorKind::DuplicateTime { t_ns }
        } else if t_ns > previous_ns.saturating_add(limits::MAX_STEP_NS) {
            ErrorKind::TimeStep { t_ns, previous_ns }
        } else {
            return Ok(false);
        };
        let field = format!("{topic}: stamps.sample_ns");
        Err(Error::message(path, index, Some(&field), kind))
    }
}
