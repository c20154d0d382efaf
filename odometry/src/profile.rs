//! Motion profiles: the rest detector and the rest handling that suit a platform. A wheeled
//! robot or vehicle rests for seconds between motions, vibrates while it moves and starts
//! gently; a foot rests for 0.2-0.5 s at every step and is not quite still while it does.

use calibrate::zero_state::learn::REST_ACCEL_SIGMA_MPS2;
use calibrate::zero_state::{DetectorConfig, DetectorKind, ROBOT_LEARN_S};
use ipc_types::stream::plausible::Envelope;
use ipc_types::units::STANDARD_GRAVITY_MPS2;

use crate::config::OdometryConfig;
use crate::eskf::Manoeuvre;
use crate::hand_bound::HAND_SPEED_SIGMA_MPS;
use crate::platform::Platform;

/// A platform's motion profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Profile {
    /// Recognize the platform from the data ([`crate::platform`]) and take its profile:
    /// `pedestrian` for a foot, `vehicle` for wheeled motion, `walking` for a walker's hand,
    /// `other` for anything else.
    #[default]
    Auto,
    /// Wheeled robot or vehicle: the GLRT against the references learned from the first
    /// second of rest (taken with the confidence of 5 s of rest; the noise is pooled over the
    /// rests that follow), rest flags taken in hindsight (a gentle start is flagged rest by a
    /// window that still holds the rest before it), the non-holonomic constraint without
    /// hints ([`crate::nonholonomic`]) and rests that vibrate refused.
    #[value(alias = "wheeled")]
    Vehicle,
    /// Foot-mounted sensor: the SHOE stance detector (no learning, 5-sample windows), every
    /// stance flag taken as it comes, a zero-velocity update of 0.01 m/s, alignment on half a
    /// second of standing.
    Pedestrian,
    /// Anything else (an arm, a hand-held box): the vehicle's detector with a window of 0.2 s
    /// (an arm's pauses are that short) and rest handling, without the non-holonomic
    /// constraint, and the velocity held to a hand's speed scale while it moves
    /// ([`crate::hand_bound`]).
    Other,
    /// A sensor in the hand of a walker (a phone held in front or up): pedestrian dead
    /// reckoning ([`crate::walking`]: a velocity update at each step, no zero-velocity update
    /// while walking, an alignment on whole steps when the walker never stands still), the
    /// robot's GLRT (0.5 s windows: a standing walker's rests, not the quiet instants between
    /// steps).
    #[value(alias = "hand-held", alias = "handheld")]
    Walking,
}

/// 1-sigma of the IMU-only non-holonomic constraint over a second of driving, m/s: skid and the
/// lever arm of an IMU off the rear axle (`omega x r`: 0.3 m at 20 deg/s is 0.1 m/s).
pub const WHEELED_NONHOLONOMIC_SIGMA_MPS: f64 = 0.1;

/// A rest whose detector window vibrates by more than this many times the alignment rest's
/// standard deviation is refused on a wheeled platform: a robot standing vibrates by 5-10 mg,
/// driving at walking pace on a smooth floor by 50-90 mg (an LSM9DS1 on a home-robot base).
pub const WHEELED_REST_VIBRATION_FACTOR: f64 = 3.0;

/// The GLRT's window for anything else than a foot or a wheeled platform, s: an arm pauses
/// for 0.1-0.65 s between moves (the MPU-family arm recordings), shorter than the
/// robot's 0.5 s window, which never finds them. Nothing vibrates there while it moves, so the
/// window need not be long enough to see vibration below the part's noise; on a simulated
/// stop-and-go robot a 0.2 s window and hindsight took cruising for rest (15-34 % of the
/// distance off on three seeds against 0.7-6.5 % with 0.5 s), while the simulated arm of
/// docs/detectors.md, "Short rests", finds every pause with them.
pub const OTHER_GLRT_WINDOW_S: f64 = 0.2;

/// Start-up learning of the vehicle profile's detector, s, when it is asked for by name: its
/// stops are seconds long, and on the simulated drives of docs/odometry.md ("wheeled-sim")
/// the robot's half second (`calibrate::zero_state::ROBOT_LEARN_S`, which `auto` starts with)
/// took one seed of five from 0.61 % to 3.0 % of its distance.
pub const VEHICLE_LEARN_S: f64 = 1.0;

/// Rest a robot's or an arm's filter aligns on after its detector has learned, s: with the
/// detector's half second of learning
/// ([`calibrate::zero_state::ROBOT_LEARN_S`]) a rest of 1 s aligns (with speed hints the
/// navigator takes a second). Half a second's mean holds
/// the noise of an MPU-9250 (datasheet densities 0.01 deg/s/sqrt(Hz), 300 ug/sqrt(Hz)) to
/// 0.014 deg/s of gyroscope bias and 0.02 deg of tilt, below what its bias leaves
/// (docs/detectors.md, "Short rests", measures it on simulated robots and arms).
pub const ROBOT_ALIGN_S: f64 = 0.5;

impl Profile {
    /// The profile for a recognized platform.
    pub fn for_platform(platform: Platform) -> Self {
        match platform {
            Platform::Foot => Self::Pedestrian,
            Platform::Wheeled => Self::Vehicle,
            Platform::Other => Self::Other,
            Platform::Walking => Self::Walking,
        }
    }

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Auto => "auto",
            Self::Vehicle => "vehicle",
            Self::Pedestrian => "pedestrian",
            Self::Other => "other",
            Self::Walking => "walking",
        }
    }

    /// The zero-state detector settings for local gravity `gravity_mps2` (`Auto` before the
    /// platform is known: the GLRT).
    pub fn detector(self, gravity_mps2: f64) -> DetectorConfig {
        match self {
            Self::Pedestrian => DetectorConfig::new(DetectorKind::Shoe, gravity_mps2),
            // The live calibration stage's default too (`mems-calibrate serve`), so that live
            // and offline agree under any of these.
            Self::Auto => DetectorConfig::robot(gravity_mps2),
            Self::Walking => {
                // A walker's hand is never still while they walk: a window that shakes more
                // than any part's noise is no rest, however steady its means (a steady turn).
                let mut config = DetectorConfig::robot(gravity_mps2);
                config.learn.max_accel_sigma_mps2 = Some(REST_ACCEL_SIGMA_MPS2);
                // A hand turns its uncalibrated part's offset with the gravity reference as a
                // vehicle does, but the allowance for that (a tenth of g per axis) also takes a
                // hand's slow motion after a tilt for rest: on the perturbed Tyrex walks
                // (docs/real-data.md) tyrex-nexus5-jakob-ar then took 304 such rests, its
                // zero-velocity NIS 411 per degree of freedom, and ended 7.7 m off instead of
                // 3.7. A hand-held part keeps the calibrated allowance.
                config.glrt.uncalibrated_accel_bias_sigma_mps2 = config.glrt.accel_bias_sigma_mps2;
                config
            }
            Self::Vehicle => {
                let mut config = DetectorConfig::robot(gravity_mps2);
                config.learn.duration_s = VEHICLE_LEARN_S;
                config.learn.first_s = Some(VEHICLE_LEARN_S);
                config
            }
            Self::Other => {
                let mut config = DetectorConfig::robot(gravity_mps2);
                config.glrt.window_s = OTHER_GLRT_WINDOW_S;
                config
            }
        }
    }

    /// `config` with this profile's rest handling.
    pub fn odometry(self, mut config: OdometryConfig) -> OdometryConfig {
        if matches!(self, Self::Auto | Self::Other | Self::Walking) {
            // The vehicle profile keeps its second, as its learning ([`VEHICLE_LEARN_S`]).
            config.align_s = ROBOT_ALIGN_S;
        }
        // The end of the learning window (`navigator::learning`), unless `config` has its
        // own: the robot's half second is within every learned detector's window these
        // profiles run (the vehicle profile's second, live `mems-calibrate serve`'s half
        // second). SHOE learns nothing.
        config.learned_rest_s = match self {
            Self::Pedestrian => 0.0,
            _ if config.learned_rest_s > 0.0 => config.learned_rest_s,
            _ => ROBOT_LEARN_S,
        };
        if self == Self::Other {
            // The detector's window is shorter (`OTHER_GLRT_WINDOW_S`), and so is the time a
            // window still holds the rest before a motion.
            config.rest_hindsight_s = OTHER_GLRT_WINDOW_S;
            // A hand or an arm moves within reach: its velocity is bounded.
            config.hand_speed_sigma_mps = HAND_SPEED_SIGMA_MPS;
        }
        // The walking mode's settings: `config`'s when given (`--weinberg-k`), for the walking
        // profile only.
        config.walking = match self {
            Self::Walking => Some(config.walking.unwrap_or_default()),
            _ => None,
        };
        // A wheel glides through what a detector may take for rest; a foot and a walker's
        // hand cannot (`consistency`'s false rests).
        config.consistency.false_rest_glides = !matches!(self, Self::Pedestrian | Self::Walking);
        // A wheeled platform's rests shake with its engine or motors, and until the platform
        // is known a rest may be a car idling (`crate::rest_scatter`).
        config.rest_rate_scatter = matches!(self, Self::Auto | Self::Vehicle);
        if self == Self::Vehicle {
            config.imu_nonholonomic_sigma_mps = WHEELED_NONHOLONOMIC_SIGMA_MPS;
            config.rest_vibration_factor = WHEELED_REST_VIBRATION_FACTOR;
        }
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
            // A swinging foot is not a vibrating chassis: its steps are measured motion, and the
            // walks of docs/real-data.md were tuned without the sampled noise.
            config.sampled_noise = false;
            // A swinging foot: several g and hundreds of deg/s within a tenth of a second,
            // tilting through a radian.
            config.manoeuvre = Manoeuvre {
                accel: 30.0,
                rate: 10.0,
                tilt: 1.0,
                duration_s: 0.1,
            };
            // A heel strike: the OpenShoe figure-8 walk peaks at 19.3 g (magnitude), the
            // corpus's walks hold at most 2.7 g from gravity over 0.5 s.
            config.plausible = Envelope {
                peak_force_mps2: 24.0 * STANDARD_GRAVITY_MPS2,
                sustained_force_mps2: 6.0 * STANDARD_GRAVITY_MPS2,
                ..config.plausible
            };
        }
        config
    }
}
