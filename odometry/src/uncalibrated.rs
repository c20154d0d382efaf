//! An accelerometer whose rest reads gravity off: the prior the filter aligns with, and what it
//! estimated of the error.
//!
//! A calibrated part reads local gravity's magnitude within a few tenths of a percent at rest,
//! and the filter starts from the calibration's small bias and scale uncertainty
//! ([`crate::config::OdometryConfig::accel_bias_sigma_mps2`], `accel_residual_scale`). An
//! uncalibrated one (cheap MPU-6050 boards read |g| 2-4 % low; the thesis's uncalibrated
//! MPU-9250 had 0.1-0.2 g offsets) contradicts that prior at its first rest: there the measured
//! specific force `f` (sensor frame, m/s^2) gives `|f| - g`, the error *along gravity*, and
//! nothing else. When `| |f| / g - 1 |` exceeds [`crate::config::UncalibratedAccel::trigger`], or the
//! calibration stage flagged the samples `GRAVITY_OFF` (its learned rest read gravity that far
//! off; its bias refinement then removes the error along gravity before the odometry sees it),
//! the filter:
//! - takes that error as an accelerometer bias along the measured up direction (the alignment's
//!   vertical bias, `eskf::align`: the same as today, only larger). At one attitude a bias and a
//!   scale error along gravity read the same; which it was shows only when the sensor turns;
//! - widens the prior of the bias across gravity to [`crate::config::UncalibratedAccel::bias_sigma_mps2`] per
//!   axis (it is indistinguishable from tilt at that rest, and the alignment correlates the two
//!   exactly), so that later rests at other attitudes (a foot's or a hand's rests, a turn between
//!   zero-velocity updates) estimate it instead of forcing it into the attitude;
//! - carries the sensitivity error it cannot estimate (scale and cross-axis, the filter has no
//!   state for them) as consider parameters ([`crate::eskf::ConsiderModel`]) of
//!   [`crate::config::UncalibratedAccel::scale_sigma`] and [`crate::config::UncalibratedAccel::cross_axis_sigma`], so the
//!   reported 1-sigma holds them.
//!
//! A part within the trigger keeps the calibrated prior unchanged. What the filter holds of the
//! bias at the end, with the sigma of what its rests could not observe added, and the per-axis
//! fit of its rest attitudes ([`crate::attitudes`]) if they allow one ([`AccelEstimate`]) go to
//! the offline JSON, the logs and the serve summary.
//!
//! The bias converges over the first rests and what the track did before is lost, so
//! `mems-odometry offline` runs such a part twice: the second pass with the first pass's
//! per-axis fit applied to the calibration ([`apply_fit`], its sigmas as the prior:
//! [`crate::config::UncalibratedAccel::fitted`]) where its rests allowed one, else with its bias
//! removed ([`remove_bias`]) and the same wide prior around it
//! ([`crate::config::UncalibratedAccel::removed_bias_mps2`]). Live, the one pass reports the fit
//! its rests allow and applies nothing.

use calibrate::calibfile::CalibrationFile;
use nalgebra::{Matrix3, Vector3};

use calibrate_fit::labelfree::LabelFreeError;

use crate::attitudes::{AttitudeFit, RestAttitudes};
use crate::config::{OdometryConfig, UncalibratedAccel};
use crate::eskf::{Eskf, NoiseModel};

/// The accelerometer prior the filter aligns with.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelPrior {
    /// 1-sigma of the bias per sensor axis before alignment, m/s^2 (the alignment removes the
    /// part along gravity, which it measures).
    pub bias_sigma_mps2: Vector3<f64>,
    /// 1-sigma of each entry of the accelerometer's residual error matrix, fraction.
    pub consider: Matrix3<f64>,
    /// `|f| / g - 1` at the alignment rest.
    pub gravity_error: f64,
    /// Whether the rest read gravity beyond the trigger or was flagged `GRAVITY_OFF` (the
    /// uncalibrated prior).
    pub uncalibrated: bool,
    /// Whether the calibration stage flagged the rest `GRAVITY_OFF`.
    pub flagged: bool,
    /// Gravity's direction at the alignment rest, unit vector, sensor frame (up: the specific
    /// force at rest points away from the Earth).
    pub up: Vector3<f64>,
}

impl AccelPrior {
    /// The prior for a rest whose mean specific force is `f_mean` (m/s^2, sensor frame);
    /// `gravity_off`: the calibration stage flagged the part (`corrected_flags::GRAVITY_OFF`),
    /// whose bias refinement may already have brought `|f_mean|` to gravity.
    pub fn at_rest(cfg: &OdometryConfig, f_mean: &Vector3<f64>, gravity_off: bool) -> Self {
        let g = cfg.gravity_mps2;
        let gravity_error = f_mean.norm() / g - 1.0;
        let scale_as_bias = g * cfg.accel_residual_scale;
        let calibrated = Vector3::from(cfg.accel_bias_sigma_mps2).map(|s| s.hypot(scale_as_bias));
        let u = &cfg.uncalibrated;
        let up = f_mean.try_normalize(1e-9).unwrap_or_else(Vector3::z);
        let mut consider = Matrix3::repeat(u.cross_axis_sigma);
        consider.fill_diagonal(u.scale_sigma);
        let removed = u.removed_bias_mps2.is_some() || u.fitted.is_some();
        if !gravity_off && !removed && gravity_error.abs() <= u.trigger {
            return Self {
                bias_sigma_mps2: calibrated,
                consider: Matrix3::repeat(cfg.accel_residual_scale),
                gravity_error,
                uncalibrated: false,
                flagged: false,
                up,
            };
        }
        let mut bias_sigma_mps2 = calibrated.map(|s| s.max(u.bias_sigma_mps2));
        if let Some(fit) = &u.fitted {
            // The samples are corrected with the fit: what is left is its uncertainty.
            bias_sigma_mps2 = calibrated.zip_map(&Vector3::from(fit.bias_sigma_mps2), f64::max);
            for i in 0..3 {
                consider[(i, i)] = fit.scale_sigma[i].max(cfg.accel_residual_scale);
            }
        }
        Self {
            bias_sigma_mps2,
            consider,
            gravity_error,
            uncalibrated: true,
            flagged: gravity_off,
            up,
        }
    }
}

impl AccelPrior {
    /// The filter's noise model under `cfg` for this prior: `cfg.noise`, with the bias's random
    /// walk at least [`UncalibratedAccel::refined_bias_walk_mps3`] for a part the calibration
    /// stage flagged `GRAVITY_OFF`. What the filter calls such a part's bias holds what its
    /// model lacks: the 3 % scale and 2 % cross-axis errors times the changes of specific force
    /// (a stop on a grade tilts gravity in the sensor frame), and the stage's refinement at
    /// every rest along gravity there (no prior, a running mean over its last minute of rest),
    /// which moves it at a rest at another tilt by the share of the offset across the old
    /// gravity that the tilt turns along the new one. A calibrated part's random walk (1e-4)
    /// holds nothing of that: on a simulated drive stopping on grades of up to 5 deg
    /// (`mems-sim drive --duration 120 --turns on --rate 200 --seed 1 --max-slope-deg 5`, the
    /// part of tests/uncalibrated.rs) the filter's bias sigma across gravity fell to
    /// 0.01-0.02 m/s^2 with its estimate 1.4 m/s^2 off, and the position's 1-sigma, 0.38 m,
    /// did not hold its error, 0.66 m; with this walk the error is 0.39 m, its 1-sigma 0.58 m.
    /// Tried and not kept (docs/odometry.md): the bias across gravity held out of the updates,
    /// the walk at rests only, the refinement's share of a tilt added at each rest.
    pub fn noise(&self, cfg: &OdometryConfig) -> NoiseModel {
        let mut noise = cfg.noise;
        if self.flagged {
            noise.accel_bias_random_walk = noise
                .accel_bias_random_walk
                .max(cfg.uncalibrated.refined_bias_walk_mps3);
        }
        noise
    }
}

/// What the filter holds of the accelerometer's error.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct AccelEstimate {
    /// Whether the uncalibrated prior was used (see the module documentation).
    pub uncalibrated: bool,
    /// Whether the calibration stage flagged the part `GRAVITY_OFF` (its bias refinement then
    /// removed the error along gravity before the alignment rest, `gravity_error` is what is
    /// left of it).
    pub flagged: bool,
    /// `|f| / g - 1` at the alignment rest.
    pub gravity_error: f64,
    /// The bias estimate, m/s^2, sensor frame (with the bias an earlier pass removed).
    pub bias_mps2: [f64; 3],
    /// Whether an earlier pass estimated and removed most of it.
    pub two_passes: bool,
    /// Its 1-sigma, m/s^2: the filter's ([`Self::filter_bias_sigma_mps2`]) and, for an
    /// uncalibrated part, what its rests could not tell ([`AccelEstimate::of`]).
    pub bias_sigma_mps2: [f64; 3],
    /// The filter's own 1-sigma of the bias, m/s^2 (given its model, which has no scale).
    pub filter_bias_sigma_mps2: [f64; 3],
    /// The 1-sigma of each axis's sensitivity error carried in the position's 1-sigma, not
    /// estimated by the filter, fraction.
    pub scale_sigma: [f64; 3],
    /// Rest attitudes gathered (poses of [`crate::attitudes`]).
    pub attitudes: usize,
    /// Largest angle between two of them, degrees.
    pub attitude_spread_deg: f64,
    /// Rest samples at an attitude beyond the bins' capacity, not gathered.
    pub attitude_samples_missed: u64,
    /// The per-axis bias and scale fitted to the rest attitudes: the one that corrected this
    /// pass's samples ([`Self::per_axis_applied`]), else this pass's own (reported only).
    pub per_axis: Option<AttitudeFit>,
    /// Whether `per_axis` corrected this pass's samples (an earlier pass fitted it).
    pub per_axis_applied: bool,
    /// Why there is no `per_axis` fit: the check that refused it and what it measured.
    pub per_axis_refused: Option<FitRefusal>,
}

/// The check that refused a per-axis fit of the rest attitudes, with what it measured.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
#[serde(tag = "check", rename_all = "snake_case")]
pub enum FitRefusal {
    /// Fewer distinct attitudes than the fit's 9 parameters need
    /// (`calibrate_fit::labelfree::MIN_POSES`).
    TooFewPoses {
        /// Poses gathered.
        poses: usize,
        /// Distinct attitudes among them.
        distinct: usize,
    },
    /// The attitudes leave a combination of the parameters undetermined (the Jacobian's
    /// condition number above `calibrate_fit::labelfree::MAX_CONDITION`).
    IllConditioned {
        /// The condition number.
        condition: f64,
    },
    /// The fit itself failed (no ellipsoid, no convergence, no usable model).
    Failed,
    /// An axis's scale sigma is not below the prior's ([`UncalibratedAccel::scale_sigma`]).
    ScaleSigma {
        /// The axis, 0-2.
        axis: usize,
        /// Its scale's 1-sigma, fraction.
        sigma: f64,
    },
    /// An axis's scale is beyond [`PLAUSIBLE_SCALE`].
    Scale {
        /// The axis, 0-2.
        axis: usize,
        /// Its scale error, fraction.
        scale: f64,
    },
    /// An axis's bias is beyond three prior sigmas ([`UncalibratedAccel::bias_sigma_mps2`]).
    Bias {
        /// The axis, 0-2.
        axis: usize,
        /// Its bias, m/s^2.
        bias_mps2: f64,
    },
}

impl FitRefusal {
    /// Why `fit` is refused under `cfg`, `None` when it is usable: every scale sigma below
    /// the prior's, every scale within [`PLAUSIBLE_SCALE`] and every bias within three prior
    /// sigmas (beyond, the rests were no rests).
    pub fn of_fit(fit: &AttitudeFit, cfg: &UncalibratedAccel) -> Option<Self> {
        (0..3).find_map(|axis| {
            let (k, dk, b) = (fit.scale[axis], fit.scale_sigma[axis], fit.bias_mps2[axis]);
            if dk >= cfg.scale_sigma {
                Some(Self::ScaleSigma { axis, sigma: dk })
            } else if k.abs() > PLAUSIBLE_SCALE {
                Some(Self::Scale { axis, scale: k })
            } else if b.abs() > 3.0 * cfg.bias_sigma_mps2 {
                Some(Self::Bias { axis, bias_mps2: b })
            } else {
                None
            }
        })
    }

    /// The refusal of the label-free fit's error `e`.
    pub fn of_error(e: &LabelFreeError) -> Self {
        match e {
            LabelFreeError::TooFewPoses { poses, distinct } => Self::TooFewPoses {
                poses: *poses,
                distinct: *distinct,
            },
            LabelFreeError::IllConditioned { condition, .. } => Self::IllConditioned {
                condition: *condition,
            },
            _ => Self::Failed,
        }
    }
}

impl std::fmt::Display for FitRefusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let axis = |i: &usize| ["x", "y", "z"][*i];
        match self {
            Self::TooFewPoses { poses, distinct } => write!(
                f,
                "{distinct} distinct attitudes among {poses} rest poses, the fit needs {}",
                calibrate_fit::labelfree::MIN_POSES
            ),
            Self::IllConditioned { condition } => write!(
                f,
                "the attitudes leave a combination of bias and scale undetermined (condition \
                 number {condition:.0} above {:.0}): rests tilted out of their plane would",
                calibrate_fit::labelfree::MAX_CONDITION
            ),
            Self::Failed => write!(f, "the fit to the rest attitudes failed"),
            Self::ScaleSigma { axis: i, sigma } => write!(
                f,
                "the fit's {} scale 1-sigma {:.1} % is not below the prior's",
                axis(i),
                100.0 * sigma
            ),
            Self::Scale { axis: i, scale } => write!(
                f,
                "the fit's {} scale {:+.1} % is beyond a plausible part's {:.0} %",
                axis(i),
                100.0 * scale,
                100.0 * PLAUSIBLE_SCALE
            ),
            Self::Bias { axis: i, bias_mps2 } => write!(
                f,
                "the fit's {} bias {bias_mps2:+.2} m/s^2 is beyond three prior sigmas (its rests \
                 were no rests)",
                axis(i)
            ),
        }
    }
}

impl AccelEstimate {
    /// The estimate of filter `kf` aligned with `prior` under `cfg` (its removed bias or
    /// applied fit added back), with the rest attitudes `attitudes` of the pass, for local
    /// gravity `g` (m/s^2).
    ///
    /// The bias sigma of an uncalibrated part adds what the filter's cannot hold: the filter
    /// has no scale state, so what it calls bias along gravity holds the scale error times g
    /// (`scale_sigma g` along the alignment's up); across gravity, where no rest at least
    /// [`crate::attitudes::OBSERVED_SPREAD_DEG`] from another was seen, the bias is the
    /// alignment's tilt's and keeps its prior sigma; where one was, it carries the scale's
    /// share too. With a fit applied, the fit's sigma is added instead.
    pub fn of(
        kf: &Eskf,
        prior: &AccelPrior,
        cfg: &UncalibratedAccel,
        attitudes: &RestAttitudes,
        g: f64,
    ) -> Self {
        let applied = cfg.fitted;
        let mut b = kf.x.b_a + Vector3::from(cfg.removed_bias_mps2.unwrap_or_default());
        if let Some(fit) = &applied {
            b += Vector3::from(fit.bias_mps2);
        }
        let filter = kf.accel_bias_sigma();
        let observed = attitudes.observed_across_gravity();
        let extra = match (&applied, prior.uncalibrated) {
            (_, false) => Matrix3::zeros(),
            (Some(fit), true) => {
                Matrix3::from_diagonal(&Vector3::from(fit.bias_sigma_mps2).map(|s| s * s))
            }
            (None, true) => {
                let uu = prior.up * prior.up.transpose();
                let along = (cfg.scale_sigma * g).powi(2);
                let across = if observed {
                    along
                } else {
                    cfg.bias_sigma_mps2.powi(2)
                };
                uu * along + (Matrix3::identity() - uu) * across
            }
        };
        let sigma = filter.zip_map(&extra.diagonal(), |f, e| (f * f + e).sqrt());
        let (per_axis, per_axis_refused) = match applied {
            Some(fit) => (Some(fit), None),
            None => match attitudes.fit(g) {
                Ok(fit) => match FitRefusal::of_fit(&fit, cfg) {
                    None => (Some(fit), None),
                    refused => (None, refused),
                },
                Err(e) => (None, Some(FitRefusal::of_error(&e))),
            },
        };
        Self {
            uncalibrated: prior.uncalibrated,
            flagged: prior.flagged,
            gravity_error: prior.gravity_error,
            bias_mps2: [b.x, b.y, b.z],
            two_passes: cfg.removed_bias_mps2.is_some() || applied.is_some(),
            bias_sigma_mps2: [sigma.x, sigma.y, sigma.z],
            filter_bias_sigma_mps2: [filter.x, filter.y, filter.z],
            scale_sigma: [0, 1, 2].map(|i| prior.consider[(i, i)]),
            attitudes: attitudes.poses_count(),
            attitude_spread_deg: attitudes.spread_deg(),
            attitude_samples_missed: attitudes.missed(),
            per_axis,
            per_axis_applied: applied.is_some(),
            per_axis_refused,
        }
    }
}

/// Largest scale error per axis taken from a fit, fraction (the datasheets' +-3 % initial
/// tolerance, with room for a part out of specification).
pub const PLAUSIBLE_SCALE: f64 = 0.1;

impl std::fmt::Display for AccelEstimate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let b = &self.bias_mps2;
        let s = &self.bias_sigma_mps2;
        write!(
            f,
            "accelerometer bias ({:+.3}, {:+.3}, {:+.3}) +- ({:.3}, {:.3}, {:.3}) m/s^2 (sensor \
             frame)",
            b[0], b[1], b[2], s[0], s[1], s[2]
        )?;
        if self.two_passes {
            write!(
                f,
                ", a first pass's estimate (removed from the samples) and this pass's"
            )?;
        }
        write!(
            f,
            "; the alignment rest read gravity {:+.1} % off",
            100.0 * self.gravity_error
        )?;
        if self.flagged {
            write!(
                f,
                " after the calibration stage's refinement (its learned rest read gravity more \
                 than {:.0} % off, or the part was declared --uncalibrated)",
                100.0 * calibrate::zero_state::learn::CALIBRATED_GRAVITY_ERROR
            )?;
        }
        if self.uncalibrated {
            let c = &self.scale_sigma;
            write!(
                f,
                ": uncalibrated, scale error of ({:.1}, {:.1}, {:.1}) % per axis carried in the \
                 1-sigma",
                100.0 * c[0],
                100.0 * c[1],
                100.0 * c[2]
            )?;
        }
        self.fmt_attitudes(f)
    }
}

impl AccelEstimate {
    /// The rest attitudes and the per-axis fit, for [`std::fmt::Display`].
    fn fmt_attitudes(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.attitudes {
            1 => write!(f, "; 1 rest attitude")?,
            n => write!(
                f,
                "; {n} rest attitudes, {:.0} deg apart at most",
                self.attitude_spread_deg
            )?,
        }
        let Some(fit) = &self.per_axis else {
            return match &self.per_axis_refused {
                Some(why) => write!(f, " (no per-axis scale: {why})"),
                None => write!(f, " (no per-axis scale)"),
            };
        };
        let (k, e) = (&fit.scale, &fit.scale_sigma);
        write!(
            f,
            "; per-axis scale error ({:+.2}, {:+.2}, {:+.2}) +- ({:.2}, {:.2}, {:.2}) % from {} \
             attitudes{}",
            100.0 * k[0],
            100.0 * k[1],
            100.0 * k[2],
            100.0 * e[0],
            100.0 * e[1],
            100.0 * e[2],
            fit.poses,
            if self.per_axis_applied {
                ", applied to this pass's samples with its bias"
            } else {
                ", estimated, not applied (offline applies it in a second pass)"
            }
        )
    }
}

/// `file` with the accelerometer bias `bias_mps2` (sensor frame, m/s^2, as the filter estimates
/// it from the file's corrected samples) removed: the calibration stage corrects
/// `a = g S^-1 (a' - b)`, so a corrected sample that reads `bias_mps2` too much is corrected
/// with `b + S bias_mps2 / g` (g units, raw frame).
pub fn remove_bias(file: &CalibrationFile, bias_mps2: &[f64; 3]) -> CalibrationFile {
    let shift = file.raw_bias_g(&Vector3::from(*bias_mps2));
    let mut out = file.clone();
    for (b, d) in out.bias_g.iter_mut().zip(shift.iter()) {
        *b += d;
    }
    out
}

/// `file` with the per-axis fit `fit` (of samples `file` corrected, [`crate::attitudes`])
/// applied: the stage corrects `c = g S0^-1 (a' - b0)`; the fit says `c / g = S1 a + b1` with
/// `S1 = I + diag(fit.scale)`, `b1 = fit.bias_mps2 / g`; so `a = (S0 S1)^-1 (a' - b0 - S0 b1)`.
/// Only the diagonal of the fit's scale is applied (its cross terms stay in the consider
/// parameters); a bias-only file becomes a scale model.
pub fn apply_fit(file: &CalibrationFile, fit: &AttitudeFit) -> CalibrationFile {
    let s0 = Matrix3::from_fn(|r, c| file.scale[r][c]);
    let s1 = Matrix3::from_diagonal(&Vector3::from(fit.scale).add_scalar(1.0));
    let shift = file.raw_bias_g(&Vector3::from(fit.bias_mps2));
    let s = s0 * s1;
    let mut out = file.clone();
    out.scale = [0, 1, 2].map(|r| [0, 1, 2].map(|c| s[(r, c)]));
    for (b, d) in out.bias_g.iter_mut().zip(shift.iter()) {
        *b += d;
    }
    if out.model == calibrate::model::ModelKind::Bias {
        out.model = calibrate::model::ModelKind::Scale;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_removed_bias_moves_the_raw_bias_through_the_scale() {
        let mut file = CalibrationFile::identity(9.8);
        file.scale[0][0] = 1.02;
        file.bias_g = [0.01, 0.0, 0.0];
        let out = remove_bias(&file, &[0.98, 0.49, -0.98]);
        let want = [0.01 + 1.02 * 0.1, 0.05, -0.1];
        for (b, w) in out.bias_g.iter().zip(want) {
            assert!((b - w).abs() < 1e-12, "{:?}", out.bias_g);
        }
        assert_eq!(out.scale, file.scale);
    }

    #[test]
    fn a_refused_fit_names_the_check_and_what_it_measured() {
        let cfg = UncalibratedAccel::default();
        let fit = AttitudeFit {
            bias_mps2: [0.5, -0.3, 0.2],
            bias_sigma_mps2: [0.01; 3],
            scale: [0.02, -0.01, 0.0],
            scale_sigma: [0.002; 3],
            poses: 12,
            condition: 3.0,
        };
        assert_eq!(FitRefusal::of_fit(&fit, &cfg), None);
        let wide = AttitudeFit {
            scale_sigma: [0.002, 0.05, 0.002],
            ..fit
        };
        let refused = FitRefusal::of_fit(&wide, &cfg).unwrap();
        assert_eq!(
            refused,
            FitRefusal::ScaleSigma {
                axis: 1,
                sigma: 0.05
            }
        );
        assert!(
            refused.to_string().contains("y scale 1-sigma 5.0 %"),
            "{refused}"
        );
        let far = AttitudeFit {
            bias_mps2: [0.5, -0.3, 4.0],
            ..fit
        };
        assert!(matches!(
            FitRefusal::of_fit(&far, &cfg),
            Some(FitRefusal::Bias { axis: 2, .. })
        ));
        let few = FitRefusal::of_error(&LabelFreeError::TooFewPoses {
            poses: 3,
            distinct: 2,
        });
        assert_eq!(
            few.to_string(),
            "2 distinct attitudes among 3 rest poses, the fit needs 9"
        );
    }

    #[test]
    fn only_a_rest_beyond_the_trigger_or_flagged_gets_the_uncalibrated_prior() {
        let cfg = OdometryConfig::mpu9250(9.8);
        let calibrated = AccelPrior::at_rest(&cfg, &Vector3::new(0.0, 0.0, 9.8 * 1.015), false);
        assert!(!calibrated.uncalibrated);
        assert!(calibrated.bias_sigma_mps2.max() < 0.02);
        assert_eq!(
            calibrated.consider,
            Matrix3::repeat(cfg.accel_residual_scale)
        );
        let off = AccelPrior::at_rest(&cfg, &Vector3::new(0.0, 0.0, 9.8 * 1.025), false);
        assert!(off.uncalibrated && !off.flagged);
        assert!(off.bias_sigma_mps2.min() >= cfg.uncalibrated.bias_sigma_mps2);
        assert_eq!(off.consider[(0, 0)], cfg.uncalibrated.scale_sigma);
        assert_eq!(off.consider[(0, 1)], cfg.uncalibrated.cross_axis_sigma);
        let flagged = AccelPrior::at_rest(&cfg, &Vector3::new(0.0, 0.0, 9.8), true);
        assert!(flagged.uncalibrated && flagged.flagged);
        let mut second = cfg;
        second.uncalibrated.removed_bias_mps2 = Some([1.0, 0.0, 0.0]);
        let rerun = AccelPrior::at_rest(&second, &Vector3::new(0.0, 0.0, 9.8), false);
        assert!(rerun.uncalibrated);
        assert_eq!(rerun.bias_sigma_mps2, off.bias_sigma_mps2);
        assert_eq!(rerun.consider, off.consider);
    }
}
