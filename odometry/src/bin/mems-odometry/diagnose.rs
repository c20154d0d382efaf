//! `mems-odometry diagnose RUN`: the residual loop on a run (`odometry::diagnose`). It runs
//! `mems-odometry offline` on the recording (this executable, with `--out` to a private
//! directory, so that the run is exactly what `offline` gives), reads back its corrected
//! samples and states, diagnoses them, writes the selected effects into a copy of the
//! calibration file and reruns with it, then prints the error before and after: the rest
//! innovation rms always (the filter's velocity just before each rest's first zero-velocity
//! update, m/s), the end error where the end is known (`--end`, `--closed-loop`: the distance
//! from the end displacement to it, m, navigation frame) and against a simulated recording's
//! truth. The rerun confirms the selection when its rest innovation rms is no larger; one that
//! does not is reported, and what the selection claimed to explain counts as unexplained.

mod lever;

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, anyhow, bail};
use calibrate::calibfile::CalibrationFile;
use ipc_types::{CorrectedImuSample, OdometryState};
use nalgebra::Vector3;
use odometry::diagnose::{self, Settings, evidence::Evidence, evidence::Gatherer, rows::Candidate};
use recording::mcap::run::RunReader;
use serde_json::{Value, json};

use crate::hint_args::parse_xyz_m;
use crate::load::odometry_config;

/// Options of `mems-odometry diagnose`.
#[derive(clap::Args)]
pub struct DiagnoseArgs {
    /// Raw recording: canonical CSV, thesis CSV or MCAP (as `offline --input`).
    run: PathBuf,
    /// Calibration file (as `offline --calib`; default the identity at standard gravity).
    #[arg(long)]
    calib: Option<PathBuf>,
    /// The run's true end point, m, in the navigation frame (origin and heading at alignment).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_xyz_m, conflicts_with = "closed_loop")]
    end: Option<[f64; 3]>,
    /// The run ends where it aligned (end point 0,0,0).
    #[arg(long)]
    closed_loop: bool,
    /// Print the result as JSON.
    #[arg(long)]
    json: bool,
    /// The accelerometer lag behind the gyro the run is known to have, s (declared: removed
    /// from the samples of both runs, `offline --accel-lag-s`; a fitted `accel_lag` adds to it).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    accel_lag_s: f64,
    /// The lever arm from the IMU to the rear axle the run is known to have, `X,Y,Z` in m,
    /// body frame (declared: both runs use it, `offline --lever-arm`; the lever-arm
    /// candidate tests the forward offset about it).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true,
          value_parser = parse_xyz_m, default_value = "0,0,0")]
    lever_arm: [f64; 3],
    /// Further `mems-odometry offline` options for both runs (after `--`: `--profile arm`).
    #[arg(last = true)]
    offline: Vec<OsString>,
}

/// What one offline run gave.
pub(crate) struct Run {
    pub(crate) json: Value,
    evidence: Evidence,
}

impl Run {
    fn innovation_rms(&self) -> Option<f64> {
        let v = &self.evidence.innovations_mps;
        (!v.is_empty())
            .then(|| (v.iter().map(|x| x.norm_squared()).sum::<f64>() / v.len() as f64).sqrt())
    }

    fn end_error(&self, end: Option<Vector3<f64>>) -> Option<f64> {
        let p = self.json["end_displacement_m"].as_array()?;
        let p = Vector3::from_fn(|i, _| p[i].as_f64().unwrap_or(f64::NAN));
        end.map(|e| (p - e).norm())
    }

    fn truth_error(&self) -> Option<f64> {
        let e = self.json["truth_error_m"].as_array()?;
        Some(
            e.iter()
                .filter_map(Value::as_f64)
                .map(|x| x * x)
                .sum::<f64>()
                .sqrt(),
        )
    }

    pub(crate) fn figures(&self, end: Option<Vector3<f64>>) -> Value {
        json!({
            "rest_innovation_rms_mps": self.innovation_rms(),
            "end_error_m": self.end_error(end),
            "truth_error_m": self.truth_error(),
            "sigma_m": self.json["sigma_m"],
        })
    }
}

/// What a run declares: the calibration file (none: the identity), the accelerometer lag
/// removed (s) and the lever arm (m, body frame).
#[derive(Clone, Copy)]
pub(crate) struct Declared<'a> {
    pub(crate) calib: Option<&'a Path>,
    pub(crate) lag_s: f64,
    pub(crate) lever_arm_m: [f64; 3],
}

/// Runs `mems-odometry offline` on `args.run` as `declared` says, reading its `--out`
/// recording back.
pub(crate) fn offline(
    args: &DiagnoseArgs,
    declared: Declared,
    dir: &Path,
    name: &str,
    config: &odometry::config::OdometryConfig,
) -> Result<Run> {
    let out = dir.join(format!("{name}.mcap"));
    let json = offline_json(args, declared, name, Some(&out))?;
    let evidence = read_evidence(&out, &config.gyro_correction)?;
    Ok(Run { json, evidence })
}

/// Runs `mems-odometry offline` on `args.run` as `declared` says (recording it to `out` if
/// given) and returns its JSON result.
pub(crate) fn offline_json(
    args: &DiagnoseArgs,
    declared: Declared,
    name: &str,
    out: Option<&Path>,
) -> Result<Value> {
    let mut cmd = Command::new(std::env::current_exe()?);
    cmd.arg("offline")
        .arg("--input")
        .arg(&args.run)
        .arg("--json");
    if let Some(out) = out {
        cmd.arg("--out").arg(out);
    }
    if let Some(c) = declared.calib {
        cmd.arg("--calib").arg(c);
    }
    if declared.lag_s != 0.0 {
        cmd.arg(format!("--accel-lag-s={}", declared.lag_s));
    }
    if declared.lever_arm_m != [0.0; 3] {
        let [x, y, z] = declared.lever_arm_m;
        cmd.arg(format!("--lever-arm={x},{y},{z}"));
    }
    cmd.args(&args.offline);
    let output = cmd.output().context("cannot run mems-odometry offline")?;
    if !output.status.success() {
        // Its error is its last line (notes come first).
        let stderr = String::from_utf8_lossy(&output.stderr);
        let last = stderr
            .lines()
            .rev()
            .find(|l| !l.trim().is_empty())
            .unwrap_or("");
        bail!(
            "mems-odometry offline on {} ({name} run) failed ({}): {}",
            args.run.display(),
            output.status,
            last.trim_start_matches("mems-odometry: error: ")
        );
    }
    serde_json::from_slice(&output.stdout)
        .with_context(|| format!("{name} run: offline printed no JSON"))
}

/// The evidence of the run recorded at `path`, read message by message: what is held is one
/// chunk of the file and one sample per state, however long the run.
fn read_evidence(path: &Path, gyro_correction: &nalgebra::Matrix3<f64>) -> Result<Evidence> {
    let mut reader = RunReader::one(path)?;
    let mut gatherer = Gatherer::new(gyro_correction);
    while let Some(message) = reader.next() {
        let message = message?;
        if let Some(c) = message.decode::<CorrectedImuSample>() {
            gatherer.corrected(c?);
        } else if let Some(s) = message.decode::<OdometryState>() {
            gatherer.state(&s?);
        }
    }
    Ok(gatherer.finish())
}

/// The accelerometer lag the diagnosis selected, s (0 if none).
fn fitted_lag(d: &diagnose::Diagnosis) -> f64 {
    d.selected
        .iter()
        .find(|(c, _)| *c == Candidate::AccelLag)
        .map_or(0.0, |(_, p)| p[0])
}

/// Runs the diagnosis and prints it.
pub fn run(args: DiagnoseArgs) -> Result<()> {
    let file = match &args.calib {
        Some(p) => CalibrationFile::load(p).context("cannot load calibration")?,
        None => CalibrationFile::identity(ipc_types::units::STANDARD_GRAVITY_MPS2),
    };
    let end = match (&args.end, args.closed_loop) {
        (Some(e), _) => Some(Vector3::from(*e)),
        (None, true) => Some(Vector3::zeros()),
        (None, false) => None,
    };
    let dir = mems_files::private_dir("mems-diagnose")?;
    let config = odometry_config(&file);
    let declared = Declared {
        calib: args.calib.as_deref(),
        lag_s: args.accel_lag_s,
        lever_arm_m: args.lever_arm,
    };
    let before = offline(&args, declared, dir.path(), "before", &config)?;
    let t_ref = file.temperature.reference_c.unwrap_or(f64::NAN);
    let d = diagnose::diagnose(&before.evidence, &config, t_ref, &Settings::default());
    let after = if d.selected.is_empty() {
        None
    } else {
        let corrected = diagnose::correct::apply(&file, &d.effects(), d.t_ref_c);
        let path = dir.path().join("corrected.toml");
        corrected
            .save(&path)
            .map_err(|e| anyhow!("cannot write the corrected calibration: {e}"))?;
        let config = odometry_config(&corrected);
        let lag = args.accel_lag_s + fitted_lag(&d);
        let corrected = Declared {
            calib: Some(&path),
            lag_s: lag,
            ..declared
        };
        let run = offline(&args, corrected, dir.path(), "after", &config)?;
        let again = diagnose::diagnose(&run.evidence, &config, d.t_ref_c, &Settings::default());
        Some((run, again))
    };
    // The rerun confirms the selection when the rest innovations do not grow.
    let confirmed = after.as_ref().map(|(r, _)| {
        let (b, a) = (before.innovation_rms(), r.innovation_rms());
        a.zip(b).is_none_or(|(a, b)| a <= b)
    });
    let lever = lever::test(&args, declared, &before, dir.path(), &config, end)?;
    let report = json!({
        "input": args.run,
        "before": before.figures(end),
        "diagnosis": d,
        "confirmed": confirmed,
        "unexplained": d.unexplained || confirmed == Some(false),
        "after": after.as_ref().map(|(r, again)| json!({
            "figures": r.figures(end),
            "magnitude_rms_mps2": again.magnitude.rms_before,
            "tilt_rms_rad": again.tilt.rms_before,
        })),
        "lever_arm": lever,
    });
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", crate::diagnose_text::text(&args.run, &d, &report));
    }
    Ok(())
}
