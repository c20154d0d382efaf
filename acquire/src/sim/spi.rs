//! The simulated MPU-9250's SPI interface, behind `embedded_hal::spi::SpiDevice` like
//! `linux_embedded_hal::SpidevDevice`.
//!
//! Protocol (PS-MPU-9250A-01 section 7.5, page 36): each transaction (chip select low to high)
//! starts with one address byte, the read/write bit (1 = read) in bit 7 and the register in
//! bits 6-0; the following bytes are data, read or written with the same auto-increment as on
//! I2C (FIFO_R_W pops the FIFO). Every byte takes 8 SCLK periods at the clock the host set
//! with [`SimMpu9250::set_spi_clock_hz`], plus [`SpiTiming::gap_ns`] between transactions. The
//! part allows 1 MHz for every register and 20 MHz only for reading the sensor and interrupt
//! registers (PS-MPU-9250A-01 section 3.4, serial interface characteristics; PX4 and ArduPilot
//! run their Invensense drivers at these two speeds): a transaction clocked faster than its
//! registers allow is counted in [`BusStats::spi_overspeed`](super::BusStats).

use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};
use mems_sim::SampleSource;

use super::SimMpu9250;
use crate::registers as reg;

/// Timing model and limits of the SPI interface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SpiTiming {
    /// Fastest SCLK for writes and for reading registers other than the sensor and interrupt
    /// registers, Hz.
    pub max_register_hz: f64,
    /// Fastest SCLK for reading the sensor, interrupt and FIFO registers, Hz.
    pub max_data_hz: f64,
    /// Chip-select set-up and hold around each transaction, ns.
    pub gap_ns: u64,
}

impl SpiTiming {
    /// The datasheet's limits: 1 MHz for all registers, 20 MHz for reading sensor and
    /// interrupt registers; 1 us of chip-select overhead per transaction.
    pub const DATASHEET: Self = Self {
        max_register_hz: 1e6,
        max_data_hz: 20e6,
        gap_ns: 1_000,
    };
}

impl<S: SampleSource> SimMpu9250<S> {
    /// Sets the SCLK frequency the host uses from now on, Hz (what `SPI_IOC_WR_MAX_SPEED_HZ`
    /// does on a spidev).
    pub fn set_spi_clock_hz(&mut self, hz: f64) {
        self.spi_clock_hz = hz;
    }

    /// Runs one SPI transaction's operations; returns the bytes clocked and whether the clock
    /// was too fast for the registers touched.
    fn run_spi(&mut self, operations: &mut [Operation<'_, u8>], now_ns: u64) -> (u64, bool) {
        let mut bytes = 0u64;
        let mut read = false;
        let mut register = 0u8;
        for op in operations.iter_mut() {
            let (out, input): (Option<&mut [u8]>, Option<&[u8]>) = match op {
                Operation::Read(buf) => (Some(&mut buf[..]), None),
                Operation::Write(data) => (None, Some(&data[..])),
                Operation::Transfer(r, w) => {
                    // Clock max(len) bytes; only the written bytes matter to the device.
                    let n = r.len().max(w.len());
                    for i in 0..n {
                        let b = w.get(i).copied().unwrap_or(0);
                        let v = self.spi_byte(bytes, b, &mut read, &mut register, now_ns);
                        if let Some(slot) = r.get_mut(i) {
                            *slot = v;
                        }
                        bytes += 1;
                    }
                    continue;
                }
                Operation::TransferInPlace(buf) => {
                    for slot in buf.iter_mut() {
                        *slot = self.spi_byte(bytes, *slot, &mut read, &mut register, now_ns);
                        bytes += 1;
                    }
                    continue;
                }
                Operation::DelayNs(ns) => {
                    self.clock.advance(u64::from(*ns));
                    continue;
                }
            };
            if let Some(buf) = out {
                for slot in buf.iter_mut() {
                    *slot = self.spi_byte(bytes, 0, &mut read, &mut register, now_ns);
                    bytes += 1;
                }
            }
            if let Some(data) = input {
                for &b in data {
                    self.spi_byte(bytes, b, &mut read, &mut register, now_ns);
                    bytes += 1;
                }
            }
        }
        let limit = if read && reg::spi_fast_readable(register) {
            self.config.spi.max_data_hz
        } else {
            self.config.spi.max_register_hz
        };
        (bytes, bytes > 0 && self.spi_clock_hz > limit)
    }

    /// Byte number `i` of a transaction, `mosi` from the host; returns the byte on MISO.
    fn spi_byte(
        &mut self,
        i: u64,
        mosi: u8,
        read: &mut bool,
        register: &mut u8,
        now_ns: u64,
    ) -> u8 {
        self.stats.bytes += 1;
        if i == 0 {
            *read = mosi & 0x80 != 0;
            *register = mosi & 0x7F;
            self.pointer = *register;
            return 0;
        }
        let value = if *read {
            self.read_register(self.pointer)
        } else {
            self.write_register(self.pointer, mosi, now_ns);
            0
        };
        self.advance_pointer();
        value
    }
}

impl<S: SampleSource> ErrorType for SimMpu9250<S> {
    type Error = ErrorKind;
}

impl<S: SampleSource> SpiDevice for SimMpu9250<S> {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), Self::Error> {
        let (start, fault) = self.begin_transaction();
        if !self.present || start < self.responsive_from_ns {
            // Nobody drives MISO: the host reads whatever the line floats to; nothing happens.
            for op in operations.iter_mut() {
                if let Operation::Read(buf) | Operation::TransferInPlace(buf) = op {
                    buf.fill(0xFF);
                }
            }
            let duration = self.config.spi.gap_ns;
            self.end_transaction(start, duration, false);
            return Ok(());
        }
        self.shadow = self.internal;
        let (bytes, overspeed) = self.run_spi(operations, start);
        if overspeed {
            self.stats.spi_overspeed += 1;
        }
        let duration =
            (bytes as f64 * 8.0 * 1e9 / self.spi_clock_hz).round() as u64 + self.config.spi.gap_ns;
        let failed = fault.is_some();
        self.end_transaction(start, duration, failed);
        if failed {
            Err(ErrorKind::Other)
        } else {
            Ok(())
        }
    }
}
