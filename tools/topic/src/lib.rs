//! Loss, duplicate, rate and latency accounting for a stream of mems messages, shared by
//! `mems-topic` and the benchmarks. No I/O: feed it messages, read a [`Report`].

use hdrhistogram::Histogram;
use serde::Serialize;

/// Running statistics over the messages of one service.
pub struct TopicStats {
    received: u64,
    lost: u64,
    lost_at_source: u64,
    duplicated: u64,
    non_monotonic: u64,
    next_seq: Option<u64>,
    first_sample_ns: Option<u64>,
    last_sample_ns: Option<u64>,
    min_period_ns: u64,
    max_period_ns: u64,
    latency_ns: Histogram<u64>,
}

/// Latency percentiles in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LatencyUs {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest seen.
    pub max: f64,
}

/// Sample-time spacing in microseconds (from the messages' `stamps.sample_ns`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PeriodUs {
    /// Mean spacing over the whole run.
    pub mean: f64,
    /// Smallest spacing between consecutive samples.
    pub min: f64,
    /// Largest spacing between consecutive samples.
    pub max: f64,
}

/// A summary of what was received.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Messages received (revisions included).
    pub received: u64,
    /// Sequence numbers skipped (never received).
    pub lost: u64,
    /// Samples the source lost before publishing and flagged (raw samples' `lost_before`):
    /// not lost on the service, but missing from the sample grid.
    pub lost_at_source: u64,
    /// Messages whose sequence number was not above the last one (revisions excluded).
    pub duplicated: u64,
    /// Rate of sample times, Hz: (n - 1) / (last sample time - first sample time).
    pub rate_hz: f64,
    /// Rate of the source's sample grid, Hz: as `rate_hz`, the samples lost at the source
    /// counted in.
    pub source_rate_hz: f64,
    /// Receive time minus the publishing stage's own stamp.
    pub latency_us: LatencyUs,
    /// Spacing of sample times.
    pub sample_period_us: PeriodUs,
    /// Consecutive messages whose sample time did not increase.
    pub non_monotonic: u64,
}

impl Default for TopicStats {
    fn default() -> Self {
        Self::new()
    }
}

impl TopicStats {
    /// Empty statistics.
    pub fn new() -> Self {
        Self {
            received: 0,
            lost: 0,
            lost_at_source: 0,
            duplicated: 0,
            non_monotonic: 0,
            next_seq: None,
            first_sample_ns: None,
            last_sample_ns: None,
            min_period_ns: u64::MAX,
            max_period_ns: 0,
            // 1 ns .. 100 s at 3 significant digits.
            latency_ns: Histogram::new_with_bounds(1, 100_000_000_000, 3)
                .expect("valid histogram bounds"),
        }
    }

    /// Accounts for one message: its sequence number, its sample time, the time its stage
    /// published it and the time it was received (ns, `CLOCK_MONOTONIC`). The first message
    /// fixes the starting sequence number, so a subscriber may join a running stream.
    pub fn observe(
        &mut self,
        seq: u64,
        sample_ns: u64,
        published_ns: u64,
        received_ns: u64,
        revision: bool,
    ) {
        self.received += 1;
        self.latency_ns
            .saturating_record(received_ns.saturating_sub(published_ns).max(1));
        if revision {
            return;
        }
        match self.next_seq {
            Some(next) if seq < next => self.duplicated += 1,
            Some(next) => self.lost += seq - next,
            None => {}
        }
        self.next_seq = Some(self.next_seq.map_or(seq + 1, |n| n.max(seq + 1)));
        if let Some(last) = self.last_sample_ns {
            if sample_ns <= last {
                self.non_monotonic += 1;
            } else {
                let period = sample_ns - last;
                self.min_period_ns = self.min_period_ns.min(period);
                self.max_period_ns = self.max_period_ns.max(period);
            }
        }
        self.first_sample_ns.get_or_insert(sample_ns);
        self.last_sample_ns = Some(self.last_sample_ns.map_or(sample_ns, |l| l.max(sample_ns)));
    }

    /// Counts `n` samples the source lost before the last message and flagged
    /// ([`ipc_types::Message::lost_at_source`]).
    pub fn lost_at_source(&mut self, n: u64) {
        self.lost_at_source += n;
    }

    /// The summary so far.
    pub fn report(&self) -> Report {
        let span_ns = match (self.first_sample_ns, self.last_sample_ns) {
            (Some(a), Some(b)) if b > a => (b - a) as f64,
            _ => 0.0,
        };
        let in_order = self.received.saturating_sub(self.duplicated);
        let us = |ns: u64| ns as f64 / 1e3;
        let empty = self.latency_ns.is_empty();
        let pct = |q: f64| {
            if empty {
                0.0
            } else {
                us(self.latency_ns.value_at_quantile(q))
            }
        };
        let rate = |n: u64| match span_ns > 0.0 {
            true => n.saturating_sub(1) as f64 / span_ns * 1e9,
            false => 0.0,
        };
        Report {
            received: self.received,
            lost: self.lost,
            lost_at_source: self.lost_at_source,
            duplicated: self.duplicated,
            rate_hz: rate(in_order),
            source_rate_hz: rate(in_order + self.lost_at_source),
            latency_us: LatencyUs {
                p50: pct(0.5),
                p99: pct(0.99),
                max: if empty {
                    0.0
                } else {
                    us(self.latency_ns.max())
                },
            },
            sample_period_us: PeriodUs {
                mean: if in_order > 1 {
                    span_ns / (in_order - 1) as f64 / 1e3
                } else {
                    0.0
                },
                min: if self.min_period_ns == u64::MAX {
                    0.0
                } else {
                    us(self.min_period_ns)
                },
                max: us(self.max_period_ns),
            },
            non_monotonic: self.non_monotonic,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_losses_duplicates_and_rate() {
        let mut s = TopicStats::new();
        // 1 kHz samples starting mid-stream at seq 10; seq 13 and 14 lost; 12 repeated.
        let seqs = [10u64, 11, 12, 12, 15, 16];
        for (i, &seq) in seqs.iter().enumerate() {
            let t = 1_000_000 * seq;
            s.observe(seq, t, t + 100, t + 100 + 1000 * i as u64, false);
        }
        let r = s.report();
        assert_eq!(r.received, 6);
        assert_eq!(r.lost, 2);
        assert_eq!(r.duplicated, 1);
        assert_eq!(r.non_monotonic, 1);
        // 5 in-order messages over 6 ms of sample time; the source lost none.
        assert!((r.rate_hz - 4.0 / 0.006).abs() < 1e-9);
        assert_eq!((r.lost_at_source, r.source_rate_hz), (0, r.rate_hz));
        // Two lost at the sensor and flagged: the grid's rate counts them.
        s.lost_at_source(2);
        let r = s.report();
        assert!((r.source_rate_hz - 6.0 / 0.006).abs() < 1e-9, "{r:?}");
        assert!((r.sample_period_us.max - 3000.0).abs() < 1.0);
        assert!((r.sample_period_us.min - 1000.0).abs() < 1.0);
        assert!((r.latency_us.max - 5.0).abs() < 0.01);
    }

    #[test]
    fn revisions_are_not_duplicates() {
        let mut s = TopicStats::new();
        s.observe(0, 0, 0, 1, false);
        s.observe(1, 1000, 0, 1, false);
        s.observe(0, 0, 0, 1, true);
        let r = s.report();
        assert_eq!((r.received, r.duplicated, r.lost), (3, 0, 0));
    }
}
