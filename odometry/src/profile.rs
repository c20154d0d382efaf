//! Motion profiles: the rest detector and the rest handling that suit a platform. A wheeled
//! robot or vehicle rests for seconds between motions, vibrates while it moves and starts
//! gently; a foot rests for 0.2-0.5 s at every step and is not quite still while it does.

use calibrate::zero_state::{DetectorConfig, DetectorKind};

use crate::config::OdometryConfig;
use crate::eskf::Manoeuvre;

/// A platform's motion profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Profile {
    /// Wheeled robot or vehicle: the GLRT against the references learned from the first
    /// second of rest (taken with the confidence of 5 s of rest; the noise is pooled over the
    /// rests that follow), rest flags taken in hindsight (a gentle start is flagged rest by a
    /// window that still holds the rest before it).
    #[default]
    Vehicle,
    /// Foot-mounted sensor: the SHOE stance detector (no learning, 5-sample windows), every
    /// stance flag taken as it comes, a zero-velocity update of 0.01 m/s, alignment on half a
    /// second of standing.
    Pedestrian,
}

impl Profile {
    /// The zero-state detector settings for local gravity `gravity_mps2`.
    pub fn detector(self, gravity_mps2: f64) -> DetectorConfig {
        match self {
            Self::Vehicle => DetectorConfig::robot(gravity_mps2),
            Self::Pedestrian => DetectorConfig::new(DetectorKind::Shoe, gravity_mps2),
        }
    }

    /// `config` with this profile's rest handling.
    pub fn odometry(self, mut config: OdometryConfig) -> OdometryConfig {
        if self == Self::Pedestrian {
            // SHOE's windows are 5 samples: no window holds the rest into a step, so there
            // is nothing to withdraw, and a stance is shorter than any confirmation.
            config.rest_hindsight_s = 0.0;
            config.motion_confirm_s = 0.0;
            config.align_s = 0.5;
            // A stance is not still to a robot's 2 mm/s: the foot rolls over. OpenShoe's
            // zero-velocity pseudo-measurement has 0.01 m/s per axis (its Matlab settings,
            // `sigma_vel`); on the real walks of docs/real-data.md it took the loops from
            // 0.19/0.37/0.56 % to 0.14/0.27/0.57 %.
            config.zupt_sigma_mps = 0.01;
            // That 0.01 m/s stands for the foot's own motion in a stance, not for the sensor's
            // noise, and the half second of standing the profile aligns on holds a person's
            // sway, which the effective-sample factors would count as correlated noise: every
            // sample counts as independent. (With the factors, the real walks of
            // docs/real-data.md gave loops of 0.15/0.21/0.57 % and a median of 0.41 % over all
            // eight, but two MicroStrain walks got worse, 7.96 -> 11.64 % and 1.44 -> 6.80 %,
            // the latter no longer covered by its 1-sigma.)
            config.effective_samples = false;
            // For the same reason a stance's updates are made at every sample: the foot's
            // motion is not white noise, so `n` updates are not one of variance
            // `zupt_sigma_mps^2 / n`. (In windows of a propagation interval, two samples at
            // 200 Hz, the MicroStrain walks of docs/real-data.md went from 0.98/0.21/0.15 % to
            // 1.79/1.59/0.32 %, the first no longer covered by its 1-sigma.)
            config.rest_window_drift = 0.0;
            // A swinging foot: several g and hundreds of deg/s within a tenth of a second,
            // tilting through a radian.
            config.manoeuvre = Manoeuvre {
                accel: 30.0,
                rate: 10.0,
                tilt: 1.0,
                duration_s: 0.1,
            };
        }
        config
    }
}
