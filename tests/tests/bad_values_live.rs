//! Real processes: absurd raw samples published live (1e300 g, 100 g, a gyro rate of 1e6 deg/s,
//! NaN, a stamp an hour ahead) into `mems-calibrate serve` and `mems-odometry serve`. The
//! calibration stage drops and counts each (its summary says how many), the next sample is
//! flagged as after a gap, and the odometry keeps publishing finite states for every sample.
//!
//! The calibration is the simulated part's, fitted as a user would (`calibrate_sim_part`). The
//! test publishes the raw samples itself, in blocks, waiting for each block's corrected samples
//! before the next (no timing assumption).
//!
//! Needs the binaries: `cargo build -p calibrate -p odometry -p mems-sim`.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use iceoryx2::prelude::*;
use integration_tests::{Proc, bin, calibrate_sim_part, path_arg, unique_namespace, wait_until};
use ipc_types::wake::Output;
use ipc_types::{
    CorrectedImuSample, OdometryState, RawImuSample, Stamps, odometry_flags, raw_flags, service,
};

/// Starts binary `name` with `args`, its stderr written to `log`.
fn spawn_logged(name: &str, args: &[&str], log: &Path) -> Proc {
    let mut command = Command::new("sh");
    command
        .arg("-c")
        .arg("exec \"$0\" \"$@\" 2>\"$STDERR_LOG\"")
        .arg(bin(name))
        .args(args)
        .env("STDERR_LOG", log);
    Proc::start(name, command)
}

/// The part a calibration file describes: `S`, `b` (g) and the gyroscope bias (deg/s).
struct Part {
    scale: [[f64; 3]; 3],
    bias_g: [f64; 3],
    gyro_bias_dps: [f64; 3],
}

impl Part {
    /// Reads the parameters from a calibration file.
    fn from_file(path: &Path) -> Self {
        let v: toml::Value = toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let row = |x: &toml::Value| -> [f64; 3] {
            let a = x.as_array().expect("an array of 3");
            std::array::from_fn(|i| a[i].as_float().expect("a number"))
        };
        let scale = v["scale"].as_array().expect("scale rows");
        Self {
            scale: std::array::from_fn(|r| row(&scale[r])),
            bias_g: row(&v["bias_g"]),
            gyro_bias_dps: v
                .get("gyro")
                .and_then(|g| g.get("bias_dps"))
                .map_or([0.0; 3], row),
        }
    }

    /// The part's reading of specific force `a` (g): `S a + b`.
    fn reading(&self, a: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|r| {
            (0..3).map(|c| self.scale[r][c] * a[c]).sum::<f64>() + self.bias_g[r]
        })
    }
}

/// The part lying level at rest, with white-ish noise from a fixed xorshift sequence, 1 kHz.
fn sample(part: &Part, seq: u64, noise: &mut u64) -> RawImuSample {
    let mut next = || {
        *noise ^= *noise << 13;
        *noise ^= *noise >> 7;
        *noise ^= *noise << 17;
        (*noise >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let a = [0.006 * next(), 0.006 * next(), 1.0 + 0.006 * next()];
    let w = part.gyro_bias_dps;
    RawImuSample {
        stamps: Stamps {
            sample_ns: 5_000_000_000 + seq * 1_000_000,
            ..Stamps::default()
        },
        seq,
        accel_g: part.reading(a),
        gyro_dps: [
            w[0] + 0.1 * next(),
            w[1] + 0.1 * next(),
            w[2] + 0.1 * next(),
        ],
        temp_c: 30.0,
        flags: raw_flags::GYRO_VALID | raw_flags::TEMP_VALID,
        ..RawImuSample::default()
    }
}

/// The number after `key` in a summary line (`refused 5,` -> 5).
fn count_after(text: &str, key: &str) -> u64 {
    let at = text
        .rfind(key)
        .unwrap_or_else(|| panic!("no {key:?} in {text}"));
    text[at + key.len()..]
        .trim_start()
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count after {key:?} in {text}"))
}

#[test]
fn absurd_live_samples_are_dropped_counted_and_the_odometry_stays_finite() {
    let ns = unique_namespace("badlive");
    let dir = std::env::temp_dir().join(&ns);
    std::fs::create_dir_all(&dir).unwrap();
    let calib = calibrate_sim_part(&dir, 3);
    let part = Part::from_file(&calib);

    let node = service::node().unwrap();
    let raw_name = service::full_name(&ns, service::RAW);
    let raw_svc = service::open::<RawImuSample>(&node, &raw_name).unwrap();
    let mut out = Output::new(&node, &raw_svc, &raw_name).unwrap();
    let cor_svc =
        service::open::<CorrectedImuSample>(&node, &service::full_name(&ns, service::CORRECTED))
            .unwrap();
    let cor_sub = service::subscriber(&cor_svc).unwrap();
    let odo_svc =
        service::open::<OdometryState>(&node, &service::full_name(&ns, service::ODOMETRY)).unwrap();
    let odo_sub = service::subscriber(&odo_svc).unwrap();

    let (cal_log, odo_log) = (dir.join("calibrate.err"), dir.join("odometry.err"));
    let calibrate = spawn_logged(
        "mems-calibrate",
        &[
            "serve",
            "--calib",
            path_arg(&calib),
            "--namespace",
            &ns,
            "--learn-s",
            "1",
            "--learn-first-s",
            "1",
        ],
        &cal_log,
    );
    let odometry = spawn_logged(
        "mems-odometry",
        &["serve", "--calib", path_arg(&calib), "--namespace", &ns],
        &odo_log,
    );
    wait_until(Duration::from_secs(30), "both services subscribed", || {
        raw_svc.dynamic_config().number_of_subscribers() >= 1
            && cor_svc.dynamic_config().number_of_subscribers() >= 2
    });

    // Which raw sample is spoiled, and how.
    let spoil = |s: &mut RawImuSample| match s.seq {
        2500 => s.accel_g[1] = 1e300,
        2600 => s.accel_g[2] = 100.0,
        2700 => s.gyro_dps[0] = 1e6,
        2800 => s.accel_g[0] = f64::NAN,
        2900 => s.stamps.sample_ns += 3_600_000_000_000,
        _ => {}
    };
    let spoiled = 5;
    let total = 4000u64;
    let (mut corrected, mut states) = (Vec::new(), Vec::new());
    let mut noise = 0x2545_f491_4f6c_dd1d_u64;
    for block in 0..total / 200 {
        for seq in block * 200..(block + 1) * 200 {
            let mut s = sample(&part, seq, &mut noise);
            spoil(&mut s);
            out.send(s);
        }
        out.end_of_input().unwrap();
        let sent = (block + 1) * 200;
        let want = sent - (2500..sent).filter(|k| k % 100 == 0 && *k <= 2900).count() as u64;
        wait_until(
            Duration::from_secs(60),
            "the block's corrected samples",
            || {
                while let Some(c) = cor_sub.receive().unwrap() {
                    corrected.push(*c.payload());
                }
                while let Some(o) = odo_sub.receive().unwrap() {
                    states.push(*o.payload());
                }
                corrected.len() as u64 >= want
            },
        );
    }
    // Revisions are states too: wait for the last sample's own state, not for a count.
    wait_until(
        Duration::from_secs(60),
        "a state for the last sample",
        || {
            while let Some(o) = odo_sub.receive().unwrap() {
                states.push(*o.payload());
            }
            states.iter().any(|s| s.seq == total - 1)
        },
    );

    calibrate.signal(libc::SIGTERM);
    odometry.signal(libc::SIGTERM);
    let (cal_status, _) = calibrate.wait(Duration::from_secs(20));
    let (odo_status, _) = odometry.wait(Duration::from_secs(20));
    let cal_err = std::fs::read_to_string(&cal_log).unwrap();
    let odo_err = std::fs::read_to_string(&odo_log).unwrap();
    assert!(cal_status.success(), "{cal_err}");
    assert!(odo_status.success(), "{odo_err}");
    assert!(
        cal_err.contains("detector ready true"),
        "the part is seen at rest: {cal_err}"
    );

    // Dropped and counted, each named on stderr.
    assert_eq!(corrected.len() as u64, total - spoiled);
    assert_eq!(count_after(&cal_err, "refused"), spoiled, "{cal_err}");
    for what in [
        "accel_g[1] = 1e300",
        "accel_g[2] = 100",
        "gyro_dps[0]",
        "accel_g[0]",
    ] {
        assert!(cal_err.contains(what), "{what}: {cal_err}");
    }
    assert!(
        cal_err.contains("seq 2900") && cal_err.contains("dropped"),
        "{cal_err}"
    );
    // The sample after each dropped one is flagged as after a gap.
    for seq in [2501, 2601, 2701, 2801, 2901] {
        let c = corrected.iter().find(|c| c.seq == seq).expect("published");
        assert_ne!(c.raw_flags & raw_flags::GAP_BEFORE, 0, "seq {seq}");
    }
    // Nothing absurd reaches the odometry, whose states all stay finite.
    assert_eq!(count_after(&odo_err, "refused"), 0, "{odo_err}");
    for s in &states {
        let values = s
            .position_m
            .iter()
            .chain(&s.position_sigma_m)
            .chain(&s.velocity_mps)
            .chain(&s.velocity_sigma_mps)
            .chain(&s.attitude_wxyz);
        assert!(values.copied().all(f64::is_finite), "{s:?}");
    }
    assert!(
        states
            .iter()
            .any(|s| s.flags & odometry_flags::ALIGNED != 0),
        "the odometry aligned and navigated"
    );
    let last = states.iter().map(|s| s.seq).max().unwrap();
    assert_eq!(last, total - 1, "states go on to the last sample");
    std::fs::remove_dir_all(&dir).unwrap();
}
