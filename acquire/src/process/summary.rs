//! What `mems-acquire` says when it stops: read lateness, FIFO timing, and the counts of
//! samples published, lost and discarded.

use std::time::Duration;

use alloc_count::pool::BlockPool;
use embedded_hal::i2c::I2c;
use ipc_types::service::Undelivered;

use crate::acquisition::{Acquisition, LoopStats};
use crate::clock::Clock;
use crate::driver::DriverStats;

/// A run's summary, gathered when the loop ends.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// The loop's counters.
    pub stats: LoopStats,
    /// The driver's counters.
    pub driver: DriverStats,
    /// Read lateness at the 50th, 99th and 99.9th percentiles, us (never above the maximum).
    pub late_us: [f64; 3],
    /// Samples given up for stalled subscribers, in all.
    pub undelivered: u64,
    /// (subscriber port id, samples given up for it).
    pub per_subscriber: Vec<(u128, u64)>,
    /// How long the loop ran.
    pub elapsed: Duration,
}

impl Summary {
    /// The summary of `acq`, which ran for `elapsed`, with the samples `undelivered` counted.
    pub fn of<I2C: I2c, C: Clock>(
        acq: &Acquisition<I2C, C>,
        undelivered: &Undelivered,
        elapsed: Duration,
    ) -> Self {
        let stats = acq.stats();
        let late = acq.lateness();
        // The histogram reports a bucket's upper end (2 significant digits): never above the
        // exact maximum.
        let us = |q: f64| late.value_at_quantile(q).min(stats.max_late_ns.max(1)) as f64 * 1e-3;
        Self {
            stats,
            driver: acq.driver().stats(),
            late_us: [us(0.5), us(0.99), us(0.999)],
            undelivered: undelivered.total(),
            per_subscriber: undelivered.per_subscriber(),
            elapsed,
        }
    }

    /// Says the summary on stderr, with the use of the process's small-block `pool`.
    pub fn log<const N: usize>(&self, pool: &BlockPool<N>) {
        let (stats, driver) = (&self.stats, &self.driver);
        tracing::info!(
            "read lateness p50 {:.0} us, p99 {:.0} us, p99.9 {:.0} us, max {:.0} us; \
             fullest FIFO {} of 512 bytes",
            self.late_us[0],
            self.late_us[1],
            self.late_us[2],
            stats.max_late_ns as f64 * 1e-3,
            driver.max_fifo_bytes
        );
        if let Some((ahead, behind)) = stats.sample_time_excursion_ns {
            tracing::info!(
                "newest sample's FIFO time at most {:.3} ms after its acquisition and \
                 {:.3} ms before its read's start minus a period (<= 0: on the clock); duplicates \
                 dropped {}, settling frames dropped {}, pair mismatches {}",
                ahead as f64 * 1e-6,
                behind as f64 * 1e-6,
                driver.duplicates,
                driver.settling_discarded,
                driver.pair_mismatches
            );
        }
        if let Some((seq, lost)) = stats.resumed {
            tracing::info!(
                "continued the sensor session from seq {seq}: {lost} samples not read while no \
                 acquisition ran"
            );
        }
        let per_subscriber: Vec<String> = self
            .per_subscriber
            .iter()
            .map(|(port, n)| format!("{n} for subscriber port {port:#x}"))
            .collect();
        tracing::info!(
            "published {} samples in {:.1} s; reads {}, failed {}, overflows {}, \
             gaps {}, lost {}, bus errors {}, re-inits {}; discarded for stalled subscribers {}{}; {}",
            stats.published,
            self.elapsed.as_secs_f64(),
            stats.reads,
            stats.failed_reads,
            driver.overflows,
            driver.gaps,
            driver.lost_samples,
            driver.bus_errors,
            driver.reinits,
            self.undelivered,
            if per_subscriber.is_empty() {
                String::new()
            } else {
                format!(" ({})", per_subscriber.join(", "))
            },
            pool.summary()
        );
    }
}
