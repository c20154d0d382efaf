//! The plots behind `mems-plot`: PNGs of an MCAP recording's acceleration (raw and corrected),
//! zero-state, and position with its 1-sigma band, against time, and its horizontal track
//! (x against y, with 1-sigma ellipses and the truth where the recording has one: [`track`]).
//!
//! Time axes are seconds since the recording's first sample time (`stamps.sample_ns`, ns
//! `CLOCK_MONOTONIC`). Raw specific force is in g and corrected specific force in m/s^2, both in
//! the sensor frame; position is in m in the navigation frame (z up). Series longer than the
//! plot is wide are reduced to each pixel column's minimum and maximum ([`envelope`]), so that
//! spikes stay visible in long recordings.

#![warn(missing_docs)]

pub mod track;

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Once;

use anyhow::{Result, anyhow};
use ipc_types::{CorrectedImuSample, OdometryState, corrected_flags, odometry_flags};
use plotters::coord::Shift;
use plotters::prelude::*;
use recording::mcap::Contents;

/// Width and height of every PNG, pixels.
pub const SIZE: (u32, u32) = (1400, 900);
/// Points kept per series: about two per pixel column of the plot area.
const MAX_POINTS: usize = 2 * SIZE.0 as usize;

/// Colours of the x, y and z axes.
pub const AXIS_COLOURS: [RGBColor; 3] = [
    RGBColor(200, 40, 40),
    RGBColor(30, 140, 30),
    RGBColor(40, 70, 210),
];
/// Colour of revised odometry states.
pub const REVISED_COLOUR: RGBColor = RGBColor(230, 140, 0);
/// Colour of zero-state (rest) intervals.
pub const REST_COLOUR: RGBColor = RGBColor(120, 200, 120);

/// One figure `mems-plot` may write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Figure {
    /// Raw (g) and corrected (m/s^2) specific force per axis.
    Acceleration,
    /// |a|, the detector window's standard deviation, and the rest intervals of the
    /// calibration stage (zero-state) and of the odometry stage (zero-velocity updates).
    ZeroState,
    /// Position per axis with its 1-sigma band; revised states on top.
    Position,
    /// The horizontal path with 1-sigma ellipses, the revised path and the truth ([`track`]).
    Track,
}

impl Figure {
    /// Every figure, in the order they are written.
    pub const ALL: [Figure; 4] = [
        Figure::Acceleration,
        Figure::ZeroState,
        Figure::Position,
        Figure::Track,
    ];

    /// The file name suffix, e.g. `acceleration` in `drive-acceleration.png`.
    pub fn name(self) -> &'static str {
        match self {
            Figure::Acceleration => "acceleration",
            Figure::ZeroState => "zero-state",
            Figure::Position => "position",
            Figure::Track => "track",
        }
    }
}

/// What happened to one figure.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// Written to this file.
    Written(PathBuf),
    /// Not written: the recording lacks its data (the reason says which).
    Skipped(String),
}

/// Registers DejaVu Sans as plotters' "sans-serif" (the `ab_glyph` backend has no system fonts).
fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .unwrap_or_else(|_| panic!("the embedded DejaVu Sans font is valid"));
    });
}

/// Reduces `points` (x increasing) to at most about `max_points`: the x range is cut into
/// `max_points / 2` equal buckets and each keeps its lowest and highest point, in x order.
/// plotters draws every point it is given and has no such reduction, hence this one.
pub fn envelope(points: &[(f64, f64)], max_points: usize) -> Vec<(f64, f64)> {
    let buckets = (max_points / 2).max(1);
    if points.len() <= max_points {
        return points.to_vec();
    }
    let (x0, x1) = (points[0].0, points[points.len() - 1].0);
    let width = (x1 - x0) / buckets as f64;
    let mut out = Vec::with_capacity(2 * buckets);
    let mut i = 0;
    while i < points.len() {
        let bucket = if width > 0.0 {
            (((points[i].0 - x0) / width) as usize).min(buckets - 1)
        } else {
            0
        };
        let (mut lo, mut hi) = (i, i);
        let mut j = i + 1;
        while j < points.len()
            && (width <= 0.0 || (((points[j].0 - x0) / width) as usize).min(buckets - 1) == bucket)
        {
            if points[j].1 < points[lo].1 {
                lo = j;
            }
            if points[j].1 > points[hi].1 {
                hi = j;
            }
            j += 1;
        }
        out.push(points[lo.min(hi)]);
        if lo != hi {
            out.push(points[lo.max(hi)]);
        }
        i = j;
    }
    out
}

/// The time intervals (s) over which `flag` holds, from samples at times `t_s` (increasing); an
/// interval runs from its first flagged sample to the next unflagged one (or the last sample).
pub fn intervals(t_s: &[f64], flag: &[bool]) -> Vec<Range<f64>> {
    let mut out = Vec::new();
    let mut start = None;
    for (&t, &f) in t_s.iter().zip(flag) {
        match (f, start) {
            (true, None) => start = Some(t),
            (false, Some(s)) => {
                out.push(s..t);
                start = None;
            }
            _ => {}
        }
    }
    if let (Some(s), Some(&last)) = (start, t_s.last()) {
        out.push(s..last);
    }
    out
}

/// The y range covering every value, padded by 5 % (a flat series gets +-1).
fn y_range<'a>(values: impl IntoIterator<Item = &'a f64>) -> Range<f64> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for &v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return -1.0..1.0;
    }
    let pad = if hi > lo { 0.05 * (hi - lo) } else { 1.0 };
    (lo - pad)..(hi + pad)
}

/// One line to draw: its label, colour and (t, value) points.
struct Line {
    label: String,
    colour: RGBColor,
    points: Vec<(f64, f64)>,
}

/// A filled band between `lower` and `upper` (same times).
struct Band {
    colour: RGBAColor,
    lower: Vec<(f64, f64)>,
    upper: Vec<(f64, f64)>,
}

/// One panel of a figure.
struct Panel {
    title: String,
    y_label: String,
    lines: Vec<Line>,
    bands: Vec<Band>,
    /// Shaded time intervals (s).
    shade: Vec<Range<f64>>,
}

fn draw_err(path: &Path) -> impl Fn(String) -> anyhow::Error + '_ {
    move |e| anyhow!("{}: cannot draw: {e}", path.display())
}

/// Draws `panels` stacked vertically, sharing the time axis `t_range`.
fn draw_panels(path: &Path, title: &str, t_range: Range<f64>, panels: &[Panel]) -> Result<()> {
    register_font();
    let e = draw_err(path);
    let out = mems_files::OutputPath::create(path, None, mems_files::Existing::Replace)?;
    let temp = out.temp_path().to_path_buf();
    let root = BitMapBackend::new(&temp, SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
    let root = root
        .titled(title, ("sans-serif", 26))
        .map_err(|x| e(x.to_string()))?;
    let areas = root.split_evenly((panels.len(), 1));
    for (area, panel) in areas.iter().zip(panels) {
        draw_panel(area, &t_range, panel).map_err(|x| e(x.to_string()))?;
    }
    root.present().map_err(|x| e(x.to_string()))?;
    Ok(out.commit()?)
}

fn draw_panel(
    area: &DrawingArea<BitMapBackend, Shift>,
    t_range: &Range<f64>,
    panel: &Panel,
) -> Result<(), DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>> {
    let values = panel
        .lines
        .iter()
        .flat_map(|l| l.points.iter().map(|p| &p.1))
        .chain(
            panel
                .bands
                .iter()
                .flat_map(|b| b.lower.iter().chain(&b.upper).map(|p| &p.1)),
        );
    let y = y_range(values);
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(t_range.clone(), y.clone())?;
    chart
        .configure_mesh()
        .x_desc("time since the first sample, s")
        .y_desc(&panel.y_label)
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 16))
        .draw()?;
    for interval in &panel.shade {
        chart.draw_series(std::iter::once(Rectangle::new(
            [(interval.start, y.start), (interval.end, y.end)],
            REST_COLOUR.mix(0.25).filled(),
        )))?;
    }
    for band in &panel.bands {
        let polygon: Vec<(f64, f64)> = band
            .upper
            .iter()
            .copied()
            .chain(band.lower.iter().rev().copied())
            .collect();
        chart.draw_series(std::iter::once(Polygon::new(polygon, band.colour.filled())))?;
    }
    for line in &panel.lines {
        // Clipped to the panel: plotters draws a line wherever its points map to.
        track::draw_path(
            &mut chart,
            &line.points,
            line.colour.stroke_width(2),
            &line.label,
        )?;
    }
    if !panel.lines.is_empty() {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()?;
    }
    Ok(())
}

/// Seconds since `t0_ns`.
fn seconds(t_ns: u64, t0_ns: u64) -> f64 {
    t_ns.saturating_sub(t0_ns) as f64 / 1e9
}

/// One line per axis of `value(sample)`, labelled `name x` etc.
fn axis_lines<T>(
    samples: &[T],
    t0_ns: u64,
    time_ns: impl Fn(&T) -> u64,
    value: impl Fn(&T) -> [f64; 3],
    name: &str,
) -> Vec<Line> {
    (0..3)
        .map(|axis| {
            let points: Vec<(f64, f64)> = samples
                .iter()
                .map(|s| (seconds(time_ns(s), t0_ns), value(s)[axis]))
                .collect();
            Line {
                label: format!("{name} {}", ["x", "y", "z"][axis]),
                colour: AXIS_COLOURS[axis],
                points: envelope(&points, MAX_POINTS),
            }
        })
        .collect()
}

fn acceleration(
    contents: &Contents,
    t0_ns: u64,
    t_range: Range<f64>,
    path: &Path,
) -> Result<Outcome> {
    let mut panels = Vec::new();
    if !contents.raw.is_empty() {
        panels.push(Panel {
            title: "Raw specific force (sensor frame)".into(),
            y_label: "g".into(),
            lines: axis_lines(
                &contents.raw,
                t0_ns,
                |s| s.stamps.sample_ns,
                |s| s.accel_g,
                "raw",
            ),
            bands: vec![],
            shade: vec![],
        });
    }
    if !contents.corrected.is_empty() {
        panels.push(Panel {
            title: "Corrected specific force (sensor frame)".into(),
            y_label: "m/s^2".into(),
            lines: axis_lines(
                &contents.corrected,
                t0_ns,
                |s| s.stamps.sample_ns,
                |s| s.accel_mps2,
                "corrected",
            ),
            bands: vec![],
            shade: vec![],
        });
    }
    if panels.is_empty() {
        return Ok(Outcome::Skipped("no raw or corrected samples".into()));
    }
    draw_panels(path, "Acceleration", t_range, &panels)?;
    Ok(Outcome::Written(path.to_path_buf()))
}

fn zero_state(
    contents: &Contents,
    t0_ns: u64,
    t_range: Range<f64>,
    path: &Path,
) -> Result<Outcome> {
    let corrected: &[CorrectedImuSample] = &contents.corrected;
    if corrected.is_empty() {
        return Ok(Outcome::Skipped(
            "no corrected samples (zero-state flags)".into(),
        ));
    }
    let t: Vec<f64> = corrected
        .iter()
        .map(|s| seconds(s.stamps.sample_ns, t0_ns))
        .collect();
    let at_rest: Vec<bool> = corrected
        .iter()
        .map(|s| s.flags & corrected_flags::ZERO_STATE != 0)
        .collect();
    let rest = intervals(&t, &at_rest);
    let norm: Vec<(f64, f64)> = corrected
        .iter()
        .zip(&t)
        .map(|(s, &t)| (t, s.accel_mps2.iter().map(|a| a * a).sum::<f64>().sqrt()))
        .collect();
    let mut panels = vec![
        Panel {
            title: "|corrected specific force|; green: zero-state (calibration stage)".into(),
            y_label: "m/s^2".into(),
            lines: vec![Line {
                label: "|a|".into(),
                colour: BLACK,
                points: envelope(&norm, MAX_POINTS),
            }],
            bands: vec![],
            shade: rest.clone(),
        },
        Panel {
            title: "Standard deviation over the detector window".into(),
            y_label: "m/s^2".into(),
            lines: axis_lines(
                corrected,
                t0_ns,
                |s| s.stamps.sample_ns,
                |s| s.zs_std_mps2,
                "std",
            ),
            bands: vec![],
            shade: rest,
        },
    ];
    let live: Vec<&OdometryState> = contents
        .odometry
        .iter()
        .filter(|s| !is_revision(s))
        .collect();
    if !live.is_empty() {
        let t: Vec<f64> = live
            .iter()
            .map(|s| seconds(s.stamps.sample_ns, t0_ns))
            .collect();
        let zupt: Vec<bool> = live
            .iter()
            .map(|s| s.flags & odometry_flags::ZERO_VELOCITY != 0)
            .collect();
        let speed: Vec<(f64, f64)> = live
            .iter()
            .zip(&t)
            .map(|(s, &t)| (t, s.velocity_mps.iter().map(|v| v * v).sum::<f64>().sqrt()))
            .collect();
        panels.push(Panel {
            title: "Speed; green: zero-velocity updates (odometry stage)".into(),
            y_label: "m/s".into(),
            lines: vec![Line {
                label: "|v|".into(),
                colour: BLACK,
                points: envelope(&speed, MAX_POINTS),
            }],
            bands: vec![],
            shade: intervals(&t, &zupt),
        });
    }
    draw_panels(path, "Zero-state", t_range, &panels)?;
    Ok(Outcome::Written(path.to_path_buf()))
}

fn is_revision(s: &OdometryState) -> bool {
    s.flags & odometry_flags::REVISION != 0
}

fn position(contents: &Contents, t0_ns: u64, t_range: Range<f64>, path: &Path) -> Result<Outcome> {
    let live: Vec<&OdometryState> = contents
        .odometry
        .iter()
        .filter(|s| !is_revision(s))
        .collect();
    if live.is_empty() {
        return Ok(Outcome::Skipped("no odometry states".into()));
    }
    let mut revised: Vec<&OdometryState> = contents
        .odometry
        .iter()
        .filter(|s| is_revision(s))
        .collect();
    // Revisions arrive after their interval ended; draw them in time order.
    revised.sort_by_key(|s| s.stamps.sample_ns);
    let panels: Vec<Panel> = (0..3)
        .map(|axis| {
            let name = ["x", "y", "z"][axis];
            let point = |s: &&OdometryState, k: f64| {
                (
                    seconds(s.stamps.sample_ns, t0_ns),
                    s.position_m[axis] + k * s.position_sigma_m[axis],
                )
            };
            let line: Vec<(f64, f64)> = live.iter().map(|s| point(s, 0.0)).collect();
            let upper: Vec<(f64, f64)> = live.iter().map(|s| point(s, 1.0)).collect();
            let lower: Vec<(f64, f64)> = live.iter().map(|s| point(s, -1.0)).collect();
            let mut lines = vec![Line {
                label: format!("{name} (live)"),
                colour: AXIS_COLOURS[axis],
                points: envelope(&line, MAX_POINTS),
            }];
            if !revised.is_empty() {
                let points: Vec<(f64, f64)> = revised.iter().map(|s| point(s, 0.0)).collect();
                lines.push(Line {
                    label: format!("{name} (revised)"),
                    colour: REVISED_COLOUR,
                    points: envelope(&points, MAX_POINTS),
                });
            }
            Panel {
                title: format!("Position {name} (navigation frame) with its 1-sigma band"),
                y_label: "m".into(),
                lines,
                bands: vec![Band {
                    colour: AXIS_COLOURS[axis].mix(0.2),
                    upper: band_edge(&upper, MAX_POINTS, f64::max),
                    lower: band_edge(&lower, MAX_POINTS, f64::min),
                }],
                shade: vec![],
            }
        })
        .collect();
    draw_panels(path, "Position", t_range, &panels)?;
    Ok(Outcome::Written(path.to_path_buf()))
}

/// The track figure ([`track::Track`]), if the recording has an aligned state.
fn track(contents: &Contents, t0_ns: u64, path: &Path) -> Result<Outcome> {
    let Some(track) = track::Track::new(&contents.odometry, &contents.truth) else {
        return Ok(Outcome::Skipped("no aligned odometry state".into()));
    };
    track.draw(path, t0_ns)?;
    Ok(Outcome::Written(path.to_path_buf()))
}

/// One band edge reduced to about `max_points`: per bucket the outermost value (`pick` is
/// `f64::max` for the upper edge, `f64::min` for the lower), so that the band never shrinks.
fn band_edge(
    points: &[(f64, f64)],
    max_points: usize,
    pick: fn(f64, f64) -> f64,
) -> Vec<(f64, f64)> {
    if points.len() <= max_points {
        return points.to_vec();
    }
    let per_bucket = points.len().div_ceil(max_points);
    points
        .chunks(per_bucket)
        .map(|c| (c[0].0, c.iter().map(|p| p.1).fold(c[0].1, pick)))
        .collect()
}

/// Writes every [`Figure`] of a recording's `contents` into `out_dir`, named
/// `<stem>-<figure>.png`; figures whose data the recording lacks are skipped. A truncated
/// recording is plotted up to the cut (the caller reports `Contents::truncation`). `done` is
/// called after each figure (`mems-plot`'s progress).
pub fn plot_recording(
    contents: &Contents,
    stem: &str,
    out_dir: &Path,
    mut done: impl FnMut(Figure),
) -> Result<Vec<(Figure, Outcome)>> {
    let first = [
        contents.raw.first().map(|s| s.stamps.sample_ns),
        contents.corrected.first().map(|s| s.stamps.sample_ns),
        contents.odometry.first().map(|s| s.stamps.sample_ns),
    ];
    let last = [
        contents.raw.last().map(|s| s.stamps.sample_ns),
        contents.corrected.last().map(|s| s.stamps.sample_ns),
        contents.odometry.iter().map(|s| s.stamps.sample_ns).max(),
    ];
    let Some(t0_ns) = first.iter().flatten().min().copied() else {
        return Ok(Figure::ALL
            .iter()
            .map(|&f| (f, Outcome::Skipped("the recording holds no samples".into())))
            .collect());
    };
    let t1_ns = last.iter().flatten().max().copied().unwrap_or(t0_ns);
    let end_s = seconds(t1_ns, t0_ns).max(1e-3);
    mems_files::create_dir(out_dir, Some("--out"))?;
    Figure::ALL
        .iter()
        .map(|&figure| {
            let path = out_dir.join(format!("{stem}-{}.png", figure.name()));
            let t_range = 0.0..end_s;
            let outcome = match figure {
                Figure::Acceleration => acceleration(contents, t0_ns, t_range, &path),
                Figure::ZeroState => zero_state(contents, t0_ns, t_range, &path),
                Figure::Position => position(contents, t0_ns, t_range, &path),
                Figure::Track => track(contents, t0_ns, &path),
            }?;
            done(figure);
            Ok((figure, outcome))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_keeps_extremes_in_time_order() {
        // 10 000 points of a slow ramp with one spike up and one down.
        let mut points: Vec<(f64, f64)> =
            (0..10_000).map(|i| (i as f64, i as f64 * 1e-4)).collect();
        points[1234].1 = 50.0;
        points[8765].1 = -50.0;
        let reduced = envelope(&points, 200);
        assert!(reduced.len() <= 200, "{}", reduced.len());
        assert!(reduced.contains(&(1234.0, 50.0)) && reduced.contains(&(8765.0, -50.0)));
        assert!(reduced.windows(2).all(|w| w[0].0 < w[1].0), "x increases");
        assert_eq!(reduced[0], points[0]);
        assert_eq!(*reduced.last().unwrap(), points[9999]);
    }

    #[test]
    fn short_series_are_kept_whole() {
        let points = vec![(0.0, 1.0), (1.0, -1.0), (2.0, 3.0)];
        assert_eq!(envelope(&points, 10), points);
    }

    #[test]
    fn intervals_run_from_first_flagged_to_next_unflagged_sample() {
        let t = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        let f = [false, true, true, false, true, true];
        assert_eq!(intervals(&t, &f), vec![1.0..3.0, 4.0..5.0]);
        assert_eq!(intervals(&t, &[false; 6]), vec![]);
    }

    #[test]
    fn band_edges_never_shrink() {
        let upper: Vec<(f64, f64)> = (0..1000).map(|i| (i as f64, (i % 7) as f64)).collect();
        let reduced = band_edge(&upper, 100, f64::max);
        assert!(reduced.len() <= 100);
        assert!(
            reduced.iter().all(|p| p.1 == 6.0),
            "each bucket of 10 holds a 6"
        );
        let lower = band_edge(&upper, 100, f64::min);
        assert!(lower.iter().all(|p| p.1 == 0.0));
    }
}
