//! The noise parameters as the calibration file stores them: the one source of truth the
//! zero-state detector, the odometry filter and the uncertainty propagation read.
//!
//! Units, for a sensor whose values are in `u` (`m/s^2` for the accelerometer, `rad/s` for the
//! gyro; [`SensorNoise::unit`] names it):
//! - `white_noise_density` `N`: `u/sqrt(Hz)` (velocity / angle random walk);
//! - `bias_instability` `B`: `u` (the Allan floor is `0.664 B`);
//! - `random_walk` `K`: `u*sqrt(Hz)`, i.e. `u/s/sqrt(Hz)` (rate random walk; Kalibr's
//!   `*_random_walk`).
//!
//! A term the record could not resolve is absent and has a 2-sigma upper limit in
//! `upper_limits` instead. As TOML (a `[noise]` table of the calibration file):
//!
//! ```toml
//! source = "static.csv"
//! sample_rate_hz = 181.6
//! record_length_s = 59.99
//! samples = 10763
//! gravity_mps2 = 9.797
//!
//! [accel]
//! unit = "m/s^2"
//!
//! [accel.x]
//! white_noise_density = { value = 2.1e-3, sigma = 2e-5 }
//! bias_instability = { value = 4.0e-4, sigma = 1e-4 }
//! upper_limits = { random_walk = 3.0e-4 }
//! ```

use serde::{Deserialize, Serialize};

/// An estimate with its 1-sigma, in the unit of the field holding it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Estimate {
    /// The value.
    pub value: f64,
    /// Its 1-sigma.
    pub sigma: f64,
}

/// 2-sigma upper limits of unresolved terms (units as the terms').
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UpperLimits {
    /// Limit on `N`, u/sqrt(Hz).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub white_noise_density: Option<f64>,
    /// Limit on `B`, u.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bias_instability: Option<f64>,
    /// Limit on `K`, u*sqrt(Hz).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub random_walk: Option<f64>,
}

impl UpperLimits {
    /// Whether no limit is set (every term resolved).
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }
}

/// The noise of one axis (see the module documentation for units).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisNoise {
    /// White noise density `N`, u/sqrt(Hz).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub white_noise_density: Option<Estimate>,
    /// Bias instability `B`, u.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bias_instability: Option<Estimate>,
    /// Rate random walk `K`, u*sqrt(Hz).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub random_walk: Option<Estimate>,
    /// Upper limits of the terms above that are absent.
    #[serde(default, skip_serializing_if = "UpperLimits::is_empty")]
    pub upper_limits: UpperLimits,
}

impl AxisNoise {
    /// `(N, B, K)` with each unresolved term replaced by its upper limit (0 when it has
    /// neither): the conservative figures a consumer needing numbers should use.
    pub fn values_or_limits(&self) -> [f64; 3] {
        let pick =
            |e: Option<Estimate>, limit: Option<f64>| e.map(|e| e.value).or(limit).unwrap_or(0.0);
        [
            pick(
                self.white_noise_density,
                self.upper_limits.white_noise_density,
            ),
            pick(self.bias_instability, self.upper_limits.bias_instability),
            pick(self.random_walk, self.upper_limits.random_walk),
        ]
    }

    /// Checks the axis at `path` (e.g. `accel.x`) whose white noise density must lie within
    /// `white` (u/sqrt(Hz)): every estimate positive with a non-negative sigma, every limit
    /// non-negative, and neither the density nor its limit below the band.
    fn check(&self, path: &str, white: (f64, f64)) -> Result<(), ParamsError> {
        let estimates = [
            ("white_noise_density", self.white_noise_density),
            ("bias_instability", self.bias_instability),
            ("random_walk", self.random_walk),
        ];
        for (name, estimate) in estimates {
            if let Some(e) = estimate {
                positive(&format!("{path}.{name}.value"), e.value)?;
                non_negative(&format!("{path}.{name}.sigma"), e.sigma)?;
            }
        }
        let (lo, hi) = white;
        if let Some(n) = self.white_noise_density.map(|e| e.value)
            && !(lo..=hi).contains(&n)
        {
            return Err(ParamsError {
                field: format!("{path}.white_noise_density.value"),
                problem: format!(
                    "{n:?} is not a MEMS sensor's white noise density ({lo:.1e} to {hi:.1e})"
                ),
            });
        }
        if let Some(n) = self.upper_limits.white_noise_density
            && n < lo
        {
            return Err(ParamsError {
                field: format!("{path}.upper_limits.white_noise_density"),
                problem: format!("{n:?} is below any MEMS sensor's white noise density ({lo:.1e})"),
            });
        }
        let limits = [
            ("white_noise_density", self.upper_limits.white_noise_density),
            ("bias_instability", self.upper_limits.bias_instability),
            ("random_walk", self.upper_limits.random_walk),
        ];
        for (name, limit) in limits {
            if let Some(v) = limit {
                non_negative(&format!("{path}.upper_limits.{name}"), v)?;
            }
        }
        Ok(())
    }
}

/// The noise of one sensor's three axes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorNoise {
    /// The unit `u` of the sensor's values: `m/s^2` (accelerometer) or `rad/s` (gyro).
    pub unit: String,
    /// Sensor x axis.
    pub x: AxisNoise,
    /// Sensor y axis.
    pub y: AxisNoise,
    /// Sensor z axis.
    pub z: AxisNoise,
}

impl SensorNoise {
    /// The axes in x, y, z order.
    pub fn axes(&self) -> [&AxisNoise; 3] {
        [&self.x, &self.y, &self.z]
    }
}

/// The noise parameters of an IMU and the record they came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseParams {
    /// The recording analysed.
    pub source: String,
    /// Sample rate of the recording, Hz (1 / mean interval): the parameters describe the noise
    /// as sampled at this rate (aliasing included).
    pub sample_rate_hz: f64,
    /// Duration of the recording, s.
    pub record_length_s: f64,
    /// Samples analysed.
    pub samples: usize,
    /// Gravity used to convert g to m/s^2.
    pub gravity_mps2: f64,
    /// Accelerometer noise (unit m/s^2).
    pub accel: SensorNoise,
    /// Gyroscope noise (unit rad/s), when the recording has the gyro.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro: Option<SensorNoise>,
}

/// A noise parameter file that does not make sense.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("noise parameters: {field}: {problem}")]
pub struct ParamsError {
    /// The offending field, as a TOML path (e.g. `accel.x.white_noise_density.sigma`).
    pub field: String,
    /// What is wrong with it.
    pub problem: String,
}

/// The white noise density a `[noise]` table may state, (lowest, highest): for the
/// accelerometer in m/s^2/sqrt(Hz), for the gyro in rad/s/sqrt(Hz). The MPU-9250's datasheet
/// figures (PS-MPU-9250A-01 rev 1.1, tables 3.1 and 3.2: 300 ug/sqrt(Hz) = 2.94e-3 m/s^2/sqrt(Hz)
/// and 0.01 deg/s/sqrt(Hz) = 1.75e-4 rad/s/sqrt(Hz)) divided and multiplied by 100: wide enough
/// for tactical-grade MEMS parts below (about 15 ug/sqrt(Hz) and 0.002 deg/s/sqrt(Hz)) and the
/// cheapest consumer parts above (about 1000 ug/sqrt(Hz) and 0.05 deg/s/sqrt(Hz)); the thesis's
/// MPU-9250 measures 1.9e-3 to 4.1e-3 m/s^2/sqrt(Hz) (docs/noise.md). A zero or 1e-12 density
/// would make the odometry filter trust every sample exactly.
pub const WHITE_NOISE_DENSITY_RANGE: [(f64, f64); 2] = [(2.94e-5, 0.294), (1.75e-6, 1.75e-2)];

fn positive(field: &str, v: f64) -> Result<(), ParamsError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(ParamsError {
            field: field.to_owned(),
            problem: format!("{v:?} is not a finite positive number"),
        })
    }
}

fn non_negative(field: &str, v: f64) -> Result<(), ParamsError> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(ParamsError {
            field: field.to_owned(),
            problem: format!("{v} is not a finite non-negative number"),
        })
    }
}

impl NoiseParams {
    /// Checks the values a consumer relies on: positive rate and length, a gravity of the
    /// Earth's surface ([`crate::gravity::GRAVITY_RANGE_MPS2`]), positive estimates with
    /// non-negative sigmas, non-negative limits, white noise densities within
    /// [`WHITE_NOISE_DENSITY_RANGE`], and the expected units.
    pub fn validate(&self) -> Result<(), ParamsError> {
        crate::gravity::check_gravity(self.gravity_mps2).map_err(|problem| ParamsError {
            field: "gravity_mps2".into(),
            problem,
        })?;
        for (field, v) in [
            ("sample_rate_hz", self.sample_rate_hz),
            ("record_length_s", self.record_length_s),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(ParamsError {
                    field: field.to_owned(),
                    problem: format!("{v} is not a positive number"),
                });
            }
        }
        let sensors = [
            ("accel", Some(&self.accel), "m/s^2"),
            ("gyro", self.gyro.as_ref(), "rad/s"),
        ];
        for ((name, sensor, unit), white) in sensors.into_iter().zip(WHITE_NOISE_DENSITY_RANGE) {
            let Some(sensor) = sensor else { continue };
            if sensor.unit != unit {
                return Err(ParamsError {
                    field: format!("{name}.unit"),
                    problem: format!("{:?}, expected {unit:?}", sensor.unit),
                });
            }
            for (axis, noise) in ["x", "y", "z"].iter().zip(sensor.axes()) {
                noise.check(&format!("{name}.{axis}"), white)?;
            }
        }
        Ok(())
    }

    /// The parameters as TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("plain numbers and strings serialise")
    }

    /// Parses and validates TOML written by [`Self::to_toml`] (or the `[noise]` table of a
    /// calibration file).
    pub fn from_toml(text: &str) -> Result<Self, ParamsError> {
        let params: Self = toml::from_str(text).map_err(|e| ParamsError {
            field: e.span().map_or_else(
                || "(file)".to_owned(),
                |s| format!("bytes {}..{}", s.start, s.end),
            ),
            problem: e.message().to_owned(),
        })?;
        params.validate()?;
        Ok(params)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Noise parameters of a plausible MPU-9250 accelerometer (no gyro).
    pub(crate) fn sample() -> NoiseParams {
        let axis = AxisNoise {
            white_noise_density: Some(Estimate {
                value: 2.1e-3,
                sigma: 2e-5,
            }),
            bias_instability: Some(Estimate {
                value: 4e-4,
                sigma: 1e-4,
            }),
            random_walk: None,
            upper_limits: UpperLimits {
                random_walk: Some(3e-4),
                ..Default::default()
            },
        };
        NoiseParams {
            source: "static.csv".into(),
            sample_rate_hz: 181.6,
            record_length_s: 59.99,
            samples: 10_763,
            gravity_mps2: 9.797,
            accel: SensorNoise {
                unit: "m/s^2".into(),
                x: axis,
                y: axis,
                z: AxisNoise::default(),
            },
            gyro: None,
        }
    }

    #[test]
    fn toml_round_trip() {
        let params = sample();
        let text = params.to_toml();
        assert!(text.contains("[accel.x.white_noise_density]"), "{text}");
        assert!(!text.contains("gyro"), "{text}");
        assert_eq!(NoiseParams::from_toml(&text).unwrap(), params);
    }

    #[test]
    fn values_or_limits_prefers_estimates() {
        let params = sample();
        assert_eq!(params.accel.x.values_or_limits(), [2.1e-3, 4e-4, 3e-4]);
        assert_eq!(params.accel.z.values_or_limits(), [0.0, 0.0, 0.0]);
    }

    #[test]
    fn rejects_bad_values_naming_the_field() {
        let mut bad = sample();
        bad.accel.x.white_noise_density = Some(Estimate {
            value: 2.1e-3,
            sigma: -2e-5,
        });
        let err = NoiseParams::from_toml(&bad.to_toml()).unwrap_err();
        assert_eq!(err.field, "accel.x.white_noise_density.sigma");
        let mut bad = sample();
        bad.accel.unit = "g".into();
        assert_eq!(
            NoiseParams::from_toml(&bad.to_toml()).unwrap_err().field,
            "accel.unit"
        );
        let mut bad = sample();
        bad.sample_rate_hz = 0.0;
        assert_eq!(
            NoiseParams::from_toml(&bad.to_toml()).unwrap_err().field,
            "sample_rate_hz"
        );
        let err = NoiseParams::from_toml("source = 3").unwrap_err();
        assert!(err.problem.contains("invalid type"), "{err}");
    }

    #[test]
    fn noise_outside_a_mems_sensors_band_is_refused() {
        type Spoil = fn(&mut NoiseParams);
        let cases: [(&str, Spoil); 6] = [
            ("accel.x.white_noise_density.value", |p| {
                p.accel.x.white_noise_density.as_mut().unwrap().value = 0.0
            }),
            ("accel.y.white_noise_density.value", |p| {
                p.accel.y.white_noise_density.as_mut().unwrap().value = 1e-12
            }),
            ("accel.x.white_noise_density.value", |p| {
                p.accel.x.white_noise_density.as_mut().unwrap().value = 0.5
            }),
            ("accel.z.upper_limits.white_noise_density", |p| {
                p.accel.z.upper_limits.white_noise_density = Some(1e-9)
            }),
            ("accel.x.bias_instability.value", |p| {
                p.accel.x.bias_instability.as_mut().unwrap().value = 0.0
            }),
            ("gravity_mps2", |p| p.gravity_mps2 = 1e6),
        ];
        for (field, spoil) in cases {
            let mut bad = sample();
            spoil(&mut bad);
            assert_eq!(bad.validate().unwrap_err().field, field);
        }
        // The band's ends: 300 ug/sqrt(Hz) and 0.01 deg/s/sqrt(Hz) divided and multiplied by 100.
        let mut edges = sample();
        edges.accel.x.white_noise_density.as_mut().unwrap().value = 2.94e-5;
        edges.accel.y.white_noise_density.as_mut().unwrap().value = 0.294;
        edges.gyro = Some(SensorNoise {
            unit: "rad/s".into(),
            x: AxisNoise {
                white_noise_density: Some(Estimate {
                    value: 1.75e-6,
                    sigma: 0.0,
                }),
                ..AxisNoise::default()
            },
            y: AxisNoise::default(),
            z: AxisNoise::default(),
        });
        edges.validate().unwrap();
        edges.gyro.as_mut().unwrap().x.white_noise_density = Some(Estimate {
            value: 0.05,
            sigma: 0.0,
        });
        assert_eq!(
            edges.validate().unwrap_err().field,
            "gyro.x.white_noise_density.value",
            "2.9 deg/s/sqrt(Hz)"
        );
    }
}
