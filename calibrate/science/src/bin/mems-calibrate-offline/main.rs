//! `mems-calibrate-offline`: the offline subcommands of `mems-calibrate`, which runs this binary
//! for them (`mems-calibrate fit ...` is `mems-calibrate-offline fit ...`), so that the live
//! `mems-calibrate serve` links none of the fitting, plotting and reporting code.
//! `fit`: fits an accelerometer model to a six-position means file or to the static segments of
//! a raw recording and writes a calibration file (TOML).
//! `diagnose`: residual diagnosis against candidate effects (see `calibrate_science::diagnose`).
//! `allan`: Allan deviation and noise parameters of a static recording (see the `noise` crate),
//! optionally stored as a calibration file's `[noise]` table.
//! `gyrocal`: the gyro's scale and misalignment correction from a pose session (also run as
//! `mems-odometry gyrocal`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, anyhow, bail};
use calibrate::calibfile::{
    CalibrationFile, CovarianceMode, FitMethod, ResidualSection, SourceSection,
};
use calibrate::model::{ModelKind, PARAM_NAMES};
use calibrate_science::coverage;
use calibrate_science::fit::{Pose, Weighting, fit_labelled};
use calibrate_science::labelfree::fit_label_free;
use calibrate_science::plots::plot_pose_residuals;
use calibrate_science::segments::SegmentConfig;
use calibrate_science::session::{
    Input, all_axis_aligned, label_axis_aligned, load_input, poses_from_six, raw_poses,
};
use clap::{Parser, Subcommand, ValueEnum};
use mems_files::Existing;

mod diagnose;
mod gyrocal;

#[derive(Parser)]
#[command(
    name = "mems-calibrate",
    bin_name = "mems-calibrate",
    version,
    about = "Accelerometer calibration for mems-odometry: the offline subcommands (fit, diagnose, allan, gyrocal)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// How poses get their gravity labels.
#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Labels {
    /// Six-position files: the file's labels. Raw recordings: the nearest axis of each static
    /// segment when all are axis aligned, otherwise a label-free fit.
    Auto,
    /// Label-free fit on |a| = 1 g (needs at least 9 well-spread orientations).
    None,
}

/// Options of `mems-calibrate fit`.
#[derive(clap::Args)]
struct FitArgs {
    /// Six-position means CSV, or a raw recording (canonical CSV, thesis CSV, MCAP).
    #[arg(long)]
    input: PathBuf,
    /// Model: bias (model 1), scale (model 2) or full (model 3).
    #[arg(long, value_enum)]
    model: ModelKind,
    /// Weight poses by 1/sigma^2 of their means (default: unweighted, as the thesis).
    #[arg(long)]
    weighted: bool,
    /// Where labels come from.
    #[arg(long, value_enum, default_value = "auto")]
    labels: Labels,
    /// Local gravity, m/s^2, recorded in the file for converting g to m/s^2.
    #[arg(long, default_value_t = ipc_types::units::STANDARD_GRAVITY_MPS2)]
    gravity: f64,
    /// Output calibration file (private, 0600); an existing file is refused unless --force.
    #[arg(long)]
    out: PathBuf,
    /// Replace the file at --out (atomically; a symbolic link there is replaced, not followed).
    #[arg(long)]
    force: bool,
    /// Also draw the per-pose residuals to this PNG.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Shortest static segment (pose) of a raw recording used, s; windows of a quarter of
    /// it (at most 0.5 s).
    #[arg(long, default_value_t = 5.0)]
    min_segment_s: f64,
}

#[derive(Subcommand)]
enum Command {
    /// Fit a model and write a calibration file.
    Fit(FitArgs),
    /// Fit the baseline, test its held-out residuals against candidate effects, add the one
    /// that explains them and report the error before and after.
    Diagnose(diagnose::DiagnoseArgs),
    /// Allan deviation of a static recording and its noise parameters (white noise, bias
    /// instability, rate random walk per axis, 1-sigma); optionally stored into a calibration
    /// file's [noise] table, exported for Kalibr and plotted.
    Allan(AllanArgs),
    /// Fit the gyro's scale and misalignment correction from a recorded pose session and
    /// optionally store it in the calibration file's `[gyro]` table.
    Gyrocal(gyrocal::GyroCalArgs),
}

/// `mems-calibrate allan`: the analysis's arguments plus where to store the parameters.
#[derive(clap::Args)]
struct AllanArgs {
    #[command(flatten)]
    analysis: noise::Args,
    /// Store the fitted noise parameters as the [noise] table of this calibration file
    /// (replacing any; the rest of the file is kept). --gravity defaults to the file's.
    #[arg(long, value_name = "CALIB.toml")]
    into: Option<PathBuf>,
}

fn main() -> ExitCode {
    mems_log::init("mems-calibrate");
    mems_log::exit(run(Cli::parse()))
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Fit(args) => fit(args),
        Command::Diagnose(args) => diagnose::run(&args),
        Command::Allan(args) => allan(args),
        Command::Gyrocal(args) => gyrocal::run(args),
    }
}

/// `mems-calibrate allan`.
fn allan(mut args: AllanArgs) -> Result<()> {
    // Read the calibration file first, so that a bad one fails before the analysis.
    let mut calib = match &args.into {
        Some(path) => Some(CalibrationFile::load(path)?),
        None => None,
    };
    if let Some(file) = &calib {
        match args.analysis.gravity {
            None => args.analysis.gravity = Some(file.gravity_mps2),
            Some(g) if g != file.gravity_mps2 => bail!(
                "--gravity {g} m/s^2 differs from the gravity of {} ({} m/s^2): the noise \
                 parameters must use the file's gravity (leave --gravity out)",
                args.into
                    .as_ref()
                    .map_or(String::new(), |p| p.display().to_string()),
                file.gravity_mps2
            ),
            Some(_) => {}
        }
    }
    let stdout = std::io::stdout();
    let report = noise::cli::run_allan_to(&args.analysis, &mut stdout.lock())?;
    if let (Some(path), Some(file)) = (&args.into, calib.as_mut()) {
        file.noise = Some(report.params);
        save(file, path, "--into", Existing::Replace)?;
        tracing::info!("wrote the noise parameters into {} [noise]", path.display());
    }
    Ok(())
}

/// The poses a fit takes from its input, and what the input says about them.
struct FitPoses {
    poses: Vec<Pose>,
    /// Whether they are fitted label-free.
    label_free: bool,
    temperature_range_c: Option<[f64; 2]>,
    repaired_samples: usize,
}

/// The poses of a six-position means file, or the static segments of a raw recording
/// (labelled when `labels` allow and they are axis aligned).
fn fit_poses(input: &Path, loaded: &Input, labels: Labels, min_segment_s: f64) -> Result<FitPoses> {
    let rec = match loaded {
        Input::SixPosition(six) => {
            return Ok(FitPoses {
                poses: poses_from_six(six),
                label_free: labels == Labels::None,
                temperature_range_c: None,
                repaired_samples: 0,
            });
        }
        Input::Raw(rec) => rec,
    };
    let raw = raw_poses(rec, &SegmentConfig::with_min_duration(min_segment_s))?;
    let repaired_samples = raw.repair.samples_repaired;
    tracing::info!(
        "{}: {} samples, {} torn reads repaired, {} static segments (noise {:.2e} / {:.2e} / {:.2e} g)",
        input.display(),
        raw.samples.len(),
        repaired_samples,
        raw.detection.segments.len(),
        raw.detection.noise_sigma_g[0],
        raw.detection.noise_sigma_g[1],
        raw.detection.noise_sigma_g[2]
    );
    let temperature_range_c = raw
        .detection
        .segments
        .iter()
        .filter_map(|s| s.temp_range_c)
        .fold(None, |acc: Option<[f64; 2]>, [lo, hi]| {
            Some(match acc {
                None => [lo, hi],
                Some([a, b]) => [f64::min(a, lo), f64::max(b, hi)],
            })
        });
    let (poses, label_free) = match labels {
        Labels::None => (label_unlabelled(&raw), true),
        Labels::Auto if all_axis_aligned(&raw) => (label_axis_aligned(input, &raw)?, false),
        Labels::Auto => {
            tracing::info!(
                "{}: the static poses are not all axis aligned; fitting label-free",
                input.display()
            );
            (label_unlabelled(&raw), true)
        }
    };
    Ok(FitPoses {
        poses,
        label_free,
        temperature_range_c,
        repaired_samples,
    })
}

/// The label-free fit of `poses` as a calibration file.
fn label_free_file(
    input: &Path,
    poses: &[Pose],
    weighting: Weighting,
    gravity: f64,
    source: SourceSection,
) -> Result<CalibrationFile> {
    let fit = fit_label_free(poses, weighting).with_context(|| format!("{}", input.display()))?;
    let per_pose_g: Vec<[f64; 3]> = fit.residuals_g.iter().map(|r| [*r, 0.0, 0.0]).collect();
    let rms =
        (fit.residuals_g.iter().map(|r| r * r).sum::<f64>() / fit.residuals_g.len() as f64).sqrt();
    let residuals = ResidualSection {
        rms_g: [rms; 3],
        max_abs_g: fit.residuals_g.iter().fold(0.0, |m, r| m.max(r.abs())),
        dof: [fit.dof; 3],
        chi2: [fit.chi2; 3],
        per_pose_g,
    };
    tracing::info!(
        "label-free fit: {} poses, {} orientations, Jacobian condition number {:.1}",
        poses.len(),
        fit.distinct_orientations,
        fit.condition
    );
    Ok(CalibrationFile::new(
        &fit.model,
        &fit.covariance,
        FitMethod::LabelFree,
        weighting,
        fit.covariance_mode,
        gravity,
        source,
        residuals,
    ))
}

/// The labelled fit of `poses` with `model` as a calibration file.
fn labelled_file(
    input: &Path,
    poses: &[Pose],
    model: ModelKind,
    weighting: Weighting,
    gravity: f64,
    source: SourceSection,
) -> Result<CalibrationFile> {
    let fit =
        fit_labelled(poses, model, weighting).with_context(|| format!("{}", input.display()))?;
    let per_pose_g: Vec<[f64; 3]> = fit.residuals_g.iter().map(|r| [r.x, r.y, r.z]).collect();
    let residuals = ResidualSection {
        rms_g: fit.residual_rms_g(),
        max_abs_g: per_pose_g
            .iter()
            .flatten()
            .fold(0.0, |m: f64, r| m.max(r.abs())),
        dof: fit.dof,
        chi2: fit.chi2,
        per_pose_g,
    };
    Ok(CalibrationFile::new(
        &fit.model,
        &fit.covariance,
        FitMethod::Labelled,
        weighting,
        fit.covariance_mode,
        gravity,
        source,
        residuals,
    ))
}

/// `mems-calibrate fit`.
fn fit(args: FitArgs) -> Result<()> {
    let FitArgs {
        input,
        model,
        weighted,
        labels,
        gravity,
        out,
        force,
        plot,
        min_segment_s,
    } = args;
    if !(min_segment_s > 0.0 && min_segment_s.is_finite()) {
        bail!("--min-segment-s must be > 0, got {min_segment_s}");
    }
    calibrate::calibfile::check_gravity(gravity).map_err(|e| anyhow!("--gravity {e}"))?;
    let weighting = if weighted {
        Weighting::PoseStd
    } else {
        Weighting::Unweighted
    };
    if !force {
        mems_files::refuse_existing(&out, Some("--out"))?;
    }
    let loaded = load_input(&input)?;
    let fp = fit_poses(&input, &loaded, labels, min_segment_s)?;
    let source = SourceSection {
        file: input.display().to_string(),
        kind: loaded.kind_name().into(),
        poses: fp.poses.len(),
        repaired_samples: fp.repaired_samples,
    };
    let mut file = if fp.label_free {
        if model != ModelKind::Full {
            bail!(
                "label-free fitting estimates the full model (upper-triangular S); use --model full"
            );
        }
        label_free_file(&input, &fp.poses, weighting, gravity, source)?
    } else {
        let file = labelled_file(&input, &fp.poses, model, weighting, gravity, source)?;
        warn_poorly_determined(&input, &fp.poses, &file);
        file
    };
    file.temperature_range_c = fp.temperature_range_c;
    print_summary(&file);
    save(&file, &out, "--out", Existing::force(force))?;
    tracing::info!("wrote {}", out.display());
    if let Some(plot) = plot {
        let title = format!(
            "{} residuals per pose ({})",
            file.model,
            input
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned())
        );
        plot_pose_residuals(&plot, &title, &file.residuals.per_pose_g)?;
        tracing::info!("wrote {}", plot.display());
    }
    Ok(())
}

/// Warns of what the poses of a labelled fit leave poorly determined
/// ([`calibrate_science::coverage`]): axis directions a six-position session lacks, parameters
/// that rest on one pose alone, and 1-sigmas scaled by a single residual.
fn warn_poorly_determined(input: &Path, poses: &[Pose], file: &CalibrationFile) {
    let input = input.display();
    if let Some(missing) = coverage::missing_directions(poses)
        && !missing.is_empty()
    {
        tracing::warn!(
            "{input}: a six-position session without a pose with {} up ({} of the 6 axis \
             directions): the parameters of those axes are seen from one side only; record \
             the missing poses",
            missing.join(", "),
            6 - missing.len()
        );
    }
    for sole in coverage::sole_poses(poses, file.model) {
        let direction = coverage::direction(&poses[sole.pose].truth_g).map_or(String::new(), |d| {
            format!(" ({} up)", coverage::DIRECTIONS[d])
        });
        tracing::warn!(
            "{input}: {} rest on pose {}{direction} alone: the fit passes through it exactly, \
             so no residual checks them and their 1-sigma leaves out that pose's error",
            sole.params.join(", "),
            sole.pose + 1
        );
    }
    if file.covariance_mode != CovarianceMode::ResidualScaled {
        return;
    }
    for (axis, &dof) in file.residuals.dof.iter().enumerate() {
        if dof == 1 {
            let (name, params) = coverage::axis_parameters(file.model, axis);
            tracing::warn!(
                "{input}: {} ({name} axis) have a 1-sigma scaled by a single residual: one time \
                 in 20 it is {:.0} times too small",
                params.join(", "),
                coverage::sigma_shortfall(dof)
            );
        }
    }
}

/// Poses for a label-free fit (labels unused).
fn label_unlabelled(raw: &calibrate_science::session::RawPoses) -> Vec<Pose> {
    raw.detection
        .segments
        .iter()
        .map(|s| raw.detection.pose(s, nalgebra::Vector3::zeros()))
        .collect()
}

fn print_summary(file: &CalibrationFile) {
    println!(
        "model {} ({:?}, {:?}, covariance {:?})",
        file.model, file.method, file.weighting, file.covariance_mode
    );
    let p = file.accel_model().map(|m| m.params()).ok();
    for (k, name) in PARAM_NAMES.iter().enumerate() {
        if let Some(p) = &p
            && file.sigma[k] > 0.0
        {
            println!("  {name:<5} {:>12.6} +- {:.6}", p[k], file.sigma[k]);
        }
    }
    let r = &file.residuals.rms_g;
    println!(
        "  residual rms {:.3e} {:.3e} {:.3e} g over {} poses",
        r[0], r[1], r[2], file.source.poses
    );
}

/// Writes `file` to `path`, given by option `flag`: a private file (0600) renamed into place
/// once complete, over an existing file only with `existing` = `Replace` (`mems_files`).
fn save(file: &CalibrationFile, path: &Path, flag: &'static str, existing: Existing) -> Result<()> {
    Ok(mems_files::write(
        path,
        Some(flag),
        existing,
        file.to_toml().as_bytes(),
    )?)
}
