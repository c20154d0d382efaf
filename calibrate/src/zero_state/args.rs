//! The detector's command-line options, shared by every process that runs the calibration
//! stage (`mems-calibrate serve`, `mems-odometry offline`, `mems-calibrate gyrocal`), so that
//! a detector is configured the same way live and offline.

use super::{DetectorConfig, DetectorKind};

/// Detector options; each overrides the process's default [`DetectorConfig`] when given.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct DetectorArgs {
    /// Zero-state detector: glrt (accelerometer and gyroscope; needs the gyroscope),
    /// glrt-accel (the same on the accelerometer alone, for a sensor run without its
    /// gyroscope), yu (accelerometer batches of 20, as in the thesis) or shoe (a foot-mounted
    /// sensor). Default: the process's (the vehicle profile's glrt).
    #[arg(long, value_enum)]
    pub detector: Option<DetectorKind>,
    /// The GLRT's window, s, at any rate (default 0.5; whole batches of 20 samples, at least
    /// one).
    #[arg(long, value_name = "SECONDS")]
    pub glrt_window_s: Option<f64>,
    /// Length of the start-up rest the detector learns its thresholds from, s (default: the
    /// process's, 0.5 for `mems-calibrate serve` and `mems-odometry`'s auto and other profiles,
    /// 1 for its vehicle profile; the first rest of this length anywhere in the data, at least
    /// two batches of 20 samples). Longer than a robot's half second, the robot's detector
    /// starts from its first half second of rest and learns again at the first rest of this
    /// length that is much quieter than what it stands on (a first half second learned while
    /// the robot drove).
    #[arg(long)]
    pub learn_s: Option<f64>,
    /// The first window the robot's detector builds its rule from, s, when `--learn-s` is
    /// longer (default: the process's, 0.5 for the robot's detector, 1 for `mems-odometry`'s
    /// vehicle profile): the detector learns again at the first rest of `--learn-s` that is
    /// much quieter. As long as `--learn-s`, the detector waits for that rest.
    #[arg(long, value_name = "SECONDS")]
    pub learn_first_s: Option<f64>,
    /// SHOE detector: the fixed threshold (default OpenShoe's 3e4).
    #[arg(long)]
    pub shoe_gamma: Option<f64>,
    /// SHOE detector: the adaptive threshold's factor on the recent minimum (0: fixed).
    #[arg(long)]
    pub shoe_factor: Option<f64>,
    /// Largest relative difference between the learned rest's specific force and local
    /// gravity (default 0.05 with a calibration file, 0.39 without one:
    /// `zero_state::learn::UNCALIBRATED_GRAVITY_ERROR`).
    #[arg(long, value_name = "FRACTION")]
    pub max_gravity_error: Option<f64>,
    /// Largest spread of the accelerometer's samples about the learning window's mean, any
    /// axis, m/s^2, that a rest may show whatever the part (default: none; `mems-odometry`'s
    /// walking profile 0.15, `zero_state::learn::REST_ACCEL_SIGMA_MPS2`: a walker's hand is
    /// never that still).
    #[arg(long, value_name = "MPS2")]
    pub max_rest_accel_sigma: Option<f64>,
    /// Largest mean rate on any gyroscope axis the learned rest may show, deg/s (default 30:
    /// `zero_state::learn::MAX_GYRO_OFFSET_DPS`, the largest zero-rate offset of a cheap MEMS
    /// gyroscope; a faster steady rate is a turn).
    #[arg(long, value_name = "DPS")]
    pub max_gyro_offset_dps: Option<f64>,
    /// The GLRT's allowance for the zero-g offset of a part whose learned rest reads gravity
    /// more than 2 % off, 1-sigma per axis, m/s^2, turned with the gravity reference through
    /// turns and tilts (default 0.1 g; `mems-odometry`'s walking profile keeps a calibrated
    /// part's 0.0061: `zero_state::glrt::GlrtConfig::uncalibrated_accel_bias_sigma_mps2`).
    #[arg(long, value_name = "MPS2")]
    pub glrt_uncalibrated_offset_mps2: Option<f64>,
    /// Take the accelerometer as uncalibrated whatever its learned rest reads: its offset
    /// across gravity unknown (0.1 g per axis in the GLRT's allowance), its samples flagged
    /// GRAVITY_OFF (the odometry's uncalibrated prior). For a part with no calibration of its
    /// own whose rest happens to read gravity within 2 % (an offset across gravity barely
    /// moves the magnitude).
    #[arg(long)]
    pub uncalibrated: bool,
}

impl DetectorArgs {
    /// `default` with the options given applied; an option out of its range is an error
    /// naming it.
    pub fn apply(&self, mut config: DetectorConfig) -> Result<DetectorConfig, String> {
        let positive = |name: &str, v: f64| {
            (v > 0.0 && v.is_finite())
                .then_some(v)
                .ok_or_else(|| format!("--{name} must be > 0, got {v}"))
        };
        if let Some(kind) = self.detector {
            config.kind = kind;
        }
        if let Some(s) = self.glrt_window_s {
            config.glrt.window_s = positive("glrt-window-s", s)?;
        }
        if let Some(s) = self.learn_s {
            config.learn.duration_s = positive("learn-s", s)?;
        }
        if let Some(s) = self.learn_first_s {
            config.learn.first_s = Some(positive("learn-first-s", s)?);
        }
        if let Some(gamma) = self.shoe_gamma {
            config.shoe.gamma = positive("shoe-gamma", gamma)?;
        }
        if let Some(factor) = self.shoe_factor {
            if !(factor >= 0.0 && factor.is_finite()) {
                return Err(format!("--shoe-factor must be >= 0, got {factor}"));
            }
            config.shoe.adaptive_factor = factor;
        }
        if let Some(e) = self.max_gravity_error {
            config.learn.max_gravity_error = positive("max-gravity-error", e)?;
        }
        if let Some(s) = self.max_rest_accel_sigma {
            config.learn.max_accel_sigma_mps2 = Some(positive("max-rest-accel-sigma", s)?);
        }
        if let Some(r) = self.max_gyro_offset_dps {
            config.learn.max_gyro_offset_rps = positive("max-gyro-offset-dps", r)?.to_radians();
        }
        if let Some(s) = self.glrt_uncalibrated_offset_mps2 {
            config.glrt.uncalibrated_accel_bias_sigma_mps2 =
                positive("glrt-uncalibrated-offset-mps2", s)?;
        }
        config.offset_unknown |= self.uncalibrated;
        Ok(config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn given_options_override_the_default_and_bad_ones_are_named() {
        let default = DetectorConfig::new(DetectorKind::Glrt, 9.8);
        assert_eq!(DetectorArgs::default().apply(default), Ok(default));
        let args = DetectorArgs {
            detector: Some(DetectorKind::GlrtAccel),
            glrt_window_s: Some(0.25),
            learn_s: Some(2.5),
            learn_first_s: Some(0.5),
            max_rest_accel_sigma: Some(0.15),
            max_gyro_offset_dps: Some(45.0),
            glrt_uncalibrated_offset_mps2: Some(0.0061),
            uncalibrated: true,
            ..DetectorArgs::default()
        };
        let c = args.apply(default).unwrap();
        assert_eq!(c.kind, DetectorKind::GlrtAccel);
        assert_eq!(c.glrt.window_s, 0.25);
        assert_eq!(c.learn.duration_s, 2.5);
        assert_eq!(c.learn.first_window_s(), 0.5);
        assert!(c.learn.learns_again() && !default.learn.learns_again());
        assert_eq!(c.learn.max_accel_sigma_mps2, Some(0.15));
        assert_eq!(c.learn.max_gyro_offset_rps, 45f64.to_radians());
        assert_eq!(c.glrt.uncalibrated_accel_bias_sigma_mps2, 0.0061);
        assert!(c.offset_unknown && !default.offset_unknown);
        for (args, name) in [
            (
                DetectorArgs {
                    learn_s: Some(0.0),
                    ..Default::default()
                },
                "--learn-s",
            ),
            (
                DetectorArgs {
                    learn_first_s: Some(-1.0),
                    ..Default::default()
                },
                "--learn-first-s",
            ),
            (
                DetectorArgs {
                    shoe_gamma: Some(f64::NAN),
                    ..Default::default()
                },
                "--shoe-gamma",
            ),
            (
                DetectorArgs {
                    shoe_factor: Some(-1.0),
                    ..Default::default()
                },
                "--shoe-factor",
            ),
            (
                DetectorArgs {
                    max_rest_accel_sigma: Some(-0.1),
                    ..Default::default()
                },
                "--max-rest-accel-sigma",
            ),
            (
                DetectorArgs {
                    max_gyro_offset_dps: Some(0.0),
                    ..Default::default()
                },
                "--max-gyro-offset-dps",
            ),
            (
                DetectorArgs {
                    glrt_uncalibrated_offset_mps2: Some(-0.1),
                    ..Default::default()
                },
                "--glrt-uncalibrated-offset-mps2",
            ),
        ] {
            assert!(args.apply(default).unwrap_err().starts_with(name));
        }
    }
}
