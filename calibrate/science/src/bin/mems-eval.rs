//! `mems-eval`: reproduces the thesis's Table 5 (`thesis`) and evaluates dead reckoning on a
//! static recording after boot (`static`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use calibrate::calibfile::CalibrationFile;
use calibrate_science::static_eval::{DriftSource, StaticEvalConfig, evaluate_static};
use calibrate_science::{plots, thesis_eval};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use noise::NoiseParams;

#[derive(Parser)]
#[command(
    name = "mems-eval",
    version,
    about = "Evaluation of accelerometer calibration by dead reckoning"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Reproduce thesis Table 5 / A-2 (trials 1-3: 60 s displacement, no calibration and models 1-3).
    Thesis {
        /// The capstone data folder (holding Six-Position-Test/).
        #[arg(long)]
        data: PathBuf,
        /// Local gravity, m/s^2 (the thesis's value by default).
        #[arg(long, default_value_t = ipc_types::units::THESIS_GRAVITY_MPS2)]
        gravity: f64,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Dead reckoning on a static recording: alignment then integration, per window start.
    Static {
        /// Six-position means file to calibrate from (model 3, unweighted).
        #[arg(long)]
        six: PathBuf,
        /// The static test recording.
        #[arg(long)]
        test: PathBuf,
        /// Alignment interval at rest, s.
        #[arg(long, default_value_t = 10.0)]
        align_s: f64,
        /// Dead-reckoning interval, s.
        #[arg(long, default_value_t = 60.0)]
        window_s: f64,
        /// Spacing of window starts, s (default: the window length).
        #[arg(long)]
        step_s: Option<f64>,
        /// Local gravity, m/s^2.
        #[arg(long, default_value_t = ipc_types::units::THESIS_GRAVITY_MPS2)]
        gravity: f64,
        /// Earlier static recordings of the same sensor (files or folders of them), recorded
        /// before the test, for the drift and warm-up terms (e.g. the thesis's start-up runs).
        #[arg(long)]
        prior: Vec<PathBuf>,
        /// Calibration file whose [noise] table (mems-calibrate allan --into) gives the bias
        /// instability and rate random walk of the drift term for windows without earlier
        /// recordings (default: an Allan analysis of the test file's rest before each window).
        #[arg(long, value_name = "CALIB.toml")]
        noise: Option<PathBuf>,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
        /// Also draw displacement over time per method to this PNG.
        #[arg(long)]
        plot: Option<PathBuf>,
    },
}

fn main() -> ExitCode {
    mems_log::init("mems-eval");
    mems_log::exit(run(Cli::parse()))
}

/// The `[noise]` table of calibration file `path`.
fn load_noise(path: &Path) -> Result<NoiseParams> {
    CalibrationFile::load(path)?.noise.with_context(|| {
        format!(
            "{}: no [noise] table (run mems-calibrate allan --into)",
            path.display()
        )
    })
}

/// The earlier recordings named by `prior` (files or folders), read with a progress bar
/// (returned for the evaluation to go on with).
fn load_priors(prior: &[PathBuf]) -> Result<(Vec<recording::Recording>, ProgressBar)> {
    let prior_files = recording::folders::expand(prior)?;
    let progress = ProgressBar::new(prior_files.len() as u64);
    progress.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    progress.set_message("reading earlier recordings");
    let priors = prior_files
        .iter()
        .map(|p| {
            progress.inc(1);
            recording::load_raw(p)
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((priors, progress))
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Thesis {
            data,
            gravity,
            json,
        } => {
            let results = thesis_eval::evaluate_all(&data, gravity)?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&thesis_eval::to_json(&results))?
                );
            } else {
                print!("{}", thesis_eval::to_text(&results));
            }
        }
        Command::Static {
            six,
            test,
            align_s,
            window_s,
            step_s,
            gravity,
            prior,
            noise,
            json,
            plot,
        } => {
            let noise = noise.as_deref().map(load_noise).transpose()?;
            let cfg = StaticEvalConfig {
                align_s,
                window_s,
                step_s: step_s.unwrap_or(window_s),
                gravity_mps2: gravity,
            };
            let six_data = recording::load_six_position(&six)?;
            let test_data = recording::load_raw(&test)?;
            let (priors, progress) = load_priors(&prior)?;
            progress.set_position(0);
            progress.set_length(priors.len() as u64 + 1);
            progress.set_message("evaluating");
            let report = evaluate_static(
                &six_data,
                &test_data,
                priors,
                noise.as_ref(),
                &cfg,
                &progress,
            )?;
            progress.finish_and_clear();
            if report.drift_source == DriftSource::OwnRest {
                tracing::info!(
                    "neither earlier recordings (--prior) nor noise parameters (--noise) cover a window: its \
                     drift term comes from an Allan analysis of the rest before it, whose unresolved bias \
                     instability and random walk count at their upper limits (a conservative sigma)"
                );
            }
            if json {
                println!("{}", serde_json::to_string_pretty(&report.to_json())?);
            } else {
                print!("{}", report.to_text(&cfg));
            }
            if let Some(plot) = plot {
                plots::plot_static_displacement(&plot, &report)?;
                tracing::info!("wrote {}", plot.display());
            }
        }
    }
    Ok(())
}
