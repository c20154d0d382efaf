//! `mems-calibrate diagnose`: residual diagnosis of a calibration (see `calibrate_science::diagnose`).

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};
use calibrate::calibfile::{CalibrationFile, FitMethod, ResidualSection, SourceSection};
use calibrate::model::{AccelModel, ParamCovariance};
use calibrate_science::diagnose::{
    BaselineKind, CandidateStatus, DiagnoseConfig, Diagnosis, Effect, ModelScore, SessionInput,
    diagnose, plots,
};
use calibrate_science::fit::{CovarianceMode, Weighting};
use calibrate_science::segments::SegmentConfig;
use calibrate_science::session::{Input, load_input, poses_from_six};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

/// Options of `mems-calibrate diagnose`.
#[derive(Args)]
pub struct DiagnoseArgs {
    /// Calibration data: six-position means CSVs, raw recordings (canonical CSV, thesis CSV,
    /// MCAP) or folders of them, one session each.
    #[arg(long, required = true, num_args = 1..)]
    input: Vec<PathBuf>,
    /// Test data (files or folders) for the held-out residuals; without it, held-out folds of
    /// the calibration data are used.
    #[arg(long, num_args = 1..)]
    test: Vec<PathBuf>,
    /// Local gravity, m/s^2, for reporting residuals in m/s^2.
    #[arg(long, default_value_t = ipc_types::units::STANDARD_GRAVITY_MPS2)]
    gravity: f64,
    /// Print the JSON summary instead of the report.
    #[arg(long)]
    json: bool,
    /// Write PNG plots (residuals against each candidate's regressor, histograms) here.
    #[arg(long)]
    plot_dir: Option<PathBuf>,
    /// Write the final model (baseline plus the selected effect, fitted on the calibration
    /// data; without reference_tilt and gaps, which are not the sensor's) as a calibration
    /// file (private, 0600); an existing file is refused unless --force.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace the file at --out (atomically; a symbolic link there is replaced, not followed).
    #[arg(long)]
    force: bool,
    /// With a static baseline (no S, b of its own): the calibration file the fitted terms are
    /// added to for --out.
    #[arg(long)]
    base: Option<PathBuf>,
    /// An effect already known to be present: part of the baseline (repeatable).
    #[arg(long, value_enum)]
    apply: Vec<Effect>,
    /// Block length, s.
    #[arg(long, default_value_t = 1.0)]
    block_s: f64,
    /// Shortest static segment (pose) used, s; windows of a quarter of it (at most 0.5 s). The
    /// default takes poses held 2 s (multi-position protocols hold each 1-4 s).
    #[arg(long, default_value_t = calibrate_science::diagnose::DEFAULT_MIN_SEGMENT_S)]
    min_segment_s: f64,
    /// The raw recordings (--input, then --test, in the order given) are of one power-on, in
    /// time order on one clock (the live driver's stamps): one time origin for all, so a bias
    /// drift or warm-up fitted on the calibration data continues into the test data.
    #[arg(long)]
    same_power_on: bool,
    /// Validation folds when no test data is given.
    #[arg(long, default_value_t = 5)]
    folds: usize,
    /// Samples behind each pose of a means file that does not record it (the thesis: 30 s at
    /// about 180 Hz).
    #[arg(long, default_value_t = 5400)]
    pose_samples: usize,
}

fn load(paths: &[PathBuf], what: &str) -> Result<Vec<SessionInput>> {
    let files = recording::folders::expand(paths)?;
    let bar = ProgressBar::new(files.len() as u64).with_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(format!("loading {what}"));
    let mut out = Vec::new();
    for f in &files {
        let name = f.display().to_string();
        let session = match load_input(f)? {
            Input::SixPosition(six) => SessionInput::Means {
                name,
                poses: poses_from_six(&six),
            },
            Input::Raw(rec) => SessionInput::Raw {
                name,
                samples: rec.samples,
            },
        };
        out.push(session);
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(out)
}

/// `mems-calibrate diagnose`.
pub fn run(args: &DiagnoseArgs) -> Result<()> {
    if let (Some(out), false) = (&args.out, args.force) {
        mems_files::refuse_existing(out, Some("--out"))?;
    }
    calibrate::calibfile::check_gravity(args.gravity).map_err(|e| anyhow!("--gravity {e}"))?;
    if !(args.block_s > 0.0 && args.block_s.is_finite()) {
        bail!("--block-s must be > 0, got {}", args.block_s);
    }
    if args.folds < 2 {
        bail!("--folds must be at least 2, got {}", args.folds);
    }
    if args.pose_samples == 0 {
        bail!("--pose-samples must be at least 1");
    }
    let calib = load(&args.input, "calibration data")?;
    let test = load(&args.test, "test data")?;
    let mut cfg = DiagnoseConfig {
        apply: args.apply.clone(),
        gravity_mps2: args.gravity,
        same_power_on: args.same_power_on,
        ..DiagnoseConfig::default()
    };
    cfg.data.block_s = args.block_s;
    if !(args.min_segment_s > 0.0 && args.min_segment_s.is_finite()) {
        bail!("--min-segment-s must be > 0, got {}", args.min_segment_s);
    }
    cfg.data.segments = SegmentConfig::with_min_duration(args.min_segment_s);
    cfg.data.folds = args.folds;
    cfg.data.pose_samples = args.pose_samples;
    let d = diagnose(&calib, &test, &cfg)?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&d.to_json()).expect("serialisable")
        );
    } else {
        print!("{}", report(&d));
    }
    if let Some(dir) = &args.plot_dir {
        for f in plots::write_all(dir, &d)? {
            tracing::info!("wrote {}", f.display());
        }
    }
    if let Some(out) = &args.out {
        write_calibration(args, &d, out)?;
    }
    Ok(())
}

/// mg with 3 decimals from g.
fn mg(x: f64) -> String {
    format!("{:.3}", x * 1e3)
}

/// The acquisition findings: a line per session (with many sessions, only those with gaps or
/// repeats beyond chance, and a sum over all).
fn write_acquisition(s: &mut String, d: &Diagnosis) {
    use std::fmt::Write;
    let sessions = d.acquisition.len();
    for a in &d.acquisition {
        // Many sessions: one line each only for those with gaps or repeats beyond chance.
        if sessions > 6 && a.gaps == 0 && !a.repeats_significant {
            continue;
        }
        let offsets: Vec<String> = a
            .outlier_offset_counts
            .iter()
            .map(|o| {
                if o.is_finite() {
                    format!("{o:.0}")
                } else {
                    "-".into()
                }
            })
            .collect();
        let _ = writeln!(
            s,
            "acquisition {}: {} samples, median interval {:.2} ms; torn reads repaired x/y/z {}/{}/{} \
             ({} read high); outliers > 5 sigma {}/{}/{} at a median offset of {} counts; exact \
             repeats {} ({:.1} expected from noise{}); gaps {} (longest interval {:.3} s, {:.3} s \
             missing)",
            a.name,
            a.samples,
            a.median_dt_s * 1e3,
            a.torn.repaired[0],
            a.torn.repaired[1],
            a.torn.repaired[2],
            a.torn.high.iter().sum::<usize>(),
            a.outliers[0],
            a.outliers[1],
            a.outliers[2],
            offsets.join("/"),
            a.repeats,
            a.repeats_expected,
            if a.repeats_significant {
                ", beyond chance"
            } else {
                ""
            },
            a.gaps,
            a.longest_gap_s,
            a.gap_time_s,
        );
    }
    if sessions > 6 {
        let sum = |f: fn(&calibrate_science::diagnose::AcquisitionFindings) -> usize| {
            d.acquisition.iter().map(f).sum::<usize>()
        };
        let _ = writeln!(
            s,
            "acquisition, {sessions} sessions: {} samples; torn reads repaired x/y/z {}/{}/{}; \
             outliers > 5 sigma x/y/z {}/{}/{}; exact repeats {}; gaps {} in {} sessions \
             (longest interval {:.3} s)",
            sum(|a| a.samples),
            sum(|a| a.torn.repaired[0]),
            sum(|a| a.torn.repaired[1]),
            sum(|a| a.torn.repaired[2]),
            sum(|a| a.outliers[0]),
            sum(|a| a.outliers[1]),
            sum(|a| a.outliers[2]),
            sum(|a| a.repeats),
            sum(|a| a.gaps),
            d.acquisition.iter().filter(|a| a.gaps > 0).count(),
            d.acquisition
                .iter()
                .map(|a| a.longest_gap_s)
                .fold(0.0, f64::max),
        );
    }
}

/// A model's score line.
fn write_score(s: &mut String, name: &str, m: &ModelScore) {
    use std::fmt::Write;
    let axes = m.rms_axes_mps2.map_or(String::new(), |a| {
        format!(" (x {:.5}, y {:.5}, z {:.5})", a[0], a[1], a[2])
    });
    let _ = writeln!(
        s,
        "{name:<9} {:<40} rms {:.5} m/s^2{axes}; white noise and parameter uncertainty \
         predict {:.5}; chi2 {:.1} for {:.1} expected, p {:.2e}",
        m.model, m.rms_mps2, m.expected_rms_mps2, m.chi2, m.expected_chi2, m.p_value
    );
}

/// A line per candidate: its score, or why it was not evaluated.
fn write_candidates(s: &mut String, d: &Diagnosis) {
    use std::fmt::Write;
    for c in &d.candidates {
        match (&c.status, &c.result) {
            (CandidateStatus::Evaluated, Some(r)) => {
                let _ = writeln!(
                    s,
                    "  {:<20} rms {:.5} m/s^2  score {:>10.1}  explains {:>6.1}% of the excess  (+{} params)",
                    c.effect.name(),
                    r.rms_mps2,
                    c.score,
                    100.0 * c.explained,
                    c.params
                );
            }
            (CandidateStatus::NotApplicable(why), _) => {
                let _ = writeln!(s, "  {:<20} not applicable: {why}", c.effect.name());
            }
            (CandidateStatus::NotIdentifiable(why), _) => {
                let _ = writeln!(s, "  {:<20} not identifiable: {why}", c.effect.name());
            }
            (CandidateStatus::Evaluated, None) => {}
        }
    }
}

/// The final fit's model and its extra terms.
fn write_final_fit(s: &mut String, d: &Diagnosis) {
    use std::fmt::Write;
    let g = d.gravity_mps2;
    let f = &d.final_fit;
    if let Some(m) = &f.model {
        let b = m.bias_g();
        let sm = m.scale();
        let _ = writeln!(
            s,
            "final fit ({} poses): b = [{}, {}, {}] mg, S = [[{:.5}, {:.5}, {:.5}], [{:.5}, {:.5}, {:.5}], [{:.5}, {:.5}, {:.5}]]",
            f.poses,
            mg(b.x),
            mg(b.y),
            mg(b.z),
            sm[(0, 0)],
            sm[(0, 1)],
            sm[(0, 2)],
            sm[(1, 0)],
            sm[(1, 1)],
            sm[(1, 2)],
            sm[(2, 0)],
            sm[(2, 1)],
            sm[(2, 2)]
        );
    }
    let t = &f.terms;
    let v3 = |v: &nalgebra::Vector3<f64>, k: f64| {
        format!("[{:.4}, {:.4}, {:.4}]", v.x * k, v.y * k, v.z * k)
    };
    if let Some(c) = &t.temp_bias_g_per_c {
        let _ = writeln!(
            s,
            "  temperature bias {} mg/degC about {:.2} degC",
            v3(c, 1e3),
            t.reference_c.unwrap_or(f64::NAN)
        );
    }
    if let Some(c) = &t.temp_scale_per_c {
        let _ = writeln!(
            s,
            "  temperature scale {} ppm/degC about {:.2} degC",
            v3(c, 1e6),
            t.reference_c.unwrap_or(f64::NAN)
        );
    }
    if let Some((r, t_max)) = &t.drift {
        let _ = writeln!(
            s,
            "  bias drift {} mg/min ({} mm/s^2 per minute), held after {:.1} s",
            v3(r, 60e3),
            v3(r, 60.0 * g * 1e3),
            t_max
        );
    }
    if let Some((w, tau)) = &t.warm_up {
        let _ = writeln!(
            s,
            "  warm-up {} mg ({} mm/s^2) decaying with tau = {:.1} s",
            v3(w, 1e3),
            v3(w, g * 1e3),
            tau
        );
    }
    if let Some(k) = &t.quadratic_g_per_g2 {
        let _ = writeln!(s, "  quadratic nonlinearity {} mg/g^2", v3(k, 1e3));
    }
    for (class, off) in &f.tilt_g {
        let _ = writeln!(
            s,
            "  reference tilt of orientation class {class}: offsets [{}, {}, {}] mg",
            mg(off[0]),
            mg(off[1]),
            mg(off[2])
        );
    }
}

/// The human-readable report.
pub fn report(d: &Diagnosis) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "baseline: {} ({:?})", d.baseline.model, d.kind);
    let _ = writeln!(s, "validation: {}", d.validation);
    write_acquisition(&mut s, d);
    write_score(&mut s, "baseline", &d.baseline);
    let _ = writeln!(s, "candidates:");
    write_candidates(&mut s, d);
    let _ = writeln!(s, "selected: {}", d.selected.map_or("none", Effect::name));
    write_score(&mut s, "final", &d.final_model);
    let _ = writeln!(
        s,
        "noise floor {:.5} m/s^2; unexplained structure: {}",
        d.noise_floor_mps2, d.unexplained_structure
    );
    write_final_fit(&mut s, d);
    s
}

/// The calibration file of the diagnosis's own model 3 (`kind` baseline) with its
/// covariance and residuals.
fn fitted_file(
    args: &DiagnoseArgs,
    d: &Diagnosis,
    kind: BaselineKind,
    model: &AccelModel,
    cov: &ParamCovariance,
) -> CalibrationFile {
    let f = &d.calibration_fit;
    let per_pose_g = f.per_pose_residual_g.clone();
    let n = per_pose_g.len().max(1) as f64;
    let rms_g: [f64; 3] =
        std::array::from_fn(|i| (per_pose_g.iter().map(|r| r[i] * r[i]).sum::<f64>() / n).sqrt());
    let residuals = ResidualSection {
        rms_g,
        max_abs_g: per_pose_g
            .iter()
            .flatten()
            .fold(0.0, |m: f64, r| m.max(r.abs())),
        dof: [f.dof; 3],
        chi2: [f.chi2; 3],
        per_pose_g,
    };
    let source = SourceSection {
        file: args
            .input
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        kind: format!("diagnose ({})", d.final_model.model),
        poses: f.poses,
        repaired_samples: f.repaired_samples,
    };
    let method = if kind == BaselineKind::LabelFree {
        FitMethod::LabelFree
    } else {
        FitMethod::Labelled
    };
    let mut file = CalibrationFile::new(
        model,
        cov,
        method,
        Weighting::PoseStd,
        CovarianceMode::ResidualScaled,
        args.gravity,
        source,
        residuals,
    );
    file.temperature_range_c = f.temperature_range_c;
    file
}

/// Writes the final model (or the terms added to `--base`) as a calibration file to `out`.
fn write_calibration(args: &DiagnoseArgs, d: &Diagnosis, out: &Path) -> Result<()> {
    let f = &d.calibration_fit;
    let mut file = match (d.kind, &f.model, &f.covariance) {
        (BaselineKind::SessionMean, _, _) | (_, None, _) | (_, _, None) => {
            let Some(base) = &args.base else {
                bail!(
                    "--out: a static baseline has no S and b of its own; pass --base CALIB.toml to add \
                     the fitted terms to an existing calibration"
                );
            };
            CalibrationFile::load(base)?
        }
        (kind, Some(model), Some(cov)) => fitted_file(args, d, kind, model, cov),
    };
    if d.final_fit.effects.contains(&Effect::ReferenceTilt) {
        tracing::info!(
            "reference_tilt describes the calibration set-up (labels off), not the sensor: the \
             file holds the model fitted without it; calibrate label-free from at least 9 \
             orientations instead"
        );
    }
    if d.final_fit.effects.contains(&Effect::Gaps) {
        tracing::info!("the bias steps at gaps belong to one session: not written");
    }
    let t = &f.terms;
    if t.temp_bias_g_per_c.is_some() || t.temp_scale_per_c.is_some() {
        file.temperature.reference_c = t.reference_c;
        file.temperature.bias_g_per_c = t.temp_bias_g_per_c.map(|v| v.into());
        file.temperature.scale_per_c = t.temp_scale_per_c.map(|v| v.into());
    }
    if let Some((r, t_max)) = t.drift {
        file.time.drift_g_per_s = Some(r.into());
        file.time.drift_max_s = Some(t_max);
    }
    if let Some((w, tau)) = t.warm_up {
        file.time.warm_up_g = Some(w.into());
        file.time.warm_up_time_constant_s = Some(tau);
    }
    if let Some(k) = t.quadratic_g_per_g2 {
        file.nonlinearity.quadratic_g_per_g2 = Some(k.into());
    }
    super::save(&file, out, "--out", mems_files::Existing::force(args.force))?;
    // Read it back: the file must load (and so drive the live stage).
    CalibrationFile::load(out)?;
    tracing::info!("wrote {}", out.display());
    Ok(())
}
