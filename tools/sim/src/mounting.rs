//! Where and when the sensor measures, relative to what the scenario moves: the two effects of
//! a mounting that the odometry's model does not carry.
//!
//! - **Accelerometer lag** `accel_lag_s` (s): the accelerometer sample stamped `t` holds the
//!   specific force at `t - accel_lag_s` while the gyro's holds the rate at `t` (positive: the
//!   accelerometer lags). On the MPU-9250 the two triads have their own low-pass filters
//!   (`GYRO_CONFIG`/`CONFIG` `DLPF_CFG` and `ACCEL_CONFIG2` `A_DLPF_CFG`, register map
//!   RM-MPU-9250A-00 rev 1.6, sections 4.6 and 4.8), whose delays differ by up to tens of ms
//!   when they are set apart (gyro 184 Hz, 2.9 ms against accelerometer 10.2 Hz, 16.83 ms);
//!   phones that timestamp the two sensors' events separately have offsets of the same order.
//! - **Lever arm** `lever_arm_m` (m, sensor frame): the sensor sits at `r` from the point whose
//!   motion the scenario describes (its rotation centre: an arm's tool point, a robot's rear
//!   axle). A rigid body's specific force at `r` is the reference point's plus `alpha x r +
//!   omega x (omega x r)` (angular acceleration `alpha`, rate `omega`, both sensor frame;
//!   Titterton and Weston, "Strapdown Inertial Navigation Technology", 2nd ed., section 10.3,
//!   lever-arm compensation). The rate is the same everywhere on the body.
//!
//! The truth written beside the samples stays the reference point's (its position, velocity
//! and specific force): the sensor's own position is `p + R r`.

use nalgebra::Vector3;
use recording::Truth;

use crate::scenario::Scenario;

/// Half-width of the central difference that gives the angular acceleration, s.
const ALPHA_STEP_S: f64 = 1e-3;

/// A sensor's mounting effects (module documentation); the default has none.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Mounting {
    /// Accelerometer lag behind the gyro, s.
    pub accel_lag_s: f64,
    /// The sensor's position from the scenario's reference point, sensor frame, m.
    pub lever_arm_m: [f64; 3],
}

impl Mounting {
    /// Checks the terms: finite, a lag within 0.5 s and a lever arm within 10 m.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.accel_lag_s.is_finite() && self.accel_lag_s.abs() <= 0.5) {
            return Err(format!(
                "accelerometer lag {} s: must be finite and within 0.5 s",
                self.accel_lag_s
            ));
        }
        let r = Vector3::from(self.lever_arm_m);
        if !(r.iter().all(|x| x.is_finite()) && r.norm() <= 10.0) {
            return Err(format!(
                "lever arm {:?} m: must be finite and within 10 m",
                self.lever_arm_m
            ));
        }
        Ok(())
    }

    /// The specific force the sensor feels at `t_s`, m/s^2, sensor frame, where `truth` is the
    /// scenario's truth at `t_s`.
    pub fn specific_force<S: Scenario>(&self, scenario: &S, truth: &Truth, t_s: f64) -> [f64; 3] {
        if *self == Self::default() {
            return truth.specific_force_mps2;
        }
        let t = (t_s - self.accel_lag_s).max(0.0);
        let at = if self.accel_lag_s == 0.0 {
            *truth
        } else {
            scenario.truth(t)
        };
        let f = Vector3::from(at.specific_force_mps2);
        let r = Vector3::from(self.lever_arm_m);
        if r == Vector3::zeros() {
            return f.into();
        }
        let rate = |t: f64| Vector3::from(scenario.truth(t).angular_rate_rps);
        let (before, after) = ((t - ALPHA_STEP_S).max(0.0), t + ALPHA_STEP_S);
        let alpha = (rate(after) - rate(before)) / (after - before);
        let omega = Vector3::from(at.angular_rate_rps);
        (f + alpha.cross(&r) + omega.cross(&omega.cross(&r))).into()
    }
}
