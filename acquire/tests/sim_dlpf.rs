//! The real driver against the simulated part with its DLPF modelled: the samples it reads are
//! correlated as the filter the registers select says (lag-1 autocorrelation and variance
//! against the closed forms of `mems_sim::dlpf`), and white without the model.

use acquire::clock::{Clock, SimClock};
use acquire::driver::{Config, Dlpf, Mpu9250, OutputMode};
use acquire::registers as reg;
use acquire::sim::{SimConfig, SimMpu9250};
use ipc_types::RawImuSample;
use mems_sim::SimSensor;
use mems_sim::dlpf::{Coefficients, DlpfConfig, Setting};
use mems_sim::model::{SensorModel, TriadModel};
use mems_sim::scenario::PoseSession;
use mems_sim::vibration::VibrationModel;

const ACCEL_DENSITY_G: f64 = 300e-6;
const GYRO_DENSITY_DPS: f64 = 0.01;

/// A level, still sensor with white noise only (datasheet densities).
fn still_sensor() -> SimSensor<PoseSession> {
    let model = SensorModel {
        accel: TriadModel {
            noise_density: [ACCEL_DENSITY_G; 3],
            ..TriadModel::ideal()
        },
        gyro: TriadModel {
            noise_density: [GYRO_DENSITY_DPS; 3],
            ..TriadModel::ideal()
        },
        ..SensorModel::ideal()
    };
    let g = ipc_types::units::STANDARD_GRAVITY_MPS2;
    let pose = PoseSession::static_pose(Default::default(), 1e6, g).unwrap();
    SimSensor::new(pose, &model, &VibrationModel::moderate(0.0), 8).unwrap()
}

/// `n` samples the driver reads with `config` from a part with or without its DLPF modelled.
fn read(config: Config, model_dlpf: bool, n: usize) -> Vec<RawImuSample> {
    let clock = SimClock::new_virtual(1_000_000_000);
    let sim = SimMpu9250::new(
        still_sensor(),
        clock.clone(),
        SimConfig {
            model_dlpf,
            ..SimConfig::default()
        },
    );
    let mut drv = Mpu9250::new(sim, "sim", reg::ADDRESS_AD0_LOW);
    drv.init(config, &clock).expect("init");
    let mut buf = [RawImuSample::default(); 128];
    let mut out = Vec::with_capacity(n + 128);
    while out.len() < n {
        clock.sleep_until(clock.now_ns() + 5_000_000);
        let got = drv.read_samples(&clock, &mut buf).expect("read_samples");
        out.extend_from_slice(&buf[..got]);
    }
    out.truncate(n);
    out
}

/// Variance and lag-1 autocorrelation.
fn var_lag1(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    let r1 = x
        .windows(2)
        .map(|w| (w[0] - mean) * (w[1] - mean))
        .sum::<f64>()
        / ((n - 1.0) * var);
    (var, r1)
}

/// Checks one axis series against the filter `setting` decimated by `decimation`, with white
/// noise of `density` at the internal rate in and quantization steps of `lsb` out.
fn check(name: &str, x: &[f64], setting: &Setting, decimation: u32, density: f64, lsb: f64) {
    let c = Coefficients::new(setting);
    let fs = setting.internal_rate_hz;
    // The quantization adds white noise of variance lsb^2 / 12 to the filtered noise.
    let filtered = density * density * fs * c.noise_variance_ratio();
    let q = lsb * lsb / 12.0;
    let want_var = filtered + q;
    let want_r1 = c.autocorrelation(decimation) * filtered / want_var;
    let (var, r1) = var_lag1(x);
    let n = x.len() as f64;
    let p = c.pole().abs().powi(decimation as i32);
    let se = (2.0 * (1.0 + p) / (1.0 - p) / n).sqrt();
    assert!(
        (var / want_var - 1.0).abs() < 5.0 * se,
        "{name}: variance {var:.3e}, closed form {want_var:.3e}"
    );
    assert!(
        (r1 - want_r1).abs() < 5.0 * se,
        "{name}: lag-1 autocorrelation {r1:.4}, closed form {want_r1:.4} +- {:.4}",
        5.0 * se
    );
}

#[test]
fn the_driver_reads_samples_correlated_as_the_selected_dlpf() {
    let n = 40_000;
    let imu = |dlpf, divider| Config {
        mode: OutputMode::Imu { dlpf, divider },
        ..Config::default()
    };
    // DLPF_CFG = A_DLPF_CFG = 4 (gyro 20 Hz, accel 21.2 Hz) at 1 kHz and 200 Hz, and the
    // 4 kHz accelerometer-only mode (accel_fchoice_b = 1: 1.13 kHz at 4 kHz).
    for (config, decimation) in [
        (imu(Dlpf::Hz20, 0), 1),
        (imu(Dlpf::Hz20, 4), 5),
        (Config::default(), 1),
    ] {
        let samples = read(config, true, n);
        let filters = match config.mode {
            OutputMode::Accel4kHz => DlpfConfig::driver(4000.0),
            OutputMode::Imu { dlpf, .. } => DlpfConfig::both(dlpf as u8),
        };
        let a_lsb = 1.0 / config.accel_range.lsb_per_g();
        let g_lsb = 1.0 / config.gyro_range.lsb_per_dps();
        for axis in 0..3 {
            let a: Vec<f64> = samples.iter().map(|s| s.accel_g[axis]).collect();
            let name = format!("{:?} accel {axis}", config.mode);
            check(
                &name,
                &a,
                &filters.accel,
                decimation,
                ACCEL_DENSITY_G,
                a_lsb,
            );
            if matches!(config.mode, OutputMode::Imu { .. }) {
                let g: Vec<f64> = samples.iter().map(|s| s.gyro_dps[axis]).collect();
                let name = format!("{:?} gyro {axis}", config.mode);
                check(
                    &name,
                    &g,
                    &filters.gyro,
                    decimation,
                    GYRO_DENSITY_DPS,
                    g_lsb,
                );
            }
        }
    }
}

#[test]
fn without_the_dlpf_model_the_samples_are_white() {
    let n = 40_000;
    let config = Config {
        mode: OutputMode::Imu {
            dlpf: Dlpf::Hz20,
            divider: 0,
        },
        ..Config::default()
    };
    let samples = read(config, false, n);
    for axis in 0..3 {
        let g: Vec<f64> = samples.iter().map(|s| s.gyro_dps[axis]).collect();
        let (var, r1) = var_lag1(&g);
        assert!(
            r1.abs() < 5.0 / (n as f64).sqrt(),
            "gyro {axis}: lag-1 {r1}"
        );
        let want = GYRO_DENSITY_DPS * GYRO_DENSITY_DPS * 1000.0;
        assert!(
            (var / want - 1.0).abs() < 0.05,
            "gyro {axis}: variance {var}"
        );
    }
}
