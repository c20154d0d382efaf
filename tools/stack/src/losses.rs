//! Where samples were lost, for the stack's status line and summary, beyond the sequence gaps
//! each topic shows: at the sensor (FIFO overflows, which acquire flags on the next sample's
//! `lost_before`), across acquire restarts (the sample time that passed while no acquire ran),
//! given up by acquire for stalled subscribers (each sample's `undelivered`), and missing from
//! the recording (the recorder's gap lines, which include what a killed recorder missed).

use std::sync::{Arc, Mutex};

use ipc_types::{RawImuSample, raw_flags};

use crate::supervisor::LineSink;

/// Losses at and before the source, from the raw samples the stack receives. No I/O.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceLosses {
    period_ns: f64,
    /// Samples the sensor lost (FIFO overflows).
    pub fifo: u64,
    /// Sample periods that passed between one acquire process's last sample and the next
    /// one's first, less one: what restarts lost.
    pub restarts: u64,
    /// Samples acquire gave up for stalled subscribers, by processes that ended.
    undelivered_before: u64,
    /// The same by the running acquire process (its counter is cumulative).
    undelivered_now: u64,
    last: Option<(u64, u64)>,
}

impl SourceLosses {
    /// Nothing lost yet; the sensor's output rate is `rate_hz`.
    pub fn new(rate_hz: u32) -> Self {
        Self {
            period_ns: 1e9 / f64::from(rate_hz.max(1)),
            fifo: 0,
            restarts: 0,
            undelivered_before: 0,
            undelivered_now: 0,
            last: None,
        }
    }

    /// Accounts for one raw sample. A restarted acquire process either continues the sensor
    /// session (its first sample is flagged `RESUMED`, and `lost_before` counts what the
    /// restart lost) or starts a new one (a sequence number that does not increase: the
    /// sample periods between the two processes' samples were lost).
    pub fn observe(&mut self, s: &RawImuSample) {
        let t = s.stamps.sample_ns;
        let resumed = s.flags & raw_flags::RESUMED != 0;
        if resumed {
            self.restarts += u64::from(s.lost_before);
        } else {
            self.fifo += u64::from(s.lost_before);
        }
        let new_session = self.last.is_some_and(|(seq, _)| s.seq <= seq);
        if resumed || new_session {
            self.undelivered_before += self.undelivered_now;
            self.undelivered_now = 0;
        }
        if let Some((_, last_t)) = self.last
            && new_session
        {
            let periods = (t.saturating_sub(last_t) as f64 / self.period_ns).round() as u64;
            self.restarts += periods.saturating_sub(1);
        }
        self.undelivered_now = self.undelivered_now.max(u64::from(s.undelivered));
        self.last = Some((s.seq, t));
    }

    /// Samples acquire gave up for stalled subscribers, all processes.
    pub fn undelivered(&self) -> u64 {
        self.undelivered_before + self.undelivered_now
    }
}

/// Samples missing from the recording, per topic, summed from the recorder's gap lines
/// (`mems_record::LOST_PREFIX`), which reach the stack through [`RecorderLosses::sink`].
#[derive(Debug, Clone, Default)]
pub struct RecorderLosses(Arc<Mutex<Vec<(String, u64)>>>);

impl RecorderLosses {
    /// Where the recorder's standard output goes: gap lines are counted, others ignored.
    pub fn sink(&self) -> LineSink {
        let counts = self.0.clone();
        Arc::new(move |line: &str| {
            let Some((n, service)) = parse_gap(line) else {
                return;
            };
            let mut counts = counts.lock().unwrap_or_else(|e| e.into_inner());
            match counts.iter_mut().find(|(s, _)| s == service) {
                Some((_, total)) => *total += n,
                None => counts.push((service.to_string(), n)),
            }
        })
    }

    /// Samples missing from the recording on `service` (its base name).
    pub fn of(&self, service: &str) -> u64 {
        let counts = self.0.lock().unwrap_or_else(|e| e.into_inner());
        counts
            .iter()
            .find(|(s, _)| s == service)
            .map_or(0, |(_, n)| *n)
    }
}

/// (count, service) of a recorder gap line `mems-record: lost N of SERVICE (seq A..=B)`.
fn parse_gap(line: &str) -> Option<(u64, &str)> {
    let rest = line.strip_prefix(mems_record::LOST_PREFIX)?;
    let (n, rest) = rest.split_once(" of ")?;
    let (service, _) = rest.split_once(' ')?;
    Some((n.parse().ok()?, service))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::Stamps;

    fn sample(seq: u64, t_ms: u64, lost_before: u32, undelivered: u32) -> RawImuSample {
        RawImuSample {
            seq,
            stamps: Stamps {
                sample_ns: t_ms * 1_000_000,
                ..Stamps::default()
            },
            lost_before,
            undelivered,
            ..RawImuSample::default()
        }
    }

    #[test]
    fn a_restart_counts_the_periods_without_samples() {
        let mut l = SourceLosses::new(1000);
        for (i, t) in (100..110).enumerate() {
            l.observe(&sample(i as u64, t, 0, 0));
        }
        l.observe(&sample(10, 112, 2, 0));
        assert_eq!((l.fifo, l.restarts), (2, 0), "a FIFO loss is not a restart");
        // Acquire restarted: its first sample 230 ms after the last one.
        l.observe(&sample(0, 342, 0, 0));
        assert_eq!(l.restarts, 229);
        l.observe(&sample(1, 343, 0, 0));
        assert_eq!(l.restarts, 229);
    }

    #[test]
    fn a_restart_that_continues_the_session_counts_its_flagged_hole() {
        let mut l = SourceLosses::new(1000);
        for (i, t) in (100..110).enumerate() {
            l.observe(&sample(i as u64, t, 0, 7));
        }
        // Acquire restarted and continued the session: the next number, 229 periods lost.
        let mut first = sample(10, 339, 229, 0);
        first.flags = raw_flags::GAP_BEFORE | raw_flags::RESUMED;
        l.observe(&first);
        l.observe(&sample(11, 340, 0, 2));
        assert_eq!((l.fifo, l.restarts), (0, 229));
        assert_eq!(l.undelivered(), 9, "the new process counts from 0 again");
    }

    #[test]
    fn undelivered_adds_up_across_acquire_processes() {
        let mut l = SourceLosses::new(1000);
        l.observe(&sample(0, 1, 0, 0));
        l.observe(&sample(1, 2, 0, 40));
        l.observe(&sample(2, 3, 0, 45));
        assert_eq!(l.undelivered(), 45);
        l.observe(&sample(0, 4, 0, 0));
        l.observe(&sample(1, 5, 0, 3));
        assert_eq!(l.undelivered(), 48);
    }

    #[test]
    fn the_recorders_gap_lines_are_summed_per_topic() {
        let losses = RecorderLosses::default();
        let sink = losses.sink();
        sink("mems-record: lost 20 of mems/imu/raw (seq 100..=119)");
        sink("mems-record: wrote run.mcap in 3.0 s; 4 events");
        sink("mems-record: lost 5 of mems/imu/raw (seq 300..=304)");
        sink("mems-record: lost 7 of mems/imu/corrected (seq 99..=105)");
        assert_eq!(losses.of("mems/imu/raw"), 25);
        assert_eq!(losses.of("mems/imu/corrected"), 7);
        assert_eq!(losses.of("mems/odometry/state"), 0);
    }
}
