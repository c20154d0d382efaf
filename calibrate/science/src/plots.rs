//! PNG plots: per-pose residuals of a fit, and displacement over time per method of
//! `mems-eval static` (the diagnosis's plots are in [`crate::diagnose::plots`]).

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;

use crate::static_eval::StaticEvalReport;

/// Registers DejaVu Sans as plotters' "sans-serif" (the `ab_glyph` backend has no system fonts).
pub(crate) fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .unwrap_or_else(|_| panic!("the embedded DejaVu Sans font is valid"));
    });
}

/// Why a plot could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{path}: cannot draw the plot: {message}")]
pub struct PlotError {
    /// The output file.
    pub path: String,
    /// The drawing backend's message.
    pub message: String,
}

pub(crate) fn err(path: &Path) -> impl Fn(String) -> PlotError + '_ {
    move |message| PlotError {
        path: path.display().to_string(),
        message,
    }
}

pub(crate) const AXIS_COLOURS: [RGBColor; 3] = [
    RGBColor(200, 40, 40),
    RGBColor(40, 140, 40),
    RGBColor(40, 70, 200),
];

/// Bar chart of per-pose residuals (g in, plotted in mg), one bar per axis and pose.
pub fn plot_pose_residuals(
    path: &Path,
    title: &str,
    residuals_g: &[[f64; 3]],
) -> Result<(), PlotError> {
    register_font();
    let e = err(path);
    let out = mems_files::OutputPath::create(path, None, mems_files::Existing::Replace)
        .map_err(|x| e(x.io.to_string()))?;
    let temp = out.temp_path().to_path_buf();
    let root = BitMapBackend::new(&temp, (900, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
    let max = residuals_g
        .iter()
        .flatten()
        .fold(1e-6f64, |m, r| m.max(r.abs()))
        * 1000.0
        * 1.15;
    let n = residuals_g.len().max(1);
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..n as f64, -max..max)
        .map_err(|x| e(x.to_string()))?;
    chart
        .configure_mesh()
        .x_desc("pose")
        .y_desc("residual (mg)")
        .x_labels(n + 1)
        .x_label_formatter(&|x| {
            let k = x.round() as usize;
            if k < n {
                format!("{}", k + 1)
            } else {
                String::new()
            }
        })
        .draw()
        .map_err(|x| e(x.to_string()))?;
    for axis in 0..3 {
        let colour = AXIS_COLOURS[axis];
        chart
            .draw_series(residuals_g.iter().enumerate().map(|(k, r)| {
                let x0 = k as f64 + 0.15 + 0.23 * axis as f64;
                Rectangle::new([(x0, 0.0), (x0 + 0.2, r[axis] * 1000.0)], colour.filled())
            }))
            .map_err(|x| e(x.to_string()))?
            .label(["x", "y", "z"][axis])
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 10, y + 5)], colour.filled()));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()
        .map_err(|x| e(x.to_string()))?;
    root.present().map_err(|x| e(x.to_string()))?;
    out.commit().map_err(|x| e(x.io.to_string()))
}

/// Displacement over time of each method and axis (rows: thesis_full, best; columns: x, y, z),
/// every window overlaid, with the method's final +-1-sigma marked at the end.
pub fn plot_static_displacement(path: &Path, report: &StaticEvalReport) -> Result<(), PlotError> {
    register_font();
    let e = err(path);
    let out = mems_files::OutputPath::create(path, None, mems_files::Existing::Replace)
        .map_err(|x| e(x.io.to_string()))?;
    let temp = out.temp_path().to_path_buf();
    let root = BitMapBackend::new(&temp, (1500, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
    let panels = root.split_evenly((2, 3));
    for (p, area) in panels.iter().enumerate() {
        let (row, axis) = (p / 3, p % 3);
        let method = |w: &crate::static_eval::WindowResult| {
            if row == 0 {
                w.thesis_full.clone()
            } else {
                w.best.clone()
            }
        };
        let name = if row == 0 { "thesis_full" } else { "best" };
        let t_max = report
            .windows
            .iter()
            .flat_map(|w| method(w).trajectory.last().map(|p| p.0))
            .fold(1.0, f64::max);
        let y_max = report
            .windows
            .iter()
            .map(|w| {
                let m = method(w);
                let traj = m
                    .trajectory
                    .iter()
                    .fold(0.0f64, |acc, p| acc.max(p.1[axis].abs()));
                traj.max(m.d[axis].abs() + m.sigma[axis])
            })
            .fold(1e-3, f64::max)
            * 1.1;
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("{name}: {} displacement", ["x", "y", "z"][axis]),
                ("sans-serif", 18),
            )
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(55)
            .build_cartesian_2d(0f64..t_max * 1.02, -y_max..y_max)
            .map_err(|x| e(x.to_string()))?;
        chart
            .configure_mesh()
            .x_desc("time since dead reckoning began (s)")
            .y_desc("m")
            .draw()
            .map_err(|x| e(x.to_string()))?;
        for w in &report.windows {
            let m = method(w);
            chart
                .draw_series(LineSeries::new(
                    m.trajectory.iter().map(|p| (p.0, p.1[axis])),
                    AXIS_COLOURS[axis],
                ))
                .map_err(|x| e(x.to_string()))?;
            let t_end = m.trajectory.last().map_or(0.0, |p| p.0);
            chart
                .draw_series(std::iter::once(PathElement::new(
                    vec![
                        (t_end, m.d[axis] - m.sigma[axis]),
                        (t_end, m.d[axis] + m.sigma[axis]),
                    ],
                    BLACK.stroke_width(3),
                )))
                .map_err(|x| e(x.to_string()))?;
        }
    }
    root.present().map_err(|x| e(x.to_string()))?;
    out.commit().map_err(|x| e(x.io.to_string()))
}
