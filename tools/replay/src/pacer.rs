//! The real-time pace of a replay: when each message of one pass is due, from the recorded
//! times of its messages and a speed.

use std::time::{Duration, Instant};

use crate::topics::Place;

/// When each message of one pass is due, and how much recorded time the pass has covered.
///
/// An epoch's clock starts once its first instant's messages have been sent: they are due at
/// once, and the next message asks for the clock, which then starts at that moment. So no
/// message goes out before its recorded offset from the epoch's first message (scaled by the
/// speed), measured from when that first message actually left, however late it was.
#[derive(Debug, Default)]
pub(crate) struct Pacer {
    /// The epoch, the replay time of its first message and when its clock started (`None`
    /// while the messages of that first time are being sent).
    anchor: Option<(u32, u64, Option<Instant>)>,
    /// Recorded time covered by the epochs before the anchor's, ns.
    before_ns: u64,
    /// Recorded time covered so far, ns.
    pub(crate) covered_ns: u64,
}

impl Pacer {
    /// When the message at `place` is due at `speed` (pacing starts over with each epoch).
    pub(crate) fn due(&mut self, place: Place, speed: f64) -> Instant {
        self.due_at(place, speed, Instant::now())
    }

    /// [`Pacer::due`] with `now` the present instant.
    fn due_at(&mut self, place: Place, speed: f64, now: Instant) -> Instant {
        let (epoch, anchor_ns, started) = self.place(place);
        let start = match started {
            Some(start) => start,
            None if place.time_ns <= anchor_ns => return now,
            None => {
                self.anchor = Some((epoch, anchor_ns, Some(now)));
                now
            }
        };
        let offset_ns = place.time_ns.saturating_sub(anchor_ns) as f64 / speed;
        start + Duration::from_nanos(offset_ns.round() as u64)
    }

    /// Notes `place` and returns the anchor of its epoch.
    pub(crate) fn place(&mut self, place: Place) -> (u32, u64, Option<Instant>) {
        let anchor = match self.anchor {
            Some(a) if a.0 == place.epoch => a,
            _ => {
                self.before_ns = self.covered_ns;
                let a = (place.epoch, place.time_ns, None);
                self.anchor = Some(a);
                a
            }
        };
        let into_epoch = place.time_ns.saturating_sub(anchor.1);
        self.covered_ns = self.covered_ns.max(self.before_ns + into_epoch);
        anchor
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(epoch: u32, time_ms: u64) -> Place {
        Place {
            epoch,
            time_ns: time_ms * 1_000_000,
        }
    }

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// The first instant's messages go at once; the clock starts when the next one asks, and
    /// later messages are due at their recorded offset divided by the speed.
    #[test]
    fn messages_are_due_at_their_recorded_offset_from_when_the_clock_started() {
        let t0 = Instant::now();
        let mut pacer = Pacer::default();
        assert_eq!(pacer.due_at(at(0, 100), 2.0, t0), t0);
        assert_eq!(pacer.due_at(at(0, 100), 2.0, t0 + ms(1)), t0 + ms(1));
        // The clock starts late (the first messages were slow to leave): offsets count from it.
        let start = t0 + ms(5);
        assert_eq!(pacer.due_at(at(0, 110), 2.0, start), start + ms(5));
        assert_eq!(pacer.due_at(at(0, 140), 2.0, t0 + ms(6)), start + ms(20));
        assert_eq!(pacer.due_at(at(0, 141), 0.5, t0 + ms(30)), start + ms(82));
        assert_eq!(pacer.covered_ns, 41_000_000);
    }

    /// A new epoch (recorded times starting over) starts its own clock and adds to the covered
    /// time instead of replacing it.
    #[test]
    fn a_new_epoch_starts_its_own_clock() {
        let t0 = Instant::now();
        let mut pacer = Pacer::default();
        pacer.due_at(at(0, 0), 1.0, t0);
        pacer.due_at(at(0, 50), 1.0, t0);
        assert_eq!(pacer.due_at(at(1, 10), 1.0, t0 + ms(60)), t0 + ms(60));
        assert_eq!(pacer.due_at(at(1, 30), 1.0, t0 + ms(61)), t0 + ms(81));
        assert_eq!(pacer.covered_ns, 70_000_000);
    }

    /// At maximum pace only the covered time is kept.
    #[test]
    fn placing_counts_the_covered_time() {
        let mut pacer = Pacer::default();
        for (epoch, t) in [(0, 5), (0, 25), (0, 15), (1, 3), (1, 13)] {
            pacer.place(at(epoch, t));
        }
        assert_eq!(pacer.covered_ns, 30_000_000);
    }
}
