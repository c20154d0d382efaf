//! The sensor error model: what an MPU-9250-class accelerometer and gyroscope add to the true
//! specific force and angular rate before the ADC.
//!
//! Each triad (accelerometer in g, gyroscope in deg/s; "unit" below) measures
//!
//! ```text
//! y = (I + diag(s + c_s dT) + M) q(u) + b + c_b dT + b_on + b_w exp(-t / tau_w) + b_rw(t) + b_bi(t) + n
//! q(u)_i = u_i + k_i u_i^2,    dT = T_die(t) - T_ref
//! ```
//!
//! with `u` the true input in the sensor frame, `s` the scale-factor error, `M` the
//! misalignment / cross-axis matrix (zero diagonal), `k` the scale nonlinearity, `b` the fixed
//! bias, `c_b` and `c_s` the temperature coefficients of bias and scale, `b_on` the turn-on bias
//! (drawn once per power-on), `b_w` the warm-up transient, `b_rw` a bias random walk, `b_bi` the
//! bias instability (flicker) and `n` white noise. Every term is a parameter; zero turns it off.
//!
//! White-noise convention (the one Allan-deviation analysis and Kalibr use): a noise density
//! `N` (unit/sqrt(Hz)) gives a per-sample standard deviation `N * sqrt(rate_hz)` at output rate
//! `rate_hz`, so that the Allan deviation of the output is `N / sqrt(tau)`. Without a DLPF the
//! whole density reaches the samples at any output rate; with one ([`crate::dlpf`], applied by
//! [`crate::SimSensor::set_dlpf`]) the noise is drawn at the internal rate and filtered, which
//! keeps the low-frequency density (and the long-cluster Allan deviation) and correlates
//! successive samples.
//!
//! Everything random is drawn from ChaCha8 streams of one seed, one stream per term and triad,
//! so that switching one term on or off does not change the realisation of the others.

use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use crate::{AnalogSample, stream_rng};

/// Standard gravity in m/s^2, the accelerometer's unit "g" (the datasheet sensitivity is per
/// standard g, whatever the local gravity).
pub const G_MPS2: f64 = ipc_types::units::STANDARD_GRAVITY_MPS2;

/// An invalid model parameter: names the field and says what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("sensor model field `{field}`: {reason}")]
pub struct ModelError {
    /// Dotted path of the field, e.g. `accel.noise_density[1]`.
    pub field: String,
    /// What is wrong with it.
    pub reason: String,
}

/// Error terms of one triad, in its unit (g for the accelerometer, deg/s for the gyroscope).
/// See the module documentation for the measurement equation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TriadModel {
    /// Fixed bias `b` at the reference temperature, unit.
    pub bias: [f64; 3],
    /// Scale-factor error `s` per axis, fraction (0.01 reads 1% high).
    pub scale: [f64; 3],
    /// Misalignment / cross-axis matrix `M`, fraction: row i, column j is the share of the
    /// input along axis j that axis i sees. The diagonal must be zero (that is `scale`).
    pub misalignment: [[f64; 3]; 3],
    /// Scale nonlinearity `k`, 1/unit: axis i reads `u_i + k_i u_i^2` before scaling.
    pub nonlinearity: [f64; 3],
    /// White-noise density `N`, unit/sqrt(Hz) (per-sample std `N * sqrt(rate_hz)`).
    pub noise_density: [f64; 3],
    /// Temperature coefficient of the bias `c_b`, unit/degC, relative to the reference
    /// temperature of the thermal model.
    pub bias_temp_coeff: [f64; 3],
    /// Temperature coefficient of the scale factor `c_s`, fraction/degC.
    pub scale_temp_coeff: [f64; 3],
    /// Standard deviation of the turn-on bias `b_on`, unit: a normal draw per power-on.
    pub turn_on_bias_std: [f64; 3],
    /// Warm-up transient `b_w`: the extra bias at power-on, unit, decaying exponentially.
    pub warmup_bias: [f64; 3],
    /// Time constant of the warm-up transient `tau_w`, s (must be > 0 when `warmup_bias` is
    /// non-zero).
    pub warmup_time_constant_s: f64,
    /// Bias random walk `K`, unit/sqrt(s) (i.e. unit/s/sqrt(Hz); for the gyroscope the rate
    /// random walk): the bias changes by `K * sqrt(dt)` (1-sigma) over `dt` seconds; its Allan
    /// variance is `K^2 tau / 3`.
    pub bias_random_walk: [f64; 3],
    /// Bias instability `B`, unit: flicker (1/f) noise with two-sided PSD `B^2 / (2 pi f)`
    /// between the correlation times in `bias_instability_corr_s`, whose Allan deviation has
    /// its flat floor at `B * sqrt(2 ln 2 / pi)` (about 0.664 B). Realised as a sum of
    /// first-order Gauss-Markov processes (see [`flicker_components`]).
    pub bias_instability: [f64; 3],
    /// Shortest and longest correlation time of the bias-instability band, s (the longest at
    /// least 10 times the shortest). The Allan floor is flat for cluster times between about
    /// 30 times the shortest and a tenth of the longest.
    pub bias_instability_corr_s: [f64; 2],
}

impl TriadModel {
    /// A perfect triad: every term zero.
    pub fn ideal() -> Self {
        Self {
            bias: [0.0; 3],
            scale: [0.0; 3],
            misalignment: [[0.0; 3]; 3],
            nonlinearity: [0.0; 3],
            noise_density: [0.0; 3],
            bias_temp_coeff: [0.0; 3],
            scale_temp_coeff: [0.0; 3],
            turn_on_bias_std: [0.0; 3],
            warmup_bias: [0.0; 3],
            warmup_time_constant_s: 0.0,
            bias_random_walk: [0.0; 3],
            bias_instability: [0.0; 3],
            bias_instability_corr_s: [1.0, 1000.0],
        }
    }

    /// Checks every field; `name` prefixes the field path in the error (`accel` or `gyro`).
    pub fn validate(&self, name: &str) -> Result<(), ModelError> {
        let err = |field: String, reason: String| Err(ModelError { field, reason });
        let finite3: [(&str, &[f64; 3]); 10] = [
            ("bias", &self.bias),
            ("scale", &self.scale),
            ("nonlinearity", &self.nonlinearity),
            ("noise_density", &self.noise_density),
            ("bias_temp_coeff", &self.bias_temp_coeff),
            ("scale_temp_coeff", &self.scale_temp_coeff),
            ("turn_on_bias_std", &self.turn_on_bias_std),
            ("warmup_bias", &self.warmup_bias),
            ("bias_random_walk", &self.bias_random_walk),
            ("bias_instability", &self.bias_instability),
        ];
        for (field, v) in finite3 {
            for (i, x) in v.iter().enumerate() {
                if !x.is_finite() {
                    return err(
                        format!("{name}.{field}[{i}]"),
                        format!("must be finite, got {x}"),
                    );
                }
            }
        }
        let non_negative: [(&str, &[f64; 3]); 4] = [
            ("noise_density", &self.noise_density),
            ("turn_on_bias_std", &self.turn_on_bias_std),
            ("bias_random_walk", &self.bias_random_walk),
            ("bias_instability", &self.bias_instability),
        ];
        for (field, v) in non_negative {
            for (i, x) in v.iter().enumerate() {
                if *x < 0.0 {
                    return err(
                        format!("{name}.{field}[{i}]"),
                        format!("a standard deviation or density must be >= 0, got {x}"),
                    );
                }
            }
        }
        for (i, row) in self.misalignment.iter().enumerate() {
            for (j, x) in row.iter().enumerate() {
                if !x.is_finite() {
                    return err(
                        format!("{name}.misalignment[{i}][{j}]"),
                        format!("must be finite, got {x}"),
                    );
                }
                if i == j && *x != 0.0 {
                    return err(
                        format!("{name}.misalignment[{i}][{i}]"),
                        format!("the diagonal must be 0 (put scale errors in `scale`), got {x}"),
                    );
                }
            }
        }
        for (i, s) in self.scale.iter().enumerate() {
            if *s <= -1.0 {
                return err(
                    format!("{name}.scale[{i}]"),
                    format!("a scale error of {s} would invert or null the axis"),
                );
            }
        }
        let tau_w = self.warmup_time_constant_s;
        if self.warmup_bias.iter().any(|b| *b != 0.0) && !(tau_w.is_finite() && tau_w > 0.0) {
            return err(
                format!("{name}.warmup_time_constant_s"),
                format!("must be finite and > 0 when warmup_bias is non-zero, got {tau_w}"),
            );
        }
        let [lo, hi] = self.bias_instability_corr_s;
        if self.bias_instability.iter().any(|b| *b != 0.0)
            && !(lo.is_finite() && hi.is_finite() && lo > 0.0 && hi >= 10.0 * lo)
        {
            return err(
                format!("{name}.bias_instability_corr_s"),
                format!(
                    "needs 0 < shortest and longest >= 10 * shortest when bias_instability is \
                     non-zero, got [{lo}, {hi}]"
                ),
            );
        }
        Ok(())
    }

    /// The Allan variance of this triad's noise terms on `axis` at cluster time `tau_s`,
    /// unit^2: white noise `N^2 / tau`, random walk `K^2 tau / 3`, and the exact Allan
    /// variance of each Gauss-Markov component of the bias instability. The deterministic
    /// terms (bias, temperature, warm-up) are not included.
    pub fn allan_variance(&self, axis: usize, tau_s: f64) -> f64 {
        let n = self.noise_density[axis];
        let k = self.bias_random_walk[axis];
        let flicker: f64 =
            flicker_components(self.bias_instability[axis], self.bias_instability_corr_s)
                .iter()
                .map(|&(corr_s, var)| gauss_markov_allan_variance(tau_s, var, corr_s))
                .sum();
        n * n / tau_s + k * k * tau_s / 3.0 + flicker
    }
}

/// The first-order Gauss-Markov components that realise a bias instability `b` (unit) over the
/// correlation-time band `[lo, hi]` s: pairs (correlation time s, stationary variance unit^2).
///
/// Correlation times are log-spaced at two per decade or closer, `tau_j = lo * r^j` up to `hi`.
/// A component of variance `v` and correlation time `T` has two-sided PSD
/// `2 v T / (1 + (2 pi f T)^2)`; summed over log-spaced `T` that is about `v / (2 f ln r)`, so
/// `v = b^2 ln(r) / pi` gives the flicker PSD `b^2 / (2 pi f)` inside the band. Empty when
/// `b` is zero.
pub fn flicker_components(b: f64, [lo, hi]: [f64; 2]) -> Vec<(f64, f64)> {
    if b == 0.0 {
        return Vec::new();
    }
    let decades = (hi / lo).log10();
    let count = (2.0 * decades).ceil().max(1.0) as usize + 1;
    let ratio = (hi / lo).powf(1.0 / (count - 1) as f64);
    let var = b * b * ratio.ln() / std::f64::consts::PI;
    (0..count)
        .map(|j| (lo * ratio.powi(j as i32), var))
        .collect()
}

/// Allan variance at cluster time `tau_s` of a stationary first-order Gauss-Markov process of
/// variance `var` and correlation time `corr_s`:
/// `2 var T / tau * (1 - T / (2 tau) * (3 - 4 e^(-tau/T) + e^(-2 tau/T)))` with `T = corr_s`.
pub fn gauss_markov_allan_variance(tau_s: f64, var: f64, corr_s: f64) -> f64 {
    let x = tau_s / corr_s;
    let bracket = 3.0 - 4.0 * (-x).exp() + (-2.0 * x).exp();
    2.0 * var * corr_s / tau_s * (1.0 - bracket / (2.0 * x))
}

/// Die temperature: ambient (optionally drifting linearly) plus self-heating that settles
/// exponentially after power-on: `T(t) = ambient + drift * t + heating * (1 - exp(-t / tau))`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThermalModel {
    /// Ambient temperature at power-on, degC.
    pub ambient_c: f64,
    /// Linear ambient drift, degC/s (0 for a constant ambient).
    pub ambient_drift_c_per_s: f64,
    /// Self-heating of the die once settled, degC above ambient.
    pub self_heating_c: f64,
    /// Time constant of the self-heating, s (> 0 when `self_heating_c` is non-zero).
    pub self_heating_time_constant_s: f64,
    /// Reference temperature of the bias and scale parameters, degC: the temperature terms
    /// are zero here.
    pub reference_c: f64,
}

impl ThermalModel {
    /// A constant 25 degC die that is also the reference temperature.
    pub fn constant_25c() -> Self {
        Self {
            ambient_c: 25.0,
            ambient_drift_c_per_s: 0.0,
            self_heating_c: 0.0,
            self_heating_time_constant_s: 0.0,
            reference_c: 25.0,
        }
    }

    /// Die temperature at `t_s` seconds after power-on, degC.
    pub fn die_temp_c(&self, t_s: f64) -> f64 {
        let heating = if self.self_heating_c == 0.0 {
            0.0
        } else {
            self.self_heating_c * (1.0 - (-t_s / self.self_heating_time_constant_s).exp())
        };
        self.ambient_c + self.ambient_drift_c_per_s * t_s + heating
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ModelError> {
        let fields = [
            ("thermal.ambient_c", self.ambient_c),
            ("thermal.ambient_drift_c_per_s", self.ambient_drift_c_per_s),
            ("thermal.self_heating_c", self.self_heating_c),
            ("thermal.reference_c", self.reference_c),
        ];
        for (field, x) in fields {
            if !x.is_finite() {
                return Err(ModelError {
                    field: field.into(),
                    reason: format!("must be finite, got {x}"),
                });
            }
        }
        let tau = self.self_heating_time_constant_s;
        if self.self_heating_c != 0.0 && !(tau.is_finite() && tau > 0.0) {
            return Err(ModelError {
                field: "thermal.self_heating_time_constant_s".into(),
                reason: format!(
                    "must be finite and > 0 when self_heating_c is non-zero, got {tau}"
                ),
            });
        }
        Ok(())
    }
}

/// The complete error model of a simulated MPU-9250: accelerometer (g), gyroscope (deg/s) and
/// die temperature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorModel {
    /// Accelerometer error terms, in g.
    pub accel: TriadModel,
    /// Gyroscope error terms, in deg/s.
    pub gyro: TriadModel,
    /// Die temperature model.
    pub thermal: ThermalModel,
}

/// Converts mm/s^2 to g.
fn mm_s2_to_g(x: f64) -> f64 {
    x * 1e-3 / G_MPS2
}

impl SensorModel {
    /// A perfect sensor at a constant 25 degC: the output is the input.
    pub fn ideal() -> Self {
        Self {
            accel: TriadModel::ideal(),
            gyro: TriadModel::ideal(),
            thermal: ThermalModel::constant_25c(),
        }
    }

    /// An uncalibrated MPU-9250 with datasheet-level errors (PS-MPU-9250A-01 rev 1.1): a fixed,
    /// representative part inside the datasheet's tolerances, so that runs are comparable.
    ///
    /// Accelerometer: zero-g offset (40, -35, 55) mg (limits +-60/60/80), scale (+1.5, -2.0,
    /// +1.0)% (+-3%), cross-axis up to 1.5% (+-2%), quadratic nonlinearity 0.002/g (about 0.3%
    /// of full scale at +-2 g; limit 0.5%), 300 ug/sqrt(Hz), bias drift (0.8, -0.6, 1.2)
    /// mg/degC (+-1.5), scale drift (0.026, -0.02, 0.026)%/degC (+-0.026), and the turn-on
    /// repeatability measured on the thesis's 60 start-up runs (4.5, 2.5, 6.1 mm/s^2).
    /// Gyroscope: zero-rate offset (2, -1.5, 3) deg/s (+-5), sensitivity (+1.5, -1.0, +2.0)%
    /// (+-3%), cross-axis up to 1.5% (+-2%), nonlinearity 6e-6 per deg/s (0.1% of full scale at
    /// +-250 deg/s), 0.01 deg/s/sqrt(Hz), offset drift (0.05, -0.04, 0.06) deg/s/degC (the
    /// datasheet's +-30 deg/s over -40..85 degC is about 0.24), sensitivity drift 0.03%/degC
    /// (+-4% over the range), turn-on repeatability 0.3 deg/s (not in the datasheet).
    /// Temperature: 25 degC ambient and reference, 2 degC self-heating with a 300 s time
    /// constant (not in the datasheet; illustrative). The datasheet gives no bias instability,
    /// random walk or warm-up transient, so they are zero.
    pub fn mpu9250_datasheet() -> Self {
        let accel = TriadModel {
            bias: [0.040, -0.035, 0.055],
            scale: [0.015, -0.020, 0.010],
            misalignment: [
                [0.0, 0.010, -0.015],
                [-0.005, 0.0, 0.012],
                [0.008, -0.010, 0.0],
            ],
            nonlinearity: [0.002, -0.002, 0.002],
            noise_density: [300e-6; 3],
            bias_temp_coeff: [0.8e-3, -0.6e-3, 1.2e-3],
            scale_temp_coeff: [0.026e-2, -0.020e-2, 0.026e-2],
            turn_on_bias_std: [mm_s2_to_g(4.5), mm_s2_to_g(2.5), mm_s2_to_g(6.1)],
            ..TriadModel::ideal()
        };
        let gyro = TriadModel {
            bias: [2.0, -1.5, 3.0],
            scale: [0.015, -0.010, 0.020],
            misalignment: [
                [0.0, -0.012, 0.008],
                [0.015, 0.0, -0.006],
                [-0.010, 0.005, 0.0],
            ],
            nonlinearity: [6e-6, -6e-6, 6e-6],
            noise_density: [0.01; 3],
            bias_temp_coeff: [0.05, -0.04, 0.06],
            scale_temp_coeff: [0.03e-2, -0.03e-2, 0.03e-2],
            turn_on_bias_std: [0.3; 3],
            ..TriadModel::ideal()
        };
        Self {
            accel,
            gyro,
            thermal: ThermalModel {
                ambient_c: 25.0,
                ambient_drift_c_per_s: 0.0,
                self_heating_c: 2.0,
                self_heating_time_constant_s: 300.0,
                reference_c: 25.0,
            },
        }
    }

    /// The MPU-9250 as the odometry sees it after this project's accelerometer calibration
    /// (the error levels of the live-processes issue): what a calibration leaves.
    ///
    /// Accelerometer: no fixed bias, turn-on repeatability (4.5, 2.5, 6.1) mm/s^2 (measured on
    /// the thesis's 60 start-up runs), residual scale (+0.1, -0.1, +0.1)% and misalignment
    /// 0.1%, no nonlinearity, 300 ug/sqrt(Hz), residual temperature drift a quarter of the
    /// datasheet preset's (0.2, -0.15, 0.3) mg/degC (calibrated temperature terms remove most
    /// of it). Gyroscope at datasheet level and uncalibrated: 0.01 deg/s/sqrt(Hz), turn-on bias
    /// 0.5 deg/s 1-sigma (so up to about 1 deg/s), scale (+1, -1, +1)%, misalignment 0.5%, no
    /// temperature terms. Temperature as in [`Self::mpu9250_datasheet`].
    pub fn mpu9250_calibrated() -> Self {
        let accel = TriadModel {
            scale: [0.001, -0.001, 0.001],
            misalignment: [
                [0.0, 0.001, -0.001],
                [-0.001, 0.0, 0.001],
                [0.001, -0.001, 0.0],
            ],
            noise_density: [300e-6; 3],
            bias_temp_coeff: [0.2e-3, -0.15e-3, 0.3e-3],
            turn_on_bias_std: [mm_s2_to_g(4.5), mm_s2_to_g(2.5), mm_s2_to_g(6.1)],
            ..TriadModel::ideal()
        };
        let gyro = TriadModel {
            scale: [0.01, -0.01, 0.01],
            misalignment: [
                [0.0, 0.005, -0.005],
                [-0.005, 0.0, 0.005],
                [0.005, -0.005, 0.0],
            ],
            noise_density: [0.01; 3],
            turn_on_bias_std: [0.5; 3],
            ..TriadModel::ideal()
        };
        Self {
            accel,
            gyro,
            thermal: Self::mpu9250_datasheet().thermal,
        }
    }

    /// Checks every field of the model.
    pub fn validate(&self) -> Result<(), ModelError> {
        self.accel.validate("accel")?;
        self.gyro.validate("gyro")?;
        self.thermal.validate()
    }
}

/// RNG stream numbers of one triad's random terms (see [`crate::stream_rng`]).
struct TriadStreams {
    turn_on: u64,
    white: u64,
    random_walk: u64,
    instability: u64,
}

const ACCEL_STREAMS: TriadStreams = TriadStreams {
    turn_on: 10,
    white: 11,
    random_walk: 12,
    instability: 13,
};
const GYRO_STREAMS: TriadStreams = TriadStreams {
    turn_on: 20,
    white: 21,
    random_walk: 22,
    instability: 23,
};

/// One Gauss-Markov component of the bias instability, per axis.
struct GaussMarkov {
    corr_s: f64,
    std: [f64; 3],
    state: [f64; 3],
}

/// A powered-on triad: its parameters and the state of its random processes.
struct TriadState {
    params: TriadModel,
    /// Time of the previous measurement, s (the random processes advance from it).
    last_t_s: f64,
    misalignment: Matrix3<f64>,
    turn_on_bias: [f64; 3],
    random_walk: [f64; 3],
    instability: Vec<GaussMarkov>,
    rng_white: ChaCha8Rng,
    rng_random_walk: ChaCha8Rng,
    rng_instability: ChaCha8Rng,
}

/// Draws one standard normal variate.
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    rng.sample(StandardNormal)
}

/// Sample times within this of each other are one instant, s: times are whole nanoseconds,
/// reached by different float sums (`t_ns * 1e-9` for a direct read, `start + k / rate` on a
/// filter's tick grid), which can round the same nanosecond a few 1e-17 s apart (a 4 kHz
/// acquisition hit 0.228659896 s after 0.22865989600000003 s).
pub const SAME_INSTANT_S: f64 = 0.5e-9;

impl TriadState {
    fn power_on(params: &TriadModel, seed: u64, streams: &TriadStreams) -> Self {
        let mut rng_turn_on = stream_rng(seed, streams.turn_on);
        let turn_on_bias = params
            .turn_on_bias_std
            .map(|s| s * normal(&mut rng_turn_on));
        let mut rng_instability = stream_rng(seed, streams.instability);
        // Each component starts in its stationary distribution: the part has been "on" for ever
        // as far as its flicker is concerned. Components are shared across axes (same
        // correlation times) but each axis has its own amplitude and state.
        let mut instability: Vec<GaussMarkov> = Vec::new();
        for axis in 0..3 {
            let comps = flicker_components(
                params.bias_instability[axis],
                params.bias_instability_corr_s,
            );
            for (j, (corr_s, var)) in comps.into_iter().enumerate() {
                if instability.len() <= j {
                    instability.push(GaussMarkov {
                        corr_s,
                        std: [0.0; 3],
                        state: [0.0; 3],
                    });
                }
                instability[j].std[axis] = var.sqrt();
            }
        }
        for comp in &mut instability {
            for axis in 0..3 {
                comp.state[axis] = comp.std[axis] * normal(&mut rng_instability);
            }
        }
        let m = &params.misalignment;
        Self {
            params: params.clone(),
            last_t_s: 0.0,
            misalignment: Matrix3::from_fn(|i, j| m[i][j]),
            turn_on_bias,
            random_walk: [0.0; 3],
            instability,
            rng_white: stream_rng(seed, streams.white),
            rng_random_walk: stream_rng(seed, streams.random_walk),
            rng_instability,
        }
    }

    /// Advances the random processes to `t_s` and returns the measurement of input `u` at that
    /// time with temperature offset `d_temp` from the reference.
    ///
    /// # Panics
    /// If `t_s` is earlier than the previous measurement's time (a caller bug) by more than
    /// [`SAME_INSTANT_S`]; within it the two are one instant.
    fn measure(&mut self, t_s: f64, rate_hz: f64, d_temp: f64, u: [f64; 3]) -> [f64; 3] {
        assert!(
            t_s >= self.last_t_s - SAME_INSTANT_S,
            "Sensor::measure: time went backwards ({t_s} s after {} s)",
            self.last_t_s
        );
        let t_s = t_s.max(self.last_t_s);
        let dt_s = t_s - self.last_t_s;
        self.last_t_s = t_s;
        let p = &self.params;
        if dt_s > 0.0 {
            if p.bias_random_walk.iter().any(|k| *k != 0.0) {
                for axis in 0..3 {
                    self.random_walk[axis] +=
                        p.bias_random_walk[axis] * dt_s.sqrt() * normal(&mut self.rng_random_walk);
                }
            }
            for comp in &mut self.instability {
                // Exact discretisation of dx = -x / T dt + q dW: the stationary variance is kept.
                let phi = (-dt_s / comp.corr_s).exp();
                let drive = (1.0 - phi * phi).sqrt();
                for axis in 0..3 {
                    comp.state[axis] = phi * comp.state[axis]
                        + comp.std[axis] * drive * normal(&mut self.rng_instability);
                }
            }
        }
        let q = Vector3::from_fn(|i, _| u[i] + p.nonlinearity[i] * u[i] * u[i]);
        let diag = Vector3::from_fn(|i, _| 1.0 + p.scale[i] + p.scale_temp_coeff[i] * d_temp);
        let scaled = (Matrix3::from_diagonal(&diag) + self.misalignment) * q;
        let white_on = p.noise_density.iter().any(|n| *n != 0.0);
        let mut y = [0.0; 3];
        for (axis, out) in y.iter_mut().enumerate() {
            let warmup = if p.warmup_bias[axis] == 0.0 {
                0.0
            } else {
                p.warmup_bias[axis] * (-t_s / p.warmup_time_constant_s).exp()
            };
            let flicker: f64 = self.instability.iter().map(|c| c.state[axis]).sum();
            let white = if white_on {
                p.noise_density[axis] * rate_hz.sqrt() * normal(&mut self.rng_white)
            } else {
                0.0
            };
            *out = scaled[axis]
                + p.bias[axis]
                + p.bias_temp_coeff[axis] * d_temp
                + self.turn_on_bias[axis]
                + warmup
                + self.random_walk[axis]
                + flicker
                + white;
        }
        y
    }
}

/// A powered-on simulated sensor: the model plus the state of its random processes. Created by
/// [`Sensor::power_on`]; [`Sensor::measure`] turns true inputs into analog samples.
pub struct Sensor {
    thermal: ThermalModel,
    accel: TriadState,
    gyro: TriadState,
}

impl Sensor {
    /// Powers the sensor on at time 0: validates the model and draws the turn-on biases and the
    /// initial bias-instability state from `seed`.
    pub fn power_on(model: &SensorModel, seed: u64) -> Result<Self, ModelError> {
        model.validate()?;
        Ok(Self {
            thermal: model.thermal.clone(),
            accel: TriadState::power_on(&model.accel, seed, &ACCEL_STREAMS),
            gyro: TriadState::power_on(&model.gyro, seed, &GYRO_STREAMS),
        })
    }

    /// The turn-on bias drawn at power-on: accelerometer in g, gyroscope in deg/s.
    pub fn turn_on_bias(&self) -> ([f64; 3], [f64; 3]) {
        (self.accel.turn_on_bias, self.gyro.turn_on_bias)
    }

    /// Measures the true specific force `accel_g` (g) and angular rate `gyro_dps` (deg/s),
    /// both in the sensor frame, at `t_s` seconds after power-on and output rate `rate_hz`
    /// (which sets the white-noise std). Times must not decrease between calls.
    ///
    /// # Panics
    /// If `t_s` is earlier than the previous call's time (a caller bug; within
    /// [`SAME_INSTANT_S`] the two are one instant).
    pub fn measure(
        &mut self,
        t_s: f64,
        rate_hz: f64,
        accel_g: [f64; 3],
        gyro_dps: [f64; 3],
    ) -> AnalogSample {
        AnalogSample {
            accel_g: self.measure_accel(t_s, rate_hz, accel_g),
            gyro_dps: self.measure_gyro(t_s, rate_hz, gyro_dps),
            temp_c: self.die_temp_c(t_s),
        }
    }

    /// The accelerometer alone (g) at `t_s` and sample rate `rate_hz`, for a part whose
    /// triads sample at different rates (see [`Self::measure`]).
    pub fn measure_accel(&mut self, t_s: f64, rate_hz: f64, accel_g: [f64; 3]) -> [f64; 3] {
        let d_temp = self.die_temp_c(t_s) - self.thermal.reference_c;
        self.accel.measure(t_s, rate_hz, d_temp, accel_g)
    }

    /// The gyroscope alone (deg/s) at `t_s` and sample rate `rate_hz` (see
    /// [`Self::measure_accel`]).
    pub fn measure_gyro(&mut self, t_s: f64, rate_hz: f64, gyro_dps: [f64; 3]) -> [f64; 3] {
        let d_temp = self.die_temp_c(t_s) - self.thermal.reference_c;
        self.gyro.measure(t_s, rate_hz, d_temp, gyro_dps)
    }

    /// The die temperature at `t_s`, degC.
    pub fn die_temp_c(&self, t_s: f64) -> f64 {
        self.thermal.die_temp_c(t_s)
    }
}

/// The named error models, as command lines spell them (`ideal`, `datasheet`, `calibrated`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preset {
    /// No errors at all ([`SensorModel::ideal`]).
    Ideal,
    /// An uncalibrated part with datasheet-level errors ([`SensorModel::mpu9250_datasheet`]).
    Datasheet,
    /// The residual errors after this project's accelerometer calibration
    /// ([`SensorModel::mpu9250_calibrated`]).
    Calibrated,
}

impl Preset {
    /// The preset's error model.
    pub fn model(self) -> SensorModel {
        match self {
            Self::Ideal => SensorModel::ideal(),
            Self::Datasheet => SensorModel::mpu9250_datasheet(),
            Self::Calibrated => SensorModel::mpu9250_calibrated(),
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ideal" => Ok(Self::Ideal),
            "datasheet" => Ok(Self::Datasheet),
            "calibrated" => Ok(Self::Calibrated),
            other => Err(format!(
                "unknown preset {other:?}: expected ideal, datasheet or calibrated"
            )),
        }
    }
}
