//! The device's configuration: output mode and rate, low-pass filter, full-scale ranges, and
//! the register values they set.

use ipc_types::units::{AccelRange, GyroRange};

use crate::registers as reg;

/// Digital low-pass filter setting for the gyro/temperature (CONFIG.DLPF_CFG) and the
/// accelerometer (ACCEL_CONFIG2.A_DLPF_CFG); both get the same value. The names give the gyro
/// bandwidth; the accelerometer's is 218, 99, 45, 21, 10 and 5 Hz respectively. All of these
/// run the sensors at a 1 kHz internal rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum Dlpf {
    /// Gyro 184 Hz, accel 218.1 Hz.
    Hz184 = 1,
    /// Gyro 92 Hz, accel 99 Hz.
    Hz92 = 2,
    /// Gyro 41 Hz, accel 44.8 Hz.
    Hz41 = 3,
    /// Gyro 20 Hz, accel 21.2 Hz.
    Hz20 = 4,
    /// Gyro 10 Hz, accel 10.2 Hz.
    Hz10 = 5,
    /// Gyro 5 Hz, accel 5.05 Hz.
    Hz5 = 6,
}

impl Dlpf {
    /// Every setting, widest first.
    pub const ALL: [Self; 6] = [
        Self::Hz184,
        Self::Hz92,
        Self::Hz41,
        Self::Hz20,
        Self::Hz10,
        Self::Hz5,
    ];

    /// The setting for output rate `rate_hz`: bandwidth about half the rate or less, as the
    /// Linux kernel's driver picks it (`mems_sim::dlpf::cfg_for_rate`, which cites it), so
    /// that decimating the 1 kHz filter output folds little noise (184 Hz at 1 kHz and
    /// 500 Hz, 92 Hz at 200-333 Hz, 41 Hz at 100 Hz).
    pub fn for_rate(rate_hz: f64) -> Self {
        let cfg = mems_sim::dlpf::cfg_for_rate(rate_hz);
        Self::ALL
            .into_iter()
            .find(|d| *d as u8 == cfg)
            .unwrap_or(Self::Hz5)
    }

    /// The gyro bandwidth this setting is named for, Hz.
    pub fn gyro_bandwidth_hz(self) -> u32 {
        match self {
            Self::Hz184 => 184,
            Self::Hz92 => 92,
            Self::Hz41 => 41,
            Self::Hz20 => 20,
            Self::Hz10 => 10,
            Self::Hz5 => 5,
        }
    }
}

impl std::str::FromStr for Dlpf {
    type Err = String;

    /// Parses a gyro bandwidth in Hz: 184, 92, 41, 20, 10 or 5.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|d| d.gyro_bandwidth_hz().to_string() == s)
            .ok_or_else(|| format!("unknown DLPF {s:?}: expected 184, 92, 41, 20, 10 or 5 (Hz)"))
    }
}

/// What the FIFO collects and how fast.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputMode {
    /// Accelerometer only, 4 kHz, its DLPF bypassed (ACCEL_CONFIG2.accel_fchoice_b = 1,
    /// 1.13 kHz bandwidth); gyros in standby. The FIFO is written at the 8 kHz sample rate
    /// (CONFIG.DLPF_CFG = 0, as ArduPilot's fast sampling), 6-byte frames, each accelerometer
    /// sample twice; the driver delivers each once. 48 kB/s: SPI only (see [`BusKind`](super::BusKind)).
    Accel4kHz,
    /// Accelerometer, temperature and gyro through the DLPF at 1 kHz / (1 + `divider`);
    /// 14-byte FIFO frames.
    Imu {
        /// The DLPF setting.
        dlpf: Dlpf,
        /// SMPLRT_DIV.
        divider: u8,
    },
}

/// Driver configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// Accelerometer full scale.
    pub accel_range: AccelRange,
    /// Gyro full scale.
    pub gyro_range: GyroRange,
    /// FIFO contents and output rate.
    pub mode: OutputMode,
    /// In [`OutputMode::Accel4kHz`] (no temperature in the FIFO): read TEMP_OUT this often, ns,
    /// and attach the latest value to the samples (`TEMP_VALID`); 0 never reads it.
    pub temp_interval_ns: u64,
}

impl Default for Config {
    /// +-2 g, +-250 deg/s, 4 kHz accelerometer-only, temperature every 100 ms.
    fn default() -> Self {
        Self {
            accel_range: AccelRange::G2,
            gyro_range: GyroRange::Dps250,
            mode: OutputMode::Accel4kHz,
            temp_interval_ns: 100_000_000,
        }
    }
}

impl Config {
    /// Output rate (distinct samples delivered), Hz.
    pub fn output_rate_hz(&self) -> f64 {
        match self.mode {
            OutputMode::Accel4kHz => reg::ACCEL_BYPASS_RATE_HZ,
            OutputMode::Imu { divider, .. } => {
                reg::INTERNAL_RATE_DLPF_HZ / (1.0 + f64::from(divider))
            }
        }
    }

    /// The sample rate (FIFO frames written per second), Hz.
    pub fn fifo_rate_hz(&self) -> f64 {
        match self.mode {
            OutputMode::Accel4kHz => reg::INTERNAL_RATE_NO_DLPF_HZ,
            OutputMode::Imu { .. } => self.output_rate_hz(),
        }
    }

    /// FIFO frames per delivered sample (2 in the 4 kHz accelerometer mode, else 1).
    pub fn frames_per_sample(&self) -> usize {
        match self.mode {
            OutputMode::Accel4kHz => 2,
            OutputMode::Imu { .. } => 1,
        }
    }

    /// The low-pass filter's delay, ns, by which sample times are moved back: the gyro's
    /// (CONFIG.DLPF_CFG table) with the gyro on, else the accelerometer's. With the gyro on,
    /// the accelerometer's own delay is 1.0 ms shorter at every DLPF setting (register 26 and
    /// 29 tables), so its samples are stamped 1.0 ms early.
    pub fn filter_delay_ns(&self) -> u64 {
        match self.mode {
            OutputMode::Accel4kHz => reg::ACCEL_BYPASS_DELAY_NS,
            OutputMode::Imu { dlpf, .. } => reg::GYRO_DLPF_DELAY_NS[dlpf as usize],
        }
    }

    /// Whether the gyros run (and their data are in the FIFO).
    pub fn gyros_on(&self) -> bool {
        matches!(self.mode, OutputMode::Imu { .. })
    }

    /// The FIFO_EN (register 35) channels.
    pub fn fifo_channels(&self) -> u8 {
        match self.mode {
            OutputMode::Accel4kHz => reg::FIFO_EN_ACCEL,
            OutputMode::Imu { .. } => {
                reg::FIFO_EN_ACCEL
                    | reg::FIFO_EN_TEMP
                    | reg::FIFO_EN_GYRO_X
                    | reg::FIFO_EN_GYRO_Y
                    | reg::FIFO_EN_GYRO_Z
            }
        }
    }

    /// Bytes per FIFO frame.
    pub fn frame_len(&self) -> usize {
        match self.mode {
            OutputMode::Accel4kHz => 6,
            OutputMode::Imu { .. } => reg::SENSOR_DATA_LEN,
        }
    }

    /// The configuration registers and their values, in the order they are written: power,
    /// filters and rate, ranges. The FIFO is started after them (see [`Mpu9250::init`](super::Mpu9250::init)).
    pub fn register_values(&self) -> [(u8, u8); 7] {
        let (pwr2, dlpf_cfg, div, accel_cfg2) = match self.mode {
            OutputMode::Accel4kHz => (
                reg::PWR_MGMT_2_DISABLE_GYRO,
                reg::DLPF_CFG_8KHZ,
                0,
                reg::ACCEL_FCHOICE_B,
            ),
            OutputMode::Imu { dlpf, divider } => (0, dlpf as u8, divider, dlpf as u8),
        };
        [
            (reg::PWR_MGMT_1, reg::CLKSEL_AUTO),
            (reg::PWR_MGMT_2, pwr2),
            (reg::CONFIG, reg::CONFIG_FIFO_MODE | dlpf_cfg),
            (reg::SMPLRT_DIV, div),
            (
                reg::GYRO_CONFIG,
                (self.gyro_range as u8) << reg::GYRO_FS_SEL_SHIFT,
            ),
            (
                reg::ACCEL_CONFIG,
                (self.accel_range as u8) << reg::ACCEL_FS_SEL_SHIFT,
            ),
            (reg::ACCEL_CONFIG2, accel_cfg2),
        ]
    }
}
