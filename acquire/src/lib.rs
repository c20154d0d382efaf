//! MPU-9250 acquisition: a small driver over `embedded_hal::i2c::I2c` with FIFO-based burst
//! reads and sample-time reconstruction ([`driver`]), the same register transactions over SPI
//! ([`spi`]), the register map it is written against ([`registers`]), a register-level
//! simulated MPU-9250 behind the same traits ([`sim`]), and the
//! clocks both run on ([`clock`]); the acquisition loop ([`acquisition`]), and the
//! `mems-acquire` process around it ([`process`]: the source opened, real-time setup,
//! publishing on `mems/imu/raw` and the run's summary), and the sensor session a restarted
//! process continues ([`session`]).

pub mod acquisition;
pub mod clock;
pub mod driver;
pub mod process;
pub mod registers;
pub mod session;
pub mod sim;
pub mod spi;
