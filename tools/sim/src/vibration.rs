//! Speed-dependent vibration of a driven robot (motors, wheels, floor), added to what the
//! sensor measures. It is a disturbance at the sensor, not rigid-body motion: it is not part of
//! the truth (its displacement is well below a millimetre at these levels and frequencies).
//!
//! Each sensor axis (accelerometer and gyroscope alike) gets its own zero-mean signal of unit
//! RMS, scaled by the level at 1 m/s times the current wheel speed. The unit signal is band
//! limited: 30% of its power a sinusoid at the wheel's rotation frequency, 30% a sinusoid at
//! the motor's (gear ratio times higher), both with phases following the wheel's rotation, and
//! 40% a chassis resonance excited by the floor (white noise through a damped second-order
//! band-pass resonator). The level is isotropic (the same RMS on every axis), so the mounting
//! of the sensor does not change it.
//!
//! **A floor while the wheels turn** (`floor_accel_rms_mps2`, `floor_gyro_rms_dps`; 0 by
//! default, which leaves the speed-scaled model as it was): motors, gearboxes and a chassis
//! on its wheels do not go quiet at low speed. The floor adds that RMS per axis to the chassis
//! resonance whenever the wheels turn, whatever the speed (at rest there is none). Measured on
//! the corpus's wheeled robots by their own wheel speeds (`python3 tools/real-data/vibration.py`:
//! 1 s windows, standard deviation of the three axes together, 10-90 %; docs/detectors.md,
//! "Short rests"): a Clearpath Husky's MicroStrain 3DM-GX2 shows 54-134 mg and 1.5-5.1 deg/s
//! driving above 0.3 m/s and 96-346 mg and 2-13 deg/s at 0.03-0.3 m/s; the VESC IMU of 1:10
//! F1TENTH cars 6-15 mg and 0.2-0.4 deg/s standing, 95 mg and 2.4 deg/s at 0.03-0.3 m/s; an
//! LSM9DS1 on a home-robot base (a recording outside the corpus) 50-90 mg and 2-4 deg/s at
//! 78 mm/s against 5-10 mg and 0.2 deg/s standing. `mems-sim drive --vibration-floor 0.3,1`
//! (0.3 m/s^2 and 1 deg/s per axis, 53 mg and 1.7 deg/s over three axes) is the low end of
//! those.
//!
//! No power at zero frequency, by design: a vibration moves the sensor about its pose, so its
//! time integral (a velocity for the accelerometer, an angle for the gyroscope) must stay
//! bounded instead of drifting like a random walk.
//! - The chassis term is the band-pass resonance `H(z) = (1 - z^-1) / (1 - a1 z^-1 - a2 z^-2)`
//!   of white noise: the zero at `z = 1` removes the DC exactly, and its running sum is the
//!   difference of two values of a stationary process, so it stays bounded.
//! - The sinusoids are `v sin(k (theta - theta0) + psi)` with wheel speed `v`, wheel angle
//!   `theta` (`theta' = v / r`), `k` 1 (wheel) or the gear ratio (motor), `theta0` the wheel
//!   angle when the wheels start turning and `psi` = +-pi/2 drawn per channel: the integral
//!   over time is `(r / k) (cos psi - cos(k (theta - theta0) + psi))`, which starts at 0 and,
//!   because `cos psi = 0`, oscillates about 0 with amplitude `r / k`. (At a stop it ends
//!   wherever the wheel is: a bounded, zero-mean velocity residue, at most `sqrt(0.6) * level
//!   * r` per motion, which a rest's zero-velocity update removes.)

use std::f64::consts::{FRAC_PI_2, TAU};

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use crate::model::ModelError;
use crate::{stream_rng, streams};

/// Share of the unit signal's power at the wheel frequency.
const WHEEL_POWER: f64 = 0.3;
/// Share of the unit signal's power at the motor frequency.
const MOTOR_POWER: f64 = 0.3;
/// Share of the unit signal's power in the chassis resonance.
const CHASSIS_POWER: f64 = 0.4;

/// Level and spectrum of the vibration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VibrationModel {
    /// Accelerometer disturbance, RMS per axis at a wheel speed of 1 m/s, m/s^2 (proportional
    /// to speed).
    pub accel_rms_mps2: f64,
    /// Gyroscope disturbance, RMS per axis at a wheel speed of 1 m/s, deg/s.
    pub gyro_rms_dps: f64,
    /// Wheel radius, m: the wheel rotates at `speed / (2 pi radius)` Hz.
    pub wheel_radius_m: f64,
    /// Motor revolutions per wheel revolution.
    pub gear_ratio: f64,
    /// Natural frequency of the chassis resonance, Hz.
    pub chassis_hz: f64,
    /// Damping ratio of the chassis resonance (0 < damping < 1).
    pub chassis_damping: f64,
    /// Accelerometer disturbance added to the chassis resonance while the wheels turn at any
    /// speed, RMS per axis, m/s^2 (see the module documentation; 0: none).
    #[serde(default)]
    pub floor_accel_rms_mps2: f64,
    /// The same for the gyroscope, deg/s.
    #[serde(default)]
    pub floor_gyro_rms_dps: f64,
}

impl VibrationModel {
    /// Moderate vibration scaled by `level` (1: 0.1 m/s^2 and 0.5 deg/s RMS per axis at
    /// 1 m/s; 0: none): 5 cm wheels, 30:1 gearing, a 25 Hz chassis resonance with damping 0.1.
    pub fn moderate(level: f64) -> Self {
        Self {
            accel_rms_mps2: 0.1 * level,
            gyro_rms_dps: 0.5 * level,
            wheel_radius_m: 0.05,
            gear_ratio: 30.0,
            chassis_hz: 25.0,
            chassis_damping: 0.1,
            floor_accel_rms_mps2: 0.0,
            floor_gyro_rms_dps: 0.0,
        }
    }

    /// `self` with a floor of `accel_rms_mps2` (m/s^2) and `gyro_rms_dps` (deg/s) RMS per axis
    /// while the wheels turn.
    pub fn with_floor(self, accel_rms_mps2: f64, gyro_rms_dps: f64) -> Self {
        Self {
            floor_accel_rms_mps2: accel_rms_mps2,
            floor_gyro_rms_dps: gyro_rms_dps,
            ..self
        }
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ModelError> {
        let err = |field: &str, reason: String| {
            Err(ModelError {
                field: format!("vibration.{field}"),
                reason,
            })
        };
        for (field, x) in [
            ("accel_rms_mps2", self.accel_rms_mps2),
            ("gyro_rms_dps", self.gyro_rms_dps),
            ("floor_accel_rms_mps2", self.floor_accel_rms_mps2),
            ("floor_gyro_rms_dps", self.floor_gyro_rms_dps),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return err(field, format!("must be finite and >= 0, got {x}"));
            }
        }
        for (field, x) in [
            ("wheel_radius_m", self.wheel_radius_m),
            ("gear_ratio", self.gear_ratio),
            ("chassis_hz", self.chassis_hz),
        ] {
            if !(x.is_finite() && x > 0.0) {
                return err(field, format!("must be finite and > 0, got {x}"));
            }
        }
        let z = self.chassis_damping;
        if !(z > 0.0 && z < 1.0) {
            return err("chassis_damping", format!("needs 0 < damping < 1, got {z}"));
        }
        Ok(())
    }
}

/// Coefficients of the discretised chassis resonance at one sample rate:
/// `x_k = a1 x_(k-1) + a2 x_(k-2) + e_std (w_k - w_(k-1))` with unit stationary variance (a
/// band-pass: the zero at `z = 1` removes the DC).
#[derive(Clone, Copy)]
struct Resonator {
    rate_hz: f64,
    a1: f64,
    a2: f64,
    e_std: f64,
}

impl Resonator {
    /// Poles of the continuous resonance mapped to the sample rate (`z = exp(s dt)`), and the
    /// drive std that gives unit variance. The output is the first difference `y_k - y_(k-1)`
    /// of the AR(2) process `y` driven by `e w` (filters commute), so its variance is
    /// `2 (g0 - g1)` with the AR(2) autocovariances `g0 = e^2 (1 - a2) / ((1 + a2) ((1 - a2)^2 -
    /// a1^2))` and `g1 = a1 g0 / (1 - a2)`, which simplifies to `2 e^2 / ((1 + a2) (1 - a2 +
    /// a1))`.
    fn new(model: &VibrationModel, rate_hz: f64) -> Self {
        let dt = 1.0 / rate_hz;
        let w0 = TAU * model.chassis_hz;
        let z = model.chassis_damping;
        let r = (-z * w0 * dt).exp();
        let theta = w0 * (1.0 - z * z).sqrt() * dt;
        let (a1, a2) = (2.0 * r * theta.cos(), -r * r);
        let var_per_drive = 2.0 / ((1.0 + a2) * (1.0 - a2 + a1));
        Self {
            rate_hz,
            a1,
            a2,
            e_std: var_per_drive.recip().sqrt(),
        }
    }
}

/// The running vibration generator: wheel rotation angle, resonator states and random phases.
pub struct Vibration {
    model: VibrationModel,
    last_t_s: f64,
    /// Wheel rotation angle since the start of the current motion, rad (0 while stopped).
    wheel_angle_rad: f64,
    /// Phase offsets (+-pi/2) of the wheel and motor sinusoids per channel (accel x, y, z,
    /// gyro x, y, z): see the module documentation for why they are not uniform.
    phases: [[f64; 2]; 6],
    /// Last two resonator outputs per channel.
    chassis: [[f64; 2]; 6],
    /// Last resonator input (white-noise draw) per channel, for the resonator's zero at DC.
    last_drive: [f64; 6],
    resonator: Option<Resonator>,
    rng: ChaCha8Rng,
}

impl Vibration {
    /// A generator for `model` with its random phases and noise drawn from `seed`.
    pub fn new(model: &VibrationModel, seed: u64) -> Result<Self, ModelError> {
        model.validate()?;
        let mut rng = stream_rng(seed, streams::VIBRATION);
        let phases = std::array::from_fn(|_| {
            std::array::from_fn(|_| {
                if rng.random_bool(0.5) {
                    FRAC_PI_2
                } else {
                    -FRAC_PI_2
                }
            })
        });
        Ok(Self {
            model: model.clone(),
            last_t_s: 0.0,
            wheel_angle_rad: 0.0,
            phases,
            chassis: [[0.0; 2]; 6],
            last_drive: [0.0; 6],
            resonator: None,
            rng,
        })
    }

    /// The disturbance at `t_s` (non-decreasing between calls) at output rate `rate_hz` while
    /// the wheels run at `wheel_speed_mps`: accelerometer in m/s^2 and gyroscope in deg/s,
    /// sensor frame.
    pub fn step(&mut self, t_s: f64, rate_hz: f64, wheel_speed_mps: f64) -> ([f64; 3], [f64; 3]) {
        let m = &self.model;
        if [
            m.accel_rms_mps2,
            m.gyro_rms_dps,
            m.floor_accel_rms_mps2,
            m.floor_gyro_rms_dps,
        ] == [0.0; 4]
        {
            return ([0.0; 3], [0.0; 3]);
        }
        let dt = (t_s - self.last_t_s).max(0.0);
        self.last_t_s = t_s;
        if wheel_speed_mps == 0.0 {
            // Stopped: the next motion's sinusoids start from their zero-velocity phase.
            self.wheel_angle_rad = 0.0;
        } else {
            self.wheel_angle_rad += wheel_speed_mps / self.model.wheel_radius_m * dt;
        }
        let res = match self.resonator {
            Some(r) if r.rate_hz == rate_hz => r,
            _ => *self.resonator.insert(Resonator::new(&self.model, rate_hz)),
        };
        let mut unit = [0.0; 6];
        // The chassis resonance's own state per channel, for the floor.
        let mut chassis = [0.0; 6];
        for (ch, out) in unit.iter_mut().enumerate() {
            let [x1, x2] = self.chassis[ch];
            let w: f64 = self.rng.sample(StandardNormal);
            let x = res.a1 * x1 + res.a2 * x2 + res.e_std * (w - self.last_drive[ch]);
            self.last_drive[ch] = w;
            self.chassis[ch] = [x, x1];
            chassis[ch] = x;
            let [pw, pm] = self.phases[ch];
            let wheel = (self.wheel_angle_rad + pw).sin();
            let motor = (self.model.gear_ratio * self.wheel_angle_rad + pm).sin();
            *out = (2.0 * WHEEL_POWER).sqrt() * wheel
                + (2.0 * MOTOR_POWER).sqrt() * motor
                + CHASSIS_POWER.sqrt() * x;
        }
        let a = self.model.accel_rms_mps2 * wheel_speed_mps;
        let g = self.model.gyro_rms_dps * wheel_speed_mps;
        let mut accel = [a * unit[0], a * unit[1], a * unit[2]];
        let mut gyro = [g * unit[3], g * unit[4], g * unit[5]];
        if wheel_speed_mps != 0.0 {
            for (out, x) in accel.iter_mut().zip(&chassis[..3]) {
                *out += self.model.floor_accel_rms_mps2 * x;
            }
            for (out, x) in gyro.iter_mut().zip(&chassis[3..]) {
                *out += self.model.floor_gyro_rms_dps * x;
            }
        }
        (accel, gyro)
    }
}
