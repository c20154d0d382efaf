//! The allocation calls a live process makes in steady state: from the end of a warm-up of
//! [`WARMUP_ENV`] inputs (default [`DEFAULT_WARMUP`]) to its last input, the calls its
//! [`BlockPool`] served from its blocks and those that reached the system allocator. The
//! counts are taken at each input, so the shutdown after the last one (ports closed, summaries
//! formatted) is not part of the steady state. Each live process feeds
//! its inputs (received samples or messages) to a [`SteadyState`] and prints [`Steady`] in its
//! summary, which the integration tests read.
//!
//! [`BlockPool`]: crate::pool::BlockPool

use std::fmt;

use crate::pool::Counts;

/// Environment variable: inputs a process handles before its steady-state count starts.
pub const WARMUP_ENV: &str = "MEMS_ALLOC_WARMUP";
/// Warm-up when [`WARMUP_ENV`] is not set: the first second at 1 kHz.
pub const DEFAULT_WARMUP: u64 = 1000;

/// Counts inputs and takes the allocator's counts when the warm-up ends.
#[derive(Debug, Clone)]
pub struct SteadyState {
    warmup: u64,
    inputs: u64,
    /// Inputs and allocation counts when the warm-up ended.
    start: Option<(u64, Counts)>,
    /// Inputs and allocation counts at the last input.
    last: (u64, Counts),
    counts: fn() -> Counts,
}

/// Allocation calls after the warm-up. Printed as
/// `steady state after W inputs: N inputs, P pool allocations, S system allocations`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Steady {
    /// Warm-up, inputs.
    pub warmup: u64,
    /// Inputs after the warm-up.
    pub inputs: u64,
    /// Allocation calls after the warm-up: served from the pool, by the system allocator.
    pub calls: Counts,
}

impl SteadyState {
    /// A tracker with the warm-up `warmup` that reads the allocator's counts with `counts`.
    pub fn new(warmup: u64, counts: fn() -> Counts) -> Self {
        Self {
            warmup,
            inputs: 0,
            start: None,
            last: (0, Counts::default()),
            counts,
        }
    }

    /// A tracker with the warm-up from [`WARMUP_ENV`] (default [`DEFAULT_WARMUP`]); an
    /// unreadable value is an error naming the variable.
    pub fn from_env(counts: fn() -> Counts) -> Result<Self, String> {
        let warmup = match std::env::var(WARMUP_ENV) {
            Ok(v) => v
                .parse()
                .map_err(|e| format!("{WARMUP_ENV}={v:?} is not a number of inputs: {e}"))?,
            Err(_) => DEFAULT_WARMUP,
        };
        Ok(Self::new(warmup, counts))
    }

    /// Accounts for `n` more inputs; the count starts once the warm-up is over and runs to
    /// the last call. Allocates nothing.
    pub fn inputs(&mut self, n: u64) {
        self.inputs += n;
        if self.start.is_some() {
            self.last = (self.inputs, (self.counts)());
        } else if self.inputs >= self.warmup {
            let start = (self.inputs, (self.counts)());
            self.start = Some(start);
            self.last = start;
        }
    }

    /// Whether the warm-up is over.
    pub fn is_steady(&self) -> bool {
        self.start.is_some()
    }

    /// The calls from the end of the warm-up to the last input (`None` before).
    pub fn steady(&self) -> Option<Steady> {
        let (inputs, start) = self.start?;
        let (last_inputs, last) = self.last;
        Some(Steady {
            warmup: self.warmup,
            inputs: last_inputs - inputs,
            calls: Counts {
                pool: last.pool - start.pool,
                system: last.system - start.system,
            },
        })
    }

    /// One line for a process's summary: [`Steady`], or that the warm-up did not end.
    pub fn summary(&self) -> String {
        match self.steady() {
            Some(s) => s.to_string(),
            None => format!(
                "steady state not reached ({} of {} warm-up inputs)",
                self.inputs, self.warmup
            ),
        }
    }
}

impl fmt::Display for Steady {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "steady state after {} inputs: {} inputs, {} pool allocations, {} system allocations",
            self.warmup, self.inputs, self.calls.pool, self.calls.system
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU64, Ordering};

    static POOL: AtomicU64 = AtomicU64::new(0);
    static SYSTEM: AtomicU64 = AtomicU64::new(0);

    fn counts() -> Counts {
        Counts {
            pool: POOL.load(Ordering::Relaxed),
            system: SYSTEM.load(Ordering::Relaxed),
        }
    }

    #[test]
    fn counts_only_after_the_warmup() {
        let mut s = SteadyState::new(10, counts);
        POOL.store(100, Ordering::Relaxed);
        SYSTEM.store(50, Ordering::Relaxed);
        s.inputs(4);
        assert_eq!(s.steady(), None);
        assert!(s.summary().contains("4 of 10 warm-up inputs"));
        s.inputs(7);
        POOL.store(120, Ordering::Relaxed);
        SYSTEM.store(51, Ordering::Relaxed);
        s.inputs(20);
        // After the last input (shutdown): not counted.
        POOL.store(500, Ordering::Relaxed);
        let steady = s.steady().unwrap();
        assert_eq!(
            steady.inputs, 20,
            "inputs after the one that ended the warm-up"
        );
        assert_eq!(
            steady.calls,
            Counts {
                pool: 20,
                system: 1
            }
        );
        assert_eq!(
            s.summary(),
            "steady state after 10 inputs: 20 inputs, 20 pool allocations, 1 system allocations"
        );
    }
}
