//! The whole analysis of a static recording: repair, sampling, Allan deviation and model fit
//! per axis (axes in parallel), noise parameters and the displacement floor.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use ipc_types::RawImuSample;
use ipc_types::units::STANDARD_GRAVITY_MPS2;
use serde::{Deserialize, Serialize};

use crate::allan::overlapping_avar_consuming;
use crate::fit::{CovarianceBasis, FitError, ModelFit, fit_with};
use crate::floor::{detrended_displacement_ns, static_displacement_sigma};
use crate::params::{AxisNoise, NoiseParams, SensorNoise};
use crate::repair::{
    RepairConfig, RepeatReport, TEAR_COUNTS, TornReport, apply_to_samples, detect_axes,
};
use crate::series::{AXES, Channel, Columns, GapPolicy, Sensor, SeriesError, Timing};

/// How to analyse a recording.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Gravity converting g to m/s^2.
    pub gravity_mps2: f64,
    /// Gap classification.
    pub gaps: GapPolicy,
    /// Torn-read repair with these sensitivities; `None` analyses the samples as recorded.
    pub repair: Option<RepairConfig>,
    /// Horizon of the predicted displacement floor, s.
    pub floor_horizon_s: f64,
}

impl Default for Options {
    /// Standard gravity, default gap policy, repair at +-2 g / +-250 deg/s, 60 s floor.
    fn default() -> Self {
        Self {
            gravity_mps2: STANDARD_GRAVITY_MPS2,
            gaps: GapPolicy::default(),
            repair: Some(RepairConfig::default()),
            floor_horizon_s: 60.0,
        }
    }
}

/// The analysis of one axis.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelReport {
    /// The sensor.
    pub sensor: Sensor,
    /// 0, 1, 2 for x, y, z.
    pub axis: usize,
    /// The unit `u` of the values (m/s^2 or rad/s).
    pub unit: String,
    /// The fitted model, with the Allan deviation points.
    pub fit: ModelFit,
}

/// The displacement floor of the accelerometer (see [`crate::floor`]), per sensor axis, m.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FloorReport {
    /// The horizon of `predicted_m`, s.
    pub horizon_s: f64,
    /// Predicted 1-sigma after `horizon_s` with the mean removed, from the fitted coefficients
    /// (terms below significance included at their estimate).
    pub predicted_m: [f64; 3],
    /// Duration of this record, s.
    pub record_s: f64,
    /// Predicted 1-sigma over this record's duration.
    pub predicted_record_m: [f64; 3],
    /// What this record shows: its displacement after removing its mean and integrating
    /// twice (trapezoid rule on the recorded times, repaired samples).
    pub measured_record_m: [f64; 3],
}

/// Everything the analysis found.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Report {
    /// The recording's path or name.
    pub source: String,
    /// Samples analysed.
    pub samples: usize,
    /// Sampling, gaps and segments.
    pub timing: Timing,
    /// Repeated samples (counted, left in place).
    pub repeats: RepeatReport,
    /// Torn-read repair, when enabled.
    pub torn: Option<TornReport>,
    /// One entry per analysed axis: accelerometer x, y, z, then gyro x, y, z when present.
    pub channels: Vec<ChannelReport>,
    /// The parameters for the calibration file.
    pub params: NoiseParams,
    /// Predicted and measured displacement floor.
    pub floor: FloorReport,
}

/// Why a recording cannot be analysed.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AnalysisError {
    /// The samples cannot form a series.
    #[error("{source_name}: {error}")]
    Series {
        /// The recording.
        source_name: String,
        /// What is wrong.
        error: SeriesError,
    },
    /// An axis cannot be fitted.
    #[error("{source_name}: {sensor:?} {axis}: {error}")]
    Fit {
        /// The recording.
        source_name: String,
        /// The sensor.
        sensor: Sensor,
        /// The axis name.
        axis: &'static str,
        /// What is wrong.
        error: FitError,
    },
}

/// Repairs torn reads in the raw counts and the same shifts on the SI columns: g (times
/// gravity) and deg/s (in radians); `samples` are repaired in place.
fn repair(
    samples: &mut [RawImuSample],
    columns: &mut Columns,
    config: &RepairConfig,
    gravity_mps2: f64,
) -> TornReport {
    let tears = detect_axes(&columns.counts);
    for (a, axis_tears) in tears.iter().enumerate() {
        let step = if a < 3 {
            f64::from(TEAR_COUNTS) / config.accel_lsb_per_g * gravity_mps2
        } else {
            (f64::from(TEAR_COUNTS) / config.gyro_lsb_per_dps).to_radians()
        };
        for &(i, k) in &axis_tears.fixes {
            columns.values[a][i] -= f64::from(k) * step;
        }
    }
    apply_to_samples(samples, &tears, config)
}

/// The noise parameters of `sensor`'s three axes, if analysed.
fn sensor_noise(reports: &[ChannelReport], sensor: Sensor) -> Option<SensorNoise> {
    let axes: Vec<AxisNoise> = reports
        .iter()
        .filter(|r| r.sensor == sensor)
        .map(|r| crate::fit::axis_noise(&r.fit))
        .collect();
    let [x, y, z]: [AxisNoise; 3] = axes.try_into().ok()?;
    Some(SensorNoise {
        unit: sensor.unit().to_owned(),
        x,
        y,
        z,
    })
}

/// The displacement floor after `t` s at rest (mean removed, 1-sigma) per accelerometer axis,
/// m, from the fitted noise.
fn floor_at(reports: &[ChannelReport], t: f64) -> [f64; 3] {
    std::array::from_fn(|axis| {
        let p = reports[axis].fit.coefficients;
        static_displacement_sigma(p[0].sqrt(), p[1].sqrt(), p[2].sqrt(), t)
    })
}

/// Analyses a static recording named `source` (see the crate documentation). The samples are
/// repaired in place when `options.repair` is set.
pub fn analyze(
    samples: &mut [RawImuSample],
    source: &str,
    options: &Options,
) -> Result<Report, AnalysisError> {
    let series_error = |error| AnalysisError::Series {
        source_name: source.to_owned(),
        error,
    };
    let mut columns = Columns::new(samples, options.gravity_mps2).map_err(series_error)?;
    let timing = columns.timing(&options.gaps);
    let repeats = columns.repeats;
    let torn = options
        .repair
        .map(|config| repair(samples, &mut columns, &config, options.gravity_mps2));
    let times_ns = std::mem::take(&mut columns.times_ns);
    let channels = columns.into_channels();
    let kinds: Vec<(Sensor, usize)> = channels.iter().map(|c| (c.sensor, c.axis)).collect();
    let (fits, displacements) = fit_channels(channels, &timing, &times_ns);
    let measured_record_m = std::array::from_fn(|axis| displacements[axis].unwrap_or(0.0));
    let mut reports = Vec::with_capacity(kinds.len());
    for (&(sensor, axis), result) in kinds.iter().zip(fits) {
        let fit = result.map_err(|error| AnalysisError::Fit {
            source_name: source.to_owned(),
            sensor,
            axis: AXES[axis],
            error,
        })?;
        reports.push(ChannelReport {
            sensor,
            axis,
            unit: sensor.unit().to_owned(),
            fit,
        });
    }

    let params = NoiseParams {
        source: source.to_owned(),
        sample_rate_hz: 1.0 / timing.mean_interval_s,
        record_length_s: timing.duration_s,
        samples: samples.len(),
        gravity_mps2: options.gravity_mps2,
        accel: sensor_noise(&reports, Sensor::Accel).expect("the accelerometer is always analysed"),
        gyro: sensor_noise(&reports, Sensor::Gyro),
    };
    let floor_at = |t: f64| floor_at(&reports, t);
    let floor = FloorReport {
        horizon_s: options.floor_horizon_s,
        predicted_m: floor_at(options.floor_horizon_s),
        record_s: timing.duration_s,
        predicted_record_m: floor_at(timing.duration_s),
        measured_record_m,
    };
    Ok(Report {
        source: source.to_owned(),
        samples: samples.len(),
        timing,
        repeats,
        torn,
        channels: reports,
        params,
        floor,
    })
}

/// Time between joined records in [`join_records`], ns: longer than any split threshold.
pub const JOIN_GAP_NS: u64 = 3_600_000_000_000;

/// Joins recordings of the same sensor into one sample list for a pooled analysis: each record
/// starts [`JOIN_GAP_NS`] after the previous one ends and its first sample carries
/// `GAP_BEFORE`, so the gap policy splits there and the Allan variance pools the records as
/// segments (no cluster straddles two records). Sequence numbers are renumbered. The
/// displacement floor measured on joined records is not meaningful: measure each record.
pub fn join_records(records: &[Vec<RawImuSample>]) -> Vec<RawImuSample> {
    let mut joined: Vec<RawImuSample> = Vec::with_capacity(records.iter().map(Vec::len).sum());
    for record in records.iter().filter(|r| !r.is_empty()) {
        let offset = match joined.last() {
            Some(last) => last.stamps.sample_ns + JOIN_GAP_NS - record[0].stamps.sample_ns,
            None => 0,
        };
        let first = joined.len();
        joined.extend(record.iter().map(|s| {
            let mut s = *s;
            s.stamps.sample_ns += offset;
            s
        }));
        if first > 0 {
            joined[first].flags |= ipc_types::raw_flags::GAP_BEFORE;
        }
    }
    for (i, s) in joined.iter_mut().enumerate() {
        s.seq = i as u64;
    }
    joined
}

/// Per channel: the fit, and the detrended displacement of accelerometer channels.
type ChannelResults = (Vec<Result<ModelFit, FitError>>, Vec<Option<f64>>);

/// Allan curve and fit of every channel, spread over the available cores (each channel's
/// values become its cumulative sums; the fits share one covariance basis, every channel having
/// the same cluster sizes), and each accelerometer channel's detrended displacement (see
/// [`crate::floor`]; `None` for the gyro), computed first on the same thread.
fn fit_channels(channels: Vec<Channel>, timing: &Timing, times_ns: &[u64]) -> ChannelResults {
    let segments = timing.segment_ranges();
    let (curves, displacements): (Vec<_>, Vec<_>) = parallel_map(channels, |channel| {
        let displacement = (channel.sensor == Sensor::Accel)
            .then(|| detrended_displacement_ns(times_ns, &channel.values));
        let curve = overlapping_avar_consuming(channel.values, &segments, timing.mean_interval_s);
        (curve, displacement)
    })
    .into_iter()
    .unzip();
    let basis = CovarianceBasis::for_curve(&curves[0]);
    let fits = parallel_map(curves.iter().collect(), |curve| fit_with(curve, &basis));
    (fits, displacements)
}

/// `items.into_iter().map(f)` on as many threads as there are cores (at most one per item).
fn parallel_map<T: Send, R: Send>(items: Vec<T>, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    let count = items.len();
    let next = AtomicUsize::new(0);
    let inputs: Mutex<Vec<Option<T>>> = Mutex::new(items.into_iter().map(Some).collect());
    let results: Mutex<Vec<Option<R>>> = Mutex::new((0..count).map(|_| None).collect());
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(count);
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    if i >= count {
                        break;
                    }
                    let item = inputs.lock().expect("no panics while locked")[i]
                        .take()
                        .expect("each item is taken once");
                    let result = f(item);
                    results.lock().expect("no panics while locked")[i] = Some(result);
                }
            });
        }
    });
    results
        .into_inner()
        .expect("workers finished")
        .into_iter()
        .map(|r| r.expect("every item processed"))
        .collect()
}
