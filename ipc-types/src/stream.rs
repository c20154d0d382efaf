//! The stream contract: what a stream of IMU samples promises, and the one place each promise
//! is checked. The file readers, the calibration stage, the odometry session and stage, the
//! gyroscope calibration and the noise series call these functions rather than writing the
//! rules again.
//!
//! A stream of samples (raw or corrected) promises:
//! - **Values**: every value finite and within the part's bounds ([`crate::limits`]: raw
//!   values in sensor units, [`check_corrected`] for calibrated ones).
//! - **A time line**: sample times (ns) strictly increase. The stream's nominal period is
//!   learned from the stream itself ([`TimeLine`]: the median of its first [`LEARN_STEPS`]
//!   steps). A step longer than [`HOLE_PERIODS`] nominal periods and [`HOLE_MIN_S`] is a
//!   **hole**: samples are missing though nothing marked them (the sequence numbers run on,
//!   no `GAP_BEFORE`). A hole is a gap like a marked one: what happened in it was not
//!   observed, and every estimate across it widens its 1-sigma as an unobserved interval's
//!   (`odometry::eskf::Eskf::missed`). A step longer than [`crate::limits::MAX_STEP_S`] is
//!   not a hole but a broken time base: a reader refuses it, a live stage drops the sample
//!   (and a second such step in a row is a new session, below).
//! - **Sequence numbers**: they increase by one per sample; a skip, `lost_before > 0` or
//!   `raw_flags::GAP_BEFORE` is a marked gap ([`Continuity::Gap`]).
//! - **Sessions**: a sensor session is one power-on of one part on one clock. A new session
//!   starts when ([`continuity`]) the sequence number does not increase (a restarted publisher
//!   numbering from 0, another part), or after a step beyond
//!   [`crate::limits::MAX_STEP_S`] that the next sample confirms (a new time base; a single
//!   such step is a corrupted stamp and is dropped). Nothing else starts one: a restarted
//!   acquisition that goes on numbering its samples and stamping them on the same clock
//!   continues its session, and its restart is a hole (or a marked gap). The calibration
//!   stage decides this and marks the first corrected sample of every new session after the
//!   first with [`crate::corrected_flags::NEW_SESSION`]; consumers of corrected samples (the
//!   odometry) follow the mark and do not decide it again.
//! - **Settling**: a provisional corrected sample's verdict (`ZERO_STATE`, `DETECTOR_READY`,
//!   `zs_*`) is final once a later sample settles it ([`settled_by`]).
//!
//! - **Trust**: a value at the end of the part's full-scale range is clipped ([`range`]); a
//!   value no platform of the profile makes is implausible ([`plausible`]). Both are flagged
//!   and counted, and the filter does not take them for measurements.
//!
//! Units: nanoseconds for times, seconds where a name ends in `_s`.

pub mod plausible;
pub mod range;

use crate::limits::{self, OutOfBounds};
use crate::{CorrectedImuSample, corrected_flags};

/// A hole is a step longer than this many nominal periods (and than [`HOLE_MIN_S`]). Real
/// loggers jitter by a fraction of a period and drop single samples now and then (two periods:
/// one sample lost, already within what the readings on either side bound).
pub const HOLE_PERIODS: f64 = 3.0;

/// Shortest hole, s: shorter steps are never reported as holes. Loggers that timestamp on a
/// busy host (ROS at 20-30 Hz: the F1TENTH logs of docs/real-data.md) step by up to 122 ms
/// with a sample or two missing now and then, which the readings on either side bound: an
/// unobserved 0.2 s widens a ground robot's position 1-sigma by 8 mm (`Eskf::missed` with its
/// default manoeuvre, `a t^2 / 2` scaled by `t / 0.5 s`), and cutting the rest detector's
/// batch there costs more than it gives (the F1TENTH DS1 run went from 2.4 % to 9.5 % of its
/// distance with a 50 ms threshold).
pub const HOLE_MIN_S: f64 = 0.2;

/// [`HOLE_MIN_S`] in nanoseconds.
pub const HOLE_MIN_NS: u64 = 200_000_000;

/// Steps the nominal period is learned from: their median (a lost sample or two among them
/// does not move it).
pub const LEARN_STEPS: usize = 16;

/// Before the period is learned, a step is a hole only beyond this, ns (1 s: slower than any
/// IMU stream's period).
pub const UNLEARNED_HOLE_NS: u64 = 1_000_000_000;

/// What one sample's time is to the stream's time line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// The stream's first sample.
    First,
    /// A step within the stream's period (jitter included).
    Regular,
    /// A hole of `dt_ns` (see the module documentation).
    Hole {
        /// The step, ns.
        dt_ns: u64,
    },
    /// The same time as the previous sample.
    Repeat,
    /// Earlier than the previous sample.
    Back,
    /// Further after the previous sample than [`limits::MAX_STEP_NS`].
    Beyond,
}

/// The time line of one stream: the previous sample's time and the nominal period learned from
/// the steps so far (module documentation).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TimeLine {
    prev_ns: Option<u64>,
    learning: [u64; LEARN_STEPS],
    learned: usize,
    period_ns: Option<u64>,
}

impl TimeLine {
    /// What a sample at `t_ns` would be (nothing changes).
    pub fn step(&self, t_ns: u64) -> Step {
        let Some(prev) = self.prev_ns else {
            return Step::First;
        };
        match t_ns.cmp(&prev) {
            std::cmp::Ordering::Less => Step::Back,
            std::cmp::Ordering::Equal => Step::Repeat,
            std::cmp::Ordering::Greater => {
                let dt_ns = t_ns - prev;
                if dt_ns > limits::MAX_STEP_NS {
                    Step::Beyond
                } else if self.is_hole(dt_ns) {
                    Step::Hole { dt_ns }
                } else {
                    Step::Regular
                }
            }
        }
    }

    /// Whether a step of `dt_ns` is a hole on this time line.
    pub fn is_hole(&self, dt_ns: u64) -> bool {
        match self.period_ns {
            Some(p) => dt_ns > HOLE_MIN_NS && dt_ns as f64 > HOLE_PERIODS * p as f64,
            None => dt_ns > UNLEARNED_HOLE_NS,
        }
    }

    /// Takes a sample at `t_ns` as the newest (learning the period from regular steps).
    pub fn accept(&mut self, t_ns: u64) {
        if let Some(prev) = self.prev_ns
            && t_ns > prev
            && self.period_ns.is_none()
            && !self.is_hole(t_ns - prev)
        {
            self.learning[self.learned] = t_ns - prev;
            self.learned += 1;
            if self.learned == LEARN_STEPS {
                let mut steps = self.learning;
                steps.sort_unstable();
                self.period_ns = Some(steps[LEARN_STEPS / 2]);
            }
        }
        self.prev_ns = Some(t_ns);
    }

    /// Forgets the previous sample (a new session) but keeps the period learned.
    pub fn restart(&mut self) {
        self.prev_ns = None;
    }

    /// The previous sample's time, ns.
    pub fn prev_ns(&self) -> Option<u64> {
        self.prev_ns
    }

    /// The nominal period, ns, once learned.
    pub fn period_ns(&self) -> Option<u64> {
        self.period_ns
    }
}

/// Where a hole ends: the sample after it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct HoleAt {
    /// The sample's sequence number (from a text file: its row index).
    pub seq: u64,
    /// Its line, when it comes from a text file.
    pub line: Option<u64>,
    /// The sample's time, ns.
    pub t_ns: u64,
    /// The hole's length, ns.
    pub dt_ns: u64,
}

/// The holes of a stream: how many, how long in all, and the longest.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Holes {
    /// Holes seen.
    pub count: u64,
    /// Their total length, ns.
    pub total_ns: u64,
    /// The longest, and where it ends.
    pub longest: Option<HoleAt>,
    /// The first.
    pub first: Option<HoleAt>,
}

impl Holes {
    /// Counts a hole of `dt_ns` ending at sample `seq` at `t_ns`.
    pub fn record(&mut self, seq: u64, t_ns: u64, dt_ns: u64) {
        self.record_at(HoleAt {
            seq,
            line: None,
            t_ns,
            dt_ns,
        });
    }

    /// Counts the hole `at`.
    pub fn record_at(&mut self, at: HoleAt) {
        let dt_ns = at.dt_ns;
        self.count += 1;
        self.total_ns += dt_ns;
        self.first.get_or_insert(at);
        if self.longest.is_none_or(|l| dt_ns > l.dt_ns) {
            self.longest = Some(at);
        }
    }

    /// One line for a report, e.g. `2 holes in the time line (5.0 s in all; the longest 3.0
    /// s, ending at seq 1234, t 12.345 s)`, with the line instead of the seq where known;
    /// `None` without holes. `t0_ns` is the stream's start.
    pub fn describe(&self, t0_ns: u64) -> Option<String> {
        let l = self.longest?;
        let at = l
            .line
            .map_or_else(|| format!("seq {}", l.seq), |n| format!("line {n}"));
        Some(format!(
            "{} hole{} in the time line that nothing marked ({:.3} s in all; the longest {:.3} \
             s, ending at {}, t {:.3} s)",
            self.count,
            if self.count == 1 { "" } else { "s" },
            self.total_ns as f64 * 1e-9,
            l.dt_ns as f64 * 1e-9,
            at,
            l.t_ns.saturating_sub(t0_ns) as f64 * 1e-9
        ))
    }
}

/// Runs of raw samples that repeat the sample before them on every valid axis (accelerometer
/// and, where valid, gyroscope values exactly) for longer than a hole ([`TimeLine::is_hole`]):
/// a sensor that stopped updating while its reader went on reading it. A repeat or two is a
/// reader polling faster than the sensor updates, a zero-order hold (`calibrate::repair`
/// counts those and leaves them); a run as long as a hole is not: the corpus's TurtleBot (a
/// navX read by a RoboRIO) repeats one reading for 1.0 s while the robot turns by about 55
/// deg (docs/real-data.md, "Data the odometry must handle"). Counted as [`Holes`] (each run
/// once it ends, its length from its first sample to its last repeat, at its last repeat's
/// sequence number and time); the samples are not changed.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Freezes {
    /// The current run: the values it repeats, its first sample's time (ns) and its last
    /// repeat's sequence number and time (ns).
    run: Option<([f64; 6], u64, u64, u64)>,
    /// The runs longer than a hole that have ended.
    pub frozen: Holes,
}

impl Freezes {
    /// Takes the next raw sample (`seq`, `t_ns`, its accelerometer values `accel_g` and its
    /// gyroscope's `gyro_dps` where valid) on the time line `line` (its period decides what is
    /// as long as a hole).
    pub fn push(
        &mut self,
        line: &TimeLine,
        seq: u64,
        t_ns: u64,
        accel_g: [f64; 3],
        gyro_dps: Option<[f64; 3]>,
    ) {
        let [a0, a1, a2] = accel_g;
        let [g0, g1, g2] = gyro_dps.unwrap_or([0.0; 3]);
        let values = [a0, a1, a2, g0, g1, g2];
        if let Some(run) = self.run.as_mut().filter(|r| r.0 == values) {
            (run.2, run.3) = (seq, t_ns);
            return;
        }
        self.end(line);
        self.run = Some((values, t_ns, seq, t_ns));
    }

    /// One line for a report of the runs `frozen` counted, e.g. `1 run of samples repeating
    /// one reading on every axis for longer than a hole (1.013 s in all; the longest 1.013 s,
    /// ending at seq 169, t 3.650 s)`; `None` without runs. `t0_ns` is the stream's start.
    pub fn describe(frozen: &Holes, t0_ns: u64) -> Option<String> {
        let l = frozen.longest?;
        Some(format!(
            "{} run{} of samples repeating one reading on every axis for longer than a hole \
             ({:.3} s in all; the longest {:.3} s, ending at seq {}, t {:.3} s)",
            frozen.count,
            if frozen.count == 1 { "" } else { "s" },
            frozen.total_ns as f64 * 1e-9,
            l.dt_ns as f64 * 1e-9,
            l.seq,
            l.t_ns.saturating_sub(t0_ns) as f64 * 1e-9
        ))
    }

    /// Ends the current run (the stream's end, a gap, a new session): counted when as long as
    /// a hole on `line`.
    pub fn end(&mut self, line: &TimeLine) {
        if let Some((_, start, seq, last)) = self.run.take() {
            let dt_ns = last.saturating_sub(start);
            if dt_ns > 0 && line.is_hole(dt_ns) {
                self.frozen.record(seq, last, dt_ns);
            }
        }
    }
}

/// Measures the holes of a whole stream of sample times (`(seq, t_ns)` in order); steps that
/// do not increase or go beyond [`limits::MAX_STEP_NS`] are the readers' to refuse and are
/// skipped here.
pub fn holes_of(samples: impl IntoIterator<Item = (u64, u64)>) -> Holes {
    let mut line = TimeLine::default();
    let mut holes = Holes::default();
    for (seq, t_ns) in samples {
        if let Step::Hole { dt_ns } = line.step(t_ns) {
            holes.record(seq, t_ns, dt_ns);
        }
        line.accept(t_ns);
    }
    holes
}

/// How a sample continues the stream before it (module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Continuity {
    /// The stream's first sample, or the next one with nothing missing.
    Next,
    /// Samples are missing before it: marked (a skipped sequence number, `lost_before`,
    /// `GAP_BEFORE`) or a hole in the time line.
    Gap,
    /// A new sensor session starts with it.
    NewSession,
}

/// How a sample (`seq`, whether a gap is marked before it, and its time line `step`) continues
/// the previous sample `prev_seq` (`None`: the first). `beyond_confirmed`: a step beyond
/// [`limits::MAX_STEP_NS`] followed one already (a new time base). A step that does not increase
/// within a session, and a first step beyond the bound, are not continuities: the caller
/// refuses them before.
pub fn continuity(prev_seq: Option<u64>, seq: u64, marked_gap: bool, step: Step) -> Continuity {
    let Some(prev) = prev_seq else {
        return Continuity::Next;
    };
    if seq <= prev || step == Step::Beyond {
        Continuity::NewSession
    } else if seq != prev + 1 || marked_gap || matches!(step, Step::Hole { .. }) {
        Continuity::Gap
    } else {
        Continuity::Next
    }
}

/// The flags a settling sample decides for the provisional samples before it.
pub const VERDICT: u16 = corrected_flags::ZERO_STATE | corrected_flags::DETECTOR_READY;

/// How many of the `held` provisional samples before it `s` settles (0 for a provisional
/// sample): the newest ones; older ones were cut from their batch and are final as they are.
pub fn settled_by(s: &CorrectedImuSample, held: usize) -> usize {
    if s.flags & corrected_flags::PROVISIONAL != 0 {
        0
    } else {
        (s.settles as usize).min(held)
    }
}

/// Gives provisional sample `held` the verdict of the sample `s` that settles it; returns
/// whether its verdict flags changed.
pub fn settle(held: &mut CorrectedImuSample, s: &CorrectedImuSample) -> bool {
    let flags = (held.flags & !(VERDICT | corrected_flags::PROVISIONAL)) | (s.flags & VERDICT);
    let changed = flags & VERDICT != held.flags & VERDICT;
    held.flags = flags;
    held.zs_mean_mps2 = s.zs_mean_mps2;
    held.zs_std_mps2 = s.zs_std_mps2;
    changed
}

/// Largest calibrated specific force per axis, m/s^2: twice the raw bound
/// ([`limits::ACCEL_LIMIT_G`]) in standard gravities, room for any plausible calibration's
/// scale and bias.
pub const ACCEL_LIMIT_MPS2: f64 = 2.0 * limits::ACCEL_LIMIT_G * crate::units::STANDARD_GRAVITY_MPS2;

/// Largest calibrated angular rate per axis, rad/s: twice the raw bound
/// ([`limits::GYRO_LIMIT_DPS`]), as for [`ACCEL_LIMIT_MPS2`].
pub const GYRO_LIMIT_RPS: f64 = 2.0 * limits::GYRO_LIMIT_DPS * std::f64::consts::PI / 180.0;

/// A corrected sample the contract refuses; the message names the sample.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SampleError {
    /// A sample's time is not after the previous one's.
    #[error("sample seq {seq}: time {t_ns} ns is not after the previous sample's {prev_ns} ns")]
    TimeNotIncreasing {
        /// Sequence number of the offending sample.
        seq: u64,
        /// Its time.
        t_ns: u64,
        /// The previous sample's time.
        prev_ns: u64,
    },
    /// A value is not finite or beyond the calibrated bounds.
    #[error("sample seq {seq}: {bad}")]
    Value {
        /// Sequence number of the offending sample.
        seq: u64,
        /// The field, its value and the bound.
        bad: OutOfBounds,
    },
}

/// Checks the values of a corrected sample: finite, and within [`ACCEL_LIMIT_MPS2`] and
/// [`GYRO_LIMIT_RPS`] (a value beyond them would drive a filter's state to infinity and NaN).
pub fn check_corrected(s: &CorrectedImuSample) -> Result<(), SampleError> {
    const FIELDS: [[&str; 3]; 6] = [
        ["accel_mps2[0]", "accel_mps2[1]", "accel_mps2[2]"],
        ["gyro_rps[0]", "gyro_rps[1]", "gyro_rps[2]"],
        ["zs_mean_mps2[0]", "zs_mean_mps2[1]", "zs_mean_mps2[2]"],
        ["zs_std_mps2[0]", "zs_std_mps2[1]", "zs_std_mps2[2]"],
        [
            "refined_accel_mps2[0]",
            "refined_accel_mps2[1]",
            "refined_accel_mps2[2]",
        ],
        [
            "refined_gyro_rps[0]",
            "refined_gyro_rps[1]",
            "refined_gyro_rps[2]",
        ],
    ];
    let values = [
        &s.accel_mps2,
        &s.gyro_rps,
        &s.zs_mean_mps2,
        &s.zs_std_mps2,
        &s.refined_accel_mps2,
        &s.refined_gyro_rps,
    ];
    let bounds = [
        ACCEL_LIMIT_MPS2,
        GYRO_LIMIT_RPS,
        ACCEL_LIMIT_MPS2,
        ACCEL_LIMIT_MPS2,
        ACCEL_LIMIT_MPS2,
        GYRO_LIMIT_RPS,
    ];
    for ((v, f), limit) in values.into_iter().zip(&FIELDS).zip(bounds) {
        limits::check_axes(v, f, limit).map_err(|bad| SampleError::Value { seq: s.seq, bad })?;
    }
    Ok(())
}

/// Checks that a sample at `t_ns` comes after the previous one (`prev_ns`).
pub fn check_increasing(seq: u64, t_ns: u64, prev_ns: Option<u64>) -> Result<(), SampleError> {
    match prev_ns {
        Some(prev_ns) if t_ns <= prev_ns => {
            Err(SampleError::TimeNotIncreasing { seq, t_ns, prev_ns })
        }
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_period_is_learned_and_holes_are_measured_against_it() {
        // 100 Hz with 2 ms of jitter, one lost sample, a 3 s hole.
        let mut t = 0u64;
        let mut times = Vec::new();
        for k in 0..400u64 {
            t += 10_000_000 + (k % 3) * 1_000_000;
            if k == 100 {
                t += 10_000_000; // one sample lost: no hole
            }
            if k == 300 {
                t += 3_000_000_000;
            }
            times.push((k, t));
        }
        let holes = holes_of(times.iter().copied());
        assert_eq!(holes.count, 1);
        let l = holes.longest.unwrap();
        assert_eq!(l.seq, 300);
        assert!((l.dt_ns as f64 * 1e-9 - 3.012).abs() < 0.002, "{l:?}");
        let line = holes.describe(0).unwrap();
        assert!(line.contains("seq 300"), "{line}");
    }

    /// 50 Hz (the period learned from the first steps): runs of 2 and 3 repeats at rest are
    /// holds, not counted; a reading repeated from 3.64 s to 4.64 s (the TurtleBot's frozen
    /// second) is one run of 1.0 s, at its last repeat; a run still going at the stream's end
    /// counts once ended.
    #[test]
    fn a_reading_that_stops_changing_for_a_hole_is_counted() {
        let mut line = TimeLine::default();
        let mut freezes = Freezes::default();
        let value = |k: u64| [k as f64 * 1e-3, 0.0, 1.0];
        let feed = |line: &mut TimeLine, freezes: &mut Freezes, k: u64, a: [f64; 3]| {
            let t_ns = k * 20_000_000;
            freezes.push(line, k, t_ns, a, Some([0.1, -0.2, 0.3]));
            line.accept(t_ns);
        };
        for k in 0..300u64 {
            let v = match k {
                40..=42 => value(40),
                100..=101 => value(100),
                182..=232 => value(182),
                _ => value(k),
            };
            feed(&mut line, &mut freezes, k, v);
        }
        assert_eq!(freezes.frozen.count, 1, "{:?}", freezes.frozen);
        let run = freezes.frozen.longest.unwrap();
        assert_eq!(
            (run.seq, run.t_ns, run.dt_ns),
            (232, 4_640_000_000, 1_000_000_000)
        );
        for k in 300..320u64 {
            feed(&mut line, &mut freezes, k, value(300));
        }
        assert_eq!(freezes.frozen.count, 1);
        freezes.end(&line);
        assert_eq!(freezes.frozen.count, 2);
        assert_eq!(freezes.frozen.total_ns, 1_380_000_000);
    }

    #[test]
    fn the_session_rule() {
        let hole = Step::Hole { dt_ns: 1 };
        assert_eq!(continuity(None, 5, false, Step::First), Continuity::Next);
        assert_eq!(
            continuity(Some(5), 6, false, Step::Regular),
            Continuity::Next
        );
        assert_eq!(
            continuity(Some(5), 8, false, Step::Regular),
            Continuity::Gap
        );
        assert_eq!(continuity(Some(5), 6, true, Step::Regular), Continuity::Gap);
        assert_eq!(continuity(Some(5), 6, false, hole), Continuity::Gap);
        assert_eq!(
            continuity(Some(5), 0, false, Step::Regular),
            Continuity::NewSession
        );
        assert_eq!(
            continuity(Some(5), 6, false, Step::Beyond),
            Continuity::NewSession
        );
    }

    #[test]
    fn corrected_values_beyond_the_bounds_are_refused() {
        let mut s = CorrectedImuSample {
            accel_mps2: [0.0, 0.0, 9.81],
            ..Default::default()
        };
        assert_eq!(check_corrected(&s), Ok(()));
        s.gyro_rps[1] = f64::NAN;
        let e = check_corrected(&s).unwrap_err();
        assert!(e.to_string().contains("gyro_rps[1]"), "{e}");
        s.gyro_rps[1] = 0.0;
        s.accel_mps2[0] = 1e6;
        let e = check_corrected(&s).unwrap_err();
        assert!(e.to_string().contains("beyond"), "{e}");
    }
}
