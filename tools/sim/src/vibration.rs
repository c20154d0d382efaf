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
//! **An engine idling at the stops** (`engine_idle_accel_rms_mps2`, `engine_idle_hz`; 0 by
//! default): a car stopped with its engine running vibrates without moving. An inline
//! four-cylinder four-stroke engine fires twice per crankshaft revolution, so its strongest
//! excitation is the second engine order, `2 rpm / 60` Hz: 20-30 Hz at an idle of 600-900 rpm
//! (the second-order shaking force of the inline four: Heywood, "Internal Combustion Engine
//! Fundamentals", 1988, section 2.2 and chapter 13, on the engine's balance). The corpus's
//! wid-car recordings (an Xsens DOT on a car's body, `python3 tools/real-data/low_frequency.py`)
//! peak at 22-23 Hz and 32-33 Hz, and their stops shake by 52-60 mg and 100-140 mg over the
//! three axes (30-80 mg per axis), with nothing below 2 Hz and the gyroscope as quiet as
//! standing. The model adds, on every accelerometer axis, 70 % of the RMS's power at
//! `engine_idle_hz` and 30 % at twice that (the fourth order), with phases drawn per channel,
//! whenever the wheels stand still after they first turned, and `engine_start_accel_rms_mps2`
//! before the first motion (0 by default: parked with the engine off; wid-car-06 idles at
//! 42-46 mg standing at its start and 52-55 mg at its stop after driving): `mems-sim drive
//! --engine-idle 0.3,23 --engine-start 0.2`.
//!
//! **The same engine shaking the gyroscope** (`engine_idle_gyro_rms_dps`; 0 by default, the
//! gyroscope then as quiet at a stop as standing): an engine's firing torque rocks it on its
//! mounts about the crankshaft (the roll mode; Heywood, chapter 13, on the torque's
//! fluctuation), and a body on a running engine turns back and forth at the firing frequency.
//! wid-car-06 (an Xsens DOT on a car's body, 120 Hz) scatters 0.37-0.53 deg/s per sample and
//! axis at its stop, against 0.11 deg/s of white noise for the MPU-9250 at that rate. The
//! model adds, on every gyroscope axis at the stops after the first motion, the
//! accelerometer's spectrum (70 % of the power at `engine_idle_hz`, 30 % at twice that) with
//! phases of its own per axis: pure sinusoids, so zero-mean (no bias) and an angle that
//! oscillates within twice their amplitudes over their angular frequencies of where the stop
//! began (0.009 deg at 0.45 deg/s and 23 Hz): `mems-sim drive --engine-idle 0.3,23
//! --engine-idle-gyro 0.45`; before the first motion at `engine_start_gyro_rms_dps` (0 by
//! default; wid-car-06 standing at its start, 0.36-0.49 deg/s: `--engine-start-gyro 0.45`).
//! Sampled through the simulated part's low-pass filter
//! (`crate::dlpf`) the shake reads less: 0.38 deg/s RMS per axis with the white noise, at
//! 100 Hz, for 0.45 configured.
//!
//! **A road under a car's body** (`road_accel_rms_mps2`; 0 by default): a road's
//! undulations rock a car's body on its suspension at its bounce and pitch modes, 1-1.5 Hz
//! with a damping ratio of 0.2-0.4 (Gillespie, "Fundamentals of Vehicle Dynamics", SAE 1992,
//! chapter 5, on ride). The wid-car recordings show 2.5-54 mg below 2 Hz while they drive
//! (mostly above 5 mg) against 0.4-2.7 mg standing. The model adds, on every accelerometer
//! axis while the wheels turn, a resonance at [`ROAD_HZ`] with damping [`ROAD_DAMPING`]
//! (band-pass, as the chassis's) of that RMS: `mems-sim drive --road 0.1`.
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
    /// Accelerometer vibration of an engine idling at the stops after the first motion, RMS
    /// per axis, m/s^2 (see the module documentation; 0: none).
    #[serde(default)]
    pub engine_idle_accel_rms_mps2: f64,
    /// The engine's firing frequency at idle (its second order), Hz.
    #[serde(default = "default_engine_idle_hz")]
    pub engine_idle_hz: f64,
    /// The same engine's vibration before the first motion, RMS per axis, m/s^2 (0: parked
    /// with the engine off).
    #[serde(default)]
    pub engine_start_accel_rms_mps2: f64,
    /// The idling engine's angular vibration at the stops after the first motion, RMS per
    /// gyroscope axis, deg/s (see the module documentation; 0: none).
    #[serde(default)]
    pub engine_idle_gyro_rms_dps: f64,
    /// The same engine's angular vibration before the first motion, RMS per gyroscope axis,
    /// deg/s (0: none; wid-car-06 standing at its start scatters 0.36-0.49 deg/s per axis).
    #[serde(default)]
    pub engine_start_gyro_rms_dps: f64,
    /// Accelerometer disturbance of a road rocking a car's body while the wheels turn, RMS
    /// per axis, m/s^2 (see the module documentation; 0: none).
    #[serde(default)]
    pub road_accel_rms_mps2: f64,
}

/// A car body's bounce on its suspension, Hz (module documentation).
pub const ROAD_HZ: f64 = 1.2;
/// Its damping ratio.
pub const ROAD_DAMPING: f64 = 0.3;

/// An idle of 690 rpm's second order, Hz (wid-car-06's stop peaks at 22-23 Hz).
fn default_engine_idle_hz() -> f64 {
    23.0
}

/// Share of the engine's power at its firing frequency (the rest at twice that).
const ENGINE_FIRST_POWER: f64 = 0.7;

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
            engine_idle_accel_rms_mps2: 0.0,
            engine_idle_hz: default_engine_idle_hz(),
            engine_start_accel_rms_mps2: 0.0,
            engine_idle_gyro_rms_dps: 0.0,
            engine_start_gyro_rms_dps: 0.0,
            road_accel_rms_mps2: 0.0,
        }
    }

    /// `self` with a road rocking the body at `accel_rms_mps2` (m/s^2 RMS per axis) while the
    /// wheels turn.
    pub fn with_road(self, accel_rms_mps2: f64) -> Self {
        Self {
            road_accel_rms_mps2: accel_rms_mps2,
            ..self
        }
    }

    /// `self` with an engine idling at the stops at `accel_rms_mps2` (m/s^2 RMS per axis) and
    /// `hz` (its firing frequency), and at `start_rms_mps2` before the first motion.
    pub fn with_engine_idle(self, accel_rms_mps2: f64, hz: f64, start_rms_mps2: f64) -> Self {
        Self {
            engine_idle_accel_rms_mps2: accel_rms_mps2,
            engine_start_accel_rms_mps2: start_rms_mps2,
            engine_idle_hz: hz,
            ..self
        }
    }

    /// `self` with the idling engine shaking the gyroscope at `gyro_rms_dps` (deg/s RMS per
    /// axis) at the stops after the first motion.
    pub fn with_engine_idle_gyro(self, gyro_rms_dps: f64) -> Self {
        Self {
            engine_idle_gyro_rms_dps: gyro_rms_dps,
            ..self
        }
    }

    /// `self` with the engine shaking the gyroscope at `gyro_rms_dps` (deg/s RMS per axis)
    /// before the first motion.
    pub fn with_engine_start_gyro(self, gyro_rms_dps: f64) -> Self {
        Self {
            engine_start_gyro_rms_dps: gyro_rms_dps,
            ..self
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
            (
                "engine_idle_accel_rms_mps2",
                self.engine_idle_accel_rms_mps2,
            ),
            (
                "engine_start_accel_rms_mps2",
                self.engine_start_accel_rms_mps2,
            ),
            ("road_accel_rms_mps2", self.road_accel_rms_mps2),
            ("engine_idle_gyro_rms_dps", self.engine_idle_gyro_rms_dps),
            ("engine_start_gyro_rms_dps", self.engine_start_gyro_rms_dps),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return err(field, format!("must be finite and >= 0, got {x}"));
            }
        }
        for (field, x) in [
            ("wheel_radius_m", self.wheel_radius_m),
            ("gear_ratio", self.gear_ratio),
            ("chassis_hz", self.chassis_hz),
            ("engine_idle_hz", self.engine_idle_hz),
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
    fn new(hz: f64, damping: f64, rate_hz: f64) -> Self {
        let dt = 1.0 / rate_hz;
        let w0 = TAU * hz;
        let z = damping;
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
    /// Whether the wheels have turned yet (the engine idles at the stops after that).
    moved: bool,
    /// Phases of the engine's two orders per accelerometer axis, rad.
    engine_phases: [[f64; 2]; 3],
    /// The same per gyroscope axis, rad.
    engine_gyro_phases: [[f64; 2]; 3],
    /// The road's resonance per accelerometer axis: its last two outputs and last drive, its
    /// coefficients, and its own random stream.
    road: [[f64; 3]; 3],
    road_resonator: Option<Resonator>,
    road_rng: ChaCha8Rng,
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
        let mut engine = stream_rng(seed, streams::ENGINE_IDLE);
        let engine_phases =
            std::array::from_fn(|_| std::array::from_fn(|_| engine.random_range(0.0..TAU)));
        // Drawn after the accelerometer's, which keep their values.
        let engine_gyro_phases =
            std::array::from_fn(|_| std::array::from_fn(|_| engine.random_range(0.0..TAU)));
        Ok(Self {
            model: model.clone(),
            last_t_s: 0.0,
            wheel_angle_rad: 0.0,
            phases,
            chassis: [[0.0; 2]; 6],
            last_drive: [0.0; 6],
            resonator: None,
            moved: false,
            engine_phases,
            engine_gyro_phases,
            road: [[0.0; 3]; 3],
            road_resonator: None,
            road_rng: stream_rng(seed, streams::ROAD),
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
            m.engine_idle_accel_rms_mps2,
            m.engine_start_accel_rms_mps2,
            m.road_accel_rms_mps2,
            m.engine_idle_gyro_rms_dps,
            m.engine_start_gyro_rms_dps,
        ] == [0.0; 9]
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
            _ => *self.resonator.insert(Resonator::new(
                self.model.chassis_hz,
                self.model.chassis_damping,
                rate_hz,
            )),
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
        self.moved |= wheel_speed_mps != 0.0;
        if wheel_speed_mps == 0.0 {
            let level = match self.moved {
                true => self.model.engine_idle_accel_rms_mps2,
                false => self.model.engine_start_accel_rms_mps2,
            };
            let idle = self.engine_idle(t_s, level, &self.engine_phases);
            for (out, x) in accel.iter_mut().zip(idle) {
                *out += x;
            }
            let level = match self.moved {
                true => self.model.engine_idle_gyro_rms_dps,
                false => self.model.engine_start_gyro_rms_dps,
            };
            if level > 0.0 {
                let idle = self.engine_idle(t_s, level, &self.engine_gyro_phases);
                for (out, x) in gyro.iter_mut().zip(idle) {
                    *out += x;
                }
            }
        }
        if wheel_speed_mps != 0.0 && self.model.road_accel_rms_mps2 > 0.0 {
            let road = self.road(rate_hz);
            for (out, x) in accel.iter_mut().zip(road) {
                *out += self.model.road_accel_rms_mps2 * x;
            }
        }
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

    /// The road's unit resonance per accelerometer axis at `rate_hz` (one step).
    fn road(&mut self, rate_hz: f64) -> [f64; 3] {
        let res = match self.road_resonator {
            Some(r) if r.rate_hz == rate_hz => r,
            _ => *self
                .road_resonator
                .insert(Resonator::new(ROAD_HZ, ROAD_DAMPING, rate_hz)),
        };
        std::array::from_fn(|i| {
            let [x1, x2, last] = self.road[i];
            let w: f64 = self.road_rng.sample(StandardNormal);
            let x = res.a1 * x1 + res.a2 * x2 + res.e_std * (w - last);
            self.road[i] = [x, x1, w];
            x
        })
    }

    /// The idling engine's vibration at `t_s` with the RMS `level` per axis and `phases` per
    /// axis (the accelerometer's, m/s^2, or the gyroscope's, deg/s).
    fn engine_idle(&self, t_s: f64, level: f64, phases: &[[f64; 2]; 3]) -> [f64; 3] {
        let m = &self.model;
        let (a1, a2) = (
            level * (2.0 * ENGINE_FIRST_POWER).sqrt(),
            level * (2.0 * (1.0 - ENGINE_FIRST_POWER)).sqrt(),
        );
        let w = TAU * m.engine_idle_hz * t_s;
        std::array::from_fn(|i| {
            let [p1, p2] = phases[i];
            a1 * (w + p1).sin() + a2 * (2.0 * w + p2).sin()
        })
    }
}
