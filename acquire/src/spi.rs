//! The MPU-9250's registers over SPI, as the two register transactions the driver uses.
//!
//! [`crate::driver::Mpu9250`] speaks embedded-hal's `I2c`: a register write is
//! `write(address, [register, value..])` and a register read `write_read(address,
//! [register], buffer)`. [`SpiRegisters`] carries exactly these two shapes over an
//! `embedded_hal::spi::SpiDevice`, as the part's SPI protocol frames them (PS-MPU-9250A-01
//! section 7.5, page 36: one address byte with the read bit in bit 7, then the data, with the
//! same auto-increment as on I2C); the address is ignored (chip select picks the part). Any
//! other transaction shape is refused. Hand-written because no crate adapts a register-level
//! I2C driver to SPI.
//!
//! Clock: embedded-hal has no SPI clock setting, so the device also implements [`SpiClock`].
//! Writes and reads of configuration registers run at 1 MHz, reads of the interrupt status,
//! sensor data and FIFO registers at 20 MHz, the part's limits (PS-MPU-9250A-01 section 3.4;
//! PX4's and ArduPilot's Invensense drivers switch between the same two speeds). The clock is
//! changed only when the next transaction needs the other speed, so the steady read loop
//! (INT_STATUS, FIFO_COUNT, FIFO_R_W, all fast) never changes it.

use embedded_hal::i2c::{self, ErrorType, I2c, Operation};
use embedded_hal::spi::{self, SpiDevice};

use crate::registers as reg;

/// Clock setting of an SPI device (what spidev's `SPI_IOC_WR_MAX_SPEED_HZ` does).
pub trait SpiClock {
    /// Sets SCLK for the following transactions, Hz.
    fn set_clock_hz(&mut self, hz: u32) -> std::io::Result<()>;
}

impl SpiClock for linux_embedded_hal::SpidevDevice {
    fn set_clock_hz(&mut self, hz: u32) -> std::io::Result<()> {
        let options = linux_embedded_hal::spidev::SpidevOptions::new()
            .max_speed_hz(hz)
            .build();
        self.configure(&options)
    }
}

impl<S: mems_sim::SampleSource> SpiClock for crate::sim::SimMpu9250<S> {
    fn set_clock_hz(&mut self, hz: u32) -> std::io::Result<()> {
        self.set_spi_clock_hz(f64::from(hz));
        Ok(())
    }
}

/// SCLK for writes and configuration reads, Hz.
pub const REGISTER_CLOCK_HZ: u32 = 1_000_000;
/// SCLK for reading interrupt status, sensor data and the FIFO, Hz.
pub const DATA_CLOCK_HZ: u32 = 20_000_000;

/// Why an SPI register transaction failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpiRegisterError {
    /// The SPI transfer failed.
    Spi(spi::ErrorKind),
    /// The clock could not be set.
    Clock,
    /// The driver asked for a transaction shape that has no SPI equivalent here.
    Unsupported,
}

impl i2c::Error for SpiRegisterError {
    fn kind(&self) -> i2c::ErrorKind {
        match self {
            Self::Spi(_) | Self::Clock => i2c::ErrorKind::Bus,
            Self::Unsupported => i2c::ErrorKind::Other,
        }
    }
}

/// An SPI device seen as the MPU-9250's register transactions; see the module documentation.
pub struct SpiRegisters<S> {
    spi: S,
    clock_hz: Option<u32>,
}

impl<S: SpiDevice + SpiClock> SpiRegisters<S> {
    /// Wraps `spi` (mode 0 or 3, chip select handled by the device).
    pub fn new(spi: S) -> Self {
        Self {
            spi,
            clock_hz: None,
        }
    }

    /// The SPI device, e.g. to reach a simulated part's controls.
    pub fn inner(&self) -> &S {
        &self.spi
    }

    /// The SPI device, mutably.
    pub fn inner_mut(&mut self) -> &mut S {
        &mut self.spi
    }

    fn clock(&mut self, hz: u32) -> Result<(), SpiRegisterError> {
        if self.clock_hz != Some(hz) {
            self.spi
                .set_clock_hz(hz)
                .map_err(|_| SpiRegisterError::Clock)?;
            self.clock_hz = Some(hz);
        }
        Ok(())
    }
}

impl<S: SpiDevice + SpiClock> ErrorType for SpiRegisters<S> {
    type Error = SpiRegisterError;
}

impl<S: SpiDevice + SpiClock> I2c for SpiRegisters<S> {
    fn transaction(
        &mut self,
        _address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        let spi_error = |e: S::Error| SpiRegisterError::Spi(spi::Error::kind(&e));
        match operations {
            [Operation::Write(bytes)] if bytes.len() >= 2 => {
                self.clock(REGISTER_CLOCK_HZ)?;
                // Bit 7 clear: write. The register byte goes first, then the data.
                let command = [bytes[0] & 0x7F];
                self.spi
                    .transaction(&mut [
                        spi::Operation::Write(&command),
                        spi::Operation::Write(&bytes[1..]),
                    ])
                    .map_err(spi_error)
            }
            [Operation::Write([register]), Operation::Read(buf)] => {
                let register = *register & 0x7F;
                let hz = if reg::spi_fast_readable(register) {
                    DATA_CLOCK_HZ
                } else {
                    REGISTER_CLOCK_HZ
                };
                self.clock(hz)?;
                let command = [register | 0x80];
                self.spi
                    .transaction(&mut [spi::Operation::Write(&command), spi::Operation::Read(buf)])
                    .map_err(spi_error)
            }
            _ => Err(SpiRegisterError::Unsupported),
        }
    }
}

impl<S: SpiDevice + SpiClock> crate::driver::Mpu9250<SpiRegisters<S>> {
    /// A driver for the part on `spi` (its I2C address is irrelevant and shown as 0x00);
    /// `bus` names the bus in errors (e.g. "/dev/spidev0.0" or "sim-spi").
    pub fn new_spi(spi: S, bus: impl Into<String>) -> Self {
        Self::new(SpiRegisters::new(spi), bus, 0).with_bus_kind(crate::driver::BusKind::SPI_20MHZ)
    }
}
