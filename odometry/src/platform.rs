//! The platform from the data: foot-mounted gait, wheeled motion or anything else (an arm, a
//! hand-held box), recognized from the IMU's own samples for `--profile auto`.
//!
//! Method. The samples are cut into windows of [`WINDOW_S`] seconds (by time, at any rate). A
//! window is *moving* when its gyro rms exceeds [`MOVING_GYRO_DPS`], the standard deviation
//! of its specific-force magnitude exceeds [`MOVING_ACCEL_G`], or either spread (the gyro's
//! about its window mean) exceeds [`MOVING_FACTOR`] times the quietest window's so far (a robot
//! at walking pace on a smooth floor vibrates by 50-90 mg and 2-4 deg/s, a standing one by 5-10
//! mg and 0.2 deg/s); resting windows are not counted. With `g` the mean specific-force direction over every
//! sample so far (up, sensor frame: a platform that keeps its attitude, as a foot between
//! strides or a vehicle, holds it; a window's own mean would hold a turning car's centripetal
//! acceleration), over the moving windows:
//! - *tilt rate*: the rms of the angular rate's component perpendicular to `g`, deg/s (pitch and
//!   roll rates of a level platform);
//! - *principal-axis share*: the largest eigenvalue of the angular rate's second-moment matrix
//!   over its trace (1 when every rotation is about one sensor axis, 1/3 when isotropic), and
//!   the *principal axis's angle* to `g`, degrees (0-90);
//! - *impacts per minute*: crossings of `|f| >` [`IMPACT_G`] at least [`IMPACT_GAP_S`] apart.
//!
//! Foot-mounted gait swings the foot about one horizontal axis (the ankle's) at hundreds of
//! deg/s and strikes the ground once per stride with several g; wheeled motion turns about
//! gravity and barely pitches or rolls (a small racing car on a bumpy floor strikes too). The
//! rule (thresholds read off the corpus of docs/real-data.md, where the classes are far apart:
//! feet 0.84-0.91 share about a horizontal axis, 168-307 deg/s tilt, 68-116 impacts/min; cars
//! 2 deg/s tilt; hand-held 0.45-0.67 share):
//! - foot: share >= [`FOOT_MIN_SHARE`] about an axis at least [`FOOT_MIN_AXIS_DEG`] from `g`,
//!   tilt rate >= [`FOOT_MIN_TILT_DPS`] and impacts/min >= [`FOOT_MIN_IMPACTS_PER_MIN`];
//! - wheeled: not carried (below), and tilt rate <= [`WHEELED_MAX_TILT_DPS`] without impacts,
//!   or share >= [`WHEELED_MIN_SHARE`] about an axis within [`WHEELED_MAX_AXIS_DEG`] of `g`
//!   (turning about gravity);
//! - *gait steps per minute*: steps of [`crate::steps`] in a walking cadence per moving minute,
//!   their mean amplitude (m/s^2), and the *still share*, the share of the windows that are not
//!   moving;
//! - *carried* (by a walking person): not a foot, gait steps/min >=
//!   [`WALK_MIN_STEPS_PER_MIN`], mean step amplitude <= [`WALK_MAX_STEP_MPS2`] and impacts/min
//!   <= [`WALK_MAX_IMPACTS_PER_MIN`] (no heel strike, no shaking), principal-axis share <
//!   [`WALK_MAX_SHARE`] and tilt rate > [`WHEELED_MAX_TILT_DPS`] (a hand turns the sensor);
//! - walking (a sensor in a walker's hand): carried, with a still share <=
//!   [`WALK_MAX_STILL_SHARE`] (the hand is never still while its carrier walks). A carried
//!   sensor still for more than a tenth of the recording is other, never wheeled: BROAD's box
//!   moved slowly by hand without breaks, broad-11-slow, shows the steps and amplitudes of a
//!   phone held up while walking, and only its 21 % of rest tells it apart; rtklibexplorer's
//!   walk (an IMU and a GNSS receiver carried through a backyard's tight turns, 13 % still)
//!   turns about gravity with a share of 0.89, which the wheeled rule alone takes for a car.
//!   On the corpus the Tyrex phone walks reach 11-90 gait steps/min of 0.4-1.8 m/s^2,
//!   a share of 0.51-0.87, at most 1 % still windows, 11-40 deg/s; BROAD's hand-moved box
//!   rests on a table for 36-51 % of its windows; the cars tilt by 2 deg/s; the F1TENTH car's
//!   bumps count as 58-67 steps/min but it turns about gravity (share 0.92-0.96);
//! - other: anything else, or fewer than [`MIN_MOVING_S`] seconds of motion.

use ipc_types::units::STANDARD_GRAVITY_MPS2;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use crate::steps::StepDetector;

/// Window length, s.
pub const WINDOW_S: f64 = 1.0;
/// Gyro rms above which a window is moving, deg/s.
pub const MOVING_GYRO_DPS: f64 = 5.0;
/// Standard deviation of `|f|` above which a window is moving, g.
pub const MOVING_ACCEL_G: f64 = 0.02;
/// A window whose spread exceeds this many times the quietest window's moves.
pub const MOVING_FACTOR: f64 = 3.0;
/// Floors of the quietest spreads (a quantised part can show none): gyro deg/s, |f| g.
const QUIET_FLOOR: (f64, f64) = (0.05, 1e-3);
/// Specific-force magnitude of an impact, g.
pub const IMPACT_G: f64 = 2.0;
/// Impacts closer than this are one, s.
pub const IMPACT_GAP_S: f64 = 0.25;
/// Fewest moving seconds a decision is made on.
pub const MIN_MOVING_S: f64 = 2.0;
/// Principal-axis share a foot reaches.
pub const FOOT_MIN_SHARE: f64 = 0.78;
/// Tilt rate a foot reaches, deg/s.
pub const FOOT_MIN_TILT_DPS: f64 = 60.0;
/// Impacts per moving minute a walk reaches (one per stride at 0.5-1 Hz is 30-60).
pub const FOOT_MIN_IMPACTS_PER_MIN: f64 = 20.0;
/// Tilt rate a wheeled platform stays under, deg/s.
pub const WHEELED_MAX_TILT_DPS: f64 = 10.0;
/// Angle from gravity a foot's principal rotation axis exceeds, degrees.
pub const FOOT_MIN_AXIS_DEG: f64 = 45.0;
/// Principal-axis share of a platform turning about gravity.
pub const WHEELED_MIN_SHARE: f64 = 0.85;
/// Angle from gravity of a wheeled platform's principal rotation axis, at most, degrees.
pub const WHEELED_MAX_AXIS_DEG: f64 = 30.0;

/// Gait steps per moving minute a hand-held walk reaches.
pub const WALK_MIN_STEPS_PER_MIN: f64 = 6.0;
/// Mean step amplitude a hand-held walk stays under, m/s^2 (the Tyrex phones: 0.4-1.8).
pub const WALK_MAX_STEP_MPS2: f64 = 2.5;
/// Impacts per moving minute a hand-held walk stays under (the hand holds the sensor off the
/// ground: the Tyrex walks show at most 0.5; the F1TENTH car strikes 42 times a minute in its
/// first 10 s of motion, where its rotation is not yet about gravity alone).
pub const WALK_MAX_IMPACTS_PER_MIN: f64 = 5.0;
/// Principal-axis share a hand-held walk stays under: the hand pitches and rolls the sensor at
/// every step, where a car turning about gravity (the F1TENTH car's bumps count as steps at
/// 18-30 Hz) holds 0.92-0.96.
pub const WALK_MAX_SHARE: f64 = 0.9;
/// Share of still windows a hand-held walk stays under.
pub const WALK_MAX_STILL_SHARE: f64 = 0.1;

/// A platform class.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Platform {
    /// Foot-mounted sensor on a walking person.
    Foot,
    /// Wheeled robot, cart or road vehicle.
    Wheeled,
    /// Anything else: an arm, a hand-held box, a sensor carried by a walker who stands for
    /// more than a tenth of the time, or too little motion to tell.
    Other,
    /// A sensor in the hand of a walker.
    Walking,
}

impl Platform {
    /// Its name as printed (`foot`, `wheeled`, `other`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Foot => "foot",
            Self::Wheeled => "wheeled",
            Self::Other => "other",
            Self::Walking => "walking",
        }
    }
}

/// What the classifier measured, and the class it gives.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Features {
    /// Moving time, s (moving windows times [`WINDOW_S`]).
    pub moving_s: f64,
    /// Rms of the angular rate perpendicular to gravity over the moving windows, deg/s.
    pub tilt_rate_dps: f64,
    /// Largest eigenvalue of the angular rate's second moment over its trace.
    pub principal_share: f64,
    /// Angle between that eigenvalue's axis and gravity, degrees (0-90).
    pub principal_axis_deg: f64,
    /// Impacts per moving minute.
    pub impacts_per_min: f64,
    /// Steps in a walking cadence per moving minute ([`crate::steps`]).
    pub gait_steps_per_min: f64,
    /// Their mean amplitude, m/s^2.
    pub step_amplitude_mps2: f64,
    /// Share of the windows that are not moving.
    pub still_share: f64,
    /// The class the rule gives.
    pub platform: Platform,
}

/// One window's sums.
#[derive(Debug, Clone, Copy, Default)]
struct Window {
    start_ns: u64,
    n: u32,
    f_sum: Vector3<f64>,
    f_norm_sum: f64,
    f_norm_sq: f64,
    w_sum: Vector3<f64>,
    w_sum_sq: f64,
    ww: Matrix3<f64>,
    impacts: u32,
    gait_steps: u32,
    gait_amplitude_sum: f64,
}

/// The classifier: feed it samples in time order ([`Classifier::push`]), read
/// [`Classifier::features`] at any time. It holds a few sums (no allocation).
#[derive(Debug, Clone, Copy, Default)]
pub struct Classifier {
    window: Window,
    last_impact_ns: Option<u64>,
    moving_windows: u32,
    moving_samples: u64,
    /// Sum of every sample's specific force, g.
    f_all: Vector3<f64>,
    /// The quietest window's gyro and |f| spreads so far, deg/s and g.
    quietest: Option<(f64, f64)>,
    ww: Matrix3<f64>,
    impacts: u64,
    /// Windows closed, moving or not.
    windows: u32,
    steps: StepDetector,
    /// Steps in cadence in the moving windows, and the sum of their amplitudes, m/s^2.
    gait_steps: u64,
    gait_amplitude_sum: f64,
}

impl Classifier {
    /// Takes one sample: time `t_ns` (ns, increasing), specific force `f_g` (g, sensor frame),
    /// angular rate `w_dps` (deg/s, sensor frame).
    pub fn push(&mut self, t_ns: u64, f_g: [f64; 3], w_dps: [f64; 3]) {
        let window_ns = (WINDOW_S * 1e9) as u64;
        if self.window.n > 0 && t_ns.saturating_sub(self.window.start_ns) >= window_ns {
            self.close_window();
        }
        self.f_all += Vector3::from(f_g);
        let w = &mut self.window;
        if w.n == 0 {
            w.start_ns = t_ns;
        }
        let f = Vector3::from(f_g);
        let r = Vector3::from(w_dps);
        let norm = f.norm();
        w.n += 1;
        w.f_sum += f;
        w.f_norm_sum += norm;
        w.f_norm_sq += norm * norm;
        w.w_sum += r;
        w.w_sum_sq += r.norm_squared();
        w.ww += r * r.transpose();
        if let Some(step) = self
            .steps
            .push(t_ns, norm * STANDARD_GRAVITY_MPS2)
            .filter(|s| s.in_cadence())
        {
            w.gait_steps += 1;
            w.gait_amplitude_sum += step.amplitude_mps2;
        }
        if norm > IMPACT_G {
            let gap_ns = (IMPACT_GAP_S * 1e9) as u64;
            if self
                .last_impact_ns
                .is_none_or(|t| t_ns.saturating_sub(t) > gap_ns)
            {
                w.impacts += 1;
            }
            self.last_impact_ns = Some(t_ns);
        }
    }

    fn close_window(&mut self) {
        let w = std::mem::take(&mut self.window);
        let n = f64::from(w.n);
        if w.n < 2 {
            return;
        }
        let mean_norm = w.f_norm_sum / n;
        let norm_sd = (w.f_norm_sq / n - mean_norm * mean_norm).max(0.0).sqrt();
        let gyro_rms = (w.w_sum_sq / n).sqrt();
        let gyro_sd = (w.w_sum_sq / n - (w.w_sum / n).norm_squared())
            .max(0.0)
            .sqrt();
        let spread = (gyro_sd.max(QUIET_FLOOR.0), norm_sd.max(QUIET_FLOOR.1));
        let louder = self
            .quietest
            .is_some_and(|(g, a)| spread.0 > MOVING_FACTOR * g || spread.1 > MOVING_FACTOR * a);
        let quietest = self.quietest.get_or_insert(spread);
        *quietest = (quietest.0.min(spread.0), quietest.1.min(spread.1));
        if gyro_rms <= MOVING_GYRO_DPS && norm_sd <= MOVING_ACCEL_G && !louder {
            self.windows += 1;
            return;
        }
        self.windows += 1;
        self.ww += w.ww;
        self.moving_windows += 1;
        self.moving_samples += u64::from(w.n);
        self.impacts += u64::from(w.impacts);
        self.gait_steps += u64::from(w.gait_steps);
        self.gait_amplitude_sum += w.gait_amplitude_sum;
    }

    /// Moving time seen so far, s (closed windows only).
    pub fn moving_s(&self) -> f64 {
        f64::from(self.moving_windows) * WINDOW_S
    }

    /// The features over the windows closed so far, and the class they give. Call
    /// [`Classifier::finish`] first at the end of a recording to count its last window.
    pub fn features(&self) -> Features {
        let moving_s = self.moving_s();
        let n = self.moving_samples.max(1) as f64;
        let up = self.f_all.try_normalize(1e-12).unwrap_or_else(Vector3::z);
        let trace = self.ww.trace();
        let yaw_sq = (up.transpose() * self.ww * up)[(0, 0)];
        let eigen = SymmetricEigen::new(self.ww);
        let i = eigen.eigenvalues.imax();
        let axis = eigen.eigenvectors.column(i).into_owned();
        let (principal_share, principal_axis_deg) = if trace > 0.0 {
            let cos = axis.dot(&up).abs().min(1.0);
            (eigen.eigenvalues[i] / trace, cos.acos().to_degrees())
        } else {
            (0.0, 0.0)
        };
        let mut f = Features {
            moving_s,
            tilt_rate_dps: ((trace - yaw_sq).max(0.0) / n).sqrt(),
            principal_share,
            principal_axis_deg,
            impacts_per_min: self.impacts as f64 / moving_s.max(WINDOW_S) * 60.0,
            gait_steps_per_min: self.gait_steps as f64 / moving_s.max(WINDOW_S) * 60.0,
            step_amplitude_mps2: self.gait_amplitude_sum / (self.gait_steps.max(1) as f64),
            still_share: 1.0 - f64::from(self.moving_windows) / f64::from(self.windows.max(1)),
            platform: Platform::Other,
        };
        f.platform = classify(&f);
        f
    }

    /// Closes the window in progress (the end of a recording).
    pub fn finish(&mut self) {
        if self.window.n > 0 {
            self.close_window();
        }
    }
}

/// The rule of the module documentation.
fn classify(f: &Features) -> Platform {
    if f.moving_s < MIN_MOVING_S {
        return Platform::Other;
    }
    if f.principal_share >= FOOT_MIN_SHARE
        && f.principal_axis_deg >= FOOT_MIN_AXIS_DEG
        && f.tilt_rate_dps >= FOOT_MIN_TILT_DPS
        && f.impacts_per_min >= FOOT_MIN_IMPACTS_PER_MIN
    {
        return Platform::Foot;
    }
    let carried = f.gait_steps_per_min >= WALK_MIN_STEPS_PER_MIN
        && f.step_amplitude_mps2 <= WALK_MAX_STEP_MPS2
        && f.impacts_per_min <= WALK_MAX_IMPACTS_PER_MIN
        && f.principal_share < WALK_MAX_SHARE
        && f.tilt_rate_dps > WHEELED_MAX_TILT_DPS;
    if carried {
        // Still for more than a tenth: a carrier who stands or sets the sensor down, not
        // the walking mode's; but a person's, not a wheeled platform's.
        return match f.still_share <= WALK_MAX_STILL_SHARE {
            true => Platform::Walking,
            false => Platform::Other,
        };
    }
    let level = f.tilt_rate_dps <= WHEELED_MAX_TILT_DPS && f.impacts_per_min == 0.0;
    let turning =
        f.principal_share >= WHEELED_MIN_SHARE && f.principal_axis_deg <= WHEELED_MAX_AXIS_DEG;
    if level || turning {
        return Platform::Wheeled;
    }
    Platform::Other
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds `seconds` of `f(t)` at 100 Hz.
    fn feed(c: &mut Classifier, seconds: f64, f: impl Fn(f64) -> ([f64; 3], [f64; 3])) {
        for i in 0..(seconds * 100.0) as u64 {
            let t = i as f64 / 100.0;
            let (a, w) = f(t);
            c.push(i * 10_000_000, a, w);
        }
        c.finish();
    }

    #[test]
    fn standing_still_is_too_little_motion() {
        let mut c = Classifier::default();
        feed(&mut c, 30.0, |_| ([0.0, 0.0, 1.0], [0.1, -0.1, 0.0]));
        let f = c.features();
        assert_eq!((f.moving_s, f.platform), (0.0, Platform::Other));
    }

    #[test]
    fn turning_about_gravity_with_vibration_is_wheeled() {
        let mut c = Classifier::default();
        feed(&mut c, 20.0, |t| {
            let buzz = 0.05 * (t * 2.0 * std::f64::consts::PI * 31.0).sin();
            ([0.0, buzz, 1.0 + buzz], [0.5, -0.5, 20.0 * (t * 0.3).sin()])
        });
        let f = c.features();
        assert!(f.moving_s >= 19.0, "{f:?}");
        assert_eq!(f.platform, Platform::Wheeled, "{f:?}");
    }

    #[test]
    fn swinging_about_one_axis_with_strikes_is_a_foot() {
        let mut c = Classifier::default();
        feed(&mut c, 20.0, |t| {
            let phase = t % 1.0;
            let strike = if phase < 0.02 { 3.0 } else { 0.0 };
            let swing = 300.0 * (t * 2.0 * std::f64::consts::PI).sin();
            ([0.0, 0.0, 1.0 + strike], [5.0, swing, 2.0])
        });
        assert_eq!(c.features().platform, Platform::Foot, "{:?}", c.features());
    }

    /// A hand's bounce at `hz` steps/s (|f| 1 m/s^2 peak to peak) and pitching (30 deg/s
    /// amplitude, about a horizontal axis), with the yaw of a slow turn.
    fn hand(t: f64, hz: f64) -> ([f64; 3], [f64; 3]) {
        let w = 2.0 * std::f64::consts::PI * hz;
        let bounce = 0.5 / STANDARD_GRAVITY_MPS2 * (w * t).sin();
        ([0.0, 0.0, 1.0 + bounce], [30.0 * (w * t).cos(), 0.0, 8.0])
    }

    #[test]
    fn a_hand_bouncing_at_a_walking_cadence_is_a_walk_unless_it_rests_long_and_never_wheeled() {
        let mut c = Classifier::default();
        feed(&mut c, 60.0, |t| hand(t, 1.7));
        let f = c.features();
        assert_eq!(f.platform, Platform::Walking, "{f:?}");
        assert!((90.0..=104.0).contains(&f.gait_steps_per_min), "{f:?}");
        // The same hand resting on a table for a third of the time: a box moved by hand.
        let mut c = Classifier::default();
        feed(&mut c, 60.0, |t| {
            if t % 30.0 < 10.0 {
                ([0.0, 0.0, 1.0], [0.05, -0.05, 0.0])
            } else {
                hand(t, 1.7)
            }
        });
        let f = c.features();
        assert!(f.still_share > 0.3, "{f:?}");
        assert_eq!(f.platform, Platform::Other, "{f:?}");
        // A walker turning about gravity all along (share 0.85-0.9 about up) who stands for
        // 8 s of 60: carried, so other, not a car turning.
        let turning_walker = |t: f64| {
            let (a, w) = hand(t, 1.7);
            (a, [w[0] * 16.0 / 30.0, 0.0, 40.0 * (0.3 * t).sin()])
        };
        let mut c = Classifier::default();
        feed(&mut c, 60.0, |t| match t < 8.0 {
            true => ([0.0, 0.0, 1.0], [0.05, -0.05, 0.0]),
            false => turning_walker(t),
        });
        let f = c.features();
        assert!((0.1..0.2).contains(&f.still_share), "{f:?}");
        assert!(
            (WHEELED_MIN_SHARE..WALK_MAX_SHARE).contains(&f.principal_share),
            "{f:?}"
        );
        assert!(f.principal_axis_deg < WHEELED_MAX_AXIS_DEG, "{f:?}");
        assert_eq!(f.platform, Platform::Other, "{f:?}");
        // A bounce at 0.5 Hz is no cadence.
        let mut c = Classifier::default();
        feed(&mut c, 60.0, |t| hand(t, 0.5));
        assert_eq!(c.features().platform, Platform::Other, "{:?}", c.features());
    }
}
