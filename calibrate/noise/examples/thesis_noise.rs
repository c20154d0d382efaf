//! The noise figures of the thesis' real static recordings, as Markdown tables (the source of
//! `docs/noise.md`):
//! `cargo run --release -p noise --example thesis_noise [-- DATA_DIR [POOLED.png]]`, with DATA_DIR
//! the capstone data folder (default `../shared/data/capstone` beside the repository) and
//! POOLED.png where to plot the pooled start-up analysis.
//!
//! For each 60 s file of the six-position trials, and for the 60 start-up runs (each, and all
//! pooled as segments of one analysis): white noise N, bias instability B and rate random
//! walk K per axis, and the 60 s displacement floor they predict (mean removed) against the
//! displacement the files show after removing their mean.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use ipc_types::RawImuSample;
use ipc_types::units::THESIS_GRAVITY_MPS2;
use noise::analysis::{Options, Report, analyze, join_records};
use noise::fit::Term;
use noise::floor::{measured_static_displacement, static_displacement_sigma};

fn term(t: &Term) -> String {
    match t {
        Term::Resolved { value, sigma } => format!("{value:.3e} ± {sigma:.1e}"),
        Term::Unresolved { upper_limit, .. } => format!("< {upper_limit:.1e}"),
    }
}

fn options() -> Options {
    Options {
        gravity_mps2: THESIS_GRAVITY_MPS2,
        ..Options::default()
    }
}

fn load(path: &Path) -> Result<Vec<RawImuSample>> {
    Ok(recording::load_raw(path)
        .with_context(|| format!("reading {}", path.display()))?
        .samples)
}

fn print_fits(name: &str, report: &Report) {
    for c in &report.channels {
        println!(
            "| {name} | {} | {} | {} | {} | {:.2} |",
            ["x", "y", "z"][c.axis],
            term(&c.fit.white),
            term(&c.fit.bias_instability),
            term(&c.fit.random_walk),
            c.fit.chi2 / c.fit.dof.max(1) as f64
        );
    }
}

fn rms(values: &[f64]) -> f64 {
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

/// The six-position trials' test files: fits and the 60 s displacement floor.
fn six_position(dir: &Path, table_head: &str) -> Result<()> {
    println!("## Six-position test files (60 s, z up)\n\n{table_head}");
    let mut floors = Vec::new();
    for trial in 1..=3 {
        let path = dir.join(format!(
            "Six-Position-Test/data/trial_{trial}/six_position_test_data_{trial}.csv"
        ));
        let mut samples = load(&path)?;
        let report = analyze(&mut samples, &path.display().to_string(), &options())?;
        print_fits(&format!("trial {trial}"), &report);
        floors.push((format!("trial {trial}"), report));
    }
    println!("\n### Displacement after 60 s, mean removed (m)\n");
    println!("| record | predicted 1σ x, y, z | measured x, y, z |\n|---|---|---|");
    for (name, r) in &floors {
        let f = &r.floor;
        println!(
            "| {name} | {:.3}, {:.3}, {:.3} | {:.3}, {:.3}, {:.3} |",
            f.predicted_m[0],
            f.predicted_m[1],
            f.predicted_m[2],
            f.measured_record_m[0],
            f.measured_record_m[1],
            f.measured_record_m[2]
        );
    }
    Ok(())
}

/// Effect of torn-read repair on trial 1: its fits without it.
fn unrepaired_trial(dir: &Path, table_head: &str) -> Result<()> {
    let path = dir.join("Six-Position-Test/data/trial_1/six_position_test_data_1.csv");
    let mut raw = load(&path)?;
    let unrepaired = analyze(
        &mut raw,
        "trial 1, no repair",
        &Options {
            repair: None,
            ..options()
        },
    )?;
    println!("\n### Trial 1 without torn-read repair\n\n{table_head}");
    print_fits("trial 1 raw", &unrepaired);
    Ok(())
}

/// The start-up runs analysed one by one: each run's repaired samples, and per axis its
/// measured 60 s displacement and resolved white noise.
struct StartUpRuns {
    records: Vec<Vec<RawImuSample>>,
    measured: [Vec<f64>; 3],
    single_n: [Vec<f64>; 3],
}

fn start_up_runs(dir: &Path) -> Result<StartUpRuns> {
    let mut runs = StartUpRuns {
        records: Vec::new(),
        measured: Default::default(),
        single_n: Default::default(),
    };
    for run in 1..=60 {
        let path = dir.join(format!(
            "Preliminary-Tests/Start-Up-Shut-Down/Data/start_up_data_{run}.csv"
        ));
        let mut samples = load(&path)?;
        let report = analyze(&mut samples, &path.display().to_string(), &options())?;
        for axis in 0..3 {
            runs.measured[axis].push(report.floor.measured_record_m[axis]);
            if let Some((n, _)) = report.channels[axis].fit.white.resolved() {
                runs.single_n[axis].push(n);
            }
        }
        // Repaired samples: the pooled analysis below must not repair twice.
        debug_assert_eq!(
            measured_static_displacement(&samples, THESIS_GRAVITY_MPS2)[0],
            report.floor.measured_record_m[0]
        );
        runs.records.push(samples);
    }
    Ok(runs)
}

/// The white noise of the runs one by one, and the pooled prediction of the 60 s floor
/// against the runs' displacements.
fn print_start_up(report: &Report, runs: &mut StartUpRuns) {
    println!("\nWhite noise of the runs analysed one by one (median, min, max):\n");
    for axis in 0..3 {
        let v = &mut runs.single_n[axis];
        v.sort_by(f64::total_cmp);
        println!(
            "- {}: {:.3e} ({:.3e} .. {:.3e}), {} runs",
            ["x", "y", "z"][axis],
            v[v.len() / 2],
            v[0],
            v[v.len() - 1],
            v.len()
        );
    }
    println!("\n### 60 s displacement floor: pooled prediction vs the 60 runs (mean removed)\n");
    println!(
        "| axis | predicted 1σ (m) | white-noise part (m) | measured RMS over 60 runs (m) | measured max abs (m) |\n|---|---|---|---|---|"
    );
    for axis in 0..3 {
        let p = report.channels[axis].fit.coefficients;
        let predicted = static_displacement_sigma(p[0].sqrt(), p[1].sqrt(), p[2].sqrt(), 60.0);
        let white = static_displacement_sigma(p[0].sqrt(), 0.0, 0.0, 60.0);
        let max = runs.measured[axis]
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        println!(
            "| {} | {predicted:.3} | {white:.3} | {:.3} | {max:.3} |",
            ["x", "y", "z"][axis],
            rms(&runs.measured[axis])
        );
    }
}

fn main() -> Result<()> {
    let dir = std::env::args().nth(1).map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/capstone"),
        PathBuf::from,
    );
    let table_head = "| record | axis | N (m/s²/√Hz) | B (m/s²) | K (m/s²·√Hz) | χ²/dof |\n|---|---|---|---|---|---|";
    six_position(&dir, table_head)?;
    unrepaired_trial(&dir, table_head)?;

    // Start-up runs: each, then pooled.
    let mut runs = start_up_runs(&dir)?;
    let mut pooled = join_records(&runs.records);
    let report = analyze(
        &mut pooled,
        "60 start-up runs pooled",
        &Options {
            repair: None, // already repaired run by run
            ..options()
        },
    )?;
    println!(
        "\n## Start-up runs (60 x 60 s), pooled as {} segments\n\n{table_head}",
        report.timing.segments.len()
    );
    print_fits("pooled", &report);
    if let Some(png) = std::env::args().nth(2) {
        noise::plot::write_png(Path::new(&png), "60 start-up runs pooled", &report.channels)?;
    }
    print_start_up(&report, &mut runs);
    Ok(())
}
