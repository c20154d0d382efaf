//! The MPU-9250's digital low-pass filters (DLPF): the settings the configuration registers
//! select, and a discrete model of each that runs at the part's internal sample rate.
//!
//! # The settings
//!
//! Bandwidths (-3 dB), delays and internal rates from the register map RM-MPU-9250A-00,
//! section 4.5 (register 26, CONFIG: the DLPF_CFG table, gyroscope columns, selected when
//! GYRO_CONFIG.FCHOICE_B = 0b00; FCHOICE_B = 0bx1 and 0b10 bypass it at 32 kHz) and section
//! 4.8 (register 29, ACCEL_CONFIG2: the A_DLPF_CFG table; accel_fchoice_b = 1 bypasses it at
//! 4 kHz). Every gyroscope row and every A_DLPF_CFG row below is also carried by the public
//! `mpu9250` Rust crate's configuration documentation (`GyroTempDataRate`, `Dlpf`, citing
//! "page 13 of the register map"), and the accelerometer bandwidths by our driver's
//! documentation (`acquire::driver::Dlpf`). The bypassed accelerometer's 1.13 kHz bandwidth
//! is the one public MPU-9250 drivers quote in their comments; its 0.75 ms delay could not be
//! checked against a public copy (the `mpu9250` crate gives 1046 Hz and 0.503 ms for that
//! mode, so revisions of the map may differ there).
//!
//! | DLPF_CFG | gyro BW, Hz | gyro delay, ms | gyro rate | A_DLPF_CFG | accel BW, Hz | accel delay, ms |
//! |---|---|---|---|---|---|---|
//! | 0 | 250 | 0.97 | 8 kHz | 0 | 218.1 | 1.88 |
//! | 1 | 184 | 2.9 | 1 kHz | 1 | 218.1 | 1.88 |
//! | 2 | 92 | 3.9 | 1 kHz | 2 | 99 | 2.88 |
//! | 3 | 41 | 5.9 | 1 kHz | 3 | 44.8 | 4.88 |
//! | 4 | 20 | 9.9 | 1 kHz | 4 | 21.2 | 8.87 |
//! | 5 | 10 | 17.85 | 1 kHz | 5 | 10.2 | 16.83 |
//! | 6 | 5 | 33.48 | 1 kHz | 6 | 5.05 | 32.48 |
//! | 7 | 3600 | 0.17 | 8 kHz | 7 | 420 | 1.38 |
//!
//! The accelerometer runs at 1 kHz for every A_DLPF_CFG; bypassed (accel_fchoice_b = 1) it
//! runs at 4 kHz with a 1.13 kHz bandwidth and 0.75 ms delay. The gyroscope bypassed runs at
//! 32 kHz: 8800 Hz / 0.064 ms (FCHOICE_B = 0bx1) or 3600 Hz / 0.11 ms (0b10). The temperature
//! sensor has its own column in the CONFIG table; it is not filtered here (the simulated die
//! temperature is slow and noise-free).
//!
//! # The model
//!
//! InvenSense does not publish the filters' structure. Each setting is modelled as
//!
//! ```text
//! H(z) = L(z) A(z) z^-m,   L(z) = K (1 + z^-1) / ((1 + K) + (K - 1) z^-1),   K = tan(pi B / fs)
//! ```
//!
//! at the internal rate `fs`: `L` is a first-order low-pass (the bilinear transform of
//! `1 / (1 + s / (2 pi B))`, pre-warped so that its -3 dB point is exactly the table's `B`),
//! `A(z) = (a + z^-1) / (1 + a z^-1)` a first-order all-pass (Thiran) and `z^-m` an integer
//! delay, which together add the pure delay that brings the low-frequency group delay to the
//! table's value `D` exactly (`L` contributes `1 / (2K)` samples, `A` contributes
//! `(1 - a) / (1 + a)`, chosen in [0.5, 1.5) samples). The all-pass and the delay do not
//! change the magnitude, so the bandwidth stays exact.
//!
//! Why first order: it is the only low order that meets both columns for every row. A
//! second-order Butterworth at 20, 10 or 5 Hz already has more group delay (`sqrt(2) / (2 pi
//! B)`: 11.3, 22.5, 45 ms) than the table gives (9.9, 17.85, 33.48 ms), while a first-order
//! section (`1 / (2 pi B)`: 8.0, 15.9, 31.8 ms) leaves a 1.5-2 ms pure delay, the kind of
//! pipeline delay a decimating converter has. InvenSense's later register maps (e.g. the
//! MPU-6886's ACCEL_CONFIG2 table, reproduced in public drivers) also list a noise bandwidth
//! per setting, which at the narrow settings is 1.52-1.54 times the -3 dB bandwidth, close to
//! a first-order section's pi/2.
//!
//! What is approximated: the roll-off above the cut-off (20 dB/decade here; the real filter is
//! likely steeper at the wide settings, where that noise-bandwidth ratio falls to 1.1-1.2), so
//! the model lets more noise through at 184-250 Hz than the part probably does; the shape of
//! the step response; and the decimation (the output is the filter output at every
//! `1 + SMPLRT_DIV`-th internal sample, with no further filtering).
//!
//! Closed forms the tests check the recursion against: `|H(e^jw)|^2 = 1 / (1 + (tan(w/2) /
//! K)^2)`; filtered white noise of variance `s^2` has variance `s^2 K / (1 + K)` and, with the
//! pole `p = (1 - K) / (1 + K)`, the lag-`k` autocorrelation `(1 + p) p^(k-1) / 2` for `k >= 1`
//! (the all-pass and delay do not change either).

use std::f64::consts::PI;

/// One DLPF setting: the -3 dB bandwidth, the delay and the internal sample rate the register
/// map gives for it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Setting {
    /// -3 dB bandwidth, Hz.
    pub bandwidth_hz: f64,
    /// Delay (low-frequency group delay), s.
    pub delay_s: f64,
    /// Internal sample rate, Hz.
    pub internal_rate_hz: f64,
}

const fn setting(bandwidth_hz: f64, delay_ms: f64, internal_rate_hz: f64) -> Setting {
    Setting {
        bandwidth_hz,
        delay_s: delay_ms * 1e-3,
        internal_rate_hz,
    }
}

/// Gyroscope settings by DLPF_CFG (CONFIG bits 2:0) with FCHOICE_B = 0b00.
pub const GYRO_DLPF: [Setting; 8] = [
    setting(250.0, 0.97, 8000.0),
    setting(184.0, 2.9, 1000.0),
    setting(92.0, 3.9, 1000.0),
    setting(41.0, 5.9, 1000.0),
    setting(20.0, 9.9, 1000.0),
    setting(10.0, 17.85, 1000.0),
    setting(5.0, 33.48, 1000.0),
    setting(3600.0, 0.17, 8000.0),
];

/// Gyroscope with GYRO_CONFIG.FCHOICE_B = 0bx1 (DLPF bypassed).
pub const GYRO_BYPASS_8800: Setting = setting(8800.0, 0.064, 32000.0);

/// Gyroscope with GYRO_CONFIG.FCHOICE_B = 0b10 (DLPF bypassed).
pub const GYRO_BYPASS_3600: Setting = setting(3600.0, 0.11, 32000.0);

/// Accelerometer settings by A_DLPF_CFG (ACCEL_CONFIG2 bits 2:0) with accel_fchoice_b = 0.
pub const ACCEL_DLPF: [Setting; 8] = [
    setting(218.1, 1.88, 1000.0),
    setting(218.1, 1.88, 1000.0),
    setting(99.0, 2.88, 1000.0),
    setting(44.8, 4.88, 1000.0),
    setting(21.2, 8.87, 1000.0),
    setting(10.2, 16.83, 1000.0),
    setting(5.05, 32.48, 1000.0),
    setting(420.0, 1.38, 1000.0),
];

/// Accelerometer with ACCEL_CONFIG2.accel_fchoice_b = 1 (DLPF bypassed, 4 kHz).
pub const ACCEL_BYPASS: Setting = setting(1130.0, 0.75, 4000.0);

/// The gyroscope setting GYRO_CONFIG.FCHOICE_B (bits 1:0) and CONFIG.DLPF_CFG (bits 2:0) select.
pub fn gyro_setting(fchoice_b: u8, dlpf_cfg: u8) -> Setting {
    match fchoice_b & 0b11 {
        0b00 => GYRO_DLPF[usize::from(dlpf_cfg & 0b111)],
        0b10 => GYRO_BYPASS_3600,
        _ => GYRO_BYPASS_8800,
    }
}

/// The accelerometer setting ACCEL_CONFIG2.accel_fchoice_b and A_DLPF_CFG (bits 2:0) select.
pub fn accel_setting(accel_fchoice_b: bool, a_dlpf_cfg: u8) -> Setting {
    if accel_fchoice_b {
        ACCEL_BYPASS
    } else {
        ACCEL_DLPF[usize::from(a_dlpf_cfg & 0b111)]
    }
}

/// The DLPF_CFG (= A_DLPF_CFG) our driver selects for output rate `rate_hz` at 1000/n Hz: the
/// widest setting whose nominal bandwidth is at most about half the rate, so that little noise
/// folds when SMPLRT_DIV keeps every (1 + SMPLRT_DIV)-th internal sample. The thresholds are
/// those of the Linux kernel's InvenSense driver (drivers/iio/imu/inv_mpu6050/inv_mpu_core.c,
/// `inv_mpu6050_set_lpf`, "lpf is set automatically when setting sampling rate to avoid any
/// aliases"): at least 400 Hz gives 1 (gyro 184 Hz), 200 Hz 2 (92 Hz), 90 Hz 3 (41 Hz), 40 Hz
/// 4 (20 Hz), 20 Hz 5 (10 Hz), anything slower 6 (5 Hz). The one rule for the driver
/// (`acquire::driver::Dlpf::for_rate`), the simulator's `--dlpf driver` and `drive_eval`.
pub fn cfg_for_rate(rate_hz: f64) -> u8 {
    const RULE: [(f64, u8); 5] = [(400.0, 1), (200.0, 2), (90.0, 3), (40.0, 4), (20.0, 5)];
    RULE.iter()
        .find(|&&(min_rate, _)| rate_hz >= min_rate)
        .map_or(6, |&(_, cfg)| cfg)
}

/// The filters of both triads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DlpfConfig {
    /// Accelerometer filter.
    pub accel: Setting,
    /// Gyroscope filter.
    pub gyro: Setting,
}

impl DlpfConfig {
    /// DLPF_CFG and A_DLPF_CFG both `cfg` with neither filter bypassed, as our driver
    /// configures the part (`acquire::driver::Config::register_values`).
    pub fn both(cfg: u8) -> Self {
        Self {
            accel: accel_setting(false, cfg),
            gyro: gyro_setting(0, cfg),
        }
    }

    /// What our driver configures for output rate `rate_hz` (`acquire::config_for_rate`):
    /// at 4 kHz the accelerometer bypassed (1.13 kHz at 4 kHz) and DLPF_CFG = 1 for the gyro;
    /// at 1000/n Hz, DLPF_CFG = A_DLPF_CFG = [`cfg_for_rate`] (e.g. 1 at 1 kHz: gyro 184 Hz,
    /// accel 218.1 Hz; 2 at 200 Hz: 92 / 99 Hz).
    pub fn driver(rate_hz: f64) -> Self {
        if rate_hz == 4000.0 {
            Self {
                accel: ACCEL_BYPASS,
                gyro: GYRO_DLPF[1],
            }
        } else {
            Self::both(cfg_for_rate(rate_hz))
        }
    }

    /// The faster of the two internal rates, Hz (the other divides it).
    pub fn fast_rate_hz(&self) -> f64 {
        self.accel.internal_rate_hz.max(self.gyro.internal_rate_hz)
    }
}

/// Longest integer delay any setting needs, internal samples.
const MAX_DELAY: usize = 8;

/// Coefficients of one setting's filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Coefficients {
    /// `K = tan(pi B / fs)`.
    pub k: f64,
    /// All-pass coefficient `a`.
    pub allpass: f64,
    /// Integer delay `m`, internal samples.
    pub delay: usize,
}

impl Coefficients {
    /// The coefficients for `setting`.
    ///
    /// # Panics
    /// If the setting's delay is shorter than its first-order section's group delay plus half
    /// a sample (no register-map setting is).
    pub fn new(setting: &Setting) -> Self {
        let fs = setting.internal_rate_hz;
        let k = (PI * setting.bandwidth_hz / fs).tan();
        let extra = setting.delay_s * fs - 0.5 / k;
        assert!(
            extra >= 0.5,
            "DLPF setting {setting:?}: the delay is too short for the first-order model"
        );
        let delay = (extra - 0.5).floor() as usize;
        assert!(
            delay < MAX_DELAY,
            "DLPF setting {setting:?}: delay too long"
        );
        let frac = extra - delay as f64;
        Self {
            k,
            allpass: (1.0 - frac) / (1.0 + frac),
            delay,
        }
    }

    /// The pole of the first-order section, `p = (1 - K) / (1 + K)`.
    pub fn pole(&self) -> f64 {
        (1.0 - self.k) / (1.0 + self.k)
    }

    /// The closed-form frequency response at `f_hz` for internal rate `fs_hz`, as (re, im).
    pub fn response(&self, f_hz: f64, fs_hz: f64) -> (f64, f64) {
        let w = 2.0 * PI * f_hz / fs_hz;
        let z1 = (w.cos(), -w.sin()); // e^{-jw}
        let mul = |a: (f64, f64), b: (f64, f64)| (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0);
        let div = |a: (f64, f64), b: (f64, f64)| {
            let d = b.0 * b.0 + b.1 * b.1;
            ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
        };
        let k = self.k;
        let lowpass = div(
            (k * (1.0 + z1.0), k * z1.1),
            ((1.0 + k) + (k - 1.0) * z1.0, (k - 1.0) * z1.1),
        );
        let a = self.allpass;
        let allpass = div((a + z1.0, z1.1), (1.0 + a * z1.0, a * z1.1));
        let m = self.delay as f64;
        mul(mul(lowpass, allpass), ((m * w).cos(), -(m * w).sin()))
    }

    /// Variance of filtered white noise over the variance of the noise, `K / (1 + K)`.
    pub fn noise_variance_ratio(&self) -> f64 {
        self.k / (1.0 + self.k)
    }

    /// Low-frequency density of the filter's output kept every `m`-th internal sample
    /// (decimation by `1 + SMPLRT_DIV`, no further filtering) over the density of the white
    /// noise at its input: `sqrt(sum_{k=0}^{m-1} |H(e^{j 2 pi k / m})|^2)`. Decimation folds the
    /// noise the filter passes between the kept rate's and the internal rate's Nyquist
    /// frequencies down to low frequency (1 for `m = 1`; `sqrt(m)` for no filter at all).
    ///
    /// # Panics
    /// If `m` is 0.
    pub fn aliased_density_ratio(&self, m: u32) -> f64 {
        assert!(m > 0, "decimation by 0");
        (0..m)
            .map(|k| {
                let half_w = PI * f64::from(k) / f64::from(m);
                1.0 / (1.0 + (half_w.tan() / self.k).powi(2))
            })
            .sum::<f64>()
            .sqrt()
    }

    /// Autocorrelation coefficient at lag `lag` (internal samples) of filtered white noise:
    /// 1 at lag 0, `(1 + p) p^(lag-1) / 2` after.
    pub fn autocorrelation(&self, lag: u32) -> f64 {
        if lag == 0 {
            return 1.0;
        }
        let p = self.pole();
        (1.0 + p) * p.powi(lag as i32 - 1) / 2.0
    }
}

/// The running filter of one axis.
#[derive(Debug, Clone, Copy)]
struct AxisState {
    /// Previous input of the first-order section.
    x1: f64,
    /// Previous output of the first-order section.
    y1: f64,
    /// Previous input and output of the all-pass.
    ap_x1: f64,
    ap_y1: f64,
    /// Delay line (ring buffer) of the all-pass output.
    line: [f64; MAX_DELAY],
    head: usize,
}

impl AxisState {
    /// The state of a filter whose input has been `x` for ever.
    fn steady(x: f64) -> Self {
        Self {
            x1: x,
            y1: x,
            ap_x1: x,
            ap_y1: x,
            line: [x; MAX_DELAY],
            head: 0,
        }
    }
}

/// The DLPF of one triad (three axes), stepped once per internal sample.
#[derive(Debug, Clone)]
pub struct TriadFilter {
    setting: Setting,
    c: Coefficients,
    state: Option<[AxisState; 3]>,
}

impl TriadFilter {
    /// A filter for `setting`; its first input sets its state as if that input had been
    /// applied for ever (no start-up transient).
    pub fn new(setting: &Setting) -> Self {
        Self {
            setting: *setting,
            c: Coefficients::new(setting),
            state: None,
        }
    }

    /// The setting this filter models.
    pub fn setting(&self) -> &Setting {
        &self.setting
    }

    /// The filter's coefficients.
    pub fn coefficients(&self) -> &Coefficients {
        &self.c
    }

    /// Filters one internal sample `x` (any unit) and returns the output.
    pub fn step(&mut self, x: [f64; 3]) -> [f64; 3] {
        let c = self.c;
        let state = self.state.get_or_insert_with(|| x.map(AxisState::steady));
        let b = c.k / (1.0 + c.k);
        let a1 = (c.k - 1.0) / (c.k + 1.0);
        std::array::from_fn(|i| {
            let s = &mut state[i];
            let y = b * (x[i] + s.x1) - a1 * s.y1;
            s.x1 = x[i];
            s.y1 = y;
            let ap = c.allpass * y + s.ap_x1 - c.allpass * s.ap_y1;
            s.ap_x1 = y;
            s.ap_y1 = ap;
            if c.delay == 0 {
                return ap;
            }
            // The ring holds the last `delay` all-pass outputs; the oldest leaves.
            let out = s.line[s.head];
            s.line[s.head] = ap;
            s.head = (s.head + 1) % c.delay;
            out
        })
    }
}
