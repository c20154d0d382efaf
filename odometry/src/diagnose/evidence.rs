//! The evidence a run gives: its rests (the specific force, angular rate and temperature the
//! sensor read while the odometry applied zero-velocity updates) and the motion between two
//! rests (the rotation the gyro carried from one rest's gravity direction to the next's).
//!
//! Units: specific force m/s^2, angular rate rad/s, sensor frame, as the calibration stage
//! publishes them (`CorrectedImuSample`); the gyro's correction `C` of the odometry
//! configuration is applied here as the odometry applies it (`omega = C w`).

use ipc_types::{CorrectedImuSample, OdometryState, corrected_flags, odometry_flags, raw_flags};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// Samples dropped at each end of a rest: the detector's verdict lags the motion's start and
/// end by part of its window.
const TRIM_SAMPLES: usize = 10;
/// Fewest samples a trimmed rest needs to count.
const MIN_REST_SAMPLES: usize = 20;

/// One rest of the run, trimmed.
#[derive(Debug, Clone)]
pub struct Rest {
    /// Mean time, s from the first state.
    pub t_s: f64,
    /// Index range in the run's sample list (trimmed).
    pub samples: std::ops::Range<usize>,
    /// Mean specific force, m/s^2.
    pub accel_mps2: Vector3<f64>,
    /// Variance of that mean per axis from the samples' own noise, (m/s^2)^2, with their
    /// correlation counted (lag-1, [`mean_variance`]).
    pub accel_mean_var: Vector3<f64>,
    /// Mean angular rate `C w`, rad/s (the gyro's bias, if the rest is still).
    pub gyro_rps: Vector3<f64>,
    /// Variance of that mean per axis, (rad/s)^2.
    pub gyro_mean_var: Vector3<f64>,
    /// Mean die temperature, degC (NaN when the samples carry none).
    pub temp_c: f64,
}

/// The motion between two consecutive rests.
#[derive(Debug, Clone)]
pub struct Interval {
    /// Index of the rest it starts from (it ends at the next).
    pub from: usize,
    /// Samples from the middle of the first rest to the middle of the second (each rest's
    /// mean gravity direction is its attitude there, also when it still turns a little).
    pub samples: std::ops::Range<usize>,
    /// Samples in it whose gyro sat at the end of its range.
    pub gyro_clipped: usize,
    /// Samples in it whose accelerometer sat at the end of its range.
    pub accel_clipped: usize,
}

/// One sample of the run: the corrected sample joined to its odometry state.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Time, s from the first state.
    pub t_s: f64,
    /// Specific force, m/s^2.
    pub accel_mps2: Vector3<f64>,
    /// Angular rate `C w`, rad/s.
    pub gyro_rps: Vector3<f64>,
    /// Die temperature, degC (NaN when not measured).
    pub temp_c: f64,
    /// The raw sample's flags.
    pub raw_flags: u16,
}

/// What a run gives to the diagnosis.
#[derive(Debug, Clone, Default)]
pub struct Evidence {
    /// The samples of the run that have a state, in time order.
    pub samples: Vec<Sample>,
    /// Rests, in time order.
    pub rests: Vec<Rest>,
    /// Motions between consecutive rests.
    pub intervals: Vec<Interval>,
    /// The filter's velocity just before each rest's first zero-velocity update after the
    /// first rest (the update's innovation), m/s, short rests included.
    pub innovations_mps: Vec<Vector3<f64>>,
    /// The gyro's bias, rad/s: the mean rate of the longest rest (a short rest may still
    /// turn, as a foot rolls through its stance; the longest is the stillest).
    pub gyro_bias_rps: Vector3<f64>,
    /// The variance of that bias per axis, (rad/s)^2.
    pub gyro_bias_var: Vector3<f64>,
}

/// Variance of the mean of `x` with the correlation of successive values counted: `s^2 / n`
/// times `(1 + rho) / (1 - rho)` for a lag-1 autocorrelation `rho` >= 0 (a first-order
/// autoregressive process; a sensor's low-pass filter correlates successive samples).
pub fn mean_variance(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    if var <= 0.0 {
        return 0.0;
    }
    let lag1 = x
        .windows(2)
        .map(|w| (w[0] - mean) * (w[1] - mean))
        .sum::<f64>()
        / ((n - 1.0) * var);
    let rho = lag1.clamp(0.0, 0.95);
    var / n * (1.0 + rho) / (1.0 - rho)
}

fn axis_stats(
    samples: &[Sample],
    f: impl Fn(&Sample) -> Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let mut mean = Vector3::zeros();
    let mut var = Vector3::zeros();
    for i in 0..3 {
        let x: Vec<f64> = samples.iter().map(|s| f(s)[i]).collect();
        mean[i] = x.iter().sum::<f64>() / x.len() as f64;
        var[i] = mean_variance(&x);
    }
    (mean, var)
}

/// The evidence gathered as a run is read, message by message (corrected samples and
/// odometry states in the order the run wrote them: each corrected sample before its state),
/// so that what is held is one [`Sample`] per state, not the run's messages.
#[derive(Debug)]
pub struct Gatherer {
    gyro_correction: Matrix3<f64>,
    /// Corrected samples whose state has not come yet, by sequence number.
    pending: std::collections::BTreeMap<u64, CorrectedImuSample>,
    t0: Option<u64>,
    samples: Vec<Sample>,
    at_rest: Vec<bool>,
    velocity: Vec<Vector3<f64>>,
}

impl Gatherer {
    /// A gatherer for a run whose odometry corrected the gyro by `gyro_correction` (`C`).
    pub fn new(gyro_correction: &Matrix3<f64>) -> Self {
        Self {
            gyro_correction: *gyro_correction,
            pending: std::collections::BTreeMap::new(),
            t0: None,
            samples: Vec::new(),
            at_rest: Vec::new(),
            velocity: Vec::new(),
        }
    }

    /// Takes a corrected sample.
    pub fn corrected(&mut self, c: CorrectedImuSample) {
        self.pending.insert(c.seq, c);
    }

    /// Takes an odometry state (revisions are skipped): joined to its corrected sample by
    /// sequence number; corrected samples before it that never got a state are dropped.
    pub fn state(&mut self, s: &OdometryState) {
        let t0 = *self.t0.get_or_insert(s.stamps.sample_ns);
        if s.flags & odometry_flags::REVISION != 0 {
            return;
        }
        let Some(c) = self.pending.remove(&s.seq) else {
            return;
        };
        self.pending = self.pending.split_off(&s.seq);
        let temp_valid = c.raw_flags & raw_flags::TEMP_VALID != 0;
        self.samples.push(Sample {
            t_s: (s.stamps.sample_ns as i64 - t0 as i64) as f64 * 1e-9,
            accel_mps2: Vector3::from(c.accel_mps2),
            gyro_rps: self.gyro_correction * Vector3::from(c.gyro_rps),
            temp_c: if temp_valid { c.temp_c } else { f64::NAN },
            raw_flags: c.raw_flags | (c.flags & corrected_flags::CLIPPED),
        });
        let aligned = s.flags & odometry_flags::ALIGNED != 0;
        self.at_rest
            .push(aligned && s.flags & odometry_flags::ZERO_VELOCITY != 0);
        self.velocity.push(Vector3::from(s.velocity_mps));
    }

    /// The evidence of the run read.
    pub fn finish(self) -> Evidence {
        Evidence::from_samples(self.samples, &self.at_rest, &self.velocity)
    }
}

impl Evidence {
    /// The evidence of `samples` (one per state) with each state's rest flag and velocity.
    fn from_samples(samples: Vec<Sample>, at_rest: &[bool], velocity: &[Vector3<f64>]) -> Self {
        let (rests, innovations_mps) = find_rests(&samples, at_rest, velocity);
        let intervals = rests
            .windows(2)
            .enumerate()
            .map(|(from, w)| {
                let mid = |r: &Rest| (r.samples.start + r.samples.end) / 2;
                let range = mid(&w[0])..mid(&w[1]);
                let clipped = |mask: u16| {
                    samples[range.clone()]
                        .iter()
                        .filter(|s| s.raw_flags & mask != 0)
                        .count()
                };
                let gyro_axes = (3..6).fold(0, |m, i| m | raw_flags::saturated_axis(i));
                let accel_axes = (0..3).fold(0, |m, i| m | raw_flags::saturated_axis(i));
                Interval {
                    from,
                    gyro_clipped: clipped(gyro_axes),
                    accel_clipped: clipped(accel_axes),
                    samples: range,
                }
            })
            .collect();
        let longest = rests.iter().max_by_key(|r| r.samples.len());
        let gyro_bias_rps = longest.map_or_else(Vector3::zeros, |r| r.gyro_rps);
        let gyro_bias_var = longest.map_or_else(Vector3::zeros, |r| r.gyro_mean_var);
        Self {
            samples,
            rests,
            intervals,
            innovations_mps,
            gyro_bias_rps,
            gyro_bias_var,
        }
    }

    /// The rotation the gyro carried over `interval` with its rate corrected by `I + n` and
    /// the bias ([`Evidence::gyro_bias_rps`]) removed, and `hidden` (rad/s per axis) added to
    /// each clipped axis of a sample with that axis's sign (the rate a clip hid beyond the
    /// range; the raw axis's flag marks the corrected axis of the same index, which `C`
    /// turns by no more than its cross-axis terms): sensor frame at the end to sensor frame
    /// at the start.
    pub fn carried(
        &self,
        interval: &Interval,
        n: &Matrix3<f64>,
        hidden: &Vector3<f64>,
    ) -> UnitQuaternion<f64> {
        let bias = self.gyro_bias_rps;
        let scale = Matrix3::identity() + n;
        let mut q = UnitQuaternion::identity();
        let s = &self.samples;
        let rate = |x: &Sample| {
            Vector3::from_fn(|i, _| {
                let clipped = x.raw_flags & raw_flags::saturated_axis(3 + i) != 0;
                let w = x.gyro_rps[i];
                if clipped {
                    w + w.signum() * hidden[i]
                } else {
                    w
                }
            })
        };
        for i in interval.samples.start.max(1)..interval.samples.end {
            let dt = s[i].t_s - s[i - 1].t_s;
            let w = scale * ((rate(&s[i]) + rate(&s[i - 1])) / 2.0 - bias);
            q *= UnitQuaternion::from_scaled_axis(w * dt);
        }
        q
    }
}

/// The rests: runs of aligned zero-velocity states, trimmed by [`TRIM_SAMPLES`] at each end,
/// of at least [`MIN_REST_SAMPLES`] samples; and the velocity before each rest but the first.
fn find_rests(
    samples: &[Sample],
    at_rest: &[bool],
    velocity: &[Vector3<f64>],
) -> (Vec<Rest>, Vec<Vector3<f64>>) {
    let mut rests = Vec::new();
    let mut innovations = Vec::new();
    let mut i = 0;
    let mut first = true;
    while i < samples.len() {
        if !at_rest[i] {
            i += 1;
            continue;
        }
        let start = i;
        while i < samples.len() && at_rest[i] {
            i += 1;
        }
        if start > 0 && !first {
            innovations.push(velocity[start - 1]);
        }
        first = false;
        let range = start + TRIM_SAMPLES..i.saturating_sub(TRIM_SAMPLES);
        if range.len() < MIN_REST_SAMPLES {
            continue;
        }
        let part = &samples[range.clone()];
        let (accel, accel_var) = axis_stats(part, |s| s.accel_mps2);
        let (gyro, gyro_var) = axis_stats(part, |s| s.gyro_rps);
        let n = part.len() as f64;
        rests.push(Rest {
            t_s: part.iter().map(|s| s.t_s).sum::<f64>() / n,
            samples: range,
            accel_mps2: accel,
            accel_mean_var: accel_var,
            gyro_rps: gyro,
            gyro_mean_var: gyro_var,
            temp_c: part.iter().map(|s| s.temp_c).sum::<f64>() / n,
        });
    }
    (rests, innovations)
}
