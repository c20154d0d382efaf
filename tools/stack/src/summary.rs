//! The stack's final summary, for a person: how long it ran, what each stage published, what
//! was lost and where, where the recording is and how big, and the last position.

use std::fmt;
use std::path::Path;

use ipc_types::{OdometryState, odometry_flags, service};
use mems_topic::TopicStats;

use crate::losses::{RecorderLosses, SourceLosses};
use crate::monitor::Monitor;

/// Everything the summary reports.
pub struct Summary<'a> {
    /// Wall time the stack ran, s.
    pub elapsed_s: f64,
    /// Restarts per child, as "name count".
    pub restarts: &'a [String],
    /// Raw, corrected and odometry statistics as the stack received them.
    pub topics: [&'a TopicStats; 3],
    /// Losses at the source.
    pub source: &'a SourceLosses,
    /// What the recording misses, when recording.
    pub recorder: Option<&'a RecorderLosses>,
    /// The recording's first file, when recording.
    pub record: Option<&'a Path>,
    /// The newest live odometry state.
    pub state: Option<&'a OdometryState>,
}

impl<'a> Summary<'a> {
    /// The summary of a run of `elapsed_s` seconds: what `monitor` saw, the children's
    /// `restarts`, and when recording, what the recording misses and its first file.
    pub fn of(
        monitor: &'a Monitor,
        elapsed_s: f64,
        restarts: &'a [String],
        recorder: Option<&'a RecorderLosses>,
        record: Option<&'a Path>,
    ) -> Self {
        let [raw, corrected, odometry] = &monitor.stats;
        Self {
            elapsed_s,
            restarts,
            topics: [raw, corrected, odometry],
            source: &monitor.source,
            recorder,
            record,
            state: monitor.last_state.as_ref(),
        }
    }
}

/// The files of the run at `base` and their total size, bytes.
fn recording_size(base: &Path) -> (usize, u64) {
    let files = recording::segment::existing(base);
    let bytes = files
        .iter()
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| m.len())
        .sum();
    (files.len(), bytes)
}

impl fmt::Display for Summary<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [r, c, o] = self.topics.map(TopicStats::report);
        writeln!(
            f,
            "mems-stack: ran {:.1} s; restarts: {}",
            self.elapsed_s,
            self.restarts.join(", ")
        )?;
        writeln!(
            f,
            "  received: {} raw samples, {} corrected samples, {} odometry states (revisions \
             included)",
            r.received, c.received, o.received
        )?;
        writeln!(
            f,
            "  lost: {} at the sensor, {} across acquire restarts, {} given up for stalled \
             subscribers; in the pipeline raw {}, corrected {}, odometry {}",
            self.source.fifo,
            self.source.restarts,
            self.source.undelivered(),
            r.lost,
            c.lost,
            o.lost
        )?;
        if let (Some(base), Some(rec)) = (self.record, self.recorder) {
            let (files, bytes) = recording_size(base);
            writeln!(
                f,
                "  recording: {} ({files} file{}, {:.1} MB), missing raw {}, corrected {}, \
                 odometry {}; `mems-info {}` shows what it holds",
                base.display(),
                if files == 1 { "" } else { "s" },
                bytes as f64 / 1e6,
                rec.of(service::RAW),
                rec.of(service::CORRECTED),
                rec.of(service::ODOMETRY),
                base.display()
            )?;
        }
        match self.state {
            Some(s) if s.flags & odometry_flags::ALIGNED != 0 => writeln!(
                f,
                "  last position: ({:+.3}, {:+.3}, {:+.3}) m +- ({:.3}, {:.3}, {:.3}) m, {:.2} m \
                 travelled, {} rests",
                s.position_m[0],
                s.position_m[1],
                s.position_m[2],
                s.position_sigma_m[0],
                s.position_sigma_m[1],
                s.position_sigma_m[2],
                s.distance_m,
                s.rest_count
            ),
            Some(_) => writeln!(
                f,
                "  no position: the odometry never aligned (no rest long enough)"
            ),
            None => writeln!(f, "  no position: no odometry state was received"),
        }
    }
}
