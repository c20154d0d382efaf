//! Whether the accelerometer's and the gyroscope's axes agree: between two still moments,
//! gravity's direction in the sensor frame must turn as the integrated gyroscope says. A file
//! whose accelerometer columns are swapped or sign-flipped against its gyroscope's (two header
//! names exchanged, a second part mounted differently) breaks this at the first turn that
//! tilts the sensor, and nothing else names it: the rest detector and the filter's tilt
//! updates take the disagreement for motion or for attitude error, and the run goes on with a
//! track that is silently wrong. (A swap that only a turn about gravity would show, such as x
//! and y on a level robot, cannot be seen this way: such a turn leaves gravity's direction
//! where it was.)
//!
//! Frames and signs: both vectors are in the sensor frame. `q` is the rotation from the
//! sensor frame now to the sensor frame at the previous still window (integrated from the
//! gyroscope's body rates, rad/s, right-handed); gravity's direction, fixed in the world, is
//! therefore `q^-1 u` now if it was `u` then. The accelerometer's specific force when still
//! points up (against gravity): both sides of the comparison use it the same way.
//!
//! The disagreement is measured against what a consistent sensor could show (an acceleration
//! within the stillness test, gyroscope scale and residual bias) and reported; the check does
//! not change the estimate.

use nalgebra::{UnitQuaternion, Vector3};

use ipc_types::CorrectedImuSample;

/// Length of a stillness window, ns: a foot's stance holds one.
const WINDOW_NS: u64 = 200_000_000;
/// Stillness: largest body rate in a window, rad/s (6 deg/s; a robot's vibration while it
/// drives stays below it, and that is fine: gravity's direction is still well measured).
const STILL_RATE_RPS: f64 = 0.1;
/// Stillness: largest standard deviation of any specific-force axis in a window, m/s^2.
const STILL_STD_MPS2: f64 = 0.3;
/// Stillness: largest departure of the window's mean specific force from gravity's
/// magnitude (the first still window's), m/s^2: 0.05 g, so that a mean tilted by an
/// acceleration is at most 3 deg off.
const STILL_NORM_MPS2: f64 = 0.5;
/// Disagreement allowed whatever the turn, rad (10 deg: a steady acceleration of 0.15 g
/// passes the stillness test, a foot rolls over in its stance).
const BASE_TOLERANCE_RAD: f64 = 0.175;
/// Share of the angle turned allowed as disagreement: a gyroscope scale error of a few
/// percent, misalignment between the two sensors' axes.
const TURN_TOLERANCE: f64 = 0.15;
/// Residual gyroscope bias allowed, rad/s (0.2 deg/s: an uncalibrated MEMS part's turn-on
/// bias after the calibration stage's refinement at rest is smaller).
const BIAS_TOLERANCE_RPS: f64 = 0.2 * core::f64::consts::PI / 180.0;
/// Tilts the gyroscope gives smaller than this between two still windows are not checked,
/// rad (20 deg): a swap shows only in a turn that tilts the sensor against gravity.
const MIN_TURN_RAD: f64 = 0.35;

/// Longest interval between two still windows that is checked, s: over a longer one a
/// gyroscope's residual bias alone can tilt its prediction by the tolerance.
const MAX_INTERVAL_S: f64 = 30.0;

/// What the check found so far.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AxesReport {
    /// Pairs of still windows at most `MAX_INTERVAL_S` apart between which the gyroscope
    /// tilted the sensor by at least `MIN_TURN_RAD` against gravity.
    pub checked: u32,
    /// Of those, the pairs where gravity's direction disagreed with the gyroscope beyond the
    /// tolerance.
    pub disagreed: u32,
    /// The largest disagreement, rad, with the angle turned between those windows, rad, and
    /// the time of the window that showed it, ns.
    pub worst: Option<(f64, f64, u64)>,
}

impl AxesReport {
    /// Whether the axes disagree: more than half the checked turns, and at least two.
    pub fn disagree(&self) -> bool {
        self.disagreed >= 2 && 2 * self.disagreed > self.checked
    }
}

/// Sums over one stillness window.
#[derive(Debug, Clone, Copy, Default)]
struct Window {
    start_ns: u64,
    n: u32,
    sum: Vector3<f64>,
    sum_sq: Vector3<f64>,
    max_rate: f64,
}

impl Window {
    /// The window's mean specific force if it was still (`g`: gravity's magnitude so far).
    fn still_mean(&self, g: Option<f64>) -> Option<Vector3<f64>> {
        if self.n < 5 || self.max_rate > STILL_RATE_RPS {
            return None;
        }
        let n = f64::from(self.n);
        let mean = self.sum / n;
        let var = self.sum_sq / n - mean.component_mul(&mean);
        let still = var.max() <= STILL_STD_MPS2 * STILL_STD_MPS2
            && g.is_none_or(|g| (mean.norm() - g).abs() <= STILL_NORM_MPS2);
        still.then_some(mean)
    }
}

/// The check, fed every sample in order ([`AxesCheck::take`]). It finds still windows by
/// itself (not by the rest detector, which may carry gravity by the same gyroscope and so
/// never see a rest when the axes disagree).
#[derive(Debug, Clone, Default)]
pub struct AxesCheck {
    window: Window,
    /// Gravity's magnitude: the first still window's mean specific force, m/s^2.
    g: Option<f64>,
    /// Gravity's direction (unit) in the last still window, the rotation since, and the time
    /// since, s; `None` before the first still window.
    since: Option<(Vector3<f64>, UnitQuaternion<f64>, f64)>,
    prev_ns: Option<u64>,
    report: AxesReport,
}

impl AxesCheck {
    /// What was found so far.
    pub fn report(&self) -> AxesReport {
        self.report
    }

    /// Takes one sample. Returns whether it ended a still window that disagreed with the
    /// gyroscope.
    pub fn take(&mut self, s: &CorrectedImuSample) -> bool {
        let t = s.stamps.sample_ns;
        let dt = self
            .prev_ns
            .map_or(0.0, |p| t.saturating_sub(p) as f64 * 1e-9);
        self.prev_ns = Some(t);
        let w = Vector3::from(s.gyro_rps);
        if let Some((_, q, since_s)) = self.since.as_mut() {
            *q *= UnitQuaternion::from_scaled_axis(w * dt);
            *since_s += dt;
        }
        let f = Vector3::from(s.accel_mps2);
        let window = &mut self.window;
        if window.n == 0 {
            window.start_ns = t;
        }
        window.n += 1;
        window.sum += f;
        window.sum_sq += f.component_mul(&f);
        window.max_rate = window.max_rate.max(w.norm());
        if t.saturating_sub(window.start_ns) < WINDOW_NS {
            return false;
        }
        let ended = std::mem::take(&mut self.window);
        ended
            .still_mean(self.g)
            .is_some_and(|mean| self.still(mean, t))
    }

    /// A still window with mean specific force `mean` ended at `t_ns`: compares its gravity
    /// direction with the one predicted from the previous still window, and starts the next
    /// interval from it.
    fn still(&mut self, mean: Vector3<f64>, t_ns: u64) -> bool {
        let g = *self.g.get_or_insert(mean.norm());
        if g == 0.0 {
            return false;
        }
        let u = mean.normalize();
        let mut disagreed = false;
        if let Some((u0, q, since_s)) = self.since {
            let predicted = q.inverse_transform_vector(&u0);
            // What the gyroscope says tilted against gravity. (Not what the accelerometer
            // says: a steady acceleration within the stillness test tilts its mean too.)
            let turned = predicted.angle(&u0);
            if turned >= MIN_TURN_RAD && since_s <= MAX_INTERVAL_S {
                let angle = predicted.angle(&u);
                let tolerance =
                    BASE_TOLERANCE_RAD + TURN_TOLERANCE * turned + BIAS_TOLERANCE_RPS * since_s;
                self.report.checked += 1;
                if angle > tolerance {
                    self.report.disagreed += 1;
                    disagreed = true;
                }
                if self.report.worst.is_none_or(|(w, _, _)| angle > w) {
                    self.report.worst = Some((angle, turned, t_ns));
                }
            }
        }
        self.since = Some((u, UnitQuaternion::identity(), 0.0));
        disagreed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ipc_types::{Stamps, corrected_flags};

    const G: f64 = 9.81;

    fn sample(t_s: f64, accel: Vector3<f64>, gyro: Vector3<f64>, rest: bool) -> CorrectedImuSample {
        CorrectedImuSample {
            stamps: Stamps {
                sample_ns: (t_s * 1e9).round() as u64,
                ..Stamps::default()
            },
            accel_mps2: accel.into(),
            gyro_rps: gyro.into(),
            flags: if rest { corrected_flags::ZERO_STATE } else { 0 },
            ..CorrectedImuSample::default()
        }
    }

    /// Rests of 1 s with turns of 1 s between them about the sensor axis `axis` at 90 deg/s,
    /// the sensor tilted so that gravity is not along the axis; `swap` exchanges the
    /// accelerometer's x and z. The specific force at each rest is computed independently:
    /// the sensor's attitude as a rotation matrix built from the angle turned so far.
    fn run(axis: Vector3<f64>, swap: bool) -> AxesReport {
        let rate = 90_f64.to_radians();
        let hz = 100.0;
        let up_world = Vector3::new(0.0, 0.0, G);
        let tilt = UnitQuaternion::from_euler_angles(0.5, -0.3, 0.0);
        let mut check = AxesCheck::default();
        let mut angle = 0.0;
        for k in 0..(8.0 * hz) as usize {
            let t = k as f64 / hz;
            let moving = (t % 2.0) >= 1.0;
            let w = if moving {
                axis * rate
            } else {
                Vector3::zeros()
            };
            // Sensor-to-world: the tilt, then the turn about the sensor axis so far.
            let attitude = tilt * UnitQuaternion::from_scaled_axis(axis * angle);
            let mut f = attitude.inverse_transform_vector(&up_world);
            if swap {
                f = Vector3::new(f.z, f.y, f.x);
            }
            check.take(&sample(t, f, w, !moving));
            angle += w.norm() / hz;
        }
        check.report()
    }

    #[test]
    fn a_consistent_sensor_agrees_about_every_axis() {
        for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
            let r = run(axis, false);
            assert_eq!(r.checked, 3, "{axis:?}: {r:?}");
            assert_eq!(r.disagreed, 0, "{axis:?}: {r:?}");
            assert!(r.worst.unwrap().0 < 0.02, "{axis:?}: {r:?}");
            assert!(!r.disagree());
        }
    }

    #[test]
    fn swapped_accelerometer_axes_disagree_with_the_gyroscope() {
        for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
            let r = run(axis, true);
            assert_eq!(r.checked, 3, "{axis:?}: {r:?}");
            assert!(r.disagree(), "{axis:?}: {r:?}");
            // A 90 deg turn seen about the wrong axis: tens of degrees off.
            assert!(r.worst.unwrap().0 > 0.5, "{axis:?}: {r:?}");
        }
    }

    #[test]
    fn rests_without_a_turn_between_them_are_not_checked() {
        let mut check = AxesCheck::default();
        let up = Vector3::new(0.0, 0.0, G);
        for k in 0..600 {
            let t = k as f64 / 100.0;
            check.take(&sample(t, up, Vector3::zeros(), (t % 2.0) < 1.0));
        }
        assert_eq!(check.report(), AxesReport::default());
    }
}
