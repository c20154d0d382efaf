//! The odometry stage's configuration ([`OdometryConfig`], MPU-9250 defaults) and the one a
//! calibration file implies: its local gravity, the gyro's scale
//! and misalignment correction from its `[gyro]` table (`mems-odometry gyrocal --into`, the
//! identity when absent) and the noise model from its `[noise]` table (`mems-calibrate allan
//! --into`, see docs/noise.md), with the MPU-9250 defaults of [`OdometryConfig::mpu9250`] for
//! every figure the file does not hold.
//!
//! Mapping (units as in [`crate::eskf::NoiseModel`]: accelerometer m/s^2, gyro rad/s):
//! - white noise density `N` -> `noise.accel_noise_density` / `noise.gyro_noise_density`;
//! - rate random walk `K` -> `noise.accel_bias_random_walk` / `noise.gyro_bias_random_walk`;
//! - accelerometer bias instability `B` (per axis) -> added in quadrature to
//!   `accel_bias_sigma_mps2`: the filter has no flicker state, and a bias that wanders by about
//!   `B` around its value widens the prior on the bias it starts from after alignment.
//!
//! The filter holds one density per sensor, so the largest of the three axes' is used (as in
//! the Kalibr export): conservative for the quieter axes. Only resolved terms are used; an
//! unresolved term (a 2-sigma upper limit in the table) falls back to the default, capped at
//! that upper limit. Accelerometer figures are rescaled from the table's gravity to the file's
//! (they are g times the gravity used).

use calibrate::calibfile::CalibrationFile;
use calibrate::noise_params::{AxisNoise, Estimate, SensorNoise};
use ipc_types::stream::plausible::Envelope;
use ipc_types::units::STANDARD_GRAVITY_MPS2;
use nalgebra::Matrix3;

use crate::consistency::ConsistencyConfig;
use crate::eskf::{Manoeuvre, NoiseModel};

/// Configuration of the stage. Noise figures come from the calibration file's noise parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryConfig {
    /// Local gravity magnitude, m/s^2.
    pub gravity_mps2: f64,
    /// Sensor noise model.
    pub noise: NoiseModel,
    /// Gyro correction `C` applied to every angular rate before the filter (`omega = C w`,
    /// sensor frame): the inverse of the gyro's scale and misalignment, from
    /// `calibrate_science::gyrocal::calibrate_gyro`; identity for an uncalibrated gyro. (The calibration
    /// stage corrects the accelerometer only, so the gyro's correction is applied here.)
    pub gyro_correction: Matrix3<f64>,
    /// 1-sigma of each entry of the corrected gyro's residual scale and misalignment error,
    /// fraction (row: corrected axis, column: raw axis). The filter does not estimate it; it
    /// widens the reported 1-sigma as the body turns (`eskf::ConsiderModel`). For a fitted
    /// correction, the fit's own sigma ([`Self::with_gyro_calibration`]).
    pub gyro_correction_sigma: Matrix3<f64>,
    /// 1-sigma of the accelerometer bias left after calibration (turn-on repeatability),
    /// m/s^2 per sensor axis.
    pub accel_bias_sigma_mps2: [f64; 3],
    /// 1-sigma of the accelerometer's residual scale and misalignment after calibration,
    /// fraction. Under gravity it reads as a bias of about `g` times this on every axis (a
    /// misalignment of 0.1% puts 10 mm/s^2 of gravity on a horizontal axis), which the
    /// alignment's bias uncertainty includes; its effect on the specific force's changes
    /// since alignment widens the reported 1-sigma (`eskf::ConsiderModel`).
    pub accel_residual_scale: f64,
    /// How an accelerometer whose first rest reads gravity off is treated (its bias prior
    /// widened, its scale carried in the 1-sigma: [`crate::uncalibrated`]).
    pub uncalibrated: UncalibratedAccel,
    /// Zero-angular-rate gate: the gyro bias is updated at rest only while the reading is
    /// within this many predicted standard deviations of the bias estimate.
    pub zaru_gate_sigma: f64,
    /// 1-sigma of the zero-velocity pseudo-measurement, m/s.
    pub zupt_sigma_mps: f64,
    /// Whether a rest's successive samples count as effective samples of the sensor's noise
    /// rather than as independent ones, with the mean-variance factors (`crate::rest_noise`)
    /// estimated from the samples of the rest the filter aligns on (1 for white samples): each
    /// zero-velocity update's variance is `zupt_sigma_mps^2` times the accelerometer's factor
    /// (its largest axis'), and the alignment's gyro-bias variance (the rest's sample variance
    /// over `n`) is multiplied by the gyro's factor per axis. A sensor whose own low-pass
    /// filter correlates successive samples (an MPU-9250 at 1 kHz with its 20 Hz DLPF: about
    /// 15) then gets from a rest the information of its effective number of samples, as the
    /// detector's thresholds do (docs/odometry.md).
    pub effective_samples: bool,
    /// Rest needed before alignment, s.
    pub align_s: f64,
    /// The end of the calibration stage's learning window its alignment may stand on, s (at
    /// most the detector's `learn.duration_s`; 0: none, the alignment waits for flagged rest):
    /// the learner judged those samples still (`navigator::learning`).
    pub learned_rest_s: f64,
    /// Time after the end of a motion interval over which corrections are gathered before the
    /// interval is republished, s.
    pub revision_delay_s: f64,
    /// Longest motion interval whose history is kept for revision, s (at `max_rate_hz`).
    pub max_motion_s: f64,
    /// Highest sample rate the history is sized for, Hz.
    pub max_rate_hz: f64,
    /// Republished states per second of motion (the history is decimated to this rate).
    pub revision_rate_hz: f64,
    /// How long the IMU's rest flag must be followed by rest for its zero-velocity update to
    /// stand, s (see the module documentation); 0 (or less) takes every flag as it comes.
    pub rest_hindsight_s: f64,
    /// Shortest run of motion flags that withdraws the rest flags before it, s: a shorter one
    /// followed by `rest_hindsight_s` of rest (a bump, a glitch, a detector's false alarm on a
    /// static sensor) leaves them standing.
    pub motion_confirm_s: f64,
    /// What the platform can do while samples are missing (a gap, flagged by the raw stream
    /// or a skipped sequence number): the reported 1-sigma grows with it across the gap
    /// (`Eskf::missed`).
    pub manoeuvre: Manoeuvre,
    /// What no platform of the profile does to the sensor: a sample beyond it is implausible
    /// (`ipc_types::stream::plausible`), flagged, counted and not integrated.
    pub plausible: Envelope,
    /// Whether clipped and implausible samples are integrated as measured (`true`: the
    /// behaviour before they were recognised, for comparison, `mems-odometry offline
    /// --trust-clipped`); they are flagged and counted either way.
    pub trust_untrusted: bool,
    /// Whether a clipped run is reconstructed and predicted again once it has ended
    /// (`crate::clip`; `false`: bridged only, `mems-odometry offline --bridge-clipped`).
    pub reconstruct_clipped: bool,
    /// Longest time between two propagations of the filter's covariance, s: the covariance is
    /// propagated from the transition and noise accumulated over the samples since the last
    /// one (`eskf::Eskf::with_propagation_interval`), and at rest the zero-velocity and
    /// zero-rate updates are made once per propagation with the information of one per
    /// sample (`rest_window_drift`). The reported 1-sigma is the last propagation's plus the
    /// process noise accumulated since (`eskf::Eskf::position_sigma`). 0 propagates and
    /// updates at every sample.
    pub propagation_interval_s: f64,
    /// Largest share of a rest window's zero-velocity update variance (`zupt_sigma_mps^2`
    /// over its `n` samples) that the velocity noise accumulated over the window may reach
    /// before the window's updates are made: the `n` per-sample updates are one of variance
    /// `zupt_sigma_mps^2 / n` only while the velocity error stays put over the window. At
    /// 0.05 the rest's steady velocity variance right after an update is 11 % below the limit
    /// that updates at every sample approach as the sample interval shrinks, `sqrt(q r T)`,
    /// and 12 % above it just before (a random walk of intensity `q` under updates of
    /// variance `r` every `T` settles after the update at the root of
    /// `x^2 + q T x - q T r = 0`, before it at `x + q T`). 0 updates at every rest sample.
    pub rest_window_drift: f64,
    /// Whether rest flags, once aligned, give zero-velocity and zero-rate updates (`false`: a
    /// diagnostic that integrates freely after alignment, as `mems-odometry offline
    /// --no-zupt`).
    pub rest_updates: bool,
    /// Wheeled platforms without hints: 1-sigma of the non-holonomic constraint (zero lateral
    /// and vertical body velocity, Brossard et al., "AI-IMU Dead-Reckoning", IEEE T-IV 2020),
    /// m/s, over one second of driving (its updates, one per covariance propagation, each
    /// carry `sigma * sqrt(1 s / interval)`: skid and lever arm are not white). 0: off.
    pub imu_nonholonomic_sigma_mps: f64,
    /// Wheeled platforms: a rest flag whose detector window's specific-force standard
    /// deviation exceeds this many times the alignment rest's is taken as motion and flagged
    /// `REST_VIBRATING`. 0: off.
    pub rest_vibration_factor: f64,
    /// With robot speed hints, the prediction's noise is at least the per-sample scatter the
    /// stream shows ([`crate::sampled_noise`]): what the samples do not resolve (vibration, a
    /// slow stream's jolts) is integration error the datasheet's white noise does not hold.
    /// Not without hints: on the IMU-only car runs of docs/real-data.md the wider noise moved
    /// the estimates further off (the gain changed, not only the 1-sigma).
    pub sampled_noise: bool,
    /// What the run's innovations say of the covariance, and how it enters the published
    /// 1-sigma ([`crate::consistency`]).
    pub consistency: ConsistencyConfig,
    /// Hand-held walking: pedestrian dead reckoning at each step instead of zero-velocity
    /// updates while walking (`crate::walking`); `None` on other platforms.
    pub walking: Option<crate::walking::WalkingConfig>,
    /// A sensor moved by a hand or an arm: 1-sigma of the velocity bound made while it moves
    /// (`crate::hand_bound`), m/s per axis. 0: off.
    pub hand_speed_sigma_mps: f64,
    /// Whether the zero-rate update's per-sample sigma is at least the rests' own rate scatter
    /// ([`crate::rest_scatter`]): a wheeled platform's, and any platform's before it is known
    /// (`--profile auto` until it recognizes one).
    pub rest_rate_scatter: bool,
}

impl OdometryConfig {
    /// Defaults for an MPU-9250 after calibration: datasheet noise densities, the thesis's
    /// measured turn-on repeatability (4.5 / 2.5 / 6.1 mm/s^2), and `gravity_mps2`.
    pub fn mpu9250(gravity_mps2: f64) -> Self {
        Self {
            gravity_mps2,
            noise: NoiseModel {
                accel_noise_density: 300e-6 * gravity_mps2,
                gyro_noise_density: 0.01_f64.to_radians(),
                accel_bias_random_walk: 1e-4,
                gyro_bias_random_walk: 1e-6,
                vibration_accel_density_per_mps: 0.0,
                vibration_gyro_density_per_mps: 0.0,
            },
            gyro_correction: Matrix3::identity(),
            gyro_correction_sigma: datasheet_gyro_error_sigma(),
            accel_bias_sigma_mps2: [4.5e-3, 2.5e-3, 6.1e-3],
            accel_residual_scale: 1e-3,
            uncalibrated: UncalibratedAccel::default(),
            zaru_gate_sigma: 5.0,
            zupt_sigma_mps: 2e-3,
            effective_samples: true,
            align_s: 1.0,
            learned_rest_s: 0.0,
            revision_delay_s: 0.2,
            max_motion_s: 120.0,
            max_rate_hz: 4000.0,
            revision_rate_hz: 100.0,
            rest_hindsight_s: 0.5,
            motion_confirm_s: 0.5,
            // A ground robot: 1 m/s^2 and 30 deg/s reached in half a second, about level.
            manoeuvre: Manoeuvre {
                accel: 1.0,
                rate: 0.5,
                tilt: 0.05,
                duration_s: 0.5,
            },
            plausible: DEFAULT_ENVELOPE,
            trust_untrusted: false,
            reconstruct_clipped: true,
            propagation_interval_s: 0.01,
            rest_window_drift: 0.05,
            rest_updates: true,
            imu_nonholonomic_sigma_mps: 0.0,
            rest_vibration_factor: 0.0,
            sampled_noise: true,
            consistency: ConsistencyConfig::default(),
            walking: None,
            hand_speed_sigma_mps: 0.0,
            rest_rate_scatter: false,
        }
    }

    /// `self` with the gyro correction fitted by `calibrate_science::gyrocal::calibrate_gyro`
    /// and its 1-sigma.
    pub fn with_gyro_calibration(mut self, correction: Matrix3<f64>, sigma: Matrix3<f64>) -> Self {
        self.gyro_correction = correction;
        self.gyro_correction_sigma = sigma;
        self
    }
}

/// What the default profile's platforms (vehicles, robots, and the hand-held recordings that
/// run with it) do to the sensor. Peak: 16 g, the MPU-9250's largest range (PS-MPU-9250A-01
/// table 3.2; the corpus's fastest hand-held run, BROAD 18, peaks at 10.7 g) and 2000 deg/s
/// (table 3.1; the corpus peaks at 739 deg/s). Sustained: 8 g from gravity as a 0.5 s mean
/// (the BROAD fast runs reach 4.8 g; a car brakes at 1 g).
pub const DEFAULT_ENVELOPE: Envelope = Envelope {
    peak_force_mps2: 16.0 * STANDARD_GRAVITY_MPS2,
    peak_rate_rps: 2000.0 * std::f64::consts::PI / 180.0,
    sustained_force_mps2: 8.0 * STANDARD_GRAVITY_MPS2,
    sustained_s: 0.5,
};

/// 1-sigma of an uncalibrated MPU-9250 gyro's scale and cross-axis errors: the product
/// specification (PS-MPU-9250A-01 rev. 1.1, table 1, "Gyroscope Specifications") gives a
/// sensitivity scale factor tolerance of +-3 % and a cross-axis sensitivity of +-2 %. With no
/// distribution stated, a bound `a` is taken as uniform, sigma `a / sqrt(3)` (GUM, JCGM
/// 100:2008, 4.3.7): 1.7 % on the diagonal, 1.2 % off it.
pub fn datasheet_gyro_error_sigma() -> Matrix3<f64> {
    let (scale, cross) = (0.03 / 3f64.sqrt(), 0.02 / 3f64.sqrt());
    Matrix3::from_fn(|r, c| if r == c { scale } else { cross })
}

/// An odometry configuration and the noise figures in it that are defaults.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibratedConfig {
    /// The configuration.
    pub config: OdometryConfig,
    /// The figures taken from [`OdometryConfig::mpu9250`] because the file does not resolve
    /// them (names as in the `[noise]` table, e.g. `accel.random_walk`); empty when the table
    /// gave every one.
    pub defaulted: Vec<&'static str>,
    /// Whether the file has no `[gyro]` correction, so that the gyro runs uncalibrated (the
    /// identity correction).
    pub gyro_uncalibrated: bool,
}

impl CalibratedConfig {
    /// A one-line note naming the defaulted figures and an uncalibrated gyro, `None` when
    /// there are none.
    pub fn defaults_note(&self) -> Option<String> {
        let gyro = self.gyro_uncalibrated.then(|| {
            "no gyro.correction in the calibration file's [gyro] table: the gyro's scale and \
             misalignment are uncalibrated (run mems-odometry gyrocal --into on a pose session)"
                .to_string()
        });
        let noise = (!self.defaulted.is_empty()).then(|| {
            format!(
                "no resolved {} in the calibration file's [noise] table: using the MPU-9250 defaults \
                 for them (run mems-calibrate allan --into on a static recording)",
                self.defaulted.join(", ")
            )
        });
        let notes: Vec<String> = gyro.into_iter().chain(noise).collect();
        (!notes.is_empty()).then(|| notes.join("; "))
    }
}

/// How an accelerometer that reads gravity off at its first rest is treated (see
/// [`crate::uncalibrated`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UncalibratedAccel {
    /// Largest `| |f| / g - 1 |` at the alignment rest taken as a calibrated part's
    /// (`calibrate::zero_state::learn::CALIBRATED_GRAVITY_ERROR`, 2 %: the corpus's
    /// factory-calibrated parts read 0.1-1.3 % off).
    pub trigger: f64,
    /// 1-sigma of the zero-g offset per axis, m/s^2: 0.1 g (MPU-6050 datasheet: +-50 mg x, y,
    /// +-80 mg z; the thesis's uncalibrated MPU-9250: 0.1-0.2 g).
    pub bias_sigma_mps2: f64,
    /// 1-sigma of the sensitivity error of each axis, fraction: 3 % (MPU-6050 and MPU-9250
    /// datasheets, "initial tolerance" +-3 %).
    pub scale_sigma: f64,
    /// 1-sigma of the cross-axis sensitivity, fraction: 2 % (the same datasheets, +-2 %).
    pub cross_axis_sigma: f64,
    /// Smallest random walk of the accelerometer bias for a part the calibration stage flagged
    /// `GRAVITY_OFF`, m/s^3/sqrt(Hz) (see [`crate::uncalibrated::AccelPrior::noise`]):
    /// `bias_sigma_mps2 sin(REST_TILT_CHANGE_DEG) / sqrt(memory_s)`, 0.011 by default.
    pub refined_bias_walk_mps3: f64,
    /// The bias an earlier pass over the same recording estimated and removed from the
    /// samples, m/s^2, sensor frame (`mems-odometry offline`,
    /// [`crate::uncalibrated::remove_bias`]): the filter then starts from it with the
    /// uncalibrated prior (the earlier pass's own sigma holds nothing of what its model lacks:
    /// on a real wheeled run a calibrated prior around it ended further off than one pass) and
    /// reports the bias as this plus its own estimate.
    pub removed_bias_mps2: Option<[f64; 3]>,
    /// The per-axis bias and scale an earlier pass fitted to its rests at several attitudes
    /// and corrected the samples with ([`crate::attitudes`], `mems-odometry offline`): the
    /// filter then starts from the fit's sigmas (bias per axis, scale per axis in the consider
    /// parameters; the cross-axis sensitivity, not applied, keeps `cross_axis_sigma`).
    pub fitted: Option<crate::attitudes::AttitudeFit>,
}

/// Tilt change between two rests the refined bias's random walk is sized by, degrees
/// ([`UncalibratedAccel::refined_bias_walk_mps3`]): a car stopping on grades of up to 5 deg
/// either way (`mems-sim drive --max-slope-deg 5`), about twice the rms between successive
/// rests of the corpus's robots, cars and hand-held recordings (`python3
/// tools/real-data/rest_tilts.py`: 43 pairs, median 0.67 deg, rms 2.40 deg, largest 8.40 deg,
/// the RTKLIB car stopping on a hill). The walk is not the part's own bias drift (a calibrated MPU-9250's
/// is `noise.accel_bias_random_walk`, two orders smaller) but what the stage's refinement moves
/// the bias by between rests at different tilts. Sized by the rms (1.6 deg: 0.0036) the
/// simulated sloped drive ends at the edge of its 1-sigma's 68 % radius (0.595 m against
/// 0.597 m; 0.39 m against 0.88 m with this walk; 0.003 did not cover it).
pub const REST_TILT_CHANGE_DEG: f64 = 5.0;

impl Default for UncalibratedAccel {
    fn default() -> Self {
        let bias_sigma_mps2 = 0.1 * ipc_types::units::STANDARD_GRAVITY_MPS2;
        let memory_s = calibrate::stage::RefineConfig::default().memory_s;
        Self {
            trigger: calibrate::zero_state::learn::CALIBRATED_GRAVITY_ERROR,
            bias_sigma_mps2,
            scale_sigma: 0.03,
            cross_axis_sigma: 0.02,
            refined_bias_walk_mps3: bias_sigma_mps2 * REST_TILT_CHANGE_DEG.to_radians().sin()
                / memory_s.sqrt(),
            removed_bias_mps2: None,
            fitted: None,
        }
    }
}

/// The largest resolved value of one term over the three axes, if any axis resolves it, and
/// the largest upper limit of the axes that do not.
fn largest(
    sensor: &SensorNoise,
    term: fn(&AxisNoise) -> Option<Estimate>,
    limit: fn(&AxisNoise) -> Option<f64>,
) -> (Option<f64>, Option<f64>) {
    let resolved = sensor
        .axes()
        .iter()
        .filter_map(|a| term(a).map(|e| e.value))
        .reduce(f64::max);
    let limit = sensor
        .axes()
        .iter()
        .filter(|a| term(a).is_none())
        .filter_map(|a| limit(a))
        .reduce(f64::max);
    (resolved, limit)
}

/// The configuration for `file` (see the module documentation), with the defaults it used.
pub fn from_calibration(file: &CalibrationFile) -> CalibratedConfig {
    let mut config = OdometryConfig::mpu9250(file.gravity_mps2);
    if let Some(c) = file.gyro.correction {
        config.gyro_correction = Matrix3::from_fn(|r, k| c[r][k]);
        // A correction without its sigma keeps the datasheet's: nothing says it is better.
        if let Some(s) = file.gyro.correction_sigma {
            config.gyro_correction_sigma = Matrix3::from_fn(|r, k| s[r][k]);
        }
    }
    let gyro_uncalibrated = file.gyro.correction.is_none();
    let mut defaulted = Vec::new();
    let Some(noise) = &file.noise else {
        return CalibratedConfig {
            config,
            gyro_uncalibrated,
            defaulted: vec![
                "accel.white_noise_density",
                "accel.bias_instability",
                "accel.random_walk",
                "gyro.white_noise_density",
                "gyro.random_walk",
            ],
        };
    };
    let accel_scale = file.gravity_mps2 / noise.gravity_mps2;
    // Resolved value, else the default capped at the record's upper limit.
    let mut pick =
        |name: &'static str, (value, limit): (Option<f64>, Option<f64>), default: f64| {
            value.unwrap_or_else(|| {
                defaulted.push(name);
                limit.map_or(default, |l| default.min(l))
            })
        };
    let white = |a: &AxisNoise| a.white_noise_density;
    let white_limit = |a: &AxisNoise| a.upper_limits.white_noise_density;
    let walk = |a: &AxisNoise| a.random_walk;
    let walk_limit = |a: &AxisNoise| a.upper_limits.random_walk;
    let scaled = |(v, l): (Option<f64>, Option<f64>)| {
        (v.map(|v| v * accel_scale), l.map(|l| l * accel_scale))
    };

    let n = &mut config.noise;
    n.accel_noise_density = pick(
        "accel.white_noise_density",
        scaled(largest(&noise.accel, white, white_limit)),
        n.accel_noise_density,
    );
    n.accel_bias_random_walk = pick(
        "accel.random_walk",
        scaled(largest(&noise.accel, walk, walk_limit)),
        n.accel_bias_random_walk,
    );
    let (gyro_white, gyro_walk) = match &noise.gyro {
        Some(g) => (largest(g, white, white_limit), largest(g, walk, walk_limit)),
        None => ((None, None), (None, None)),
    };
    n.gyro_noise_density = pick("gyro.white_noise_density", gyro_white, n.gyro_noise_density);
    n.gyro_bias_random_walk = pick("gyro.random_walk", gyro_walk, n.gyro_bias_random_walk);

    let mut any_instability = false;
    for (sigma, axis) in config
        .accel_bias_sigma_mps2
        .iter_mut()
        .zip(noise.accel.axes())
    {
        if let Some(b) = axis.bias_instability {
            any_instability = true;
            *sigma = sigma.hypot(b.value * accel_scale);
        }
    }
    if !any_instability {
        defaulted.push("accel.bias_instability");
    }
    CalibratedConfig {
        config,
        defaulted,
        gyro_uncalibrated,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use calibrate::noise_params::{NoiseParams, UpperLimits};

    fn estimate(value: f64) -> Option<Estimate> {
        Some(Estimate {
            value,
            sigma: value / 10.0,
        })
    }

    fn axis(n: f64, b: Option<f64>, k: Option<f64>, k_limit: Option<f64>) -> AxisNoise {
        AxisNoise {
            white_noise_density: estimate(n),
            bias_instability: b.and_then(estimate),
            random_walk: k.and_then(estimate),
            upper_limits: UpperLimits {
                random_walk: k_limit,
                ..Default::default()
            },
        }
    }

    /// The identity calibration at `gravity` with `noise` as its `[noise]` table (the accelerometer
    /// model plays no part in the odometry's configuration).
    fn file_with(gravity: f64, noise: Option<NoiseParams>) -> CalibrationFile {
        let mut file = CalibrationFile::identity(gravity);
        file.noise = noise;
        file
    }

    fn params(gravity: f64, gyro: bool) -> NoiseParams {
        NoiseParams {
            source: "static.csv".into(),
            sample_rate_hz: 200.0,
            record_length_s: 600.0,
            samples: 120_000,
            gravity_mps2: gravity,
            accel: SensorNoise {
                unit: "m/s^2".into(),
                x: axis(1.5e-3, Some(1.1e-3), None, Some(3e-5)),
                y: axis(1.4e-3, None, None, Some(2e-5)),
                z: axis(2.6e-3, Some(0.9e-3), None, Some(4e-5)),
            },
            gyro: gyro.then(|| SensorNoise {
                unit: "rad/s".into(),
                x: axis(1.7e-4, None, Some(2e-6), None),
                y: axis(1.9e-4, None, Some(3e-6), None),
                z: axis(1.8e-4, None, None, Some(1e-5)),
            }),
        }
    }

    #[test]
    fn without_a_noise_table_every_figure_is_the_default_and_named() {
        let c = from_calibration(&file_with(9.797, None));
        assert_eq!(c.config, OdometryConfig::mpu9250(9.797));
        assert_eq!(c.defaulted.len(), 5);
        assert!(c.gyro_uncalibrated);
        let note = c.defaults_note().unwrap();
        for name in &c.defaulted {
            assert!(note.contains(name), "{note}");
        }
        assert!(
            note.contains("gyro.correction") && note.contains("mems-odometry gyrocal"),
            "{note}"
        );
    }

    #[test]
    fn the_files_gyro_correction_is_used_and_its_absence_named() {
        let c = [
            [0.99, 0.004, -0.006],
            [-0.005, 1.012, 0.003],
            [0.007, -0.002, 0.985],
        ];
        let mut file = file_with(9.797, Some(params(9.797, true)));
        file.gyro.correction = Some(c);
        file.gyro.correction_sigma = Some([[1e-4, 2e-4, 3e-4]; 3]);
        let with = from_calibration(&file);
        assert!(!with.gyro_uncalibrated);
        for (r, row) in c.iter().enumerate() {
            for (k, value) in row.iter().enumerate() {
                assert_eq!(with.config.gyro_correction[(r, k)], *value);
            }
        }
        let note = with.defaults_note().unwrap();
        assert!(
            !note.contains("gyro.correction") && note.contains("accel.random_walk"),
            "{note}"
        );

        // The same file without it: the identity, named in the note with the noise defaults,
        // and nothing else changes.
        file.gyro.correction = None;
        file.gyro.correction_sigma = None;
        let without = from_calibration(&file);
        assert!(without.gyro_uncalibrated);
        assert_eq!(without.config.gyro_correction, Matrix3::identity());
        let note = without.defaults_note().unwrap();
        assert!(
            note.contains("no gyro.correction") && note.contains("accel.random_walk"),
            "{note}"
        );
        assert_eq!(with.config.gyro_correction_sigma[(0, 2)], 3e-4);
        let mut same = with.config;
        same.gyro_correction = Matrix3::identity();
        same.gyro_correction_sigma = without.config.gyro_correction_sigma;
        assert_eq!(same, without.config);
        assert_eq!(with.defaulted, without.defaulted);
    }

    #[test]
    fn resolved_terms_are_used_and_unresolved_ones_capped_at_their_limit() {
        // The table converted g with 9.81; the file's gravity is 9.797.
        let scale = 9.797 / 9.81;
        let c = from_calibration(&file_with(9.797, Some(params(9.81, true))));
        let d = OdometryConfig::mpu9250(9.797);
        let n = &c.config.noise;
        assert_eq!(n.accel_noise_density, 2.6e-3 * scale);
        // K unresolved on every axis: the default 1e-4 exceeds the largest 2-sigma limit.
        assert_eq!(n.accel_bias_random_walk, 4e-5 * scale);
        assert_eq!(n.gyro_noise_density, 1.9e-4);
        assert_eq!(n.gyro_bias_random_walk, 3e-6);
        let b = c.config.accel_bias_sigma_mps2;
        let expected = [
            (d.accel_bias_sigma_mps2[0].powi(2) + (1.1e-3 * scale).powi(2)).sqrt(),
            d.accel_bias_sigma_mps2[1],
            (d.accel_bias_sigma_mps2[2].powi(2) + (0.9e-3 * scale).powi(2)).sqrt(),
        ];
        for i in 0..3 {
            assert!((b[i] - expected[i]).abs() < 1e-15, "{b:?} {expected:?}");
        }
        assert_eq!(c.defaulted, vec!["accel.random_walk"]);
        // Everything that is not a noise figure stays the default.
        let mut same = c.config;
        same.noise = d.noise;
        same.accel_bias_sigma_mps2 = d.accel_bias_sigma_mps2;
        assert_eq!(same, d);
    }

    #[test]
    fn an_accelerometer_only_table_leaves_the_gyro_at_its_defaults() {
        let c = from_calibration(&file_with(9.797, Some(params(9.797, false))));
        let d = OdometryConfig::mpu9250(9.797);
        assert_eq!(
            c.config.noise.gyro_noise_density,
            d.noise.gyro_noise_density
        );
        assert_eq!(
            c.config.noise.gyro_bias_random_walk,
            d.noise.gyro_bias_random_walk
        );
        assert_eq!(
            c.defaulted,
            vec![
                "accel.random_walk",
                "gyro.white_noise_density",
                "gyro.random_walk"
            ]
        );
    }
}
