//! The `mems-calibrate allan` command's analysis: arguments and entry point (the calibration
//! file update, `--into`, is `mems-calibrate`'s).

use std::fmt::Write as _;
use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result};
use ipc_types::units::STANDARD_GRAVITY_MPS2;

use crate::analysis::{Options, Report, analyze, join_records};
use crate::fit::Term;
use crate::repair::RepairConfig;
use crate::series::{AXES, GapPolicy, Sensor};
use crate::{kalibr, plot};

/// Noise characterisation of a static recording: overlapping Allan deviation with confidence
/// intervals, and the fitted white noise, bias instability and rate random walk per axis.
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct Args {
    /// Static recording: canonical CSV, thesis CSV or MCAP. Several files, or folders (their
    /// .csv and .mcap files, sorted), are pooled: each a segment of one analysis (records of
    /// the same sensor at rest, e.g. repeated start-up runs).
    #[arg(long, value_name = "STATIC_REC", num_args = 1.., required = true)]
    pub input: Vec<PathBuf>,
    /// Print the full report as JSON instead of the text summary.
    #[arg(long)]
    pub json: bool,
    /// Write Kalibr's imu.yaml here (needs the gyro).
    #[arg(long, value_name = "OUT.yaml")]
    pub kalibr: Option<PathBuf>,
    /// Write a PNG plot of the Allan deviation and the fitted model here.
    #[arg(long, value_name = "OUT.png")]
    pub plot: Option<PathBuf>,
    /// Write the noise parameters (the calibration file's `[noise]` table) as TOML here.
    #[arg(long, value_name = "OUT.toml")]
    pub toml: Option<PathBuf>,
    /// Replace the files at --toml and --kalibr (atomically; a symbolic link there is
    /// replaced, not followed). Without it an existing file is refused. Files are 0600.
    #[arg(long)]
    pub force: bool,
    /// Gravity converting g to m/s^2 (the thesis used 9.797); default: standard gravity, or
    /// the gravity of the calibration file the parameters are stored into.
    #[arg(long, value_name = "M_S2")]
    pub gravity: Option<f64>,
    /// An interval longer than this many median intervals is a gap.
    #[arg(long, default_value_t = GapPolicy::default().gap_factor)]
    pub gap_factor: f64,
    /// A gap longer than this many median intervals splits the record into segments.
    #[arg(long, default_value_t = GapPolicy::default().split_factor)]
    pub split_factor: f64,
    /// Analyse the samples as recorded, without torn-read repair.
    #[arg(long)]
    pub no_repair: bool,
    /// Accelerometer sensitivity of the recording, counts per g (for torn-read repair).
    #[arg(long, default_value_t = RepairConfig::default().accel_lsb_per_g)]
    pub accel_lsb_per_g: f64,
    /// Gyro sensitivity of the recording, counts per deg/s (for torn-read repair).
    #[arg(long, default_value_t = RepairConfig::default().gyro_lsb_per_dps)]
    pub gyro_lsb_per_dps: f64,
    /// Horizon of the predicted displacement floor, s.
    #[arg(long, value_name = "S", default_value_t = 60.0)]
    pub floor_s: f64,
    /// ROS topic written into the Kalibr file.
    #[arg(long, default_value = "/imu0")]
    pub rostopic: String,
}

impl Args {
    /// The gravity used, m/s^2: `--gravity`, else standard gravity.
    pub fn gravity_mps2(&self) -> f64 {
        self.gravity.unwrap_or(STANDARD_GRAVITY_MPS2)
    }

    /// The analysis options these arguments select; errors on values that make no sense.
    pub fn options(&self) -> Result<Options> {
        calibrate::calibfile::check_gravity(self.gravity_mps2())
            .map_err(|e| anyhow::anyhow!("--gravity {e}"))?;
        let positive = [
            ("--floor-s", self.floor_s),
            ("--accel-lsb-per-g", self.accel_lsb_per_g),
            ("--gyro-lsb-per-dps", self.gyro_lsb_per_dps),
        ];
        for (flag, v) in positive {
            anyhow::ensure!(
                v.is_finite() && v > 0.0,
                "{flag} {v}: must be a positive number"
            );
        }
        anyhow::ensure!(
            self.gap_factor >= 1.0 && self.split_factor >= self.gap_factor,
            "--gap-factor {} / --split-factor {}: need 1 <= gap factor <= split factor",
            self.gap_factor,
            self.split_factor
        );
        Ok(Options {
            gravity_mps2: self.gravity_mps2(),
            gaps: GapPolicy {
                gap_factor: self.gap_factor,
                split_factor: self.split_factor,
            },
            repair: (!self.no_repair).then_some(RepairConfig {
                accel_lsb_per_g: self.accel_lsb_per_g,
                gyro_lsb_per_dps: self.gyro_lsb_per_dps,
            }),
            floor_horizon_s: self.floor_s,
        })
    }
}

/// Runs the command, printing to standard output.
pub fn run_allan(args: &Args) -> Result<()> {
    let stdout = std::io::stdout();
    run_allan_to(args, &mut stdout.lock()).map(|_| ())
}

/// Runs the command, printing to `out`; returns the report.
pub fn run_allan_to(args: &Args, out: &mut impl Write) -> Result<Report> {
    let options = args.options()?;
    let files = recording::folders::expand(&args.input)?;
    let source = args
        .input
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ");
    let mut samples = if let [file] = files.as_slice() {
        recording::load_raw(file)?.samples
    } else {
        let records = files
            .iter()
            .map(|f| recording::load_raw(f).map(|r| r.samples))
            .collect::<Result<Vec<_>, _>>()?;
        join_records(&records)
    };
    let report = analyze(&mut samples, &source, &options)?;
    if args.json {
        serde_json::to_writer_pretty(&mut *out, &report).context("writing the JSON report")?;
        writeln!(out)?;
    } else {
        out.write_all(render(&report).as_bytes())?;
    }
    if let Some(path) = &args.toml {
        let existing = mems_files::Existing::force(args.force);
        mems_files::write(
            path,
            Some("--toml"),
            existing,
            report.params.to_toml().as_bytes(),
        )?;
    }
    if let Some(path) = &args.kalibr {
        let text = kalibr::imu_yaml(&report.params, &args.rostopic)?;
        let existing = mems_files::Existing::force(args.force);
        mems_files::write(path, Some("--kalibr"), existing, text.as_bytes())?;
    }
    if let Some(path) = &args.plot {
        let title = match args.input.as_slice() {
            [one] => one
                .file_name()
                .map_or_else(|| source.clone(), |n| n.to_string_lossy().into_owned()),
            _ => format!("{} records pooled", files.len()),
        };
        plot::write_png(path, &title, &report.channels)?;
    }
    Ok(report)
}

fn term_text(term: &Term) -> String {
    match term {
        Term::Resolved { value, sigma } => format!("{value:.3e} ± {sigma:.1e}"),
        Term::Unresolved { upper_limit, .. } => format!("< {upper_limit:.2e} (2σ)"),
    }
}

/// The recording: samples, timing, gaps, repeats and the torn-read repair.
fn write_recording(s: &mut String, report: &Report) {
    let t = &report.timing;
    let _ = writeln!(
        s,
        "  {} samples over {:.2} s; mean interval {:.3} ms ({:.1} Hz), median {:.3} ms",
        report.samples,
        t.duration_s,
        t.mean_interval_s * 1e3,
        1.0 / t.mean_interval_s,
        t.median_interval_s * 1e3
    );
    let _ = writeln!(
        s,
        "  gaps: {} (bridged unless split), splits: {}, segments: {}, longest interval {:.1} ms",
        t.gaps,
        t.splits,
        t.segments.len(),
        t.longest_interval_s * 1e3
    );
    let _ = writeln!(
        s,
        "  repeated samples: {} (longest run {}), left in place",
        report.repeats.repeats, report.repeats.longest_run
    );
    match &report.torn {
        Some(torn) => {
            let per_axis = |axes: &[crate::repair::AxisRepair; 3]| {
                AXES.iter()
                    .zip(axes)
                    .map(|(n, a)| format!("{n} {}", a.repaired))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let gyro = torn
                .gyro
                .as_ref()
                .map(|g| format!("; gyro {}", per_axis(g)))
                .unwrap_or_default();
            let _ = writeln!(
                s,
                "  torn reads repaired: accel {}{gyro} ({} samples touched)",
                per_axis(&torn.accel),
                torn.samples_repaired
            );
        }
        None => {
            let _ = writeln!(s, "  torn-read repair disabled");
        }
    }
}

/// A table per sensor: each axis's terms and fit, then why the unresolved ones are.
fn write_channels(s: &mut String, report: &Report) {
    for sensor in [Sensor::Accel, Sensor::Gyro] {
        let channels: Vec<_> = report
            .channels
            .iter()
            .filter(|c| c.sensor == sensor)
            .collect();
        let Some(first) = channels.first() else {
            let _ = writeln!(s, "  gyroscope: not in the recording");
            continue;
        };
        let u = &first.unit;
        let _ = writeln!(
            s,
            "  {} ({u}): N [{u}/sqrt(Hz)], B [{u}], K [{u}*sqrt(Hz)], 1-sigma",
            match sensor {
                Sensor::Accel => "accelerometer",
                Sensor::Gyro => "gyroscope",
            }
        );
        let mut notes = Vec::new();
        for c in &channels {
            let f = &c.fit;
            let _ = writeln!(
                s,
                "    {}: N {:<22} B {:<22} K {:<22} chi2/dof {:.2}; tau {:.3}..{:.1} s",
                AXES[c.axis],
                term_text(&f.white),
                term_text(&f.bias_instability),
                term_text(&f.random_walk),
                f.chi2 / f.dof.max(1) as f64,
                f.points[0].tau_s,
                f.points[f.points.len() - 1].tau_s,
            );
            for (symbol, term) in [
                ("N", &f.white),
                ("B", &f.bias_instability),
                ("K", &f.random_walk),
            ] {
                if let Term::Unresolved { reason, .. } = term {
                    notes.push(format!("    {} {symbol}: {reason}", AXES[c.axis]));
                }
            }
        }
        for note in notes {
            let _ = writeln!(s, "{note}");
        }
    }
}

/// The displacement floor the noise predicts, and this record's.
fn write_floor(s: &mut String, report: &Report) {
    let f = &report.floor;
    let axes = |v: &[f64; 3]| format!("x {:.3}, y {:.3}, z {:.3} m", v[0], v[1], v[2]);
    let _ = writeln!(
        s,
        "  displacement floor (mean removed, 1-sigma): {:.0} s: {}",
        f.horizon_s,
        axes(&f.predicted_m)
    );
    let _ = writeln!(
        s,
        "  this record ({:.2} s): predicted {}; measured {}",
        f.record_s,
        axes(&f.predicted_record_m),
        axes(&f.measured_record_m)
    );
}

/// The human-readable summary.
pub fn render(report: &Report) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "Allan deviation of {}", report.source);
    write_recording(&mut s, report);
    write_channels(&mut s, report);
    write_floor(&mut s, report);
    s
}
