//! The driver's errors, each naming the bus and the device address.

/// Driver errors. Every variant names the bus (the caller's label, e.g. "/dev/i2c-1" or "sim")
/// and the device address.
#[derive(Debug, thiserror::Error)]
pub enum Error<E: embedded_hal::i2c::Error> {
    /// Nothing acknowledges the address.
    #[error(
        "no device answers at address {address:#04x} on {bus} (is the MPU-9250 connected, and \
         AD0 wired for this address?): {error:?}"
    )]
    Absent {
        /// Bus label.
        bus: String,
        /// 7-bit address.
        address: u8,
        /// The error of the last attempt.
        error: E,
    },
    /// A device answers but is not an MPU-9250 or a part with its register map.
    #[error(
        "the device at address {address:#04x} on {bus} is not an MPU-9250: WHO_AM_I (0x75) \
         reads {found:#04x}, expected 0x71 (MPU-9250), 0x73 (MPU-9255) or 0x70 (MPU-6500)"
    )]
    WrongDevice {
        /// Bus label.
        bus: String,
        /// 7-bit address.
        address: u8,
        /// The WHO_AM_I value read.
        found: u8,
    },
    /// A transaction kept failing through the retries.
    #[error("I2C error on {bus} at address {address:#04x} while {during}: {error:?}")]
    Bus {
        /// Bus label.
        bus: String,
        /// 7-bit address.
        address: u8,
        /// What the driver was doing.
        during: &'static str,
        /// The error of the last attempt.
        error: E,
    },
    /// A configuration register does not read back what was written.
    #[error(
        "register {register:#04x} of the MPU-9250 at address {address:#04x} on {bus} reads \
         {read:#04x} after writing {wrote:#04x}"
    )]
    Verify {
        /// Bus label.
        bus: String,
        /// 7-bit address.
        address: u8,
        /// Register address.
        register: u8,
        /// Value written.
        wrote: u8,
        /// Value read back.
        read: u8,
    },
    /// The bus cannot carry the configuration's FIFO data.
    #[error("{bus}: {message}")]
    Infeasible {
        /// Bus label.
        bus: String,
        /// What the configuration needs and the bus has.
        message: String,
    },
    /// [`Mpu9250::read_samples`](super::Mpu9250::read_samples) was called before [`Mpu9250::init`](super::Mpu9250::init).
    #[error("the MPU-9250 at address {address:#04x} on {bus} was never initialised")]
    NotInitialised {
        /// Bus label.
        bus: String,
        /// 7-bit address.
        address: u8,
    },
}
