//! Simulated MPU-9250 physics: the sensor error model and scenarios that carry their ground
//! truth. The register-level device in `acquire::sim` samples a [`SampleSource`] at its output
//! rate and quantizes what it gets, exactly as the ADC would ([`adc::quantize_sample`] is that
//! quantization, shared with the `mems-sim` writer).
//!
//! - [`dlpf`]: the digital low-pass filters the configuration registers select, modelled at
//!   the part's internal rate ([`SimSensor::set_dlpf`] applies them).
//! - [`model`]: the error model (bias, scale, misalignment, nonlinearity, noise, temperature,
//!   warm-up, turn-on repeatability, random walk, bias instability) and its presets.
//! - [`mounting`]: an accelerometer lag behind the gyro and a lever arm from the scenario's
//!   reference point ([`SimSensor::set_mounting`]).
//! - [`scenario`]: six-position, N-orientation, static, ground-robot drive and foot-mounted
//!   walk scenarios with exact truth.
//! - [`vibration`]: the speed-dependent vibration of a driven robot.
//! - [`defects`]: the defects of real logs (repeated rows, host timestamp jitter and
//!   quantisation, a start in motion).
//! - [`hints`]: the robot controller's rest and speed hints during a drive.
//! - [`SimSensor`]: a scenario measured by a powered-on sensor, a [`SampleSource`].
//! - [`calibration`]: the commands that calibrate the simulated part as a user would, which
//!   `mems-stack` and the integration tests run.

pub mod adc;
pub mod calibration;
pub mod defects;
pub mod dlpf;
pub mod hints;
pub mod model;
pub mod mounting;
pub mod scenario;
pub mod vibration;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use recording::Truth;

use model::{G_MPS2, ModelError, Sensor, SensorModel};
use mounting::Mounting;
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

    /// Applies the DLPF `grid.config` from now on (`None`: no filter, samples are what the
    /// sensor measures at the output rate); see [`SimSensor::set_dlpf`].
    ///
    /// # Panics
    /// The default panics when asked for a filter: this source does not model one.
    fn set_dlpf(&mut self, grid: Option<DlpfGrid>) {
        assert!(
            grid.is_none(),
            "this SampleSource does not model the DLPF (asked for {grid:?})"
        );
    }
}

/// A DLPF configuration and the internal sample grid it runs on: internal sample `n` is taken
/// at `start_s + n / (rate * clock_scale)` for each triad's internal rate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DlpfGrid {
    /// The filters.
    pub config: dlpf::DlpfConfig,
    /// Time of internal sample 0, s (the same time base as [`SampleSource::sample`]).
    pub start_s: f64,
    /// The device clock's rate over nominal (1 + error), > 0.
    pub clock_scale: f64,
}

impl DlpfGrid {
    /// The filters `config` on a grid that starts at power-on (t = 0) with a nominal clock, as
    /// a part sampling from power-on at a fixed configuration.
    pub fn from_power_on(config: dlpf::DlpfConfig) -> Self {
        Self {
            config,
            start_s: 0.0,
            clock_scale: 1.0,
        }
    }
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
    /// A logger's defects: repeats and timestamp jitter.
    pub const LOG_DEFECTS: u64 = 6;
    /// The plan of a walk: stance times and swing speeds.
    pub const WALK_PLAN: u64 = 7;
    /// A walker's tremor phases.
    pub const WALK_TREMOR: u64 = 8;
    /// The grade of each stop of a drive on slopes (its own stream, so that drives without
    /// slopes draw as before).
    pub const DRIVE_SLOPES: u64 = 9;
    /// The waypoints, moves and pauses of an arm's path.
    pub const ARM_PLAN: u64 = 40;
    /// The phases of an engine idling at the stops (its own stream, so that drives without an
    /// engine draw as before).
    pub const ENGINE_IDLE: u64 = 41;
    /// A road's rocking of a car's body (its own stream likewise).
    pub const ROAD: u64 = 42;
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
    dlpf: Option<FilterRun>,
    mounting: Mounting,
}

/// The running DLPF of a [`SimSensor`]: both triads' filters on their internal grids.
struct FilterRun {
    grid: DlpfGrid,
    /// The faster internal rate, Hz (with the clock scale): one tick of the run.
    tick_hz: f64,
    /// Ticks per internal sample of each triad (the faster has 1).
    accel_every: u64,
    gyro_every: u64,
    /// Next tick to process.
    next: u64,
    accel: dlpf::TriadFilter,
    gyro: dlpf::TriadFilter,
    /// The latest outputs.
    accel_out: [f64; 3],
    gyro_out: [f64; 3],
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
            dlpf: None,
            mounting: Mounting::default(),
        })
    }

    /// Measures with `mounting`'s accelerometer lag and lever arm from now on (the state after
    /// [`Self::new`]: none). The truth stays the scenario's reference point's.
    pub fn set_mounting(&mut self, mounting: Mounting) {
        self.mounting = mounting;
    }

    /// Applies a DLPF from now on (`None`, the state after [`Self::new`]: no filter).
    ///
    /// With a filter, each triad is measured at its internal rate on the grid `grid` (white
    /// noise drawn at that rate, so its density is kept) and filtered; a sample at `t_s`
    /// returns the latest filter outputs at or before `t_s` (the output is the filter output at
    /// the sample instants: decimation by `1 + SMPLRT_DIV` when `t_s` is on the output grid,
    /// a hold when a triad runs slower than the output) and the die temperature at `t_s`
    /// unfiltered. The `rate_hz` given to the sample calls is then not used. The filters start
    /// in the steady state of their first input. The truth stays that at `t_s`: the
    /// filter's delay shows as a lag of the samples behind it, as on the real part.
    ///
    /// # Panics
    /// If a triad's internal rate does not divide the other's, or the clock scale is not > 0.
    pub fn set_dlpf(&mut self, grid: Option<DlpfGrid>) {
        self.dlpf = grid.map(|grid| {
            assert!(
                grid.clock_scale.is_finite() && grid.clock_scale > 0.0,
                "DLPF clock scale {}",
                grid.clock_scale
            );
            let c = grid.config;
            let fast = c.fast_rate_hz();
            let every = |rate: f64| {
                let n = fast / rate;
                assert!(
                    n.fract() == 0.0,
                    "internal rates {} and {} Hz do not nest",
                    c.accel.internal_rate_hz,
                    c.gyro.internal_rate_hz
                );
                n as u64
            };
            FilterRun {
                grid,
                tick_hz: fast * grid.clock_scale,
                accel_every: every(c.accel.internal_rate_hz),
                gyro_every: every(c.gyro.internal_rate_hz),
                next: 0,
                accel: dlpf::TriadFilter::new(&c.accel),
                gyro: dlpf::TriadFilter::new(&c.gyro),
                accel_out: [0.0; 3],
                gyro_out: [0.0; 3],
            }
        });
    }

    /// The sensor's input at `t_s` (truth plus vibration at `rate_hz`): specific force in g and
    /// angular rate in deg/s, sensor frame.
    fn input(&mut self, truth: &Truth, t_s: f64, rate_hz: f64) -> ([f64; 3], [f64; 3]) {
        let (vib_accel, vib_gyro) =
            self.vibration
                .step(t_s, rate_hz, self.scenario.wheel_speed_mps(t_s));
        let (dist_accel, dist_gyro) = self.scenario.disturbance(t_s);
        let force = self.mounting.specific_force(&self.scenario, truth, t_s);
        let accel_g = std::array::from_fn(|i| (force[i] + vib_accel[i] + dist_accel[i]) / G_MPS2);
        let gyro_dps = std::array::from_fn(|i| {
            truth.angular_rate_rps[i].to_degrees() + vib_gyro[i] + dist_gyro[i]
        });
        (accel_g, gyro_dps)
    }

    /// Runs the filters over every internal tick up to `t_s` and returns their latest outputs.
    fn filtered(&mut self, t_s: f64) -> AnalogSample {
        let mut run = self.dlpf.take().expect("filtered() needs a DLPF");
        // Sample times are rounded to whole nanoseconds: a tick within a thousandth of a tick
        // period after `t_s` is the one `t_s` stands for.
        let last = ((t_s - run.grid.start_s) * run.tick_hz + 1e-3).floor();
        while (run.next as f64) <= last {
            let t = run.grid.start_s + run.next as f64 / run.tick_hz;
            let truth = self.scenario.truth(t.max(0.0));
            let (accel_g, gyro_dps) = self.input(&truth, t, run.tick_hz);
            let c = &run.grid.config;
            if run.next.is_multiple_of(run.accel_every) {
                let rate = c.accel.internal_rate_hz * run.grid.clock_scale;
                let y = self.sensor.measure_accel(t.max(0.0), rate, accel_g);
                run.accel_out = run.accel.step(y);
            }
            if run.next.is_multiple_of(run.gyro_every) {
                let rate = c.gyro.internal_rate_hz * run.grid.clock_scale;
                let y = self.sensor.measure_gyro(t.max(0.0), rate, gyro_dps);
                run.gyro_out = run.gyro.step(y);
            }
            run.next += 1;
        }
        let out = AnalogSample {
            accel_g: run.accel_out,
            gyro_dps: run.gyro_out,
            temp_c: self.sensor.die_temp_c(t_s),
        };
        self.dlpf = Some(run);
        out
    }

    /// The analog sample and the truth at `t_s` (seconds since power-on, non-decreasing between
    /// calls) at output rate `rate_hz`.
    pub fn sample_with_truth(&mut self, t_s: f64, rate_hz: f64) -> (AnalogSample, Truth) {
        let truth = self.scenario.truth(t_s);
        if self.dlpf.is_some() {
            return (self.filtered(t_s), truth);
        }
        let (accel_g, gyro_dps) = self.input(&truth, t_s, rate_hz);
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

    fn set_dlpf(&mut self, grid: Option<DlpfGrid>) {
        SimSensor::set_dlpf(self, grid);
    }
}
