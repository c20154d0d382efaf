//! The ADC: quantization and saturation of analog samples into raw samples, exactly as the
//! register-level device and the `mems-sim` writer both do it.

use ipc_types::stream::range;
use ipc_types::units::{self, AccelRange, GyroRange};
use ipc_types::{RawImuSample, Stamps, raw_flags};

use crate::AnalogSample;

/// Quantizes `analog` with the configured full-scale ranges into a raw sample with sequence
/// number `seq` and sample time `sample_ns`: counts are `round(value * LSB)` saturated to i16
/// (`units::quantize`), scaled values are `counts / LSB`, the temperature goes through
/// TEMP_OUT's formula, and `SATURATED` is set when any accelerometer or gyroscope axis sits
/// at either end of the 16-bit range, with that axis's `SATURATED_AXES` bit. Gyroscope and temperature are flagged valid.
pub fn quantize_sample(
    analog: &AnalogSample,
    accel_range: AccelRange,
    gyro_range: GyroRange,
    sample_ns: u64,
    seq: u64,
) -> RawImuSample {
    let a_lsb = accel_range.lsb_per_g();
    let g_lsb = gyro_range.lsb_per_dps();
    let accel_counts = analog.accel_g.map(|a| units::quantize(a * a_lsb));
    let gyro_counts = analog.gyro_dps.map(|g| units::quantize(g * g_lsb));
    let temp_counts = units::temp_counts_from_c(analog.temp_c);
    let mut raw = RawImuSample {
        stamps: Stamps {
            sample_ns,
            ..Stamps::default()
        },
        seq,
        accel_g: accel_counts.map(|c| f64::from(c) / a_lsb),
        gyro_dps: gyro_counts.map(|c| f64::from(c) / g_lsb),
        temp_c: units::temp_c_from_counts(temp_counts),
        accel_counts,
        gyro_counts,
        temp_counts,
        flags: raw_flags::GYRO_VALID | raw_flags::TEMP_VALID,
        lost_before: 0,
        undelivered: 0,
    };
    let clipped = range::clipped_axes_from_counts(&raw);
    range::mark_clipped(&mut raw, clipped);
    raw
}
