//! Simulated MPU-9250 physics: the sensor error model and scenarios that carry their ground
//! truth. The register-level device in `acquire::sim` samples a [`SampleSource`] at its output
//! rate and quantizes what it gets, exactly as the ADC would ([`adc::quantize_sample`] is that
//! quantization, shared with the `mems-sim` writer).
//!
//! - [`model`]: the error model (bias, scale, misalignment, nonlinearity, noise, temperature,
//!   warm-up, turn-on repeatability, random walk, bias instability) and its presets.
//! - [`scenario`]: six-position, N-orientation, static and ground-robot drive scenarios with
//!   exact truth.
//! - [`vibration`]: the speed-dependent vibration of a driven robot.
//! - [`hints`]: the robot controller's rest and speed hints during a drive.
//! - [`SimSensor`]: a scenario measured by a powered-on sensor, a [`SampleSource`].

pub mod adc;
pub mod hints;
pub mod model;
pub mod scenario;
pub mod vibration;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use recording::Truth;

use model::{G_MPS2, ModelError, Sensor, SensorModel};
use scenario::Scenario;
use vibration::{Vibration, VibrationModel};

/// What the simulated sensor measures at one output sample, before the ADC (no quantization,
/// no saturation): specific force in g and angular rate in deg/s in the sensor frame, die
/// temperature in degC.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AnalogSample {
    /// Specific force, g, sensor frame (+1 g on z when lying level, z up).
    pub accel_g: [f64; 3],
    /// Angular rate, deg/s, sensor frame.
    pub gyro_dps: [f64; 3],
    /// Die temperature, degC.
    pub temp_c: f64,
}

/// A source of analog samples for the simulated device: called once per output sample with
/// strictly increasing sample times `t_s` (seconds since power-on) at output rate `rate_hz`
/// (which sets the per-sample white-noise standard deviation).
pub trait SampleSource {
    /// The analog measurement at time `t_s`.
    fn sample(&mut self, t_s: f64, rate_hz: f64) -> AnalogSample;
}

/// The ChaCha8 stream numbers of the simulator's random choices: one stream per independent
/// random term, so that changing one term leaves the realisation of the others unchanged.
pub(crate) mod streams {
    /// Headings and tilts of pose placements.
    pub const POSE_PLACEMENT: u64 = 1;
    /// The random rotation of the N-orientation lattice.
    pub const POSE_SPREAD: u64 = 2;
    /// The plan of a drive.
    pub const DRIVE_PLAN: u64 = 3;
    /// Vibration phases and noise.
    pub const VIBRATION: u64 = 4;
    /// Robot hints: encoder scale error, noise, latency and losses.
    pub const HINTS: u64 = 5;
}

/// A ChaCha8 generator for stream `stream` of `seed` (see [`streams`] and the model's streams).
pub(crate) fn stream_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// A scenario measured by a simulated sensor: the scenario's truth plus vibration, through the
/// error model. Deterministic from the seed given at construction.
pub struct SimSensor<S> {
    scenario: S,
    sensor: Sensor,
    vibration: Vibration,
}

impl<S: Scenario> SimSensor<S> {
    /// Powers on a sensor with `model` (turn-on bias drawn from `seed`) on `scenario`, with the
    /// robot's vibration `vibration` (only where the scenario drives wheels).
    pub fn new(
        scenario: S,
        model: &SensorModel,
        vibration: &VibrationModel,
        seed: u64,
    ) -> Result<Self, ModelError> {
        Ok(Self {
            scenario,
            sensor: Sensor::power_on(model, seed)?,
            vibration: Vibration::new(vibration, seed)?,
        })
    }

    /// The analog sample and the truth at `t_s` (seconds since power-on, non-decreasing between
    /// calls) at output rate `rate_hz`.
    pub fn sample_with_truth(&mut self, t_s: f64, rate_hz: f64) -> (AnalogSample, Truth) {
        let truth = self.scenario.truth(t_s);
        let (vib_accel, vib_gyro) =
            self.vibration
                .step(t_s, rate_hz, self.scenario.wheel_speed_mps(t_s));
        let accel_g =
            std::array::from_fn(|i| (truth.specific_force_mps2[i] + vib_accel[i]) / G_MPS2);
        let gyro_dps =
            std::array::from_fn(|i| truth.angular_rate_rps[i].to_degrees() + vib_gyro[i]);
        (self.sensor.measure(t_s, rate_hz, accel_g, gyro_dps), truth)
    }

    /// The scenario being measured.
    pub fn scenario(&self) -> &S {
        &self.scenario
    }

    /// The powered-on sensor (e.g. for its turn-on bias).
    pub fn sensor(&self) -> &Sensor {
        &self.sensor
    }
}

impl<S: Scenario> SampleSource for SimSensor<S> {
    fn sample(&mut self, t_s: f64, rate_hz: f64) -> AnalogSample {
        self.sample_with_truth(t_s, rate_hz).0
    }
}
