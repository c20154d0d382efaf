//! Full-scale ranges and clipping: the part of the stream contract that says which values a
//! part could not measure because they lay beyond its range.
//!
//! An axis whose reading sits at the end of its full-scale range is **clipped**: the true
//! value was at least that large, by an unknown amount. Every reader knows each axis's range:
//! - a live part from its registers (the MPU-9250's `ACCEL_CONFIG`/`GYRO_CONFIG`
//!   `FS_SEL` bits, register map RM-MPU-9250A-00 rev 1.6, registers 27-28; the Linux
//!   `inv_mpu6050` driver's `inv_mpu6050_set_full_scale`/`_accel_scale` tables): the driver
//!   flags an axis whose 16-bit output is at -32768 or +32767 ([`clipped_axes_from_counts`]);
//! - a file from the caller ([`Ranges`] from `--accel-range-g` and `--gyro-range-dps`), else
//!   inferred from its samples ([`infer_range`]: several runs of consecutive samples stuck at
//!   the file's extreme |value|, as a clipping logger leaves them).
//!
//! A clipped axis is marked on the raw sample: `raw_flags::SATURATED` and the axis's
//! `raw_flags::saturated_axis` bit ([`mark_clipped`]); the calibration stage turns it into
//! `corrected_flags::CLIPPED`. Units: g and deg/s (raw values). Axis index 0-2: accelerometer
//! x, y, z; 3-5: gyroscope x, y, z (sensor frame).

use crate::{RawImuSample, raw_flags};

/// Axis names in the order of the axis index.
pub const AXES: [&str; 6] = ["ax", "ay", "az", "gx", "gy", "gz"];

/// A reading within this fraction of the range's end is at it: a 16-bit ADC's largest positive
/// output is `32767 / 32768` of the range, and a logger that scales its counts may round;
/// 1/4096 is eight counts.
pub const END_FRACTION: f64 = 1.0 / 4096.0;

/// Shortest run of consecutive samples stuck at the extreme that [`infer_range`] counts.
pub const STUCK_RUN: usize = 3;

/// Runs [`infer_range`] needs before it takes the extreme for the range: a smooth peak's
/// largest value may repeat once or twice; several flat tops at the same value do not happen
/// unless something clipped them.
pub const STUCK_RUNS: usize = 2;

/// Smallest accelerometer range [`infer_range`] takes, g: no MEMS part has a range below
/// +-2 g, and a file that never leaves 1 g (at rest) repeats its largest value often.
pub const MIN_ACCEL_RANGE_G: f64 = 1.5;

/// Smallest gyroscope range [`infer_range`] takes, deg/s (the smallest common range is
/// +-125 deg/s).
pub const MIN_GYRO_RANGE_DPS: f64 = 100.0;

/// Where a range came from (for reports).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RangeSource {
    /// Not known: nothing is marked but what the sample's own flags say.
    #[default]
    Unknown,
    /// Given by the caller (a command-line flag).
    Given,
    /// Inferred from samples stuck at the file's extreme value.
    Inferred,
}

/// One sensor's full-scale range and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Range {
    /// The range, g or deg/s (`None`: unknown).
    pub value: Option<f64>,
    /// Where it came from.
    pub source: RangeSource,
}

impl Range {
    /// A range given by the caller.
    pub fn given(value: Option<f64>) -> Self {
        Self {
            value,
            source: if value.is_some() {
                RangeSource::Given
            } else {
                RangeSource::Unknown
            },
        }
    }
}

/// The full-scale ranges of a part's accelerometer (g) and gyroscope (deg/s), the same on
/// each of a sensor's axes (as on the MPU-9250).
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Ranges {
    /// Accelerometer, g.
    pub accel_g: Range,
    /// Gyroscope, deg/s.
    pub gyro_dps: Range,
}

impl Ranges {
    /// The `raw_flags::saturated_axis` bits of the axes of `raw` at the end of their range.
    pub fn clipped_axes(&self, raw: &RawImuSample) -> u16 {
        let mut bits = 0;
        let sensors = [(self.accel_g.value, &raw.accel_g, 0)];
        let gyro = (raw.flags & raw_flags::GYRO_VALID != 0).then_some((
            self.gyro_dps.value,
            &raw.gyro_dps,
            3,
        ));
        for (range, values, first) in sensors.into_iter().chain(gyro) {
            let Some(range) = range else { continue };
            for (i, v) in values.iter().enumerate() {
                if at_end(*v, range) {
                    bits |= raw_flags::saturated_axis(first + i);
                }
            }
        }
        bits
    }
}

/// Whether `value` sits at the end of `range` (within [`END_FRACTION`]).
pub fn at_end(value: f64, range: f64) -> bool {
    value.abs() >= range * (1.0 - END_FRACTION)
}

/// The `raw_flags::saturated_axis` bits of the axes whose 16-bit output is at either end
/// (-32768 or +32767): what a part's own counts say, whatever its range.
pub fn clipped_axes_from_counts(raw: &RawImuSample) -> u16 {
    let gyro = raw.flags & raw_flags::GYRO_VALID != 0;
    let counts = raw.accel_counts.iter().chain(&raw.gyro_counts);
    counts
        .enumerate()
        .filter(|&(i, &c)| (i < 3 || gyro) && (c == i16::MAX || c == i16::MIN))
        .fold(0, |bits, (i, _)| bits | raw_flags::saturated_axis(i))
}

/// Marks the clipped axes `bits` on `raw` (with `SATURATED` when any).
pub fn mark_clipped(raw: &mut RawImuSample, bits: u16) {
    if bits != 0 {
        raw.flags |= raw_flags::SATURATED | (bits & raw_flags::SATURATED_AXES);
    }
}

/// The range a sensor's recording was clipped at, if it shows one: the largest |value| of
/// any axis, when at least [`STUCK_RUNS`] runs of [`STUCK_RUN`] or more consecutive samples of
/// one axis sit at it (within [`END_FRACTION`]) and it is at least `min_range`. `axes` yields
/// each sample's three axes, in time order.
pub fn infer_range(axes: &[[f64; 3]], min_range: f64) -> Option<f64> {
    let extreme = axes
        .iter()
        .flatten()
        .map(|v| v.abs())
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    if extreme < min_range {
        return None;
    }
    let mut runs = 0;
    for axis in 0..3 {
        let mut len = 0;
        for s in axes {
            if at_end(s[axis], extreme) {
                len += 1;
                if len == STUCK_RUN {
                    runs += 1;
                }
            } else {
                len = 0;
            }
        }
    }
    (runs >= STUCK_RUNS).then_some(extreme)
}

/// Samples clipped, per axis and in all.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Clipping {
    /// Samples with any axis clipped.
    pub samples: u64,
    /// Samples clipped on each axis ([`AXES`]).
    pub per_axis: [u64; 6],
}

impl Clipping {
    /// Counts a sample with the raw flags `flags`.
    pub fn count(&mut self, flags: u16) {
        if flags & raw_flags::SATURATED == 0 {
            return;
        }
        self.samples += 1;
        for (i, n) in self.per_axis.iter_mut().enumerate() {
            *n += u64::from(flags & raw_flags::saturated_axis(i) != 0);
        }
    }

    /// e.g. `ax 0, ay 0, az 3, gx 0, gy 120, gz 0`.
    pub fn per_axis_text(&self) -> String {
        AXES.iter()
            .zip(self.per_axis)
            .map(|(a, n)| format!("{a} {n}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(accel_g: [f64; 3], gyro_dps: [f64; 3]) -> RawImuSample {
        RawImuSample {
            accel_g,
            gyro_dps,
            flags: raw_flags::GYRO_VALID,
            ..Default::default()
        }
    }

    #[test]
    fn given_ranges_mark_the_axes_at_their_ends() {
        let r = Ranges {
            accel_g: Range::given(Some(2.0)),
            gyro_dps: Range::given(Some(250.0)),
        };
        let s = sample([0.1, -2.0, 1.0], [249.99, 10.0, -250.0]);
        let bits = r.clipped_axes(&s);
        assert_eq!(
            bits,
            raw_flags::saturated_axis(1)
                | raw_flags::saturated_axis(3)
                | raw_flags::saturated_axis(5)
        );
        let s = sample([0.1, -1.9, 1.0], [249.0, 10.0, -20.0]);
        assert_eq!(r.clipped_axes(&s), 0);
        let mut clipping = Clipping::default();
        let mut marked = s;
        mark_clipped(&mut marked, bits);
        clipping.count(marked.flags);
        clipping.count(s.flags);
        assert_eq!(clipping.samples, 1);
        assert_eq!(clipping.per_axis, [0, 1, 0, 1, 0, 1]);
    }

    #[test]
    fn counts_at_the_ends_are_clipped_whatever_the_range() {
        let mut s = sample([0.0; 3], [0.0; 3]);
        s.accel_counts = [0, i16::MIN, 5];
        s.gyro_counts = [i16::MAX, 0, 0];
        let bits = clipped_axes_from_counts(&s);
        assert_eq!(
            bits,
            raw_flags::saturated_axis(1) | raw_flags::saturated_axis(3)
        );
    }

    #[test]
    fn a_range_is_inferred_from_flat_tops_only() {
        // A swing peaking at 300 deg/s, clipped at 250 twice: inferred.
        let mut axes: Vec<[f64; 3]> = (0..400)
            .map(|k| [0.0, 300.0 * (k as f64 * 0.05).sin(), 1.0])
            .collect();
        assert_eq!(infer_range(&axes, MIN_GYRO_RANGE_DPS), None);
        for a in &mut axes {
            a[1] = a[1].clamp(-250.0, 250.0);
        }
        assert_eq!(infer_range(&axes, MIN_GYRO_RANGE_DPS), Some(250.0));
        // A recording at rest repeats its largest value but is no range.
        let rest: Vec<[f64; 3]> = (0..400)
            .map(|k| [0.0, 0.0, 1.0 + (k % 2) as f64 * 1e-3])
            .collect();
        assert_eq!(infer_range(&rest, MIN_ACCEL_RANGE_G), None);
    }
}
