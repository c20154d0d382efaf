//! Static-segment detection in a raw session: finds the intervals where the sensor was at rest
//! (the poses of a calibration session) from the data alone.
//!
//! 1. Noise level and autocorrelation per axis from the data itself ([`NoiseLevel`], from the
//!    MAD of lag-L differences), which hold for samples correlated by the part's low-pass
//!    filter and depend little on how much of the session is at rest.
//! 2. Non-overlapping windows ([`WindowAccumulator`], default 0.5 s) tested with
//!    [`RestCriterion::from_noise_level`]: std consistent with the noise and mean consistent
//!    with the previous window's, each at false-alarm probability `alpha` per axis.
//! 3. Runs of consecutive rest windows, minus `trim_windows` windows at each end (the settling
//!    after a move), at least `min_duration_s` long, become segments; a gap in the sample times
//!    longer than `max_gap_s` ends a run.
//!
//! Run [`calibrate::repair::repair_torn_reads`] first on data with torn reads: a single +-256-count
//! outlier makes its window's std fail the test.

use ipc_types::RawImuSample;

use crate::fit::Pose;
use calibrate::noise_level::NoiseLevel;
use calibrate::window::{RestCriterion, WindowAccumulator};
use nalgebra::Vector3;

/// Settings of the detector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentConfig {
    /// Window length, s.
    pub window_s: f64,
    /// Shortest segment kept, s.
    pub min_duration_s: f64,
    /// False-alarm probability per axis and window of each test (small: one false alarm
    /// splits a rest in two).
    pub alpha: f64,
    /// Rest windows dropped at each end of a run.
    pub trim_windows: usize,
    /// Longest gap between samples inside a segment, s.
    pub max_gap_s: f64,
}

impl Default for SegmentConfig {
    fn default() -> Self {
        Self {
            window_s: 0.5,
            min_duration_s: 5.0,
            alpha: 1e-5,
            trim_windows: 1,
            max_gap_s: 1.0,
        }
    }
}

impl SegmentConfig {
    /// The defaults with the shortest segment kept `min_duration_s` (s): windows of a quarter
    /// of it (at most the default 0.5 s), so that a segment still spans the trimmed windows
    /// and two more. Multi-position protocols (imu_tk, Tedaldi et al.) hold each pose 1-4 s.
    pub fn with_min_duration(min_duration_s: f64) -> Self {
        let default = Self::default();
        Self {
            window_s: (min_duration_s / 4.0).min(default.window_s),
            min_duration_s,
            ..default
        }
    }
}

/// One interval at rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticSegment {
    /// Index of the first sample.
    pub start: usize,
    /// Index one past the last sample.
    pub end: usize,
    /// Time of the first sample, ns.
    pub t_start_ns: u64,
    /// Time of the last sample, ns.
    pub t_end_ns: u64,
    /// Number of samples.
    pub n: usize,
    /// Mean reading, g, sensor frame.
    pub mean_g: [f64; 3],
    /// Per-sample standard deviation, g.
    pub std_g: [f64; 3],
    /// Lowest and highest die temperature seen, degC, when the samples carry temperature.
    pub temp_range_c: Option<[f64; 2]>,
}

impl StaticSegment {
    /// Duration, s.
    pub fn duration_s(&self) -> f64 {
        (self.t_end_ns - self.t_start_ns) as f64 * 1e-9
    }

    /// The segment as a fitting pose with the given label (g), its sample count divided by
    /// `mean_variance_factor` (the largest axis' [`Detection::mean_variance_factor`]; 1 for
    /// white noise) to give the independent samples its mean is worth.
    pub fn to_pose(&self, truth_g: Vector3<f64>, mean_variance_factor: f64) -> Pose {
        let effective = (self.n as f64 / mean_variance_factor.max(1.0)).floor() as usize;
        Pose {
            truth_g,
            mean_g: Vector3::from(self.mean_g),
            std_g: Vector3::from(self.std_g),
            n: Some(effective.max(1)),
        }
    }
}

/// The result of a detection.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// Per-sample noise sigma per axis measured from the data (the marginal one, correlated
    /// or not), g.
    pub noise_sigma_g: [f64; 3],
    /// How much more a long mean of the noise scatters than white noise's, per axis
    /// ([`NoiseLevel::mean_variance_factor`] of the shortest segment kept; 1 for white noise).
    pub mean_variance_factor: [f64; 3],
    /// Window length used, samples.
    pub window_len: usize,
    /// The thresholds applied.
    pub criterion: RestCriterion,
    /// The segments found, in time order.
    pub segments: Vec<StaticSegment>,
}

impl Detection {
    /// Segment `seg` of this detection as a fitting pose with the given label (g), worth the
    /// independent samples the noise's correlation leaves ([`StaticSegment::to_pose`] with the
    /// largest axis' mean-variance factor).
    pub fn pose(&self, seg: &StaticSegment, truth_g: Vector3<f64>) -> Pose {
        let [x, y, z] = self.mean_variance_factor;
        seg.to_pose(truth_g, x.max(y).max(z))
    }
}

/// Why detection could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SegmentError {
    /// Too few samples for even a few windows.
    #[error("{0} samples are too few to detect static segments")]
    TooFewSamples(usize),
    /// Sample times do not increase.
    #[error("sample times must increase (sample {0})")]
    NonMonotonic(usize),
}

/// Lowest noise sigma assumed, g: below the MPU-9250's quantization step (6.1e-5 g at +-2 g),
/// so that noiseless (simulated) data still gives finite thresholds.
const SIGMA_FLOOR_G: f64 = 1e-5;

/// What the detector reads of a series of samples: sample times (ns), accelerometer values
/// (g, sensor frame) and die temperatures (degC, when present). Implemented for raw samples;
/// other holders of the same data (e.g. repaired values beside the original samples) can
/// implement it to avoid a copy.
pub trait SampleSeries {
    /// Number of samples.
    fn len(&self) -> usize;
    /// Whether there are no samples.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Sample time of sample `k`, ns.
    fn t_ns(&self, k: usize) -> u64;
    /// Accelerometer reading of sample `k`, g.
    fn accel_g(&self, k: usize) -> [f64; 3];
    /// Die temperature of sample `k`, degC, when it has one.
    fn temp_c(&self, k: usize) -> Option<f64>;
}

impl SampleSeries for [RawImuSample] {
    fn len(&self) -> usize {
        <[RawImuSample]>::len(self)
    }

    fn t_ns(&self, k: usize) -> u64 {
        self[k].stamps.sample_ns
    }

    fn accel_g(&self, k: usize) -> [f64; 3] {
        self[k].accel_g
    }

    fn temp_c(&self, k: usize) -> Option<f64> {
        let s = &self[k];
        (s.flags & ipc_types::raw_flags::TEMP_VALID != 0).then_some(s.temp_c)
    }
}

/// Per-sample statistics (mean, std, temperature range) of `samples[start..end]`.
pub fn segment_stats<S: SampleSeries + ?Sized>(
    samples: &S,
    start: usize,
    end: usize,
) -> StaticSegment {
    let n = end - start;
    // One pass: sums about the first value (shifted sums keep the variance accurate).
    let first = samples.accel_g(start);
    let mut sum = [0.0; 3];
    let mut sum2 = [0.0; 3];
    let mut temp_range_c: Option<[f64; 2]> = None;
    for k in start..end {
        let a = samples.accel_g(k);
        for i in 0..3 {
            let d = a[i] - first[i];
            sum[i] += d;
            sum2[i] += d * d;
        }
        if let Some(t) = samples.temp_c(k) {
            temp_range_c = Some(match temp_range_c {
                None => [t, t],
                Some([lo, hi]) => [lo.min(t), hi.max(t)],
            });
        }
    }
    let nf = n as f64;
    let mean: [f64; 3] = std::array::from_fn(|i| first[i] + sum[i] / nf);
    let std: [f64; 3] = std::array::from_fn(|i| {
        let ss = (sum2[i] - sum[i] * sum[i] / nf).max(0.0);
        (ss / (n.max(2) - 1) as f64).sqrt()
    });
    StaticSegment {
        start,
        end,
        t_start_ns: samples.t_ns(start),
        t_end_ns: samples.t_ns(end - 1),
        n,
        mean_g: mean,
        std_g: std,
        temp_range_c,
    }
}

/// Finds the static segments of a session (see the module documentation).
pub fn detect_static_segments(
    samples: &[RawImuSample],
    cfg: &SegmentConfig,
) -> Result<Detection, SegmentError> {
    detect_static_segments_in(samples, cfg)
}

/// [`detect_static_segments`] on any [`SampleSeries`].
pub fn detect_static_segments_in<S: SampleSeries + ?Sized>(
    samples: &S,
    cfg: &SegmentConfig,
) -> Result<Detection, SegmentError> {
    let n = samples.len();
    if n < 20 {
        return Err(SegmentError::TooFewSamples(n));
    }
    if let Some(k) = (1..n).find(|&k| samples.t_ns(k) <= samples.t_ns(k - 1)) {
        return Err(SegmentError::NonMonotonic(k));
    }
    let mut dts: Vec<u64> = (1..n)
        .map(|k| samples.t_ns(k) - samples.t_ns(k - 1))
        .collect();
    let mid = dts.len() / 2;
    let median_dt_s = *dts.select_nth_unstable(mid).1 as f64 * 1e-9;
    let window_len = ((cfg.window_s / median_dt_s).round() as usize).max(5);
    if n < 3 * window_len {
        return Err(SegmentError::TooFewSamples(n));
    }
    let noise: [NoiseLevel; 3] = std::array::from_fn(|i| {
        let axis: Vec<f64> = (0..n).map(|k| samples.accel_g(k)[i]).collect();
        let mut level = NoiseLevel::of(&axis);
        level.sigma = level.sigma.max(SIGMA_FLOOR_G);
        level
    });
    let noise_sigma_g = noise.each_ref().map(|l| l.sigma);
    let criterion = RestCriterion::from_noise_level(&noise, window_len, cfg.alpha);
    let max_gap_ns = (cfg.max_gap_s * 1e9) as u64;

    // Runs of rest windows as (first sample, one past last sample, number of windows).
    let mut runs: Vec<(usize, usize, usize)> = Vec::new();
    let mut acc = WindowAccumulator::new(window_len);
    let mut window_start = 0usize;
    let mut prev_mean: Option<[f64; 3]> = None;
    let mut run: Option<(usize, usize, usize)> = None;
    for k in 0..n {
        let t = samples.t_ns(k);
        if k > 0 && t - samples.t_ns(k - 1) > max_gap_ns {
            acc.reset();
            prev_mean = None;
            window_start = k;
            runs.extend(run.take());
        }
        let Some(w) = acc.push(t, samples.accel_g(k)) else {
            continue;
        };
        let rest = criterion.is_rest(&w, prev_mean.as_ref());
        prev_mean = Some(w.mean);
        if rest {
            run = Some(match run {
                Some((a, _, c)) => (a, k + 1, c + 1),
                None => (window_start, k + 1, 1),
            });
        } else {
            runs.extend(run.take());
        }
        window_start = k + 1;
    }
    runs.extend(run.take());

    let trim = cfg.trim_windows * window_len;
    let segments = runs
        .into_iter()
        .filter(|&(_, _, windows)| windows > 2 * cfg.trim_windows)
        .map(|(a, b, _)| (a + trim, b - trim))
        .map(|(a, b)| segment_stats(samples, a, b))
        .filter(|seg| seg.duration_s() >= cfg.min_duration_s)
        .collect();
    let min_len = ((cfg.min_duration_s / median_dt_s).round() as usize).max(2);
    Ok(Detection {
        noise_sigma_g,
        mean_variance_factor: noise.each_ref().map(|l| l.mean_variance_factor(min_len)),
        window_len,
        criterion,
        segments,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A session of rests at the given directions separated by 3 s rotations, 200 Hz, white
    /// noise of 0.002 g.
    fn session(dirs: &[[f64; 3]], rest_s: f64) -> (Vec<RawImuSample>, Vec<(f64, f64)>) {
        let rate = 200.0;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let noise = Normal::new(0.0, 0.002).unwrap();
        let mut out = Vec::new();
        let mut rests = Vec::new();
        let mut t = 0.0;
        let mut push = |t: f64, a: Vector3<f64>, out: &mut Vec<RawImuSample>| {
            let mut s = RawImuSample {
                seq: out.len() as u64,
                ..Default::default()
            };
            s.stamps.sample_ns = (t * 1e9) as u64;
            s.accel_g = std::array::from_fn(|i| a[i] + noise.sample(&mut rng));
            out.push(s);
        };
        for (k, d) in dirs.iter().enumerate() {
            let a = Vector3::from(*d);
            rests.push((t, t + rest_s));
            let steps = (rest_s * rate) as usize;
            for _ in 0..steps {
                push(t, a, &mut out);
                t += 1.0 / rate;
            }
            if let Some(next) = dirs.get(k + 1) {
                let b = Vector3::from(*next);
                // A rotation at constant rate along the great circle from a to b (through a
                // perpendicular direction when they are opposite).
                let theta = a.dot(&b).clamp(-1.0, 1.0).acos();
                let perp = (b - a * a.dot(&b))
                    .try_normalize(1e-9)
                    .unwrap_or_else(|| a.cross(&Vector3::new(a.y, a.z, a.x)).normalize());
                let steps = (3.0 * rate) as usize;
                for j in 0..steps {
                    let f = theta * j as f64 / steps as f64;
                    let v = a * f.cos() + perp * f.sin();
                    push(t, v, &mut out);
                    t += 1.0 / rate;
                }
            }
        }
        (out, rests)
    }

    #[test]
    fn finds_each_rest_and_its_mean() {
        let dirs = [
            [0., 0., 1.],
            [0., 0., -1.],
            [0., 1., 0.],
            [0., -1., 0.],
            [1., 0., 0.],
            [-1., 0., 0.],
        ];
        let (samples, rests) = session(&dirs, 20.0);
        let det = detect_static_segments(&samples, &SegmentConfig::default()).unwrap();
        assert_eq!(
            det.segments.len(),
            6,
            "{:?}",
            det.segments
                .iter()
                .map(|s| s.duration_s())
                .collect::<Vec<_>>()
        );
        for ((seg, d), (t0, t1)) in det.segments.iter().zip(&dirs).zip(&rests) {
            let (s0, s1) = (seg.t_start_ns as f64 * 1e-9, seg.t_end_ns as f64 * 1e-9);
            assert!(
                s0 >= *t0 && s1 <= *t1,
                "segment {s0}..{s1} outside rest {t0}..{t1}"
            );
            assert!(
                seg.duration_s() > 17.0,
                "segment too short: {}",
                seg.duration_s()
            );
            for (i, di) in d.iter().enumerate() {
                assert!((seg.mean_g[i] - di).abs() < 5.0 * 0.002 / (seg.n as f64).sqrt());
                assert!((seg.std_g[i] / 0.002 - 1.0).abs() < 0.1);
            }
        }
        for i in 0..3 {
            assert!((det.noise_sigma_g[i] / 0.002 - 1.0).abs() < 0.05);
        }
    }

    #[test]
    fn short_rests_are_dropped() {
        let (samples, _) = session(&[[0., 0., 1.], [1., 0., 0.]], 3.0);
        let det = detect_static_segments(&samples, &SegmentConfig::default()).unwrap();
        assert!(det.segments.is_empty());
    }
}
