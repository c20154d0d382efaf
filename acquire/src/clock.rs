//! Time sources: the host's `CLOCK_MONOTONIC` for real hardware, and [`SimClock`], a clock
//! shared between a simulated device and the code that drives it, either virtual
//! (deterministic, advanced explicitly and by simulated bus transactions) or real-time.
//!
//! All times are nanoseconds. [`MonotonicClock`] and a real-time [`SimClock`] read
//! `CLOCK_MONOTONIC`, so their stamps compare with every other process on the machine; a
//! virtual [`SimClock`] starts wherever its creator says.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// A monotonic time source that can also let time pass.
pub trait Clock {
    /// The current time, ns.
    fn now_ns(&self) -> u64;

    /// Returns once the clock reads at least `deadline_ns` (sleeps, or advances virtual time).
    fn sleep_until(&self, deadline_ns: u64);

    /// Lets `duration_ns` pass.
    fn sleep_ns(&self, duration_ns: u64) {
        self.sleep_until(self.now_ns().saturating_add(duration_ns));
    }
}

/// The host's `CLOCK_MONOTONIC`, for real hardware.
#[derive(Debug, Clone, Copy, Default)]
pub struct MonotonicClock;

impl Clock for MonotonicClock {
    fn now_ns(&self) -> u64 {
        ipc_types::clock::monotonic_ns()
    }

    fn sleep_until(&self, deadline_ns: u64) {
        sleep_until_monotonic(deadline_ns);
    }
}

/// Sleeps until `CLOCK_MONOTONIC` reads `deadline_ns`, with an absolute-deadline
/// `clock_nanosleep`: unlike a relative sleep computed from an earlier reading, a preemption
/// between reading the clock and going to sleep does not push the wake-up later. Signals
/// (EINTR) resume the same deadline.
fn sleep_until_monotonic(deadline_ns: u64) {
    let deadline = libc::timespec {
        tv_sec: (deadline_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (deadline_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `deadline` is a valid timespec (tv_nsec < 1e9); with TIMER_ABSTIME the
        // remaining-time pointer is unused and may be null.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &deadline,
                std::ptr::null_mut(),
            )
        };
        match rc {
            0 => return,
            libc::EINTR => continue,
            // Only EINVAL remains (an invalid timespec, which the construction rules out).
            other => panic!("clock_nanosleep(CLOCK_MONOTONIC, {deadline_ns} ns): error {other}"),
        }
    }
}

/// A clock shared (by cloning) between a simulated device and its users.
///
/// Virtual: time stands still until someone calls [`Clock::sleep_until`] / [`SimClock::advance`]
/// (a simulated bus transaction does so for its own duration), so runs are deterministic and
/// as fast as the host allows. Real-time: `CLOCK_MONOTONIC`, and letting time pass sleeps.
#[derive(Debug, Clone)]
pub struct SimClock {
    /// Virtual time in ns, or `None` for real time.
    virtual_ns: Option<Arc<AtomicU64>>,
}

impl SimClock {
    /// A virtual clock reading `start_ns`.
    pub fn new_virtual(start_ns: u64) -> Self {
        Self {
            virtual_ns: Some(Arc::new(AtomicU64::new(start_ns))),
        }
    }

    /// A clock that follows `CLOCK_MONOTONIC` (for the live demo).
    pub fn real_time() -> Self {
        Self { virtual_ns: None }
    }

    /// Whether this clock is virtual.
    pub fn is_virtual(&self) -> bool {
        self.virtual_ns.is_some()
    }

    /// Lets `duration_ns` pass (the same as [`Clock::sleep_ns`]).
    pub fn advance(&self, duration_ns: u64) {
        self.sleep_ns(duration_ns);
    }
}

impl Clock for SimClock {
    fn now_ns(&self) -> u64 {
        match &self.virtual_ns {
            Some(t) => t.load(Ordering::Acquire),
            None => ipc_types::clock::monotonic_ns(),
        }
    }

    fn sleep_until(&self, deadline_ns: u64) {
        match &self.virtual_ns {
            Some(t) => {
                t.fetch_max(deadline_ns, Ordering::AcqRel);
            }
            None => sleep_until_monotonic(deadline_ns),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn virtual_clock_is_shared_and_never_goes_back() {
        let a = SimClock::new_virtual(1_000);
        let b = a.clone();
        assert_eq!(b.now_ns(), 1_000);
        a.advance(500);
        assert_eq!(b.now_ns(), 1_500);
        b.sleep_until(1_200); // already past: no change
        assert_eq!(a.now_ns(), 1_500);
        b.sleep_until(2_000);
        assert_eq!(a.now_ns(), 2_000);
        assert!(a.is_virtual());
    }

    #[test]
    fn real_time_clock_follows_monotonic_and_sleeps() {
        let c = SimClock::real_time();
        assert!(!c.is_virtual());
        let t0 = c.now_ns();
        let m0 = MonotonicClock.now_ns();
        assert!(m0 >= t0 && m0 - t0 < 50_000_000);
        c.sleep_ns(2_000_000);
        let dt = c.now_ns() - t0;
        assert!(dt >= 2_000_000, "slept only {dt} ns");
    }
}
