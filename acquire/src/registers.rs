//! MPU-9250 register addresses and bit fields used by the driver and the simulated device.
//!
//! Source: InvenSense "MPU-9250 Register Map and Descriptions", RM-MPU-9250A-00 rev 1.6 (table 1
//! and the register descriptions), and the product specification PS-MPU-9250A-01 (I2C
//! addresses, start-up time). Registers are cited by their decimal number, as the register
//! map's section titles do. Only the registers this project touches are listed; the
//! magnetometer (AK8963) and the auxiliary I2C master are not used.
//!
//! All registers reset to 0x00 except PWR_MGMT_1 (0x01) and WHO_AM_I (0x71 on an MPU-9250).

/// I2C address with the AD0 pin low (PS-MPU-9250A-01: 7-bit address 1101000).
pub const ADDRESS_AD0_LOW: u8 = 0x68;
/// I2C address with the AD0 pin high (7-bit address 1101001).
pub const ADDRESS_AD0_HIGH: u8 = 0x69;

/// The value WHO_AM_I (register 117) reads on an MPU-9250 (RM-MPU-9250A-00 register 117).
pub const WHO_AM_I_VALUE: u8 = 0x71;
/// The parts sold as (or on boards sold as) MPU-9250 that share its accelerometer, gyro and
/// FIFO register map, with their WHO_AM_I values: the MPU-6500 (the MPU-9250 without the
/// magnetometer), the MPU-9250 and the MPU-9255. The Linux driver accepts all three
/// (drivers/iio/imu/inv_mpu6050/inv_mpu_iio.h, `INV_MPU6500_WHOAMI_VALUE`,
/// `INV_MPU9250_WHOAMI_VALUE`, `INV_MPU9255_WHOAMI_VALUE`, checked in inv_mpu_core.c
/// `inv_check_and_setup_chip`), and so does ArduPilot (AP_InertialSensor_Invensense.cpp,
/// `_check_whoami`).
pub const WHO_AM_I_PARTS: [(u8, &str); 3] =
    [(0x70, "MPU-6500"), (0x71, "MPU-9250"), (0x73, "MPU-9255")];

/// Size of the FIFO in bytes (register 116; PS-MPU-9250A-01 section 4.17).
pub const FIFO_SIZE: usize = 512;

/// Start-up time for register read/write after power-up or reset, maximum, ns
/// (PS-MPU-9250A-01 section 3.4.2: 11 ms typical, 100 ms maximum).
pub const STARTUP_MAX_NS: u64 = 100_000_000;
/// The same start-up time, typical value, ns.
pub const STARTUP_TYPICAL_NS: u64 = 11_000_000;
/// Gyro start-up time from sleep, typical, ns (PS-MPU-9250A-01 section 3.1, table 1).
pub const GYRO_STARTUP_TYPICAL_NS: u64 = 35_000_000;
/// How long the driver lets the gyros settle after configuring them, ns: the Linux driver's
/// value for this family (inv_mpu_iio.h, `INV_MPU6500_GYRO_STARTUP_TIME`, 70 ms), twice the
/// datasheet's typical start-up time.
pub const GYRO_SETTLE_NS: u64 = 70_000_000;

/// Register 25, SMPLRT_DIV: SAMPLE_RATE = INTERNAL_SAMPLE_RATE / (1 + SMPLRT_DIV), effective
/// only with the gyro DLPF enabled (FCHOICE_B = 0b00 and 0 < DLPF_CFG < 7), where the internal
/// rate is 1 kHz.
pub const SMPLRT_DIV: u8 = 0x19;

/// Register 26, CONFIG.
pub const CONFIG: u8 = 0x1A;
/// CONFIG bit 6, FIFO_MODE: 1 = when the FIFO is full, further writes are dropped;
/// 0 = further writes replace the oldest data.
pub const CONFIG_FIFO_MODE: u8 = 1 << 6;
/// CONFIG bits `[2:0]`, DLPF_CFG: gyro and temperature low-pass filter (table under register 26).
pub const CONFIG_DLPF_CFG_MASK: u8 = 0b111;

/// Register 27, GYRO_CONFIG.
pub const GYRO_CONFIG: u8 = 0x1B;
/// GYRO_CONFIG bits `[4:3]`, GYRO_FS_SEL.
pub const GYRO_FS_SEL_SHIFT: u8 = 3;
/// GYRO_CONFIG bits `[1:0]`, FCHOICE_B (inverted FCHOICE): 0b00 routes the gyro through the DLPF.
pub const GYRO_FCHOICE_B_MASK: u8 = 0b11;

/// Register 28, ACCEL_CONFIG.
pub const ACCEL_CONFIG: u8 = 0x1C;
/// ACCEL_CONFIG bits `[4:3]`, ACCEL_FS_SEL.
pub const ACCEL_FS_SEL_SHIFT: u8 = 3;

/// Register 29, ACCEL_CONFIG2. Bits `[2:0]`, A_DLPF_CFG, select the accelerometer low-pass
/// filter (1 kHz output rate) when accel_fchoice_b is 0.
pub const ACCEL_CONFIG2: u8 = 0x1D;
/// ACCEL_CONFIG2 bit 3, accel_fchoice_b: 1 bypasses the accelerometer DLPF; the accelerometer
/// then outputs at 4 kHz with 1.13 kHz bandwidth (1046 Hz in the product specification).
pub const ACCEL_FCHOICE_B: u8 = 1 << 3;

/// Register 35, FIFO_EN: which sensor registers are written into the FIFO at the sample rate.
/// Data enter the FIFO in register order (register 116): accel (59-64), temperature (65-66),
/// gyro (67-72).
pub const FIFO_EN: u8 = 0x23;
/// FIFO_EN bit 7, TEMP_FIFO_EN: TEMP_OUT_H/L.
pub const FIFO_EN_TEMP: u8 = 1 << 7;
/// FIFO_EN bit 6, GYRO_XOUT: GYRO_XOUT_H/L.
pub const FIFO_EN_GYRO_X: u8 = 1 << 6;
/// FIFO_EN bit 5, GYRO_YOUT: GYRO_YOUT_H/L.
pub const FIFO_EN_GYRO_Y: u8 = 1 << 5;
/// FIFO_EN bit 4, GYRO_ZOUT: GYRO_ZOUT_H/L.
pub const FIFO_EN_GYRO_Z: u8 = 1 << 4;
/// FIFO_EN bit 3, ACCEL: ACCEL_XOUT_H through ACCEL_ZOUT_L.
pub const FIFO_EN_ACCEL: u8 = 1 << 3;

/// Register 58, INT_STATUS. Its bits clear when the register is read.
pub const INT_STATUS: u8 = 0x3A;
/// INT_STATUS bit 4, FIFO_OFLOW_INT: the FIFO overflowed.
pub const INT_STATUS_FIFO_OFLOW: u8 = 1 << 4;
/// INT_STATUS bit 0, RAW_DATA_RDY_INT: new sensor data are in the data registers.
pub const INT_STATUS_RAW_DATA_RDY: u8 = 1 << 0;

/// Register 59, ACCEL_XOUT_H: the accelerometer outputs are six big-endian bytes from here
/// (registers 59-64), X, Y, Z.
pub const ACCEL_XOUT_H: u8 = 0x3B;
/// Register 65, TEMP_OUT_H: big-endian with TEMP_OUT_L (register 66).
/// TEMP_degC = (TEMP_OUT - RoomTemp_Offset) / Temp_Sensitivity + 21 degC, with offset 0 LSB and
/// sensitivity 333.87 LSB/degC (see `ipc_types::units`).
pub const TEMP_OUT_H: u8 = 0x41;
/// Register 67, GYRO_XOUT_H: the gyro outputs are six big-endian bytes from here
/// (registers 67-72), X, Y, Z.
pub const GYRO_XOUT_H: u8 = 0x43;
/// Number of sensor data bytes from ACCEL_XOUT_H to GYRO_ZOUT_L.
pub const SENSOR_DATA_LEN: usize = 14;

/// Register 106, USER_CTRL.
pub const USER_CTRL: u8 = 0x6A;
/// USER_CTRL bit 4, I2C_IF_DIS: disables the I2C interface (set when using SPI, so that the
/// part never switches into I2C mode; PS-MPU-9250A-01 section 7.1, page 32).
pub const USER_CTRL_I2C_IF_DIS: u8 = 1 << 4;
/// USER_CTRL bit 6, FIFO_EN: enables FIFO operation.
pub const USER_CTRL_FIFO_EN: u8 = 1 << 6;
/// USER_CTRL bit 2, FIFO_RST: resets the FIFO; clears itself.
pub const USER_CTRL_FIFO_RST: u8 = 1 << 2;

/// Register 107, PWR_MGMT_1. Resets to 0x01.
pub const PWR_MGMT_1: u8 = 0x6B;
/// PWR_MGMT_1 bit 7, H_RESET: resets the internal registers to their defaults; clears itself.
pub const PWR_MGMT_1_H_RESET: u8 = 1 << 7;
/// PWR_MGMT_1 bit 6, SLEEP: puts the chip to sleep (no sampling).
pub const PWR_MGMT_1_SLEEP: u8 = 1 << 6;
/// PWR_MGMT_1 bits `[2:0]`, CLKSEL, value 1: the gyro PLL when ready, else the internal
/// oscillator.
pub const CLKSEL_AUTO: u8 = 1;
/// Reset value of PWR_MGMT_1.
pub const PWR_MGMT_1_RESET_VALUE: u8 = 0x01;

/// Register 108, PWR_MGMT_2: bits `[5:3]` put accel X/Y/Z in standby, `[2:0]` gyro X/Y/Z.
pub const PWR_MGMT_2: u8 = 0x6C;
/// PWR_MGMT_2 bits `[2:0]`: DIS_XG, DIS_YG, DIS_ZG.
pub const PWR_MGMT_2_DISABLE_GYRO: u8 = 0b111;

/// Register 114, FIFO_COUNTH: `FIFO_CNT[12:8]`; reading it latches FIFO_COUNTL.
pub const FIFO_COUNTH: u8 = 0x72;
/// Register 115, FIFO_COUNTL: `FIFO_CNT[7:0]` as latched by the last FIFO_COUNTH read.
pub const FIFO_COUNTL: u8 = 0x73;
/// Register 116, FIFO_R_W: reading pops one byte from the FIFO; an empty FIFO repeats the
/// last byte read.
pub const FIFO_R_W: u8 = 0x74;
/// Register 117, WHO_AM_I.
pub const WHO_AM_I: u8 = 0x75;

/// Whether `register` may be read over SPI at 20 MHz: the interrupt status, the sensor data
/// registers, and the FIFO count and data registers (PS-MPU-9250A-01 section 3.4: 20 MHz for
/// reading sensor and interrupt registers, 1 MHz for everything else).
pub fn spi_fast_readable(register: u8) -> bool {
    register == INT_STATUS
        || (ACCEL_XOUT_H..ACCEL_XOUT_H + SENSOR_DATA_LEN as u8).contains(&register)
        || (FIFO_COUNTH..=FIFO_R_W).contains(&register)
}

/// CONFIG.DLPF_CFG = 0: gyro 250 Hz bandwidth, 8 kHz internal sample rate (register 26 table).
pub const DLPF_CFG_8KHZ: u8 = 0;

/// Gyro and temperature DLPF delay by CONFIG.DLPF_CFG (0-7) with FCHOICE_B = 0, ns
/// (RM-MPU-9250A-00 register 26 table, "Delay (ms)" of the gyroscope).
pub const GYRO_DLPF_DELAY_NS: [u64; 8] = [
    970_000, 2_900_000, 3_900_000, 5_900_000, 9_900_000, 17_850_000, 33_480_000, 170_000,
];
/// Accelerometer DLPF delay by ACCEL_CONFIG2.A_DLPF_CFG (0-7) with accel_fchoice_b = 0, ns
/// (RM-MPU-9250A-00 register 29 table, "Delay (ms)").
pub const ACCEL_DLPF_DELAY_NS: [u64; 8] = [
    1_880_000, 1_880_000, 2_880_000, 4_880_000, 8_870_000, 16_830_000, 32_480_000, 1_380_000,
];
/// Accelerometer delay with its DLPF bypassed (accel_fchoice_b = 1, 1.13 kHz bandwidth), ns
/// (RM-MPU-9250A-00 register 29 table).
pub const ACCEL_BYPASS_DELAY_NS: u64 = 750_000;

/// Internal sample rate with the gyro DLPF enabled (DLPF_CFG 1-6), Hz (register 25).
pub const INTERNAL_RATE_DLPF_HZ: f64 = 1000.0;
/// Internal sample rate with the gyro DLPF off (DLPF_CFG 0 or 7: 8 kHz; FCHOICE_B != 0:
/// 32 kHz, which this project never uses and the simulation treats as 8 kHz), Hz.
pub const INTERNAL_RATE_NO_DLPF_HZ: f64 = 8000.0;
/// Accelerometer output rate with accel_fchoice_b = 1, Hz (register 29). The FIFO is still
/// written at the sample rate (register 25), so all of these samples reach it only at an
/// 8 kHz sample rate, each twice.
pub const ACCEL_BYPASS_RATE_HZ: f64 = 4000.0;
