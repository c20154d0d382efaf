//! PNG plot of the Allan deviation per axis, with 1-sigma error bars and the fitted model.
//!
//! Text needs a font and plotters is built without system-font support: DejaVu Sans (from
//! the `dejavu` crate, embedded in the binary) is registered as plotters' `sans-serif` once.

use std::path::Path;
use std::sync::OnceLock;

use anyhow::{Context, Result, anyhow};
use plotters::prelude::*;
use plotters::style::{FontStyle, register_font};

use crate::analysis::ChannelReport;
use crate::fit::{FitPoint, ModelFit, Term, model_avar};
use crate::series::{AXES, Sensor};

/// Colours of the x, y, z axes.
const COLOURS: [RGBColor; 3] = [
    RGBColor(200, 30, 30),
    RGBColor(20, 140, 40),
    RGBColor(30, 60, 200),
];

/// Size of the picture per sensor panel, pixels.
const PANEL: (u32, u32) = (1000, 620);

fn ensure_font() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    if ok {
        Ok(())
    } else {
        Err(anyhow!("the embedded DejaVu Sans font could not be loaded"))
    }
}

/// A short label of a term for the legend, e.g. `N 2.10e-3±1.2e-5`.
fn term_label(symbol: &str, term: &Term) -> String {
    match term {
        Term::Resolved { value, sigma } => format!("{symbol} {value:.2e}±{sigma:.1e}"),
        Term::Unresolved { upper_limit, .. } => format!("{symbol} <{upper_limit:.1e}"),
    }
}

fn legend(axis: usize, fit: &ModelFit) -> String {
    format!(
        "{}: {}  {}  {}",
        AXES[axis],
        term_label("N", &fit.white),
        term_label("B", &fit.bias_instability),
        term_label("K", &fit.random_walk)
    )
}

/// Draws every channel's Allan deviation (one panel per sensor, axes in colour) with error
/// bars and the fitted model, and writes the PNG to `path`.
pub fn write_png(path: &Path, title: &str, channels: &[ChannelReport]) -> Result<()> {
    ensure_font()?;
    let sensors: Vec<Sensor> = [Sensor::Accel, Sensor::Gyro]
        .into_iter()
        .filter(|s| channels.iter().any(|c| c.sensor == *s))
        .collect();
    if sensors.is_empty() {
        return Err(anyhow!("nothing to plot"));
    }
    let height = PANEL.1 * sensors.len() as u32;
    let out = mems_files::OutputPath::create(path, None, mems_files::Existing::Replace)?;
    let temp = out.temp_path().to_path_buf();
    let root = BitMapBackend::new(&temp, (PANEL.0, height)).into_drawing_area();
    let draw_error = |e: &dyn std::fmt::Display| anyhow!("drawing {}: {e}", path.display());
    root.fill(&WHITE).map_err(|e| draw_error(&e))?;
    let panels = root.split_evenly((sensors.len(), 1));
    for (panel, &sensor) in panels.iter().zip(&sensors) {
        let mine: Vec<&ChannelReport> = channels.iter().filter(|c| c.sensor == sensor).collect();
        let points = mine.iter().flat_map(|c| c.fit.points.iter());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for p in points {
            x0 = x0.min(p.tau_s);
            x1 = x1.max(p.tau_s);
            y0 = y0.min(p.adev_low.min(p.model_adev));
            y1 = y1.max(p.adev_high.max(p.model_adev));
        }
        let (x0, x1, y0, y1) = (x0 / 1.5, x1 * 1.5, y0 / 1.5, y1 * 1.5);
        let caption = format!(
            "{title}: {}",
            match sensor {
                Sensor::Accel => "accelerometer",
                Sensor::Gyro => "gyroscope",
            }
        );
        let mut chart = ChartBuilder::on(panel)
            .caption(caption, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| draw_error(&e))?;
        chart
            .configure_mesh()
            .x_desc("cluster time tau (s)")
            .y_desc(format!("Allan deviation ({})", sensor.unit()))
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .draw()
            .map_err(|e| draw_error(&e))?;
        for channel in &mine {
            let colour = COLOURS[channel.axis];
            draw_channel(&mut chart, &channel.fit.points, colour).map_err(|e| draw_error(&e))?;
            let p = channel.fit.coefficients;
            let curve = (0..=200).map(|i| {
                let tau = x0 * (x1 / x0).powf(f64::from(i) / 200.0);
                (tau, model_avar(&p, tau).sqrt())
            });
            chart
                .draw_series(LineSeries::new(
                    curve.filter(|&(_, y)| y >= y0 && y <= y1),
                    colour.stroke_width(2),
                ))
                .map_err(|e| draw_error(&e))?
                .label(legend(channel.axis, &channel.fit))
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| draw_error(&e))?;
    }
    root.present()
        .map_err(|e| draw_error(&e))
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(out.commit()?)
}

/// Points with vertical 1-sigma error bars (and caps).
fn draw_channel<DB: DrawingBackend>(
    chart: &mut ChartContext<
        '_,
        DB,
        Cartesian2d<
            plotters::coord::combinators::LogCoord<f64>,
            plotters::coord::combinators::LogCoord<f64>,
        >,
    >,
    points: &[FitPoint],
    colour: RGBColor,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart.draw_series(
        points
            .iter()
            .map(|p| Circle::new((p.tau_s, p.adev), 3, colour.filled())),
    )?;
    chart.draw_series(
        points
            .iter()
            .map(|p| PathElement::new(vec![(p.tau_s, p.adev_low), (p.tau_s, p.adev_high)], colour)),
    )?;
    for end in [|p: &FitPoint| p.adev_low, |p: &FitPoint| p.adev_high] {
        chart.draw_series(points.iter().map(|p| {
            PathElement::new(
                vec![(p.tau_s / 1.06, end(p)), (p.tau_s * 1.06, end(p))],
                colour,
            )
        }))?;
    }
    Ok(())
}
