//! What the stack watches while it runs: the three topics' rates and losses, the losses at the
//! source and in the recording, the rest verdict and the newest position, and the status line
//! that shows them.

use anyhow::Result;
use iceoryx2::node::Node;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::service::ipc;
use ipc_types::service;
use ipc_types::{
    CorrectedImuSample, Message, OdometryState, RawImuSample, clock::monotonic_ns, corrected_flags,
    odometry_flags,
};
use mems_topic::TopicStats;

use crate::losses::{RecorderLosses, SourceLosses};

/// The stack's subscriptions to raw, corrected and odometry, and what they showed so far.
pub struct Monitor {
    raw: Subscriber<ipc::Service, RawImuSample, ()>,
    corrected: Subscriber<ipc::Service, CorrectedImuSample, ()>,
    odometry: Subscriber<ipc::Service, OdometryState, ()>,
    /// Rate and sequence losses of raw, corrected and odometry as the stack receives them.
    pub stats: [TopicStats; 3],
    /// Losses at the sensor and across acquire restarts.
    pub source: SourceLosses,
    /// The calibration stage's rest verdict on the newest sample; `None` until its detector
    /// has learned (no verdict yet).
    pub zero_state: Option<bool>,
    /// The newest live (non-revision) odometry state.
    pub last_state: Option<OdometryState>,
}

impl Monitor {
    /// Subscribes to the three topics of `namespace`; `rate_hz` is the sensor's output rate.
    pub fn new(node: &Node<ipc::Service>, namespace: &str, rate_hz: u32) -> Result<Self> {
        let name = |topic| service::full_name(namespace, topic);
        Ok(Self {
            raw: service::subscriber(&service::open(node, &name(service::RAW))?)?,
            corrected: service::subscriber(&service::open(node, &name(service::CORRECTED))?)?,
            odometry: service::subscriber(&service::open(node, &name(service::ODOMETRY))?)?,
            stats: [TopicStats::new(), TopicStats::new(), TopicStats::new()],
            source: SourceLosses::new(rate_hz),
            zero_state: None,
            last_state: None,
        })
    }

    /// Takes everything the three topics hold.
    pub fn drain(&mut self) -> Result<()> {
        let [raw, corrected, odometry] = &mut self.stats;
        while let Some(s) = self.raw.receive()? {
            observe(raw, s.payload());
            self.source.observe(s.payload());
        }
        while let Some(s) = self.corrected.receive()? {
            observe(corrected, s.payload());
            self.zero_state = (s.flags & corrected_flags::DETECTOR_READY != 0)
                .then_some(s.flags & corrected_flags::ZERO_STATE != 0);
        }
        while let Some(s) = self.odometry.receive()? {
            observe(odometry, s.payload());
            if s.flags & odometry_flags::REVISION == 0 {
                self.last_state = Some(*s.payload());
            }
        }
        Ok(())
    }

    /// The status line of what was seen so far (see [`status_line`]).
    pub fn status(&self, recorder: Option<&RecorderLosses>) -> String {
        let [raw, corrected, odometry] = &self.stats;
        status_line(
            &[raw, corrected, odometry],
            &self.source,
            recorder,
            self.zero_state,
            self.last_state.as_ref(),
        )
    }
}

fn observe<T: Message>(stats: &mut TopicStats, m: &T) {
    stats.observe(
        m.seq(),
        m.stamps().sample_ns,
        m.published_ns(),
        monotonic_ns(),
        m.is_revision(),
    );
}

/// The status line: losses at the source (sensor FIFO, acquire restarts), rate and losses
/// per topic (sequence gaps as the stack receives them; for raw also the samples acquire gave
/// up for stalled subscribers), what the recording misses per topic (when recording), the rest
/// verdict of the newest corrected sample, and the newest live odometry state's position (or
/// why there is none).
pub fn status_line(
    [raw, cor, odo]: &[&TopicStats; 3],
    source: &SourceLosses,
    recorder: Option<&RecorderLosses>,
    zero_state: Option<bool>,
    state: Option<&OdometryState>,
) -> String {
    let (r, c, o) = (raw.report(), cor.report(), odo.report());
    let recording = recorder.map_or(String::new(), |rec| {
        format!(
            " | recording lost {}/{}/{}",
            rec.of(service::RAW),
            rec.of(service::CORRECTED),
            rec.of(service::ODOMETRY)
        )
    });
    let position = match state {
        Some(s) if s.flags & odometry_flags::NO_GYRO != 0 => {
            "no position: the sensor runs without its gyroscope at this rate".to_string()
        }
        Some(s) if s.flags & odometry_flags::ALIGNED != 0 => format!(
            "pos ({:+.2}, {:+.2}, {:+.2}) m +- ({:.2}, {:.2}, {:.2})",
            s.position_m[0],
            s.position_m[1],
            s.position_m[2],
            s.position_sigma_m[0],
            s.position_sigma_m[1],
            s.position_sigma_m[2]
        ),
        Some(_) => "aligning".to_string(),
        None => "no odometry yet".to_string(),
    };
    format!(
        "sensor lost {} + {} across acquire restarts | raw {:.0} Hz lost {} undelivered {} | \
         corrected {:.0} Hz lost {} | odometry {:.0} Hz lost {}{recording} | {} | {}",
        source.fifo,
        source.restarts,
        r.rate_hz,
        r.lost,
        source.undelivered(),
        c.rate_hz,
        c.lost,
        o.rate_hz,
        o.lost,
        match zero_state {
            None => "rest detector learning",
            Some(true) => "at rest",
            Some(false) => "moving",
        },
        position
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_status_line_shows_no_position_without_gyro() {
        let stats = TopicStats::new();
        let line = |flags| {
            let state = OdometryState {
                flags,
                position_m: [1.5, -2.0, 0.0],
                ..OdometryState::default()
            };
            let source = SourceLosses::new(1000);
            status_line(&[&stats; 3], &source, None, Some(true), Some(&state))
        };
        let aligned = line(odometry_flags::ALIGNED);
        assert!(aligned.contains("pos (+1.50, -2.00, +0.00) m"), "{aligned}");
        let no_gyro = line(odometry_flags::NO_GYRO);
        assert!(no_gyro.contains("no position"), "{no_gyro}");
        assert!(!no_gyro.contains("pos ("), "{no_gyro}");
        let learning = status_line(&[&stats; 3], &SourceLosses::new(1000), None, None, None);
        assert!(learning.contains("rest detector learning"), "{learning}");
        assert!(
            !learning.contains("at rest") && !learning.contains("moving"),
            "{learning}"
        );
    }

    #[test]
    fn the_status_line_shows_losses_at_every_point() {
        let stats = TopicStats::new();
        let mut source = SourceLosses::new(1000);
        let raw = |seq, t_ms: u64, lost_before, undelivered| RawImuSample {
            seq,
            stamps: ipc_types::Stamps {
                sample_ns: t_ms * 1_000_000,
                ..Default::default()
            },
            lost_before,
            undelivered,
            ..Default::default()
        };
        source.observe(&raw(7, 10, 3, 45));
        source.observe(&raw(0, 240, 0, 0));
        let recorder = RecorderLosses::default();
        recorder.sink()("mems-record: lost 20 of mems/imu/raw (seq 100..=119)");
        let line = status_line(&[&stats; 3], &source, Some(&recorder), None, None);
        for needle in [
            "sensor lost 3 + 229 across acquire restarts",
            "undelivered 45",
            "recording lost 20/0/0",
        ] {
            assert!(line.contains(needle), "{needle:?} missing from: {line}");
        }
        let unrecorded = status_line(&[&stats; 3], &source, None, None, None);
        assert!(!unrecorded.contains("recording"), "{unrecorded}");
    }
}
