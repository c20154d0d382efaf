//! Export of the noise parameters as Kalibr's `imu.yaml` (also read by OpenVINS, VINS-Mono and
//! allan_variance_ros users): `accelerometer_noise_density` (m/s^2/sqrt(Hz)),
//! `accelerometer_random_walk` (m/s^3/sqrt(Hz)), `gyroscope_noise_density` (rad/s/sqrt(Hz)),
//! `gyroscope_random_walk` (rad/s^2/sqrt(Hz)), `rostopic` and `update_rate` (Hz).
//!
//! Kalibr takes one isotropic value per sensor; this export uses the **largest** of the three
//! axes (the conservative choice: a filter tuned with it never trusts an axis more than its
//! measured noise). An unresolved term (typically the random walk of a short record) is
//! exported as its 2-sigma upper limit, and the file says so in a comment.

use std::fmt::Write as _;

use crate::params::{NoiseParams, SensorNoise};

/// Why the file cannot be written.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum KalibrError {
    /// The recording has no gyro, and Kalibr needs the gyroscope's noise too.
    #[error(
        "{recording}: Kalibr's imu.yaml needs the gyroscope's noise, and the recording has no gyro \
         samples (GYRO_VALID is not set on every sample)"
    )]
    NoGyro {
        /// The recording the parameters came from.
        recording: String,
    },
    /// A sensor has neither an estimate nor a limit for a term on any axis.
    #[error("{sensor} {term}: no axis has an estimate or an upper limit")]
    Missing {
        /// `accelerometer` or `gyroscope`.
        sensor: &'static str,
        /// `noise_density` or `random_walk`.
        term: &'static str,
    },
}

/// The largest value (estimate or limit) over the axes for term `index` of
/// [`crate::params::AxisNoise::values_or_limits`], and the axes where it is only a limit.
fn combine(sensor: &SensorNoise, index: usize) -> (f64, Vec<&'static str>) {
    let mut largest: f64 = 0.0;
    let mut limited = Vec::new();
    for (name, axis) in ["x", "y", "z"].into_iter().zip(sensor.axes()) {
        largest = largest.max(axis.values_or_limits()[index]);
        let resolved = match index {
            0 => axis.white_noise_density.is_some(),
            _ => axis.random_walk.is_some(),
        };
        if !resolved {
            limited.push(name);
        }
    }
    (largest, limited)
}

/// Kalibr's `imu.yaml` text for these parameters, publishing on `rostopic`.
pub fn imu_yaml(params: &NoiseParams, rostopic: &str) -> Result<String, KalibrError> {
    let gyro = params.gyro.as_ref().ok_or_else(|| KalibrError::NoGyro {
        recording: params.source.clone(),
    })?;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "# IMU noise model for Kalibr, from the Allan deviation of {} ({} samples, {:.1} s).\n\
         # One value per sensor: the largest of the x, y, z axes.",
        params.source, params.samples, params.record_length_s
    );
    let sensors = [
        ("accelerometer", &params.accel, "m/s^2"),
        ("gyroscope", gyro, "rad/s"),
    ];
    for (sensor, noise, unit) in sensors {
        let units = [format!("{unit}/sqrt(Hz)"), format!("{unit}/s/sqrt(Hz)")];
        for (index, term) in [(0usize, "noise_density"), (2, "random_walk")] {
            let (value, limited) = combine(noise, index);
            if value <= 0.0 {
                return Err(KalibrError::Missing { sensor, term });
            }
            let note = if limited.is_empty() {
                String::new()
            } else {
                format!(
                    "; axes {} not resolved by the record: their 2-sigma upper limit",
                    limited.join(", ")
                )
            };
            let unit = &units[usize::from(index == 2)];
            let _ = writeln!(out, "{sensor}_{term}: {value:.6e}  # {unit}{note}");
        }
    }
    let _ = writeln!(out, "rostopic: {rostopic}");
    let _ = writeln!(out, "update_rate: {:.3}  # Hz", params.sample_rate_hz);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{AxisNoise, Estimate, UpperLimits};

    fn axis(n: f64, k: Option<f64>, k_limit: Option<f64>) -> AxisNoise {
        AxisNoise {
            white_noise_density: Some(Estimate {
                value: n,
                sigma: n / 100.0,
            }),
            bias_instability: None,
            random_walk: k.map(|value| Estimate {
                value,
                sigma: value / 10.0,
            }),
            upper_limits: UpperLimits {
                random_walk: k_limit,
                ..Default::default()
            },
        }
    }

    fn params(gyro: bool) -> NoiseParams {
        NoiseParams {
            source: "rec.csv".into(),
            sample_rate_hz: 200.0,
            record_length_s: 3600.0,
            samples: 720_000,
            gravity_mps2: 9.81,
            accel: SensorNoise {
                unit: "m/s^2".into(),
                x: axis(2e-3, Some(1e-4), None),
                y: axis(3e-3, Some(2e-4), None),
                z: axis(2.5e-3, None, Some(5e-4)),
            },
            gyro: gyro.then(|| SensorNoise {
                unit: "rad/s".into(),
                x: axis(1.7e-4, Some(1e-5), None),
                y: axis(1.8e-4, Some(2e-5), None),
                z: axis(1.9e-4, Some(3e-5), None),
            }),
        }
    }

    /// The `key: value` pairs of the YAML, comments stripped.
    fn entries(text: &str) -> Vec<(String, String)> {
        text.lines()
            .filter(|l| !l.starts_with('#'))
            .map(|l| {
                let l = l.split('#').next().unwrap();
                let (k, v) = l.split_once(':').unwrap();
                (k.trim().to_owned(), v.trim().to_owned())
            })
            .collect()
    }

    #[test]
    fn takes_the_largest_axis_and_flags_limits() {
        let text = imu_yaml(&params(true), "/imu0").unwrap();
        let e = entries(&text);
        let get =
            |key: &str| -> f64 { e.iter().find(|(k, _)| k == key).unwrap().1.parse().unwrap() };
        assert_eq!(get("accelerometer_noise_density"), 3e-3);
        // z's limit (5e-4) exceeds x's and y's estimates.
        assert_eq!(get("accelerometer_random_walk"), 5e-4);
        assert_eq!(get("gyroscope_noise_density"), 1.9e-4);
        assert_eq!(get("gyroscope_random_walk"), 3e-5);
        assert_eq!(get("update_rate"), 200.0);
        assert!(e.contains(&("rostopic".into(), "/imu0".into())));
        let walk_line = text
            .lines()
            .find(|l| l.starts_with("accelerometer_random_walk"))
            .unwrap();
        assert!(walk_line.contains("axes z not resolved"), "{walk_line}");
        assert_eq!(e.len(), 6);
    }

    #[test]
    fn refuses_without_gyro() {
        let err = imu_yaml(&params(false), "/imu0").unwrap_err();
        assert!(
            err.to_string()
                .starts_with("rec.csv: Kalibr's imu.yaml needs the gyroscope")
        );
    }
}
