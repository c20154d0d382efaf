//! A generalised-likelihood-ratio rest test on accelerometer and gyroscope, in the spirit of
//! the SHOE detector (Skog et al., as in OpenShoe), but against the gravity vector and the
//! gyroscope bias *learned at rest* rather than gravity's direction taken from each window
//! (which tests only the magnitude and misses steady horizontal acceleration).
//!
//! Over a sliding window of the last `window_s` seconds of whole batches (`N` samples; the
//! window's length in batches follows the stream's rate, measured when the detector learns, so
//! that it means the same time at 40 Hz and at 4 kHz), with references `mu_c` (specific force at
//! rest, gyroscope bias) and per-sample noise `sigma_c` of the six channels `c`, and `rho_c` the
//! learned excess scatter of means over white noise (1 for white noise), and `delta_c` the
//! tolerance on each reference (its drift between rests):
//!
//! ```text
//! T_mean    = sum_c (mean_c - mu_c)^2 / (rho_c sigma_c^2 / N + delta_c^2) ~ chi2(6) at rest
//! T_scatter = sum_c (W_c d_c / (n - 1) + B_c / rho_c) / sigma_c^2  ~ chi2(sum_c K d_c + K - 1)
//! ```
//!
//! where `W_c` is the window's within-batch sum of squares and `B_c` its between-batch part
//! (`sum_b n_b (mean_bc - mean_c)^2`): noise correlated by the sensor's own filter scatters the
//! batch means `rho_c` times more than white noise, which is not motion; it also leaves each
//! batch's within sum of squares fewer effective degrees of freedom `d_c` than `n - 1` (`K`
//! batches of `n` samples; `d_c = n - 1` for white noise, both learned at rest).
//!
//! **Gravity carried by the gyroscope.** The accelerometer's reference `mu` is not the gravity
//! vector of the start: a robot that stops on a slope or after a turn rests with gravity
//! elsewhere in its frame. Between rests `mu` is turned with the body, by the gyroscope's batch
//! means less the bias reference (`mu <- exp(-omega dt) mu`, sensor frame), so the mean test
//! still sees steady horizontal acceleration, against where gravity must be now. Its error
//! grows across gravity only (a rotation keeps the magnitude): with `t` the time since the last
//! rest, its 1-sigma across gravity is
//! `g (s_b t + e_turn |theta|)` (`s_b` the bias reference's own noise, `theta` the gyroscope's
//! integral: a scale error is linear in it, so a turn and back cancels), and the batch means'
//! own noise integrated (an angle random walk, at rest as well), on top of what the last
//! rests left (`P_perp`), and the
//! accelerometer's part of `T_mean` is the component along `mu` against the window mean's own
//! noise plus the component across it against that noise plus `P_perp` and the drift (still 3
//! degrees of freedom). A rest batch updates the direction as a Kalman filter would (gain
//! `P / (P + var(batch mean))`, at least the running-mean gain) and the magnitude as a running
//! mean, so a rest measures gravity again and the test is tight right after it.
//!
//! **A reference that was lost.** Carrying is not exact: a turn and back does not cancel when
//! the body turns about changing axes (cross-axis errors and the turns' non-commutativity add
//! up along the path). Hand-held slow translations of the BROAD data set (a myon aktos-t,
//! `broad-14-slow-breaks` of the real-data corpus) leave the carried reference 1.3-2.0 deg from
//! gravity at each 10 s break after 560-750 deg of back-and-forth turning (net 5-12 deg, so the
//! bound above allows 0.06-0.15 deg): every later rest failed the mean test across gravity
//! alone, and the recording never rested again. So a window that is still by every other test
//! (the scatter, the gyroscope at its bias, |f| at gravity's magnitude, each against its
//! quantile) and fails only across gravity is counted, while its mean specific force holds
//! steady (a braking vehicle's changes as it slows); once such windows have lasted
//! [`REANCHOR_S`] without a break, the reference is taken as lost: the window's direction
//! becomes the reference, with the window mean's own uncertainty, and the window is a rest.
//! A steady horizontal acceleration that long with no vibration and no turn is what this
//! gives up; a slow cruise at constant speed was never told from rest by the mean test anyway.
//!
//! **A magnitude the reference does not hold.** A part's accelerometer bias `b` (fixed in the
//! sensor frame) reads gravity's magnitude as `|g u + b| ~ g + u . b` (`u` gravity's direction
//! in the sensor frame), so between two attitudes the magnitude at rest moves by
//! `(u2 - u1) . b`, up to `2 |b|`; a long window's mean holds the magnitude to a fraction of
//! what a short one allows (a 2 s window at 120 Hz, a fourth of the 0.5 s window's variance),
//! so a rest at another attitude can fail on the magnitude alone. A window still by the
//! scatter and the gyroscope whose mean specific force lies within a bias bound
//! (`GlrtRule::bias_bound`) of the reference (`2 |b|` with `|b|` three sigmas of
//! [`GlrtConfig::accel_bias_sigma_mps2`] on each axis, plus the difference's own noise) is
//! counted as well, and after [`REANCHOR_S`] of it, steady, it is a rest for as long as it
//! stays so. The reference learns nothing from such a rest (the gyroscope bias does): a
//! biased part at another pose would drag it, magnitude and direction, away from what every
//! other pose reads (the simulated arm of docs/diagnosis.md, a 6 mg bias at poses up to 90 deg
//! apart, whose magnitude measured anew at two poses then found 17 of its 25 rests). With a
//! calibrated part's 6.1 mm/s^2 the bound is 63 mm/s^2 (6.5 mg): a steady acceleration within
//! it held 2 s with no vibration and no turn is what this gives up. An uncalibrated part's
//! 0.1 g ([`GlrtConfig::uncalibrated_accel_bias_sigma_mps2`]) gives 10 m/s^2: the stillness
//! tests alone, as its offset may read gravity up to 1 g differently between attitudes.
//!
//! - [`GlrtStatistic::Split`] (default): rest iff each is below its `1 - a/2` chi-squared
//!   quantile. The mean part (6 degrees of freedom) is what catches steady acceleration, turns
//!   and the low-frequency (wheel) part of vibration; the scatter part catches vibration.
//!   A window whose mean test passes and whose scatter test does not is steady but vibrating
//!   ([`super::Verdict::vibrating`]): motion that only vibration tells from rest (a slow cruise
//!   on a smooth floor), counted as such and never taken for rest.
//! - [`GlrtStatistic::Combined`]: SHOE's single sum `T_mean + T_scatter ~ chi2(6 N)` against
//!   its `1 - a` quantile, which dilutes the 6 mean degrees of freedom among `6 N`.
//!
//! **Accelerometer only** ([`super::DetectorKind::GlrtAccel`], for a sensor run without its
//! gyroscope, as the MPU-9250 at 4 kHz): the same test on the three accelerometer channels,
//! `chi2(3)` and `chi2(3 (N - 1))`, with nothing to turn the gravity reference by: it sees
//! acceleration and tilt against the gravity vector of the last rests, and vibration in the
//! scatter, but not a rotation about gravity, and a rest at another tilt is motion to it.
//!
//! The quantiles are the F distribution's rather than the chi-squared's: the noise levels are
//! estimates from the learned rest (`L` degrees of freedom for the sigmas, the learned batches
//! less one for the correlations), so `T / dof ~ F(dof, L)` at rest, which tends to the
//! chi-squared as `L` grows. A half-second learning is what makes that matter.
//!
//! `a` is the configured false-alarm rate per window at rest. The noise levels stay as learned
//! at start-up (a part's noise density does not drift); the gravity vector and gyroscope bias
//! are kept current over rest batches (temperature moves them).

use nalgebra::{Rotation3, Vector3};
use statrs::distribution::{ContinuousCDF, FisherSnedecor};

use super::learn::{MAX_RATE_HZ, StaticReference};
use super::{BATCH_LEN, Decision};
use crate::window::WindowStats;

/// How the two parts of the test are combined.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum GlrtStatistic {
    /// Mean and scatter tested separately, each at half the false-alarm rate.
    Split,
    /// One sum of both (SHOE).
    Combined,
}

/// Settings of the GLRT.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlrtConfig {
    /// Probability that a window at rest is called motion.
    pub false_alarm: f64,
    /// Window length, s, rounded to whole batches of [`BATCH_LEN`] samples at the rate the
    /// detector learned at (at least one batch; it slides by one batch).
    pub window_s: f64,
    /// How mean and scatter are combined.
    pub statistic: GlrtStatistic,
    /// How far the learned specific force at rest may be off between rests, m/s^2 (1-sigma per
    /// axis, added to the window mean's variance). 0 by default: the mean test is what
    /// separates slow cruising from rest, and any tolerance here costs that (measured in
    /// docs/detectors.md).
    pub accel_tolerance_mps2: f64,
    /// The same for the gyroscope bias, rad/s: an uncompensated gyroscope's bias moves by a few
    /// hundredths of a deg/s as the part warms up between rests, which is several times the
    /// window mean's own noise; a reference held tighter than that calls every later rest
    /// motion.
    pub gyro_tolerance_rps: f64,
    /// 1-sigma of the gravity reference's turn across gravity per radian the body turns
    /// between rests, as the gyroscope's scale and cross-axis errors make it: an uncalibrated
    /// MPU-9250 has +-2 % of cross-axis sensitivity (PS-MPU-9250A-01 rev. 1.1, table 1), 1.2 %
    /// as a uniform bound's sigma.
    pub turn_error: f64,
    /// 1-sigma per axis of the accelerometer bias the learned gravity reference holds, m/s^2.
    /// The bias is fixed in the sensor frame, but carrying the reference turns it with the
    /// body: after a turn by `theta` the reference is off by `(R(theta) - I) b`, up to
    /// `2 sin(theta / 2) |b|` across gravity, which a rest after a turn must be allowed.
    pub accel_bias_sigma_mps2: f64,
    /// The same for a part whose learned rest reads gravity more than
    /// [`super::learn::CALIBRATED_GRAVITY_ERROR`] off (an uncalibrated part, whatever its file
    /// says) or declared uncalibrated ([`super::DetectorConfig::uncalibrated`]), m/s^2: its zero-g offset is unknown across gravity too, and a 0.15 g offset turned
    /// by a car's 10 degree bend moves the reference by 0.25 m/s^2, which held to a calibrated
    /// part's 6 mm/s^2 calls every later cruise and rest motion.
    pub uncalibrated_accel_bias_sigma_mps2: f64,
}

impl GlrtConfig {
    /// Batches the window holds at most, at [`MAX_RATE_HZ`] (the ring's capacity).
    pub fn max_window_batches(&self) -> usize {
        ((self.window_s * MAX_RATE_HZ / BATCH_LEN as f64).ceil() as usize).max(1)
    }

    /// The window in whole batches at `rate_hz`, at least one.
    pub fn window_batches(&self, rate_hz: f64) -> usize {
        ((self.window_s * rate_hz / BATCH_LEN as f64).round() as usize)
            .clamp(1, self.max_window_batches())
    }
}

impl Default for GlrtConfig {
    /// False-alarm rate 1e-2 per window, 0.5 s (25 batches at 1 kHz), split statistic: the
    /// best trade-off measured on simulated drives (docs/detectors.md); reference tolerances of
    /// 0 for the accelerometer and 0.02 deg/s for the gyroscope; 1.2 % per radian turned; an
    /// accelerometer bias of 6.1 mm/s^2 (the thesis's turn-on repeatability of a calibrated
    /// MPU-9250, its largest axis; `odometry::config::OdometryConfig::mpu9250`), 0.1 g for an
    /// uncalibrated part (the MPU-6050 datasheet's zero-g offset, +-50 mg on x and y, +-80 mg on
    /// z; the thesis's uncalibrated MPU-9250 read 0.1-0.2 g off; the same prior as
    /// `odometry::config::UncalibratedAccel::bias_sigma_mps2`).
    fn default() -> Self {
        Self {
            false_alarm: 1e-2,
            window_s: 0.5,
            statistic: GlrtStatistic::Split,
            accel_tolerance_mps2: 0.0,
            gyro_tolerance_rps: 0.02_f64.to_radians(),
            turn_error: 0.012,
            accel_bias_sigma_mps2: 6.1e-3,
            uncalibrated_accel_bias_sigma_mps2: 0.1 * ipc_types::units::STANDARD_GRAVITY_MPS2,
        }
    }
}

/// One batch's six channels: sample count, means and within-batch sums of squares.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct BatchSums {
    n: f64,
    mean: [f64; 6],
    ss: [f64; 6],
}

impl BatchSums {
    /// A batch of `n` samples with per-channel means and within-batch sums of squares
    /// (accelerometer x, y, z then gyroscope x, y, z).
    pub(crate) fn from_parts(n: f64, mean: [f64; 6], ss: [f64; 6]) -> Self {
        Self { n, mean, ss }
    }

    fn new(accel: &WindowStats, gyro: &WindowStats) -> Self {
        let n = accel.n as f64;
        let mut b = Self {
            n,
            ..Self::default()
        };
        for i in 0..3 {
            b.mean[i] = accel.mean[i];
            b.mean[i + 3] = gyro.mean[i];
            b.ss[i] = accel.std[i] * accel.std[i] * (n - 1.0);
            b.ss[i + 3] = gyro.std[i] * gyro.std[i] * (n - 1.0);
        }
        b
    }
}

/// How long windows must be still by every test but the gravity reference's direction before
/// the reference is taken as lost and measured anew, s (see the module's "A reference that was
/// lost"): four windows of the default 0.5 s, longer than a vehicle's gentle start keeps its
/// vibration under the noise, shorter than a hand-held sensor's pause.
pub const REANCHOR_S: f64 = 2.0;

/// What of the gravity reference a window still by the scatter and the gyroscope failed on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Lost {
    /// Its direction across gravity alone.
    Direction,
    /// Its magnitude (and perhaps its direction), within [`GlrtRule::bias_bound`].
    Magnitude,
}

/// Sigmas of the accelerometer bias per axis that [`GlrtRule::bias_bound`] allows for.
const BIAS_BOUND_SIGMAS: f64 = 3.0;

/// The learned GLRT: references, noise, thresholds and the window ring.
#[derive(Debug, Clone)]
pub(crate) struct GlrtRule {
    statistic: GlrtStatistic,
    /// Channels tested: 6 (accelerometer and gyroscope) or 3 (accelerometer only).
    channels: usize,
    /// Specific force at rest where the body is now (turned by the gyroscope since the last
    /// rest), m/s^2, then the gyroscope bias, rad/s.
    reference: [f64; 6],
    inv_var: [f64; 6],
    inv_rho: [f64; 6],
    /// Effective over nominal degrees of freedom of a batch's within sum of squares.
    dof_factor: [f64; 6],
    /// Variance of each reference's drift between rests (tolerance squared).
    drift_var: [f64; 6],
    /// Variance of the gravity reference across gravity that the last rests left, per axis,
    /// (m/s^2)^2.
    across_var: f64,
    /// Time since the last rest batch, s.
    moving_s: f64,
    /// Rotation since the last rest batch, the gyroscope's integral (less the bias
    /// reference), rad, sensor frame: a scale or cross-axis error turns the gravity reference
    /// by a fraction of it (linear in the integral, so a turn and back cancels, and so does
    /// noise, as a random walk).
    turned_rad: Vector3<f64>,
    /// The gravity reference's direction at the last rest (unit vector, sensor frame): how far
    /// gravity has turned in the sensor frame since, which moves the accelerometer bias's
    /// share of the reference's magnitude ([`Self::along_var_now`]).
    rest_dir: Vector3<f64>,
    /// Variance of the gravity reference's magnitude that the last rests left, (m/s^2)^2.
    along_var: f64,
    /// The accelerometer bias 1-sigma whose share of the magnitude a tilt moves, m/s^2: an
    /// uncalibrated part's (the configuration's bias sigma, which the caller widened to
    /// [`GlrtConfig::uncalibrated_accel_bias_sigma_mps2`]); 0 for a calibrated one, whose 6 mm/s^2 would loosen the magnitude test after every tilt by
    /// about the window mean's own noise (on the simulated arm runs of docs/diagnosis.md,
    /// slow moves then passed for rests: 19 rests counted of 25, the end 0.52 -> 1.30 m off).
    along_bias_sigma_mps2: f64,
    /// 1-sigma of the gyroscope bias reference, rad/s (the learned mean's noise, largest axis).
    bias_sigma_rps: f64,
    turn_error: f64,
    accel_bias_sigma_mps2: f64,
    /// Consecutive rest decisions up to the last batch.
    rest_run: usize,
    /// Time the windows have been still by the scatter and the gyroscope but failing on the
    /// gravity reference (its direction, or its magnitude within [`Self::bias_bound`]), s.
    lost_s: f64,
    /// The last window is a rest held against a magnitude the reference does not hold: its
    /// rest update leaves the gravity reference as it was.
    holding: bool,
    /// Rests held so since the start.
    held: u64,
    /// The window mean (m/s^2) where that began: the specific force must hold steady.
    lost_from: Vector3<f64>,
    /// Gravity references taken as lost and measured anew.
    reanchored: u64,
    mean_quantile: f64,
    /// The mean test's quantile without the two degrees of freedom across gravity.
    still_quantile: f64,
    /// The quantile of a change of the accelerometer's window mean (3 degrees of freedom).
    steady_quantile: f64,
    scatter_quantile: f64,
    combined_quantile: f64,
    /// The noise pooled over the learned rest and the rest batches since (see [`Pool`]).
    pool: Pool,
    /// Ring of the last batches, allocated once.
    ring: Vec<BatchSums>,
    head: usize,
    filled: usize,
}

impl GlrtRule {
    /// The test from the start-up reference `r` (after the noise floor; `learned` before it),
    /// its window in batches at the reference's rate; `ring` (capacity at least
    /// [`GlrtConfig::max_window_batches`]) becomes the window, so that learning allocates
    /// nothing. `accel_only` leaves the gyroscope out. `prior_batches`: the batches of rest
    /// the part's known noise (the calibration file's `[noise]` table or the datasheet's, at
    /// this rate) stands for in the mean test's quantile, 0 when it is not known.
    /// `uncalibrated`: the learned rest read gravity more than
    /// [`super::learn::CALIBRATED_GRAVITY_ERROR`] off (the caller's decision, which also set
    /// `config.accel_bias_sigma_mps2`): only then does a tilt move the bias's share of the
    /// gravity magnitude by more than the window mean's noise ([`Self::along_var_now`]).
    pub fn new(
        r: &StaticReference,
        learned: &StaticReference,
        config: &GlrtConfig,
        mut ring: Vec<BatchSums>,
        accel_only: bool,
        prior_batches: f64,
        uncalibrated: bool,
    ) -> Self {
        let channels = if accel_only { 3 } else { 6 };
        let k = config.window_batches(r.rate_hz());
        let mut reference = [0.0; 6];
        let mut inv_var = [0.0; 6];
        let mut inv_rho = [0.0; 6];
        let mut drift_var = [0.0; 6];
        let mut dof_factor = [1.0; 6];
        let nominal = (BATCH_LEN - 1) as f64;
        for i in 0..3 {
            dof_factor[i] = r.accel_batch_dof[i] / nominal;
            dof_factor[i + 3] = r.gyro_batch_dof[i] / nominal;
            drift_var[i] = config.accel_tolerance_mps2.powi(2);
            drift_var[i + 3] = config.gyro_tolerance_rps.powi(2);
            reference[i] = r.accel_mean_mps2[i];
            reference[i + 3] = r.gyro_mean_rps[i];
            inv_var[i] = 1.0 / (r.accel_sigma_mps2[i] * r.accel_sigma_mps2[i]);
            inv_var[i + 3] = 1.0 / (r.gyro_sigma_rps[i] * r.gyro_sigma_rps[i]);
            inv_rho[i] = 1.0 / r.accel_correlation[i];
            inv_rho[i + 3] = 1.0 / r.gyro_correlation[i];
        }
        let pool = Pool::new(r, learned, config.false_alarm, prior_batches);
        let mut rule = Self {
            statistic: config.statistic,
            channels,
            reference,
            inv_var,
            inv_rho,
            dof_factor,
            drift_var,
            across_var: 0.0,
            moving_s: 0.0,
            turned_rad: Vector3::zeros(),
            rest_dir: Vector3::from_column_slice(&r.accel_mean_mps2)
                .try_normalize(1e-9)
                .unwrap_or_else(Vector3::z),
            along_var: 0.0,
            along_bias_sigma_mps2: if uncalibrated {
                config.accel_bias_sigma_mps2
            } else {
                0.0
            },
            bias_sigma_rps: 0.0,
            turn_error: config.turn_error,
            accel_bias_sigma_mps2: config.accel_bias_sigma_mps2,
            rest_run: 0,
            lost_s: 0.0,
            holding: false,
            held: 0,
            lost_from: Vector3::zeros(),
            reanchored: 0,
            mean_quantile: 0.0,
            still_quantile: 0.0,
            steady_quantile: 0.0,
            scatter_quantile: 0.0,
            combined_quantile: 0.0,
            pool,
            ring: {
                ring.clear();
                ring.resize(k, BatchSums::default());
                ring
            },
            head: 0,
            filled: 0,
        };
        // The learned means' own noise: the gravity reference's across gravity (per axis on
        // average) and the gyroscope bias reference's (largest axis).
        let learned_n = (r.batches * BATCH_LEN) as f64;
        rule.across_var = (0..3).map(|c| rule.mean_var(c, learned_n)).sum::<f64>() / 3.0;
        rule.bias_sigma_rps = (3..6)
            .map(|c| rule.mean_var(c, learned_n).sqrt())
            .fold(0.0, f64::max);
        rule.set_quantiles();
        rule
    }

    /// Variance at rest of a mean of `n` samples of channel `c` (its noise and correlation).
    fn mean_var(&self, c: usize, n: f64) -> f64 {
        1.0 / (n * self.inv_var[c] * self.inv_rho[c])
    }

    /// The gravity reference where the body is now, m/s^2, sensor frame.
    fn gravity(&self) -> Vector3<f64> {
        Vector3::new(self.reference[0], self.reference[1], self.reference[2])
    }

    /// The three quantiles for the window and the pooled noise's degrees of freedom.
    fn set_quantiles(&mut self) {
        let channels = self.channels;
        let dof = channels as f64;
        let k = self.ring.len() as f64;
        let nominal = (BATCH_LEN - 1) as f64;
        let a = self.pool.false_alarm;
        // The noise levels are estimates from rest, so each statistic over its degrees of
        // freedom is F-distributed at rest (a chi-squared over an independent estimate's
        // chi-squared), not chi-squared: `dof F^-1(1 - p; dof, learned)`. With a long rest
        // behind it this is the chi-squared quantile; after half a second of learning it is
        // what keeps the false-alarm rate at `a`.
        let quantile = |dof: f64, learned: f64, p: f64| {
            dof * FisherSnedecor::new(dof, learned.max(1.0))
                .expect("dof > 0")
                .inverse_cdf(1.0 - p)
        };
        // The fewest effective degrees of freedom of the channels' sigmas.
        let sigma_dof = (0..channels)
            .map(|c| self.pool.ss_dof[c] * self.dof_factor[c])
            .fold(f64::INFINITY, f64::min);
        self.mean_quantile = quantile(dof, self.pool.mean_dof, a / 2.0);
        self.still_quantile = quantile(dof - 2.0, self.pool.mean_dof, a / 2.0);
        self.steady_quantile = quantile(3.0, self.pool.mean_dof, a / 2.0);
        let scatter_dof = self.dof_factor[..channels]
            .iter()
            .map(|f| k * f * nominal + k - 1.0)
            .sum();
        self.scatter_quantile = quantile(scatter_dof, sigma_dof, a / 2.0);
        self.combined_quantile = quantile(dof * k * BATCH_LEN as f64, sigma_dof, a);
    }

    /// Pools the rest batch just decided (the window's newest) into the noise levels, when the
    /// rest has held for two windows (a false rest at a motion's start or end is short, and its
    /// vibration must not loosen the test); once the pooled degrees of freedom have doubled
    /// since the last refit, the sigmas (at least the floor they were installed with) and the
    /// quantiles are set from the pool. The mean's variance per sample, `rho sigma^2`, is kept
    /// as learned.
    fn pool_rest(&mut self) {
        let k = self.ring.len();
        if self.rest_run < 2 * k {
            return;
        }
        // The batch just decided, as `decide` put it in the window.
        let newest = self.ring[(self.head + k - 1) % k];
        for (pooled, ss) in self.pool.ss.iter_mut().zip(&newest.ss) {
            *pooled += ss;
        }
        for d in &mut self.pool.ss_dof {
            *d += newest.n - 1.0;
        }
        if self.pool.ss_dof[0] < self.pool.refit_at || self.pool.refit_at > MAX_POOLED_DOF {
            return;
        }
        self.pool.refit_at *= 2.0;
        for c in 0..6 {
            let mean_var = self.mean_var(c, 1.0);
            let var = (self.pool.ss[c] / self.pool.ss_dof[c]).max(self.pool.floor_var[c]);
            self.inv_var[c] = 1.0 / var;
            self.inv_rho[c] = (var / mean_var).min(1.0);
        }
        self.set_quantiles();
    }

    /// Fills the window with the batches the detector learned from (oldest first; the last
    /// `window` of them are kept), so that the batch after learning is decided on a full
    /// window: a rest is a rest from its learning on, not a window later.
    pub fn seed(&mut self, batches: impl Iterator<Item = BatchSums>) {
        for b in batches {
            self.push(b);
        }
    }

    fn push(&mut self, b: BatchSums) {
        let k = self.ring.len();
        self.ring[self.head] = b;
        self.head = (self.head + 1) % k;
        self.filled = (self.filled + 1).min(k);
    }

    /// Turns the gravity reference with the body over one batch (gyroscope mean less the bias
    /// reference, over the batch's duration), and counts the time and angle since the last rest.
    fn carry_gravity(&mut self, gyro: &WindowStats) {
        if self.channels == 3 {
            // Nothing turns the reference: it stays as tight as the last rests left it.
            return;
        }
        let dt = super::batch_duration_s(gyro);
        self.moving_s += dt;
        // The turn's own noise (the batch means' noise over the batch: an angle random walk)
        // adds to the reference's uncertainty across gravity, at rest too.
        let g2 = self.gravity().norm_squared();
        let mean_var = (3..6)
            .map(|c| self.mean_var(c, gyro.n as f64))
            .fold(0.0, f64::max);
        self.across_var += g2 * mean_var * dt * dt;
        let omega = Vector3::from_fn(|i, _| gyro.mean[i] - self.reference[i + 3]);
        self.turned_rad += omega * dt;
        if omega.norm() > 0.0 {
            // The body turns by exp(omega dt); a vector fixed in the world turns the other way
            // in the body's frame.
            let turn = Rotation3::new(-omega * dt);
            let g = turn * self.gravity();
            self.reference[..3].copy_from_slice(g.as_slice());
        }
    }

    /// Variance per axis of the gravity reference across gravity now, (m/s^2)^2: what the last
    /// rests left, the turn the gyroscope's bias error (the bias reference's own noise over
    /// the learned rest) and its scale and cross-axis errors add since, and the accelerometer
    /// bias the turn carried with gravity (`2 sin(theta / 2)` of it, `theta` the angle turned).
    fn across_var_now(&self) -> f64 {
        let g = self.gravity().norm();
        let theta = self.turned_rad.norm();
        let drift = g * (self.bias_sigma_rps * self.moving_s + self.turn_error * theta);
        let bias = self.accel_bias_sigma_mps2 * 2.0 * (0.5 * theta.min(std::f64::consts::PI)).sin();
        self.across_var + drift * drift + bias * bias
    }

    /// Variance of the gravity reference's magnitude now, (m/s^2)^2: what the last rests left,
    /// and what a tilt since moved. The reference holds the accelerometer bias `b` with
    /// gravity, `|g_s + b|`, and a tilt that turns gravity in the sensor frame by `phi` changes
    /// the reading's magnitude by `(g_s' - g_s) . b / g`, up to `2 sin(phi / 2)` of the bias (a
    /// pitch of 2 deg with a 0.15 g offset along the forward axis: 0.05 m/s^2). `phi` is taken
    /// as the angle the reference turned since the last rest, which counts a turn about gravity
    /// by the reference's tilt from it (the bias across gravity over g) too: on the safe side.
    fn along_var_now(&self) -> f64 {
        let phi = self
            .gravity()
            .try_normalize(1e-9)
            .map_or(0.0, |u| u.angle(&self.rest_dir));
        self.along_var + (self.along_bias_sigma_mps2 * 2.0 * (0.5 * phi).sin()).powi(2)
    }

    /// Adds the batch to the window and decides; not at rest until the window is full.
    pub fn decide(&mut self, accel: &WindowStats, gyro: &WindowStats) -> Decision {
        self.carry_gravity(gyro);
        self.push(BatchSums::new(accel, gyro));

        // Window statistics: pooled means, and within-batch plus between-batch sums of squares.
        let n: f64 = self.ring[..self.filled].iter().map(|b| b.n).sum();
        let mut mean = [0.0; 6];
        for b in &self.ring[..self.filled] {
            for (m, bm) in mean.iter_mut().zip(&b.mean) {
                *m += b.n * bm / n;
            }
        }
        let (mut within, mut between) = ([0.0; 6], [0.0; 6]);
        for b in &self.ring[..self.filled] {
            for c in 0..6 {
                let d = b.mean[c] - mean[c];
                within[c] += b.ss[c];
                between[c] += b.n * d * d;
            }
        }
        // The window mean's variance about each reference: its own noise plus the reference's
        // drift since it was learned.
        let var: [f64; 6] = std::array::from_fn(|c| self.mean_var(c, n) + self.drift_var[c]);
        let (t_along, t_across) = self.accel_mean_statistic(&mean, &var);
        let mut t_mean = t_along + t_across;
        let mut t_scatter = 0.0;
        for c in 0..self.channels {
            if c >= 3 {
                let d = mean[c] - self.reference[c];
                t_mean += d * d / var[c];
            }
            t_scatter +=
                (within[c] * self.dof_factor[c] + between[c] * self.inv_rho[c]) * self.inv_var[c];
        }
        let full = self.filled == self.ring.len();
        let steady = t_mean <= self.mean_quantile;
        let quiet = match self.statistic {
            GlrtStatistic::Split => steady && t_scatter <= self.scatter_quantile,
            GlrtStatistic::Combined => t_mean + t_scatter <= self.combined_quantile,
        };
        // Still by the scatter and the gyroscope, failing on the gravity reference alone: its
        // direction across gravity, or its magnitude (the gyroscope's part of `T_mean` has 3
        // degrees of freedom, as the steadiness test) by no more than a biased part reads.
        let still = self.channels == 6 && full && !quiet && t_scatter <= self.scatter_quantile;
        let lost = if !still {
            None
        } else if t_mean - t_across <= self.still_quantile {
            Some(Lost::Direction)
        } else if t_mean - t_across - t_along <= self.steady_quantile
            && self.within_bias_bound(&mean, &var)
        {
            Some(Lost::Magnitude)
        } else {
            None
        };
        self.holding = false;
        let rest = (quiet && full) || self.reanchor(lost, accel, &mean, &var);
        self.rest_run = if rest { self.rest_run + 1 } else { 0 };
        Decision {
            rest,
            vibrating: full && steady && !quiet,
            mean_mps2: [mean[0], mean[1], mean[2]],
            std_mps2: std::array::from_fn(|i| ((within[i] + between[i]) / (n - 1.0)).sqrt()),
        }
    }

    /// Counts the time windows have been still but for the gravity reference (`lost`: what of
    /// it the window failed on), with the window mean `mean` (its variance `var` per axis)
    /// steady: a vehicle's braking tail changes its specific force as it slows, a lost
    /// reference's rest does not. After [`REANCHOR_S`] of it the window is a rest: one that
    /// failed across gravity alone takes the gravity reference's direction as lost and
    /// measures it anew (the window's); one that failed on the magnitude stays a rest for as
    /// long as it stays so, and the reference is left as it was ([`Self::holding`]).
    fn reanchor(
        &mut self,
        lost: Option<Lost>,
        accel: &WindowStats,
        mean: &[f64; 6],
        var: &[f64; 6],
    ) -> bool {
        let Some(lost) = lost else {
            self.lost_s = 0.0;
            return false;
        };
        let m = Vector3::new(mean[0], mean[1], mean[2]);
        // Two window means' difference: twice one mean's variance.
        let moved = (0..3)
            .map(|i| (m[i] - self.lost_from[i]).powi(2) / (2.0 * var[i]))
            .sum::<f64>();
        if self.lost_s == 0.0 || moved > self.steady_quantile {
            self.lost_from = m;
            self.lost_s = 0.0;
        }
        let before = self.lost_s;
        self.lost_s += super::batch_duration_s(accel);
        if self.lost_s < REANCHOR_S {
            return false;
        }
        if lost == Lost::Magnitude {
            // Held, as long as it stays so; the reference is left as it was.
            self.holding = true;
            if before < REANCHOR_S {
                self.held += 1;
            }
            return true;
        }
        self.lost_s = 0.0;
        self.reanchored += 1;
        // The window's direction is the new reference (a step of any size: the rest update's
        // linear step would leave part of a large one), gravity's magnitude as it was, with
        // the window mean's own uncertainty across it.
        let g = m.normalize() * self.gravity().norm();
        self.reference[..3].copy_from_slice(g.as_slice());
        self.across_var = (var[0] + var[1] + var[2]) / 3.0;
        self.rest_dir = m.normalize();
        true
    }

    /// How far a rest's specific force may read from the gravity reference for a part whose
    /// accelerometer bias is [`GlrtConfig::accel_bias_sigma_mps2`] per axis, m/s^2: twice
    /// [`BIAS_BOUND_SIGMAS`] of it on each axis (`|b|` at most `3 sqrt(3)` sigma; between two
    /// attitudes the magnitude moves by `(u2 - u1) . b`, at most `2 |b|`). 63 mm/s^2 for a
    /// calibrated part's 6.1 mm/s^2, 10 m/s^2 for an uncalibrated part's 0.1 g.
    fn bias_bound(&self) -> f64 {
        2.0 * BIAS_BOUND_SIGMAS * 3f64.sqrt() * self.accel_bias_sigma_mps2
    }

    /// Whether the window mean `mean` (its variance `var` per axis) lies within
    /// [`Self::bias_bound`] of the gravity reference: its magnitude, plus three sigmas of the
    /// mean's own noise along gravity and of the reference's magnitude, and the whole vector,
    /// plus three sigmas of the mean's noise and the reference's uncertainty across gravity. A
    /// biased part at rest at another attitude reads `g u2 + b` where the carried reference is
    /// `g u2 + R b` (`R` the turn since the reference held `b`): `(I - R) b` apart, at most
    /// `2 |b|`, along gravity and across it; a steady horizontal acceleration `a` is `a` apart.
    fn within_bias_bound(&self, mean: &[f64; 6], var: &[f64; 6]) -> bool {
        let reference = self.gravity();
        let u = reference.normalize();
        let m = Vector3::new(mean[0], mean[1], mean[2]);
        let along_sigma =
            ((0..3).map(|i| u[i] * u[i] * var[i]).sum::<f64>() + self.along_var_now()).sqrt();
        let sigma = (var[0] + var[1] + var[2] + 2.0 * self.across_var_now()).sqrt();
        (m.norm() - reference.norm()).abs() <= self.bias_bound() + 3.0 * along_sigma
            && (m - reference).norm() <= self.bias_bound() + 3.0 * sigma
    }

    /// Gravity references taken as lost and measured anew since the start.
    pub fn reanchored(&self) -> u64 {
        self.reanchored
    }

    /// Rests held against a magnitude the reference does not hold since the start (each
    /// counted once, when it begins).
    pub fn held(&self) -> u64 {
        self.held
    }

    /// The accelerometer's part of `T_mean` (3 degrees of freedom), along gravity (1) and
    /// across it (2) apart: the window mean's distance from the gravity reference along it,
    /// against the mean's noise `var` (per axis), and across it, against that noise plus the
    /// reference's own uncertainty across gravity.
    /// Along is the difference of the magnitudes: a turn keeps a vector's magnitude, so the
    /// accelerometer bias that carrying turned with gravity (it tilts the reference by
    /// `|b| / g`) does not leak into the magnitude test; what a tilt changes of the bias's share
    /// of the magnitude is allowed for ([`Self::along_var_now`]).
    fn accel_mean_statistic(&self, mean: &[f64; 6], var: &[f64; 6]) -> (f64, f64) {
        let reference = self.gravity();
        let u = reference.normalize();
        let m = Vector3::new(mean[0], mean[1], mean[2]);
        let d = m - reference;
        let along = m.norm() - reference.norm();
        let across = (d.norm_squared() - along * along).max(0.0);
        let var_along: f64 =
            (0..3).map(|i| u[i] * u[i] * var[i]).sum::<f64>() + self.along_var_now();
        let var_across = (var[0] + var[1] + var[2] - var_along) / 2.0 + self.across_var_now();
        (along * along / var_along, across / var_across)
    }

    /// Keeps gravity and the gyroscope bias current with a rest batch: the gyroscope bias as a
    /// running mean of gain `gain`, and gravity ([`Self::update_gravity`]) unless the rest is
    /// held against a magnitude the reference does not hold ([`Self::holding`]).
    pub fn update(&mut self, accel: &WindowStats, gyro: &WindowStats, gain: f64) {
        if !self.holding {
            self.update_gravity(accel, gain);
        }
        for i in 3..6 {
            self.reference[i] += gain * (gyro.mean[i - 3] - self.reference[i]);
        }
        self.pool_rest();
    }

    /// Keeps gravity current with a rest batch: its magnitude as a running mean of gain
    /// `gain`, its direction with the gain of a Kalman update on what the gyroscope left
    /// uncertain (at least `gain`).
    fn update_gravity(&mut self, accel: &WindowStats, gain: f64) {
        let reference = self.gravity();
        let u = reference.normalize();
        let d = Vector3::from_fn(|i, _| accel.mean[i] - reference[i]);
        let along = u * d.dot(&u);
        let m_norm = |m: &[f64; 3]| Vector3::from(*m).norm();
        let batch_var = (0..3)
            .map(|i| self.mean_var(i, accel.n as f64))
            .sum::<f64>()
            / 3.0;
        let prior = self.across_var_now();
        let k = (prior / (prior + batch_var)).max(gain);
        // Direction and magnitude apart: a step across gravity alone would lengthen the
        // reference by `|step|^2 / 2 g` (a rest after a turn that carried a 20 mg bias with
        // gravity: 0.4 m/s^2 across, 0.01 m/s^2 longer), which the magnitude test then holds
        // against every later rest. The magnitude is a running mean, but what a tilt since
        // the last rest moved of the bias's share of it ([`Self::along_var_now`]) is
        // uncertain as the direction is: it takes the same Kalman gain.
        let prior_along = self.along_var_now();
        let k_along = (prior_along / (prior_along + batch_var)).max(gain);
        let magnitude = reference.norm() + k_along * (m_norm(&accel.mean) - reference.norm());
        self.along_var = (1.0 - k_along) * prior_along;
        let g = (reference + (d - along) * k).normalize() * magnitude;
        self.reference[..3].copy_from_slice(g.as_slice());
        self.across_var = (1.0 - k) * prior;
        self.moving_s = 0.0;
        self.turned_rad = Vector3::zeros();
        self.rest_dir = g.normalize();
    }

    /// Gives the window's storage back (for the next session).
    pub fn into_ring(self) -> Vec<BatchSums> {
        self.ring
    }

    /// Empties the window (after a gap).
    pub fn clear_window(&mut self) {
        self.head = 0;
        self.filled = 0;
    }

    /// The gravity reference where the body is now, m/s^2.
    pub fn accel_mean_mps2(&self) -> [f64; 3] {
        [self.reference[0], self.reference[1], self.reference[2]]
    }

    /// The gyroscope bias reference, rad/s.
    pub fn gyro_mean_rps(&self) -> [f64; 3] {
        [self.reference[3], self.reference[4], self.reference[5]]
    }
}

/// Pooled degrees of freedom past which the sigmas are no longer refitted: the F quantiles are
/// then within a percent of the chi-squared's, and each refit (three inverse F distributions,
/// on the hot path) costs more as they grow.
const MAX_POOLED_DOF: f64 = 1e5;

/// The noise pooled over rest: within-batch sums of squares and their nominal degrees of
/// freedom per channel, from the learned rest on.
#[derive(Debug, Clone, Copy)]
struct Pool {
    ss: [f64; 6],
    ss_dof: [f64; 6],
    /// Degrees of freedom of the learned correlations (the learned batches less one).
    mean_dof: f64,
    /// The variance each sigma was installed at least with (the noise floor), or 0.
    floor_var: [f64; 6],
    /// Pooled degrees of freedom at which the sigmas are next set from the pool.
    refit_at: f64,
    false_alarm: f64,
}

impl Pool {
    /// The pool of the learned rest `learned`; `installed` is it after the noise floor;
    /// `prior_batches` the batches the part's known noise stands for (0 when unknown).
    fn new(
        installed: &StaticReference,
        learned: &StaticReference,
        false_alarm: f64,
        prior_batches: f64,
    ) -> Self {
        let nominal = learned.batches as f64 * (BATCH_LEN - 1) as f64;
        let sigma = |r: &StaticReference, c: usize| {
            if c < 3 {
                r.accel_sigma_mps2[c]
            } else {
                r.gyro_sigma_rps[c - 3]
            }
        };
        Self {
            ss: std::array::from_fn(|c| sigma(learned, c).powi(2) * nominal),
            ss_dof: [nominal; 6],
            mean_dof: (learned.batches as f64).max(prior_batches) - 1.0,
            floor_var: std::array::from_fn(|c| {
                let (i, l) = (sigma(installed, c), sigma(learned, c));
                if i > l { i * i } else { 0.0 }
            }),
            refit_at: 2.0 * nominal,
            false_alarm,
        }
    }
}
