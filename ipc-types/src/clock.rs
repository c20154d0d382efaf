//! The one clock every stage stamps messages with: `CLOCK_MONOTONIC` in nanoseconds, the same
//! clock in every process on the machine, so stamps from different processes subtract.

/// Nanoseconds of `CLOCK_MONOTONIC` now.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC is always supported on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_MONOTONIC) failed");
    // tv_sec and tv_nsec are non-negative for CLOCK_MONOTONIC.
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_and_agrees_with_instant() {
        let a = monotonic_ns();
        let start = std::time::Instant::now();
        std::thread::sleep(std::time::Duration::from_millis(20));
        let b = monotonic_ns();
        let elapsed = start.elapsed().as_nanos() as u64;
        assert!(b > a);
        // Instant is CLOCK_MONOTONIC too: the two intervals agree to well under a millisecond.
        assert!(
            (b - a).abs_diff(elapsed) < 1_000_000,
            "{} vs {elapsed}",
            b - a
        );
    }
}
