//! The stack's child processes: where their binaries are, and the command line of each
//! (`mems-record`, `mems-foxglove`, `mems-odometry serve`, `mems-calibrate serve` and
//! `mems-acquire`), in start order.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::ValueEnum;

use crate::cli::Cli;
use crate::losses::RecorderLosses;
use crate::supervisor::ChildSpec;

/// The directory holding this executable, where the other `mems-*` binaries are built.
pub fn bin_dir() -> Result<PathBuf> {
    let exe = std::env::current_exe().context("cannot locate mems-stack's own executable")?;
    Ok(exe
        .parent()
        .context("mems-stack's executable has no parent directory")?
        .to_path_buf())
}

/// The supervised processes, in start order: consumers first, the source last, so nothing is
/// published to nobody. `calib` is the calibration file, `work` the stack's work directory.
pub fn specs(
    cli: &Cli,
    bins: &Path,
    namespace: &str,
    calib: String,
    work: &Path,
    recorder_losses: Option<&RecorderLosses>,
) -> Vec<ChildSpec> {
    let spec = |name: &str, program: &str, args: Vec<String>| ChildSpec {
        name: name.to_string(),
        program: bins.join(program),
        args: args
            .into_iter()
            .chain(["--namespace".to_string(), namespace.to_string()])
            .collect(),
        restart_at_once: false,
        stdout: None,
    };
    let mut specs = Vec::new();
    if let Some(out) = &cli.record {
        let args = vec![
            "--out".into(),
            out.display().to_string(),
            "--continue".into(),
        ];
        specs.push(ChildSpec {
            restart_at_once: true,
            stdout: recorder_losses.map(RecorderLosses::sink),
            ..spec("record", "mems-record", args)
        });
    }
    if let Some(addr) = &cli.foxglove {
        let mut args = vec!["--listen".into(), addr.clone()];
        for setting in &cli.settings {
            args.extend(["--parameter".into(), setting.clone()]);
        }
        specs.push(spec("foxglove", "mems-foxglove", args));
    }
    let profile = cli
        .profile
        .to_possible_value()
        .expect("every profile has a name");
    let args = vec![
        "serve".into(),
        "--calib".into(),
        calib.clone(),
        "--profile".into(),
        profile.get_name().into(),
    ];
    specs.push(spec("odometry", "mems-odometry", args));
    // A restarted calibration stage goes on from what the killed one had learned, in the
    // stack's work directory (a new stack starts afresh).
    let state = work.join("calibrate-state.json").display().to_string();
    let args = [
        "serve".into(),
        "--calib".into(),
        calib,
        "--state".into(),
        state,
    ];
    let args = args.into_iter().chain(detector_args(cli)).collect();
    specs.push(spec("calibrate", "mems-calibrate", args));
    // A restarted acquisition continues the sensor session (numbering, clock, simulated
    // motion) kept in the work directory: the stages see one session with a counted hole.
    let session = work.join("acquire.session").display().to_string();
    let args = acquire_args(cli)
        .into_iter()
        .chain(["--session".into(), session])
        .collect();
    specs.push(spec("acquire", "mems-acquire", args));
    specs
}

/// `mems-calibrate serve`'s detector arguments for `cli` ([`crate::cli::detector`]; the
/// GLRT's window is the default 0.5 s at any rate, and the other profile's
/// [`odometry::profile::OTHER_GLRT_WINDOW_S`] with `--profile other`, whose odometry holds its
/// rest flags in hindsight for that long; the vehicle profile's learning,
/// [`odometry::profile::VEHICLE_LEARN_S`], with `--profile vehicle`; the walking profile's
/// ceiling on a rest's accelerometer spread,
/// [`calibrate::zero_state::learn::REST_ACCEL_SIGMA_MPS2`], and its calibrated allowance for
/// an uncalibrated part's offset, with `--profile walking`).
fn detector_args(cli: &Cli) -> Vec<String> {
    let mut args = vec!["--detector".into(), crate::cli::detector(cli).name().into()];
    if cli.profile == odometry::profile::Profile::Other && cli.detector.is_none() {
        args.extend([
            "--glrt-window-s".into(),
            odometry::profile::OTHER_GLRT_WINDOW_S.to_string(),
        ]);
    }
    if cli.profile == odometry::profile::Profile::Vehicle && cli.detector.is_none() {
        let learn_s = odometry::profile::VEHICLE_LEARN_S.to_string();
        args.extend([
            "--learn-s".into(),
            learn_s.clone(),
            "--learn-first-s".into(),
            learn_s,
        ]);
    }
    if cli.profile == odometry::profile::Profile::Walking && cli.detector.is_none() {
        let walking = odometry::profile::Profile::Walking.detector(1.0);
        args.extend([
            "--max-rest-accel-sigma".into(),
            calibrate::zero_state::learn::REST_ACCEL_SIGMA_MPS2.to_string(),
            "--glrt-uncalibrated-offset-mps2".into(),
            walking.glrt.uncalibrated_accel_bias_sigma_mps2.to_string(),
        ]);
    }
    args
}

/// `mems-acquire`'s arguments for `cli` (the namespace is added by the caller): the source,
/// rate and seed, and the real-time options passed through. Every restart uses the same.
fn acquire_args(cli: &Cli) -> Vec<String> {
    let mut args = vec![
        "--source".into(),
        cli.source.clone(),
        "--rate".into(),
        cli.rate.to_string(),
        "--seed".into(),
        cli.seed.to_string(),
    ];
    if let Some(priority) = cli.sched_fifo {
        args.extend(["--sched-fifo".into(), priority.to_string()]);
    }
    if let Some(cpu) = cli.cpu {
        args.extend(["--cpu".into(), cpu.to_string()]);
    }
    if cli.mlock {
        args.push("--mlock".into());
    }
    args
}

#[cfg(test)]
mod tests {
    use super::*;

    fn acquire_args_for(args: &[&str]) -> Vec<String> {
        acquire_args(&Cli::parse_args(args))
    }

    /// `flag`'s value in `args`, `None` when absent.
    fn value<'a>(args: &'a [String], flag: &str) -> Option<&'a str> {
        let i = args.iter().position(|a| a == flag)?;
        Some(args.get(i + 1).expect("flag has a value").as_str())
    }

    #[test]
    fn real_time_options_are_passed_to_acquire() {
        let args = acquire_args_for(&[
            "--rate",
            "4000",
            "--sched-fifo",
            "50",
            "--cpu",
            "1",
            "--mlock",
        ]);
        assert_eq!(value(&args, "--sched-fifo"), Some("50"));
        assert_eq!(value(&args, "--cpu"), Some("1"));
        assert_eq!(value(&args, "--rate"), Some("4000"));
        assert!(args.iter().any(|a| a == "--mlock"), "{args:?}");
    }

    #[test]
    fn without_real_time_options_acquire_gets_none() {
        let args = acquire_args_for(&[]);
        for flag in ["--sched-fifo", "--cpu", "--mlock"] {
            assert!(!args.iter().any(|a| a == flag), "{flag} in {args:?}");
        }
        assert_eq!(value(&args, "--source"), Some("sim"));
    }

    #[test]
    fn the_detector_needs_no_gyro_above_1_khz() {
        let detector = |args: &[&str]| detector_args(&Cli::parse_args(args));
        // 4 kHz is accelerometer-only: the accelerometer GLRT.
        let at_4k = detector(&["--rate", "4000"]);
        assert_eq!(
            at_4k,
            vec!["--detector".to_string(), "glrt-accel".to_string()]
        );
        let at_1k = detector(&["--rate", "1000"]);
        assert_eq!(at_1k, vec!["--detector".to_string(), "glrt".to_string()]);
        let asked = detector(&["--rate", "4000", "--detector", "yu"]);
        assert_eq!(asked, vec!["--detector".to_string(), "yu".to_string()]);
        // The other profile's shorter window, which its odometry's hindsight matches.
        let other = detector(&["--profile", "other"]);
        assert_eq!(
            other,
            ["--detector", "glrt", "--glrt-window-s", "0.2"].map(String::from)
        );
        let vehicle = detector(&["--profile", "vehicle"]);
        assert_eq!(
            vehicle,
            [
                "--detector",
                "glrt",
                "--learn-s",
                "1",
                "--learn-first-s",
                "1"
            ]
            .map(String::from)
        );
        // A walker's hand: no window that shakes is learned as rest (a steady turn), and the
        // calibrated allowance for an uncalibrated part's offset, as offline.
        let walking = detector(&["--profile", "walking"]);
        assert_eq!(
            walking,
            [
                "--detector",
                "glrt",
                "--max-rest-accel-sigma",
                "0.15",
                "--glrt-uncalibrated-offset-mps2",
                "0.0061"
            ]
            .map(String::from)
        );
    }
}
