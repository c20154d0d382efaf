//! PNG plots of a diagnosis: held-out residuals against each candidate's regressor (elapsed
//! time, die temperature, specific force along the axis, orientation class), histograms of the
//! samples' deviations from their block means (raw and torn-read repaired, log scale) and of
//! the standardized held-out residuals. Residuals are plotted in mg (1e-3 of the local g), with
//! their means in 24 bins along the regressor drawn as lines.

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use super::{Diagnosis, ResidualPoint};
use crate::plots::{AXIS_COLOURS, PlotError, err, register_font};

const GREY: RGBColor = RGBColor(150, 150, 150);

/// A regressor to plot the residuals against.
struct Regressor {
    file: &'static str,
    label: &'static str,
    /// The x value of a point on an axis (None: not plotted).
    x: fn(&ResidualPoint, usize) -> Option<f64>,
}

const REGRESSORS: [Regressor; 4] = [
    Regressor {
        file: "residuals_vs_time.png",
        label: "elapsed time since the time origin (s)",
        x: |p, _| p.t_s,
    },
    Regressor {
        file: "residuals_vs_temperature.png",
        label: "die temperature (degC)",
        x: |p, _| p.temp_c,
    },
    Regressor {
        file: "residuals_vs_specific_force.png",
        label: "specific force along the axis (g)",
        x: |p, axis| Some(p.direction[axis]),
    },
    Regressor {
        file: "residuals_vs_orientation.png",
        label: "orientation class (0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z; sessions side by side)",
        x: |p, _| Some(p.class as f64 + 0.08 * (p.session % 5) as f64 - 0.16),
    },
];

/// Writes every plot into `dir` (created if needed) and returns the files written.
pub fn write_all(dir: &Path, d: &Diagnosis) -> Result<Vec<PathBuf>, PlotError> {
    mems_files::create_dir(dir, Some("--plot-dir")).map_err(|e| PlotError {
        path: dir.display().to_string(),
        message: e.io.to_string(),
    })?;
    let mut written = Vec::new();
    for r in &REGRESSORS {
        let has = d.baseline_points.iter().any(|p| (r.x)(p, 0).is_some());
        if !has {
            continue;
        }
        let path = dir.join(r.file);
        residual_scatter(&path, d, r)?;
        written.push(path);
    }
    let path = dir.join("histogram_standardized.png");
    standardized_histogram(&path, d)?;
    written.push(path);
    if d.histogram.is_some() {
        let path = dir.join("histogram_samples.png");
        sample_histogram(&path, d)?;
        written.push(path);
    }
    Ok(written)
}

/// Number of residual axes (1 for the label-free magnitude residual).
fn axes(d: &Diagnosis) -> usize {
    if d.kind == super::BaselineKind::LabelFree {
        1
    } else {
        3
    }
}

fn residual_scatter(path: &Path, d: &Diagnosis, r: &Regressor) -> Result<(), PlotError> {
    register_font();
    let e = err(path);
    let n_axes = axes(d);
    let out = mems_files::OutputPath::create(path, None, mems_files::Existing::Replace)
        .map_err(|x| e(x.io.to_string()))?;
    let temp = out.temp_path().to_path_buf();
    let root = BitMapBackend::new(&temp, (1200, 330 * n_axes as u32 + 40)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
    let (title, body) = root.split_vertically(40);
    title
        .titled(
            &format!(
                "held-out residuals: {} (grey, binned means black) and {} (colour)",
                d.baseline.model, d.final_model.model
            ),
            ("sans-serif", 20),
        )
        .map_err(|x| e(x.to_string()))?;
    let panels = body.split_evenly((n_axes, 1));
    for (axis, area) in panels.iter().enumerate() {
        let pts = |set: &[ResidualPoint]| -> Vec<(f64, f64)> {
            set.iter()
                .filter_map(|p| {
                    let x = (r.x)(p, axis)?;
                    let y = p.resid_g[axis] * 1e3;
                    (x.is_finite() && y.is_finite()).then_some((x, y))
                })
                .collect()
        };
        let base = pts(&d.baseline_points);
        let fin = pts(&d.final_points);
        let all = base.iter().chain(&fin);
        let (mut x0, mut x1, mut ymax) = (f64::INFINITY, f64::NEG_INFINITY, 1e-6f64);
        for (x, y) in all {
            x0 = x0.min(*x);
            x1 = x1.max(*x);
            ymax = ymax.max(y.abs());
        }
        if !x0.is_finite() {
            continue;
        }
        let pad = ((x1 - x0) * 0.03).max(1e-3);
        let name = if n_axes == 1 {
            "magnitude".to_string()
        } else {
            ["x", "y", "z"][axis].to_string()
        };
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .caption(format!("{name} axis"), ("sans-serif", 16))
            .build_cartesian_2d(x0 - pad..x1 + pad, -ymax * 1.1..ymax * 1.1)
            .map_err(|x| e(x.to_string()))?;
        chart
            .configure_mesh()
            .x_desc(r.label)
            .y_desc("residual (mg)")
            .draw()
            .map_err(|x| e(x.to_string()))?;
        chart
            .draw_series(base.iter().map(|&p| Circle::new(p, 2, GREY.filled())))
            .map_err(|x| e(x.to_string()))?;
        let colour = AXIS_COLOURS[axis];
        chart
            .draw_series(
                fin.iter()
                    .map(|&p| Circle::new(p, 2, colour.mix(0.5).filled())),
            )
            .map_err(|x| e(x.to_string()))?;
        // Binned means show structure smaller than the scatter.
        for (points, style) in [
            (&base, BLACK.stroke_width(2)),
            (&fin, colour.stroke_width(3)),
        ] {
            chart
                .draw_series(LineSeries::new(binned_means(points, x0, x1), style))
                .map_err(|x| e(x.to_string()))?;
        }
    }
    root.present().map_err(|x| e(x.to_string()))?;
    out.commit().map_err(|x| e(x.io.to_string()))
}

/// Means of `points` (x, y) in 24 equal bins of x over `[x0, x1]` (empty bins skipped), at the
/// bins' mean x.
fn binned_means(points: &[(f64, f64)], x0: f64, x1: f64) -> Vec<(f64, f64)> {
    const BINS: usize = 24;
    let width = ((x1 - x0) / BINS as f64).max(f64::MIN_POSITIVE);
    let mut acc = [(0.0, 0.0, 0usize); BINS];
    for &(x, y) in points {
        let b = (((x - x0) / width) as usize).min(BINS - 1);
        acc[b].0 += x;
        acc[b].1 += y;
        acc[b].2 += 1;
    }
    acc.iter()
        .filter(|a| a.2 > 0)
        .map(|a| (a.0 / a.2 as f64, a.1 / a.2 as f64))
        .collect()
}

/// The standardized histogram's range (residuals beyond it are clamped to its ends) and bins.
const Z_LIM: f64 = 8.0;
const Z_BINS: usize = 64;

/// Density of the standardized residuals `r / sigma` of every axis in `set`, per bin of
/// [`Z_BINS`] over +-[`Z_LIM`].
fn standardized_density(set: &[ResidualPoint]) -> Vec<f64> {
    let mut h = vec![0.0; Z_BINS];
    let mut n = 0;
    for p in set {
        for i in 0..3 {
            let z = p.resid_g[i] / p.sigma_g[i];
            if !z.is_finite() {
                continue;
            }
            n += 1;
            let b =
                ((z.clamp(-Z_LIM, Z_LIM - 1e-9) + Z_LIM) / (2.0 * Z_LIM) * Z_BINS as f64) as usize;
            h[b] += 1.0;
        }
    }
    let width = 2.0 * Z_LIM / Z_BINS as f64;
    h.into_iter()
        .map(|c| c / (n.max(1) as f64 * width))
        .collect()
}

/// The standard normal density over +-[`Z_LIM`], 401 points.
fn standard_normal() -> impl Iterator<Item = (f64, f64)> {
    (0..=400).map(|k| {
        let x = -Z_LIM + 2.0 * Z_LIM * k as f64 / 400.0;
        (
            x,
            (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt(),
        )
    })
}

fn standardized_histogram(path: &Path, d: &Diagnosis) -> Result<(), PlotError> {
    register_font();
    let e = err(path);
    let out = mems_files::OutputPath::create(path, None, mems_files::Existing::Replace)
        .map_err(|x| e(x.io.to_string()))?;
    let temp = out.temp_path().to_path_buf();
    let root = BitMapBackend::new(&temp, (900, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
    let hb = standardized_density(&d.baseline_points);
    let hf = standardized_density(&d.final_points);
    let top = hb.iter().chain(&hf).fold(0.45f64, |m, v| m.max(*v)) * 1.1;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "standardized held-out residuals r / sigma (clamped at +-8)",
            ("sans-serif", 20),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(-Z_LIM..Z_LIM, 0.0..top)
        .map_err(|x| e(x.to_string()))?;
    chart
        .configure_mesh()
        .x_desc("r / sigma")
        .y_desc("density")
        .draw()
        .map_err(|x| e(x.to_string()))?;
    let width = 2.0 * Z_LIM / Z_BINS as f64;
    for (h, colour, label) in [
        (&hb, GREY, d.baseline.model.as_str()),
        (&hf, RGBColor(40, 70, 200), d.final_model.model.as_str()),
    ] {
        chart
            .draw_series(LineSeries::new(
                h.iter().enumerate().flat_map(|(k, v)| {
                    let x = -Z_LIM + k as f64 * width;
                    [(x, *v), (x + width, *v)]
                }),
                colour.stroke_width(2),
            ))
            .map_err(|x| e(x.to_string()))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 15, y)], colour.stroke_width(2))
            });
    }
    chart
        .draw_series(LineSeries::new(standard_normal(), BLACK))
        .map_err(|x| e(x.to_string()))?
        .label("white noise: N(0, 1)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 15, y)], BLACK));
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()
        .map_err(|x| e(x.to_string()))?;
    root.present().map_err(|x| e(x.to_string()))?;
    out.commit().map_err(|x| e(x.io.to_string()))
}

fn sample_histogram(path: &Path, d: &Diagnosis) -> Result<(), PlotError> {
    let Some(h) = &d.histogram else {
        return Ok(());
    };
    register_font();
    let e = err(path);
    let out = mems_files::OutputPath::create(path, None, mems_files::Existing::Replace)
        .map_err(|x| e(x.io.to_string()))?;
    let temp = out.temp_path().to_path_buf();
    let root = BitMapBackend::new(&temp, (1500, 480)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
    let panels = root.split_evenly((1, 3));
    let end = h.start_counts + h.bin_counts * h.raw[0].len() as f64;
    for (axis, area) in panels.iter().enumerate() {
        let top = h.raw[axis]
            .iter()
            .chain(&h.repaired[axis])
            .fold(1u64, |m, v| m.max(*v)) as f64
            * 2.0;
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("{} axis: samples minus block mean", ["x", "y", "z"][axis]),
                ("sans-serif", 18),
            )
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(h.start_counts..end, (0.5f64..top).log_scale())
            .map_err(|x| e(x.to_string()))?;
        chart
            .configure_mesh()
            .x_desc("counts (16384 per g)")
            .y_desc("samples")
            .draw()
            .map_err(|x| e(x.to_string()))?;
        for (counts, colour, label) in [
            (&h.raw[axis], RGBColor(200, 40, 40), "as recorded"),
            (
                &h.repaired[axis],
                RGBColor(40, 70, 200),
                "torn reads repaired",
            ),
        ] {
            chart
                .draw_series(LineSeries::new(
                    counts.iter().enumerate().flat_map(|(k, c)| {
                        let x = h.start_counts + k as f64 * h.bin_counts;
                        let y = (*c as f64).max(0.5);
                        [(x, y), (x + h.bin_counts, y)]
                    }),
                    colour.stroke_width(2),
                ))
                .map_err(|x| e(x.to_string()))?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 15, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|x| e(x.to_string()))?;
    }
    root.present().map_err(|x| e(x.to_string()))?;
    out.commit().map_err(|x| e(x.io.to_string()))
}
