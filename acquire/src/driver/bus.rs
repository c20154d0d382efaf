//! What a bus can carry: the driver refuses configurations whose FIFO data alone would take
//! more than [`MAX_DATA_SHARE`] of the bus.
//!
//! An I2C byte takes 9 SCL periods (8 bits and the acknowledge); an SPI byte 8 SCLK periods.
//! The MPU-9250's I2C runs at most at 400 kHz (PS-MPU-9250A-01 section 7.2, page 32); its SPI
//! at 1 MHz for all registers and 20 MHz for reading sensor and interrupt registers (section
//! 3.4 and section 7.5, page 36), which covers the FIFO reads. ArduPilot for the same reason
//! enables the 8 kHz FIFO ("fast sampling") only on SPI and limits other buses to 1 kHz
//! (AP_InertialSensor_Invensense.cpp, `_set_filter_register`).

use super::Config;

/// The largest share of the bus the FIFO data may take: the rest is for each read's
/// INT_STATUS and FIFO_COUNT transactions, the temperature, and retries.
pub const MAX_DATA_SHARE: f64 = 0.7;

/// The bus a driver talks over, with its clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BusKind {
    /// I2C at `scl_hz`.
    I2c {
        /// SCL frequency, Hz.
        scl_hz: f64,
    },
    /// SPI, FIFO and sensor data read at `data_hz`.
    Spi {
        /// SCLK frequency of FIFO and sensor register reads, Hz.
        data_hz: f64,
    },
}

impl BusKind {
    /// I2C fast mode, 400 kHz: the MPU-9250's fastest I2C.
    pub const I2C_FAST_MODE: Self = Self::I2c { scl_hz: 400_000.0 };
    /// SPI with data reads at 20 MHz, the MPU-9250's fastest.
    pub const SPI_20MHZ: Self = Self::Spi { data_hz: 20e6 };

    /// Clock periods per byte.
    pub fn clocks_per_byte(&self) -> f64 {
        match self {
            Self::I2c { .. } => 9.0,
            Self::Spi { .. } => 8.0,
        }
    }

    /// The clock that moves the FIFO data, Hz.
    pub fn data_clock_hz(&self) -> f64 {
        match *self {
            Self::I2c { scl_hz } => scl_hz,
            Self::Spi { data_hz } => data_hz,
        }
    }

    /// Whether this is SPI.
    pub fn is_spi(&self) -> bool {
        matches!(self, Self::Spi { .. })
    }

    /// The share of the bus the FIFO data of `config` take, 0-1 (more than 1 cannot be read).
    pub fn data_share(&self, config: &Config) -> f64 {
        config.fifo_rate_hz() * config.frame_len() as f64 * self.clocks_per_byte()
            / self.data_clock_hz()
    }

    /// Refuses `config` if its FIFO data need more than [`MAX_DATA_SHARE`] of this bus, with
    /// the arithmetic in the message.
    pub fn check(&self, config: &Config) -> Result<(), String> {
        let share = self.data_share(config);
        if share <= MAX_DATA_SHARE {
            return Ok(());
        }
        let (name, unit) = match self {
            Self::I2c { .. } => ("I2C", "SCL"),
            Self::Spi { .. } => ("SPI", "SCLK"),
        };
        let alternative = if self.is_spi() {
            "a lower rate"
        } else {
            "SPI (--source spi:/dev/spidevB.C, or sim-spi), or at most 1000 Hz on I2C"
        };
        Err(format!(
            "{} Hz cannot be read over a {:.0} kHz {name} bus: the FIFO is written at {:.0} \
             frames/s x {} B x {} clocks = {:.0} kHz of {unit}, {:.0} % of the bus (at most \
             {:.0} % may carry FIFO data; the rest is for status and count reads); use \
             {alternative}",
            config.output_rate_hz(),
            self.data_clock_hz() * 1e-3,
            config.fifo_rate_hz(),
            config.frame_len(),
            self.clocks_per_byte(),
            config.fifo_rate_hz() * config.frame_len() as f64 * self.clocks_per_byte() * 1e-3,
            share * 100.0,
            MAX_DATA_SHARE * 100.0,
        ))
    }
}
