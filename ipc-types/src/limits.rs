//! The bounds every boundary checks a sample against (file readers, the live stages): values a
//! MEMS IMU of the MPU-9250's class can produce, with a margin for recordings of other parts
//! whose loggers already applied their own calibration. A value outside them is not a
//! measurement (a corrupted file, a broken driver) and must not reach an estimate.
//!
//! Units: g, deg/s, degC, seconds; per axis (each component on its own).

use crate::units::{TEMP_LSB_PER_DEGC, TEMP_OFFSET_DEGC};

/// Largest accelerometer reading per axis, g: the MPU-9250's largest full-scale range, +-16 g
/// (PS-MPU-9250A-01 rev 1.1, table 3.2, `ACCEL_FS_SEL` = 3), plus 25 % for a logger's own scale
/// correction of another part's output (the OpenShoe figure-8 log reaches 16.85 g).
pub const ACCEL_LIMIT_G: f64 = 20.0;

/// Largest angular rate per axis, deg/s: the MPU-9250's largest full-scale range, +-2000 deg/s
/// (PS-MPU-9250A-01 rev 1.1, table 3.1, `GYRO_FS_SEL` = 3), plus 25 % as for
/// [`ACCEL_LIMIT_G`].
pub const GYRO_LIMIT_DPS: f64 = 2500.0;

/// Lowest die temperature TEMP_OUT can express, degC (-32768 counts; register map
/// RM-MPU-9250A-00 rev 1.6, TEMP_OUT: `TEMP_degC = TEMP_OUT / 333.87 + 21`).
pub const TEMP_MIN_C: f64 = -32768.0 / TEMP_LSB_PER_DEGC + TEMP_OFFSET_DEGC;

/// Highest die temperature TEMP_OUT can express, degC (+32767 counts).
pub const TEMP_MAX_C: f64 = 32767.0 / TEMP_LSB_PER_DEGC + TEMP_OFFSET_DEGC;

/// Longest step between consecutive samples of one stream, s. Real logs step by at most
/// 18 ms (the x-io walks; 1-8 ms elsewhere); a stalled pipeline is seconds. A longer step is
/// not a gap dead reckoning can bridge: a file reader refuses it, a live stage drops the
/// sample.
pub const MAX_STEP_S: f64 = 60.0;

/// [`MAX_STEP_S`] in nanoseconds.
pub const MAX_STEP_NS: u64 = 60_000_000_000;

/// What is wrong with a value (see [`check_raw`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutOfBounds {
    /// The field, e.g. `accel_g[2]`.
    pub field: &'static str,
    /// Its value.
    pub value: f64,
    /// The bound it breaks, in the field's unit (the limit of `|value|`, or the far end of the
    /// temperature range it left).
    pub limit: f64,
}

impl std::fmt::Display for OutOfBounds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.value.is_finite() {
            write!(
                f,
                "{} = {:?} is beyond the sensor's range (limit {:?})",
                self.field, self.value, self.limit
            )
        } else {
            write!(f, "{} = {:?} is not finite", self.field, self.value)
        }
    }
}

const ACCEL_FIELDS: [&str; 3] = ["accel_g[0]", "accel_g[1]", "accel_g[2]"];
const GYRO_FIELDS: [&str; 3] = ["gyro_dps[0]", "gyro_dps[1]", "gyro_dps[2]"];

/// Checks a raw reading in sensor units: every accelerometer axis finite and within
/// [`ACCEL_LIMIT_G`]; the gyroscope's within [`GYRO_LIMIT_DPS`] when `gyro` is given; the
/// temperature within [`TEMP_MIN_C`]..=[`TEMP_MAX_C`] when `temp_c` is given. Returns the
/// first offending field.
pub fn check_raw(
    accel_g: &[f64; 3],
    gyro_dps: Option<&[f64; 3]>,
    temp_c: Option<f64>,
) -> Result<(), OutOfBounds> {
    check_axes(accel_g, &ACCEL_FIELDS, ACCEL_LIMIT_G)?;
    if let Some(gyro) = gyro_dps {
        check_axes(gyro, &GYRO_FIELDS, GYRO_LIMIT_DPS)?;
    }
    if let Some(t) = temp_c
        && !(TEMP_MIN_C..=TEMP_MAX_C).contains(&t)
    {
        let limit = if t < TEMP_MIN_C {
            TEMP_MIN_C
        } else {
            TEMP_MAX_C
        };
        return Err(OutOfBounds {
            field: "temp_c",
            value: t,
            limit,
        });
    }
    Ok(())
}

/// Checks that every value is finite and at most `limit` in magnitude; `fields` names them.
pub fn check_axes(
    values: &[f64; 3],
    fields: &[&'static str; 3],
    limit: f64,
) -> Result<(), OutOfBounds> {
    for (&value, &field) in values.iter().zip(fields) {
        if !value.is_finite() || value.abs() > limit {
            return Err(OutOfBounds {
                field,
                value,
                limit,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::temp_c_from_counts;

    #[test]
    fn the_temperature_range_is_what_temp_out_can_express() {
        assert_eq!(TEMP_MIN_C, temp_c_from_counts(i16::MIN));
        assert_eq!(TEMP_MAX_C, temp_c_from_counts(i16::MAX));
        assert_eq!(MAX_STEP_NS, (MAX_STEP_S * 1e9) as u64);
    }

    #[test]
    fn absurd_values_are_refused_and_real_ones_pass() {
        let g = [0.01, -0.02, 1.0];
        assert_eq!(check_raw(&g, Some(&[1.0, -600.0, 0.0]), Some(35.0)), Ok(()));
        // Full scale of the largest range, both ends.
        assert_eq!(
            check_raw(&[-16.0, 15.9995, 16.0], Some(&[2000.0; 3]), None),
            Ok(())
        );
        for (accel, field) in [
            ([100.0, 0.0, 1.0], "accel_g[0]"),
            ([0.0, 1e300, 1.0], "accel_g[1]"),
            ([0.0, 0.0, f64::NAN], "accel_g[2]"),
            ([0.0, 0.0, f64::NEG_INFINITY], "accel_g[2]"),
        ] {
            assert_eq!(check_raw(&accel, None, None).unwrap_err().field, field);
        }
        let err = check_raw(&g, Some(&[0.0, 0.0, -3000.0]), None).unwrap_err();
        assert_eq!((err.field, err.limit), ("gyro_dps[2]", GYRO_LIMIT_DPS));
        assert!(
            err.to_string().contains("beyond the sensor's range"),
            "{err}"
        );
        let err = check_raw(&g, None, Some(-200.0)).unwrap_err();
        assert_eq!((err.field, err.limit), ("temp_c", TEMP_MIN_C));
        let err = check_raw(&g, None, Some(f64::NAN)).unwrap_err();
        assert!(err.to_string().contains("not finite"), "{err}");
    }
}
