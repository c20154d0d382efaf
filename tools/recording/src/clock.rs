//! Wall-clock anchoring: every time in this project is ns of `CLOCK_MONOTONIC` (which starts
//! near boot), and Foxglove and the MCAP tools place messages by Unix time. A [`WallClock`]
//! pairs one reading of `CLOCK_REALTIME` with one of `CLOCK_MONOTONIC`, taken back to back at
//! start, and shifts monotonic times by their difference. A recording stores it as a metadata
//! record named [`METADATA_NAME`] (see [`WallClock::metadata`]).

use std::collections::BTreeMap;
use std::time::{SystemTime, UNIX_EPOCH};

/// Name of the MCAP metadata record that holds a recording's [`WallClock`].
pub const METADATA_NAME: &str = "mems.clock";

/// One reading of each clock, taken together; converts `CLOCK_MONOTONIC` ns to Unix ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WallClock {
    /// `CLOCK_REALTIME` at the reading, ns since the Unix epoch (UTC).
    pub realtime_ns: u64,
    /// `CLOCK_MONOTONIC` at the reading, ns.
    pub monotonic_ns: u64,
}

impl WallClock {
    /// Reads both clocks now (monotonic first, then realtime, back to back).
    pub fn now() -> Self {
        let monotonic_ns = ipc_types::clock::monotonic_ns();
        let realtime_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        Self {
            realtime_ns,
            monotonic_ns,
        }
    }

    /// `CLOCK_REALTIME - CLOCK_MONOTONIC` at the reading, ns.
    pub fn offset_ns(&self) -> i128 {
        i128::from(self.realtime_ns) - i128::from(self.monotonic_ns)
    }

    /// The Unix time, ns, of monotonic time `t_ns` (0 before 1970, `u64::MAX` past 2554).
    pub fn unix_ns(&self, t_ns: u64) -> u64 {
        let unix = i128::from(t_ns) + self.offset_ns();
        u64::try_from(unix.max(0)).unwrap_or(u64::MAX)
    }

    /// The metadata record's fields: `realtime_ns`, `monotonic_ns`, `offset_ns` (decimal
    /// integers) and `clock` (what they are).
    pub fn metadata(&self) -> BTreeMap<String, String> {
        BTreeMap::from([
            ("realtime_ns".into(), self.realtime_ns.to_string()),
            ("monotonic_ns".into(), self.monotonic_ns.to_string()),
            ("offset_ns".into(), self.offset_ns().to_string()),
            (
                "clock".into(),
                "log_time and publish_time are CLOCK_MONOTONIC ns + offset_ns (Unix ns, UTC); \
                 the stamps inside the messages stay CLOCK_MONOTONIC ns"
                    .into(),
            ),
        ])
    }

    /// The clock of a metadata record's fields, `None` if `realtime_ns` or `monotonic_ns` is
    /// missing or not an integer.
    pub fn from_metadata(fields: &BTreeMap<String, String>) -> Option<Self> {
        let field = |name: &str| fields.get(name)?.parse().ok();
        Some(Self {
            realtime_ns: field("realtime_ns")?,
            monotonic_ns: field("monotonic_ns")?,
        })
    }
}

/// Unix time `ns` as an RFC 3339 UTC date and time with nanoseconds, e.g.
/// `2026-11-25T06:00:01.123456789Z`.
pub fn utc(ns: u64) -> String {
    let secs = ns / 1_000_000_000;
    let (days, rem) = (secs / 86_400, secs % 86_400);
    let (y, m, d) = civil_from_days(days as i64);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{:09}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60,
        ns % 1_000_000_000
    )
}

/// The proleptic Gregorian (year, month, day) of `days` since 1970-01-01: H. Hinnant's
/// `civil_from_days` ("chrono-Compatible Low-Level Date Algorithms"). Hand-written: a date
/// crate for one formatting call is more than this.
fn civil_from_days(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against dates computed independently (`date -u -d @SECONDS`).
    #[test]
    fn utc_matches_known_dates() {
        assert_eq!(utc(0), "1970-01-01T00:00:00.000000000Z");
        // date -u -d @951782400: Tue Feb 29 00:00:00 UTC 2000 (a leap day of a 400-year).
        assert_eq!(
            utc(951_782_400_000_000_001),
            "2000-02-29T00:00:00.000000001Z"
        );
        // date -u -d @1795935601: Sun Nov 29 07:00:01 UTC 2026.
        assert_eq!(
            utc(1_795_935_601_500_000_000),
            "2026-11-29T07:00:01.500000000Z"
        );
        // date -u -d @4107542399: Sun Feb 28 23:59:59 UTC 2100 (not a leap year).
        assert_eq!(
            utc(4_107_542_399_000_000_000),
            "2100-02-28T23:59:59.000000000Z"
        );
    }

    #[test]
    fn the_metadata_round_trips_and_shifts_times() {
        let clock = WallClock {
            realtime_ns: 1_795_935_601_000_000_000,
            monotonic_ns: 35_000_000_000_000,
        };
        assert_eq!(WallClock::from_metadata(&clock.metadata()), Some(clock));
        assert_eq!(
            clock.unix_ns(35_000_000_000_000 + 7),
            1_795_935_601_000_000_007
        );
        assert_eq!(
            clock.unix_ns(0),
            1_795_935_601_000_000_000 - 35_000_000_000_000
        );
        let mut bad = clock.metadata();
        bad.insert("realtime_ns".into(), "x".into());
        assert_eq!(WallClock::from_metadata(&bad), None);
    }
}
