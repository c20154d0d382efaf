//! Simulated MPU-9250 physics: the sensor error model and scenarios that carry their ground
//! truth. The register-level device in `acquire::sim` samples a [`SampleSource`] at its output
//! rate and quantizes what it gets, exactly as the ADC would.

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
