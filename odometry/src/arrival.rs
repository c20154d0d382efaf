//! The order in which a live pipeline receives a recording's raw samples and robot hints, for
//! runs over a recording ([`Arrival`]).
//!
//! A recording holds each message at the time it was logged, and a robot hint is often logged
//! after raw samples taken later than its publication (the controller's transport is slower
//! than the sensor's). Live, the odometry session gets such a hint before those samples reach
//! it (they pass through the calibration stage first) and hands it to its stage before the
//! first sample taken at or after its publication (`crate::session`). Over a recording the
//! same order comes from holding each raw sample back [`HINT_WINDOW_NS`] of sample time: a
//! hint logged up to that long after its publication is read before the samples it precedes
//! are released. A hint logged later is still delivered, one sample late, and counted
//! ([`Arrival::late_hints`]). Times are ns of the recording's `CLOCK_MONOTONIC`: a raw
//! sample's `stamps.sample_ns`, a hint's publication `stamps.acquired_ns`.

use std::collections::VecDeque;

use ipc_types::{RawImuSample, RobotHint};

/// How long a raw sample is held back for the robot hints logged after it, ns (2 s).
pub const HINT_WINDOW_NS: u64 = 2_000_000_000;

/// Raw samples held back for the hints logged after them. Hints pass at once (the session
/// queues them by publication); raw samples leave in the order they came.
#[derive(Debug, Default)]
pub struct Arrival {
    held: VecDeque<RawImuSample>,
    /// Time of the newest raw sample taken, ns (`None`: none yet).
    newest_ns: Option<u64>,
    /// Whether the input has ended: every held sample is due.
    ended: bool,
    /// Time of the last raw sample released, ns.
    released_ns: Option<u64>,
    hints: u64,
    late_hints: u64,
}

impl Arrival {
    /// Nothing held.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes the next raw sample read; it leaves through [`Self::release`] once the input has
    /// passed its time by [`HINT_WINDOW_NS`] (or ended).
    pub fn raw(&mut self, raw: RawImuSample) {
        self.newest_ns = Some(raw.stamps.sample_ns);
        self.held.push_back(raw);
    }

    /// Notes the next hint read, which goes on at once; counted late when a raw sample taken
    /// at or after its publication has already left.
    pub fn hint(&mut self, h: &RobotHint) {
        self.hints += 1;
        let late = self.released_ns.is_some_and(|r| h.stamps.acquired_ns <= r);
        self.late_hints += u64::from(late);
    }

    /// The input has ended: every held sample is due.
    pub fn end(&mut self) {
        self.ended = true;
    }

    /// The oldest held raw sample, when it is due.
    pub fn release(&mut self) -> Option<RawImuSample> {
        let front = self.held.front()?;
        let waiting = !self.ended
            && self
                .newest_ns
                .is_some_and(|n| front.stamps.sample_ns + HINT_WINDOW_NS > n);
        if waiting {
            return None;
        }
        let raw = self.held.pop_front()?;
        self.released_ns = Some(raw.stamps.sample_ns);
        Some(raw)
    }

    /// Hints read.
    pub fn hints(&self) -> u64 {
        self.hints
    }

    /// Hints logged more than [`HINT_WINDOW_NS`] after their publication: delivered after a
    /// sample they precede.
    pub fn late_hints(&self) -> u64 {
        self.late_hints
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn raw(t_ms: u64) -> RawImuSample {
        let mut s = RawImuSample {
            seq: t_ms,
            ..RawImuSample::default()
        };
        s.stamps.sample_ns = t_ms * MS;
        s
    }

    fn hint(published_ms: u64) -> RobotHint {
        let mut h = RobotHint::default();
        h.stamps.acquired_ns = published_ms * MS;
        h
    }

    /// Feeds `log` (raw sample times and hint publication times, in file order) and returns
    /// the order the pipeline gets them in: ("r", t) or ("h", t), ms.
    fn arrive(log: &[(&'static str, u64)]) -> (Vec<(&'static str, u64)>, Arrival) {
        let mut a = Arrival::new();
        let mut out = Vec::new();
        let drain = |a: &mut Arrival, out: &mut Vec<_>| {
            while let Some(r) = a.release() {
                out.push(("r", r.stamps.sample_ns / MS));
            }
        };
        for &(kind, t) in log {
            if kind == "r" {
                a.raw(raw(t));
                drain(&mut a, &mut out);
            } else {
                a.hint(&hint(t));
                out.push(("h", t));
            }
        }
        a.end();
        drain(&mut a, &mut out);
        (out, a)
    }

    #[test]
    fn a_hint_logged_within_the_window_goes_before_the_samples_it_precedes() {
        // Samples every 500 ms; the hint published at 1000 ms is logged after the 2500 ms
        // sample (1.5 s late), the one published at 600 ms after the 3000 ms one (2.4 s late).
        let log = [
            ("r", 0),
            ("r", 500),
            ("r", 1000),
            ("r", 1500),
            ("r", 2000),
            ("r", 2500),
            ("h", 1000),
            ("r", 3000),
            ("h", 600),
            ("r", 3500),
        ];
        let (order, a) = arrive(&log);
        assert_eq!(
            order,
            [
                ("r", 0),
                ("r", 500),
                ("h", 1000),
                ("r", 1000),
                ("h", 600),
                ("r", 1500),
                ("r", 2000),
                ("r", 2500),
                ("r", 3000),
                ("r", 3500),
            ]
        );
        // The 1000 ms hint still came before the 1000 ms sample; the 600 ms one, logged beyond
        // the window, after the 1000 ms sample it precedes: late.
        assert_eq!((a.hints(), a.late_hints()), (2, 1));
    }

    #[test]
    fn every_sample_leaves_in_order_once_the_input_ends() {
        let (order, a) = arrive(&[("r", 0), ("r", 10), ("r", 20)]);
        assert_eq!(order, [("r", 0), ("r", 10), ("r", 20)]);
        assert_eq!((a.hints(), a.late_hints()), (0, 0));
        // A sample exactly one window older than the newest is due.
        let mut a = Arrival::new();
        a.raw(raw(0));
        a.raw(raw(1999));
        assert!(a.release().is_none());
        a.raw(raw(2000));
        assert_eq!(a.release().map(|r| r.seq), Some(0));
        assert!(a.release().is_none());
    }
}
