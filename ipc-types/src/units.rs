//! MPU-9250 unit conversions (datasheet PS-MPU-9250A-01 rev 1.1, section 3; register map
//! RM-MPU-9250A-00 rev 1.6), and the physical constants the project shares.

/// Standard gravity, m/s^2 (the default when no local value is configured).
pub const STANDARD_GRAVITY_MPS2: f64 = 9.806_65;

/// Local gravity the capstone thesis used for its recordings, m/s^2.
pub const THESIS_GRAVITY_MPS2: f64 = 9.797;

/// Accelerometer full-scale range, ACCEL_CONFIG bits `[4:3]` (`ACCEL_FS_SEL`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum AccelRange {
    /// +-2 g, 16384 LSB/g.
    #[default]
    G2 = 0,
    /// +-4 g, 8192 LSB/g.
    G4 = 1,
    /// +-8 g, 4096 LSB/g.
    G8 = 2,
    /// +-16 g, 2048 LSB/g.
    G16 = 3,
}

impl AccelRange {
    /// Sensitivity in counts per g.
    pub fn lsb_per_g(self) -> f64 {
        16384.0 / f64::from(1u16 << self as u8)
    }

    /// The range for an `ACCEL_FS_SEL` value (the two bits only).
    pub fn from_bits(bits: u8) -> Self {
        match bits & 3 {
            0 => Self::G2,
            1 => Self::G4,
            2 => Self::G8,
            _ => Self::G16,
        }
    }
}

/// Gyroscope full-scale range, GYRO_CONFIG bits `[4:3]` (`GYRO_FS_SEL`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum GyroRange {
    /// +-250 deg/s, 131 LSB/(deg/s).
    #[default]
    Dps250 = 0,
    /// +-500 deg/s, 65.5 LSB/(deg/s).
    Dps500 = 1,
    /// +-1000 deg/s, 32.8 LSB/(deg/s).
    Dps1000 = 2,
    /// +-2000 deg/s, 16.4 LSB/(deg/s).
    Dps2000 = 3,
}

impl GyroRange {
    /// Sensitivity in counts per deg/s.
    pub fn lsb_per_dps(self) -> f64 {
        // The datasheet's figures (not 131 / 2^n: it rounds 32.75 and 16.375 up).
        match self {
            Self::Dps250 => 131.0,
            Self::Dps500 => 65.5,
            Self::Dps1000 => 32.8,
            Self::Dps2000 => 16.4,
        }
    }

    /// The range for a `GYRO_FS_SEL` value (the two bits only).
    pub fn from_bits(bits: u8) -> Self {
        match bits & 3 {
            0 => Self::Dps250,
            1 => Self::Dps500,
            2 => Self::Dps1000,
            _ => Self::Dps2000,
        }
    }
}

/// TEMP_OUT sensitivity, counts per degC.
pub const TEMP_LSB_PER_DEGC: f64 = 333.87;
/// Temperature at TEMP_OUT = 0, degC (register map, TEMP_OUT: TEMP_degC = TEMP_OUT/333.87 + 21).
pub const TEMP_OFFSET_DEGC: f64 = 21.0;

/// Die temperature in degC from TEMP_OUT counts.
pub fn temp_c_from_counts(counts: i16) -> f64 {
    f64::from(counts) / TEMP_LSB_PER_DEGC + TEMP_OFFSET_DEGC
}

/// TEMP_OUT counts for a die temperature in degC (rounded, saturated to i16).
pub fn temp_counts_from_c(temp_c: f64) -> i16 {
    quantize((temp_c - TEMP_OFFSET_DEGC) * TEMP_LSB_PER_DEGC)
}

/// Rounds a value in counts to the nearest representable 16-bit output, saturating at the ends
/// of the range as the ADC does. NaN maps to 0.
pub fn quantize(counts: f64) -> i16 {
    // `as` saturates and maps NaN to 0, which is exactly the ADC-like behaviour wanted.
    counts.round() as i16
}

/// Whether an output in counts sits at either end of the 16-bit range (a saturated axis).
pub fn is_saturated(counts: i16) -> bool {
    counts == i16::MAX || counts == i16::MIN
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sensitivities_match_the_datasheet() {
        assert_eq!(AccelRange::G2.lsb_per_g(), 16384.0);
        assert_eq!(AccelRange::G16.lsb_per_g(), 2048.0);
        assert_eq!(GyroRange::Dps250.lsb_per_dps(), 131.0);
        assert_eq!(GyroRange::Dps500.lsb_per_dps(), 65.5);
        assert_eq!(GyroRange::Dps2000.lsb_per_dps(), 16.4);
    }

    #[test]
    fn temperature_formula_round_trips() {
        assert_eq!(temp_c_from_counts(0), 21.0);
        assert!((temp_c_from_counts(3339) - (21.0 + 3339.0 / 333.87)).abs() < 1e-12);
        for c in [-40.0, 0.0, 21.0, 25.3, 85.0] {
            assert!((temp_c_from_counts(temp_counts_from_c(c)) - c).abs() <= 0.5 / 333.87);
        }
    }

    #[test]
    fn quantize_saturates_and_rounds() {
        assert_eq!(quantize(1e9), i16::MAX);
        assert_eq!(quantize(-1e9), i16::MIN);
        assert_eq!(quantize(1.5), 2);
        assert_eq!(quantize(-1.4), -1);
        assert_eq!(quantize(f64::NAN), 0);
        assert!(is_saturated(quantize(40000.0)));
    }
}
