//! From raw samples to the per-axis SI series the Allan analysis reads, and how irregular
//! sampling is handled.
//!
//! The thesis recordings are snapshots of the sensor's output registers polled by a Python loop:
//! intervals are about 5.5 ms with jitter (never below 0.9x the median, sometimes 1.5-2.5x) and
//! a few longer gaps (up to 1.36 s). The sensor samples internally at 1 kHz, so each snapshot
//! is one sensor sample whatever the jitter. The analysis therefore treats the samples of a
//! gap-free stretch as a uniform series with the stretch's *mean* interval (so that a cluster of
//! `m` samples spans `m` mean intervals, which is right on average whatever the jitter):
//! - an interval longer than `gap_factor` median intervals (or a sample flagged
//!   `GAP_BEFORE` / with `lost_before > 0`) is counted as a gap;
//! - a gap longer than `split_factor` median intervals splits the record into segments, and
//!   the Allan variance pools the segments (clusters never straddle a split);
//! - shorter gaps are bridged: only cluster pairs that contain one see a slightly longer time
//!   span, which matters only for slow noise at cluster times comparable to the gap, where
//!   white noise dominates.

use std::ops::Range;

use ipc_types::{RawImuSample, raw_flags};
use serde::{Deserialize, Serialize};

use crate::repair::{RepeatReport, is_repeat};

/// Intervals the median interval is taken from at most.
const MEDIAN_SUBSAMPLE: usize = 1 << 20;

/// Fewest samples an analysis accepts.
pub const MIN_SAMPLES: usize = 32;

/// How intervals are classified (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GapPolicy {
    /// An interval longer than this many median intervals is a gap.
    pub gap_factor: f64,
    /// A gap longer than this many median intervals splits the record.
    pub split_factor: f64,
}

impl Default for GapPolicy {
    /// Gaps beyond 2 median intervals, splits beyond 10 (about 55 ms in the thesis files).
    fn default() -> Self {
        Self {
            gap_factor: 2.0,
            split_factor: 10.0,
        }
    }
}

/// The sampling of a recording as the analysis sees it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Median interval between samples, s (of at most 2^20 evenly spread intervals).
    pub median_interval_s: f64,
    /// Mean interval within segments (bridged gaps included), s: the analysis' `tau0`.
    pub mean_interval_s: f64,
    /// Intervals classified as gaps (bridged or splitting).
    pub gaps: usize,
    /// Gaps that split the record.
    pub splits: usize,
    /// Longest interval, s.
    pub longest_interval_s: f64,
    /// Gap-free segments as half-open sample index ranges `[start, end)`.
    pub segments: Vec<(usize, usize)>,
    /// Time from the first to the last sample, s.
    pub duration_s: f64,
}

impl Timing {
    /// The segments as ranges.
    pub fn segment_ranges(&self) -> Vec<Range<usize>> {
        self.segments.iter().map(|&(a, b)| a..b).collect()
    }

    /// Length of the longest segment, samples.
    pub fn longest_segment(&self) -> usize {
        self.segments.iter().map(|&(a, b)| b - a).max().unwrap_or(0)
    }
}

/// Why a recording cannot be analysed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SeriesError {
    /// Too few samples.
    #[error("{found} samples; the Allan analysis needs at least {MIN_SAMPLES}")]
    TooShort {
        /// Samples in the recording.
        found: usize,
    },
    /// Sample times do not strictly increase.
    #[error("sample {index} (seq {seq}): time {t_ns} ns does not follow {previous_ns} ns")]
    TimeNotIncreasing {
        /// Index of the offending sample.
        index: usize,
        /// Its sequence number.
        seq: u64,
        /// Its `stamps.sample_ns`.
        t_ns: u64,
        /// The previous sample's `stamps.sample_ns`.
        previous_ns: u64,
    },
    /// A value is not finite or beyond the part's bounds (the stream contract's check,
    /// [`ipc_types::limits::check_raw`]).
    #[error("sample {index} (seq {seq}): {bad}")]
    NotFinite {
        /// Index of the offending sample.
        index: usize,
        /// Its sequence number.
        seq: u64,
        /// The field, its value and the bound.
        bad: ipc_types::limits::OutOfBounds,
    },
}

/// Classifies the intervals of a recording and finds its gap-free segments.
pub fn timing(samples: &[RawImuSample], policy: &GapPolicy) -> Result<Timing, SeriesError> {
    check_times(samples)?;
    let times: Vec<u64> = samples.iter().map(|s| s.stamps.sample_ns).collect();
    let losses: Vec<(usize, u32)> = samples
        .iter()
        .enumerate()
        .filter_map(|(i, s)| loss(s).map(|lost| (i, lost)))
        .collect();
    Ok(timing_of(&times, &losses, policy))
}

/// Errors unless there are enough samples and their times strictly increase.
fn check_times(samples: &[RawImuSample]) -> Result<(), SeriesError> {
    if samples.len() < MIN_SAMPLES {
        return Err(SeriesError::TooShort {
            found: samples.len(),
        });
    }
    for (index, pair) in samples.windows(2).enumerate() {
        let (previous_ns, t_ns) = (pair[0].stamps.sample_ns, pair[1].stamps.sample_ns);
        if t_ns <= previous_ns {
            return Err(SeriesError::TimeNotIncreasing {
                index: index + 1,
                seq: pair[1].seq,
                t_ns,
                previous_ns,
            });
        }
    }
    Ok(())
}

/// Samples lost before `s` when it is flagged (`GAP_BEFORE` or `lost_before > 0`).
fn loss(s: &RawImuSample) -> Option<u32> {
    (s.flags & raw_flags::GAP_BEFORE != 0 || s.lost_before > 0).then_some(s.lost_before)
}

/// [`timing`] from strictly increasing times (ns, at least two) and the flagged losses
/// `(index, samples lost before it)`, sorted by index.
fn timing_of(times: &[u64], losses: &[(usize, u32)], policy: &GapPolicy) -> Timing {
    // The median of at most MEDIAN_SUBSAMPLE evenly spread intervals (exact for shorter
    // records; a long record's sampling does not change along it fast enough to matter).
    let stride = (times.len() - 1).div_ceil(MEDIAN_SUBSAMPLE).max(1);
    let mut sorted: Vec<u64> = times
        .windows(2)
        .step_by(stride)
        .map(|p| p[1] - p[0])
        .collect();
    let mid = sorted.len() / 2;
    let median = *sorted.select_nth_unstable(mid).1 as f64 * 1e-9;

    let mut gaps = 0;
    let mut splits = 0;
    let mut segments = Vec::new();
    let mut start = 0;
    let (mut inside_time, mut inside_intervals) = (0.0, 0usize);
    let mut longest: f64 = 0.0;
    let mut flagged = losses.iter().peekable();
    for (k, pair) in times.windows(2).enumerate() {
        let dt = (pair[1] - pair[0]) as f64 * 1e-9;
        longest = longest.max(dt);
        let lost = match flagged.peek() {
            Some(&&(index, lost)) if index == k + 1 => {
                flagged.next();
                Some(lost)
            }
            _ => None,
        };
        let periods = (dt / median).max(lost.map_or(0.0, |l| f64::from(l) + 1.0));
        if lost.is_some() || periods > policy.gap_factor {
            gaps += 1;
        }
        if periods > policy.split_factor {
            splits += 1;
            segments.push((start, k + 1));
            start = k + 1;
        } else {
            inside_time += dt;
            inside_intervals += 1;
        }
    }
    segments.push((start, times.len()));
    let mean = if inside_intervals > 0 {
        inside_time / inside_intervals as f64
    } else {
        median
    };
    Timing {
        median_interval_s: median,
        mean_interval_s: mean,
        gaps,
        splits,
        longest_interval_s: longest,
        segments,
        duration_s: (times[times.len() - 1] - times[0]) as f64 * 1e-9,
    }
}

/// A recording split into per-axis columns in one pass (records of millions of samples make
/// every pass over the samples count).
#[derive(Debug, Clone, PartialEq)]
pub struct Columns {
    /// `stamps.sample_ns` of every sample.
    pub times_ns: Vec<u64>,
    /// `(index, samples lost before it)` of the samples flagged `GAP_BEFORE` or with
    /// `lost_before > 0`.
    pub losses: Vec<(usize, u32)>,
    /// Counts per axis: accelerometer x, y, z, then gyro x, y, z when every sample has it.
    pub counts: Vec<Vec<i16>>,
    /// The same axes in SI units (m/s^2 with the given gravity, rad/s).
    pub values: Vec<Vec<f64>>,
    /// Repeated samples (see [`crate::repair::count_repeats`]).
    pub repeats: RepeatReport,
}

impl Columns {
    /// Splits the samples; errors as [`timing`] and [`channels`] do.
    pub fn new(samples: &[RawImuSample], gravity_mps2: f64) -> Result<Self, SeriesError> {
        if samples.len() < MIN_SAMPLES {
            return Err(SeriesError::TooShort {
                found: samples.len(),
            });
        }
        // The gyro columns are filled on a second thread (fresh memory costs page faults, which
        // then run on both cores), and dropped when a sample lacks the gyro.
        let n = samples.len();
        let with_gyro = samples[0].flags & raw_flags::GYRO_VALID != 0;
        std::thread::scope(|scope| {
            let gyro = with_gyro.then(|| scope.spawn(|| gyro_columns(samples)));
            let mut columns = Self {
                times_ns: Vec::with_capacity(n),
                losses: Vec::new(),
                counts: (0..3).map(|_| Vec::with_capacity(n)).collect(),
                // One spare element: the Allan analysis turns them into cumulative sums in place.
                values: (0..3).map(|_| Vec::with_capacity(n + 1)).collect(),
                repeats: RepeatReport::default(),
            };
            let mut run = 0;
            let mut previous: Option<&RawImuSample> = None;
            for (index, s) in samples.iter().enumerate() {
                if let Some(p) = previous
                    && s.stamps.sample_ns <= p.stamps.sample_ns
                {
                    return Err(SeriesError::TimeNotIncreasing {
                        index,
                        seq: s.seq,
                        t_ns: s.stamps.sample_ns,
                        previous_ns: p.stamps.sample_ns,
                    });
                }
                if let Err(bad) = check_values(s) {
                    return Err(SeriesError::NotFinite {
                        index,
                        seq: s.seq,
                        bad,
                    });
                }
                columns.times_ns.push(s.stamps.sample_ns);
                if let Some(lost) = loss(s) {
                    columns.losses.push((index, lost));
                }
                for a in 0..3 {
                    columns.counts[a].push(s.accel_counts[a]);
                    columns.values[a].push(s.accel_g[a] * gravity_mps2);
                }
                if previous.is_some_and(|p| is_repeat(p, s)) {
                    columns.repeats.repeats += 1;
                    run += 1;
                    columns.repeats.longest_run = columns.repeats.longest_run.max(run);
                } else {
                    run = 0;
                }
                previous = Some(s);
            }
            if let Some((counts, values)) =
                gyro.and_then(|h| h.join().expect("the gyro columns do not panic"))
            {
                columns.counts.extend(counts);
                columns.values.extend(values);
            }
            Ok(columns)
        })
    }

    /// The sampling (see [`timing`]).
    pub fn timing(&self, policy: &GapPolicy) -> Timing {
        timing_of(&self.times_ns, &self.losses, policy)
    }

    /// The SI columns as channels (consumes the columns).
    pub fn into_channels(self) -> Vec<Channel> {
        self.values
            .into_iter()
            .enumerate()
            .map(|(k, values)| Channel {
                sensor: if k < 3 { Sensor::Accel } else { Sensor::Gyro },
                axis: k % 3,
                values,
            })
            .collect()
    }
}

/// Counts and SI values per axis.
type AxisColumns = (Vec<Vec<i16>>, Vec<Vec<f64>>);

/// The gyro's counts and values (rad/s) per axis, or `None` when a sample lacks the gyro.
fn gyro_columns(samples: &[RawImuSample]) -> Option<AxisColumns> {
    let n = samples.len();
    let mut counts: Vec<Vec<i16>> = (0..3).map(|_| Vec::with_capacity(n)).collect();
    let mut values: Vec<Vec<f64>> = (0..3).map(|_| Vec::with_capacity(n + 1)).collect();
    for s in samples {
        if s.flags & raw_flags::GYRO_VALID == 0 {
            return None;
        }
        for a in 0..3 {
            counts[a].push(s.gyro_counts[a]);
            values[a].push(s.gyro_dps[a].to_radians());
        }
    }
    Some((counts, values))
}

/// Which sensor a channel comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sensor {
    /// Accelerometer: specific force, m/s^2.
    Accel,
    /// Gyroscope: angular rate, rad/s.
    Gyro,
}

impl Sensor {
    /// The SI unit of the channel's values.
    pub fn unit(self) -> &'static str {
        match self {
            Self::Accel => "m/s^2",
            Self::Gyro => "rad/s",
        }
    }
}

/// Axis names, index 0..3.
pub const AXES: [&str; 3] = ["x", "y", "z"];

/// One axis of one sensor as a series in SI units (sensor frame).
#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    /// The sensor.
    pub sensor: Sensor,
    /// 0, 1, 2 for x, y, z.
    pub axis: usize,
    /// Values in m/s^2 (accelerometer, g times `gravity_mps2`) or rad/s (gyro).
    pub values: Vec<f64>,
}

/// Converts samples to SI channels: accelerometer always, gyro when every sample has
/// `GYRO_VALID`. `gravity_mps2` converts g to m/s^2. Errors on a non-finite value.
pub fn channels(samples: &[RawImuSample], gravity_mps2: f64) -> Result<Vec<Channel>, SeriesError> {
    check_finite(samples)?;
    let gyro = has_gyro(samples);
    let axes = if gyro { 6 } else { 3 };
    let mut values: Vec<Vec<f64>> = (0..axes)
        .map(|_| Vec::with_capacity(samples.len()))
        .collect();
    for s in samples {
        for (a, column) in values.iter_mut().enumerate() {
            column.push(if a < 3 {
                s.accel_g[a] * gravity_mps2
            } else {
                s.gyro_dps[a - 3].to_radians()
            });
        }
    }
    Ok(values
        .into_iter()
        .enumerate()
        .map(|(k, values)| Channel {
            sensor: if k < 3 { Sensor::Accel } else { Sensor::Gyro },
            axis: k % 3,
            values,
        })
        .collect())
}

/// Errors on the first accelerometer value, or gyro value of a sample with `GYRO_VALID`, that is
/// not finite or beyond the part's bounds.
fn check_finite(samples: &[RawImuSample]) -> Result<(), SeriesError> {
    for (index, s) in samples.iter().enumerate() {
        if let Err(bad) = check_values(s) {
            return Err(SeriesError::NotFinite {
                index,
                seq: s.seq,
                bad,
            });
        }
    }
    Ok(())
}

/// The stream contract's value check of a sample (gyro fields only with `GYRO_VALID`).
fn check_values(s: &RawImuSample) -> Result<(), ipc_types::limits::OutOfBounds> {
    let gyro = s.flags & raw_flags::GYRO_VALID != 0;
    ipc_types::limits::check_raw(&s.accel_g, gyro.then_some(&s.gyro_dps), None)
}

/// Whether every sample holds a gyro measurement.
pub fn has_gyro(samples: &[RawImuSample]) -> bool {
    !samples.is_empty() && samples.iter().all(|s| s.flags & raw_flags::GYRO_VALID != 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(times_ms: &[f64]) -> Vec<RawImuSample> {
        times_ms
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                let mut s = RawImuSample {
                    seq: i as u64,
                    ..Default::default()
                };
                s.stamps.sample_ns = (t * 1e6).round() as u64;
                s
            })
            .collect()
    }

    #[test]
    fn classifies_gaps_and_splits() {
        // 5 ms sampling with a 12 ms interval (gap, bridged) and a 100 ms one (split).
        let mut t: Vec<f64> = (0..40).map(|i| i as f64 * 5.0).collect();
        for v in &mut t[10..] {
            *v += 7.0;
        }
        for v in &mut t[25..] {
            *v += 95.0;
        }
        let timing = timing(&at(&t), &GapPolicy::default()).unwrap();
        assert!((timing.median_interval_s - 0.005).abs() < 1e-12);
        assert_eq!(timing.gaps, 2);
        assert_eq!(timing.splits, 1);
        assert_eq!(timing.segments, vec![(0, 25), (25, 40)]);
        // Inside segments: 38 intervals spanning 38 * 5 + 7 ms.
        assert!((timing.mean_interval_s - (38.0 * 5.0 + 7.0) / 38.0 * 1e-3).abs() < 1e-12);
        assert!((timing.longest_interval_s - 0.1).abs() < 1e-12);
        assert!((timing.duration_s - (39.0 * 5.0 + 102.0) * 1e-3).abs() < 1e-12);
    }

    #[test]
    fn flagged_losses_count_as_gaps() {
        let t: Vec<f64> = (0..40).map(|i| i as f64 * 5.0).collect();
        let mut samples = at(&t);
        samples[7].flags |= raw_flags::GAP_BEFORE;
        samples[7].lost_before = 1;
        samples[30].lost_before = 20;
        let timing = timing(&samples, &GapPolicy::default()).unwrap();
        assert_eq!((timing.gaps, timing.splits), (2, 1));
        assert_eq!(timing.segments, vec![(0, 30), (30, 40)]);
    }

    #[test]
    fn rejects_bad_input() {
        let t: Vec<f64> = (0..40).map(|i| i as f64 * 5.0).collect();
        let mut samples = at(&t);
        samples[12].stamps.sample_ns = samples[11].stamps.sample_ns;
        let err = timing(&samples, &GapPolicy::default()).unwrap_err();
        assert!(matches!(
            err,
            SeriesError::TimeNotIncreasing {
                index: 12,
                seq: 12,
                ..
            }
        ));
        assert_eq!(
            timing(&samples[..5], &GapPolicy::default()).unwrap_err(),
            SeriesError::TooShort { found: 5 }
        );
        let mut samples = at(&t);
        samples[3].accel_g[2] = f64::NAN;
        let err = channels(&samples, 9.8).unwrap_err();
        assert_eq!(
            err.to_string(),
            "sample 3 (seq 3): accel_g[2] = NaN is not finite"
        );
    }

    #[test]
    fn converts_to_si() {
        let t: Vec<f64> = (0..40).map(|i| i as f64 * 5.0).collect();
        let mut samples = at(&t);
        for s in &mut samples {
            s.accel_g = [0.5, -1.0, 2.0];
            s.gyro_dps = [180.0, 0.0, -90.0];
        }
        let accel_only = channels(&samples, 9.8).unwrap();
        assert_eq!(accel_only.len(), 3);
        assert_eq!(accel_only[1].values[0], -9.8);
        for s in &mut samples {
            s.flags |= raw_flags::GYRO_VALID;
        }
        let all = channels(&samples, 9.8).unwrap();
        assert_eq!(all.len(), 6);
        assert_eq!(all[3].sensor, Sensor::Gyro);
        assert!((all[3].values[5] - std::f64::consts::PI).abs() < 1e-15);
        assert!((all[5].values[5] + std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    }
}
