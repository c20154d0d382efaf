//! The track figure: the horizontal path (navigation x against y, one metre the same length on
//! both axes), 1-sigma ellipses of the live position every few seconds, the revised path, and
//! the ground truth where the recording carries one. The axes cover the live path and the
//! truth; the revised path and the ellipses are clipped to the plot area ([`clip`]).

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;

use anyhow::{Result, anyhow};
use ipc_types::OdometryState;
use plotters::prelude::*;
use recording::Truth;

use crate::{AXIS_COLOURS, REVISED_COLOUR, SIZE, is_revision, register_font, seconds};

/// Colour of the live path and its 1-sigma ellipses.
pub const TRACK_COLOUR: RGBColor = AXIS_COLOURS[2];
/// Colour of the ground truth's path.
pub const TRUTH_COLOUR: RGBColor = RGBColor(60, 60, 60);
/// The most 1-sigma ellipses drawn: one every `max(2 s, duration / ELLIPSES)` of sample time.
pub const ELLIPSES: f64 = 25.0;
/// Points kept per path.
const MAX_POINTS: usize = 4000;

/// A horizontal point, m.
type Point = (f64, f64);

/// The horizontal position of `s`.
fn xy(s: &OdometryState) -> Point {
    (s.position_m[0], s.position_m[1])
}

/// `path` reduced to at most about `max_points` points, evenly spaced in index.
fn thin(path: &[Point], max_points: usize) -> Vec<Point> {
    let step = path.len().div_ceil(max_points.max(1)).max(1);
    let mut out: Vec<Point> = path.iter().step_by(step).copied().collect();
    if let Some(&last) = path.last()
        && out.last() != Some(&last)
    {
        out.push(last);
    }
    out
}

/// The pieces of `path` inside the rectangle `x` by `y`: each segment is cut at the edges
/// (Liang-Barsky), and a path that leaves and comes back becomes two pieces. plotters draws a
/// line wherever its points map to, over neighbouring panels and labels, hence this.
pub fn clip(path: &[Point], x: &Range<f64>, y: &Range<f64>) -> Vec<Vec<Point>> {
    let mut pieces: Vec<Vec<Point>> = Vec::new();
    let mut open = false;
    for w in path.windows(2) {
        let Some((a, b)) = clip_segment(w[0], w[1], x, y) else {
            open = false;
            continue;
        };
        match pieces.last_mut() {
            Some(piece) if open && piece.last() == Some(&a) => piece.push(b),
            _ => pieces.push(vec![a, b]),
        }
        // The piece goes on only if the segment ended inside (not cut at its end).
        open = b == w[1];
    }
    pieces
}

/// The part of segment `a`-`b` inside the rectangle, if any.
fn clip_segment(a: Point, b: Point, x: &Range<f64>, y: &Range<f64>) -> Option<(Point, Point)> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0_f64, 1.0_f64);
    for (p, q) in [
        (-dx, a.0 - x.start),
        (dx, x.end - a.0),
        (-dy, a.1 - y.start),
        (dy, y.end - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else if p < 0.0 {
            t0 = t0.max(q / p);
        } else {
            t1 = t1.min(q / p);
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| {
        if t == 0.0 {
            a
        } else if t == 1.0 {
            b
        } else {
            (a.0 + t * dx, a.1 + t * dy)
        }
    };
    Some((at(t0), at(t1)))
}

/// The 1-sigma ellipse of `s`'s horizontal position (the state carries a sigma per axis, so
/// its axes are the frame's), as a closed polygon.
fn ellipse(s: &OdometryState) -> Vec<Point> {
    let (cx, cy) = xy(s);
    let (sx, sy) = (s.position_sigma_m[0], s.position_sigma_m[1]);
    (0..=48)
        .map(|k| {
            let a = f64::from(k) * std::f64::consts::TAU / 48.0;
            (cx + sx * a.cos(), cy + sy * a.sin())
        })
        .collect()
}

/// The live states at which an ellipse is drawn: the first, then one per period.
fn ellipse_states<'a>(live: &[&'a OdometryState], t0_ns: u64) -> Vec<&'a OdometryState> {
    let end_s = live
        .last()
        .map_or(0.0, |s| seconds(s.stamps.sample_ns, t0_ns));
    let period_s = (end_s / ELLIPSES).max(2.0);
    let mut next = f64::NEG_INFINITY;
    let mut chosen = Vec::new();
    for s in live {
        let t = seconds(s.stamps.sample_ns, t0_ns);
        if t >= next {
            chosen.push(*s);
            next = t + period_s;
        }
    }
    chosen
}

/// Maps truth positions into the odometry's navigation frame: origin and heading fixed at
/// alignment, as the odometry's own frame is (the rotation is the yaw between the two
/// attitudes at the first aligned state).
fn truth_in_our_frame(truth: &[Truth], first_aligned: &OdometryState) -> Vec<Point> {
    let t_ns = first_aligned.stamps.sample_ns;
    let Some(at) = truth.iter().find(|t| t.t_ns >= t_ns) else {
        return Vec::new();
    };
    // q = q_ours * conj(q_truth); its yaw rotates truth-frame vectors into ours.
    let [w1, x1, y1, z1] = first_aligned.attitude_wxyz;
    let [w2, x2, y2, z2] = at.attitude_wxyz;
    let (x2, y2, z2) = (-x2, -y2, -z2);
    let w = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2;
    let x = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2;
    let y = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2;
    let z = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2;
    let yaw = (2.0 * (x * y + w * z)).atan2(1.0 - 2.0 * (y * y + z * z));
    let (sin, cos) = yaw.sin_cos();
    let [ox, oy, _] = at.position_m;
    truth
        .iter()
        .filter(|t| t.t_ns >= t_ns)
        .map(|t| {
            let (dx, dy) = (t.position_m[0] - ox, t.position_m[1] - oy);
            (cos * dx - sin * dy, sin * dx + cos * dy)
        })
        .collect()
}

/// Ranges covering `points`, padded by 5 %, widened so that a metre is as long on both axes
/// in a plot area of `w` by `h` pixels.
fn equal_ranges<'a>(
    points: impl Iterator<Item = &'a Point>,
    (w, h): (u32, u32),
) -> (Range<f64>, Range<f64>) {
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in points.filter(|p| p.0.is_finite() && p.1.is_finite()) {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    if x0 > x1 {
        (x0, x1, y0, y1) = (-1.0, 1.0, -1.0, 1.0);
    }
    let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
    // Metres per pixel: enough for both spans (1 m at least).
    let m_per_px = ((x1 - x0) / f64::from(w))
        .max((y1 - y0) / f64::from(h))
        .max(1.0 / f64::from(w.min(h)))
        * 1.1;
    let (hw, hh) = (m_per_px * f64::from(w) / 2.0, m_per_px * f64::from(h) / 2.0);
    ((cx - hw)..(cx + hw), (cy - hh)..(cy + hh))
}

/// A chart of metres (or seconds) against metres.
pub(crate) type Chart<'a> = ChartContext<
    'a,
    BitMapBackend<'a>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;
/// What drawing on a PNG can fail with.
pub(crate) type DrawError =
    DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>;

/// Draws each piece of `path` inside the chart's axes ([`clip`]) in `style`, labelled (in the
/// legend) once with `label` unless it is empty.
pub(crate) fn draw_path(
    chart: &mut Chart<'_>,
    path: &[Point],
    style: ShapeStyle,
    label: &str,
) -> Result<(), DrawError> {
    let (x, y) = (chart.x_range(), chart.y_range());
    for (k, piece) in clip(path, &x, &y).into_iter().enumerate() {
        let series = chart.draw_series(LineSeries::new(piece, style))?;
        if k == 0 && !label.is_empty() {
            series
                .label(label)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], style));
        }
    }
    Ok(())
}

/// What the track figure draws.
pub struct Track<'a> {
    /// Live (not revised) states in time order.
    pub live: Vec<&'a OdometryState>,
    /// The last revision of each revised sample time, in time order.
    pub revised: Vec<&'a OdometryState>,
    /// The truth in the odometry's frame (empty without one).
    pub truth: Vec<Point>,
}

impl<'a> Track<'a> {
    /// The track of `odometry` (revisions included) and `truth` (the recording's, maybe
    /// empty); `None` without an aligned state (no horizontal path yet).
    pub fn new(odometry: &'a [OdometryState], truth: &[Truth]) -> Option<Self> {
        let aligned = |s: &&OdometryState| s.flags & ipc_types::odometry_flags::ALIGNED != 0;
        let live: Vec<&OdometryState> = odometry
            .iter()
            .filter(|s| !is_revision(s))
            .filter(aligned)
            .collect();
        let first = *live.first()?;
        // A sample time may be revised more than once: its last revision is the best estimate
        // (earlier ones drawn with it would zigzag between passes).
        let revised: BTreeMap<u64, &OdometryState> = odometry
            .iter()
            .filter(|s| is_revision(s))
            .map(|s| (s.stamps.sample_ns, s))
            .collect();
        let revised = revised.into_values().collect();
        Some(Self {
            live,
            revised,
            truth: truth_in_our_frame(truth, first),
        })
    }

    /// Writes the figure to `path`; times of the ellipses are counted from `t0_ns`.
    pub fn draw(&self, path: &Path, t0_ns: u64) -> Result<()> {
        register_font();
        let e = |x: String| anyhow!("{}: cannot draw: {x}", path.display());
        let root = BitMapBackend::new(path, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
        let root = root
            .titled(
                "Track: horizontal position with its 1-sigma ellipses",
                ("sans-serif", 26),
            )
            .map_err(|x| e(x.to_string()))?;
        self.draw_chart(&root, t0_ns)
            .map_err(|x| e(x.to_string()))?;
        root.present().map_err(|x| e(x.to_string()))?;
        Ok(())
    }

    fn builder<'b, 'c>(
        area: &'b DrawingArea<BitMapBackend<'c>, plotters::coord::Shift>,
    ) -> ChartBuilder<'b, 'c, BitMapBackend<'c>> {
        let mut builder = ChartBuilder::on(area);
        builder
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(80);
        builder
    }

    fn draw_chart(
        &self,
        area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
        t0_ns: u64,
    ) -> Result<(), DrawError> {
        let live: Vec<Point> = thin(
            &self.live.iter().map(|s| xy(s)).collect::<Vec<_>>(),
            MAX_POINTS,
        );
        let revised: Vec<Point> = thin(
            &self.revised.iter().map(|s| xy(s)).collect::<Vec<_>>(),
            MAX_POINTS,
        );
        let truth = thin(&self.truth, MAX_POINTS);
        // The plot area's size, from a chart built the same way (building draws nothing).
        let probe = Self::builder(area).build_cartesian_2d(0.0..1.0, 0.0..1.0)?;
        let pixels = probe.plotting_area().dim_in_pixel();
        let (x, y) = equal_ranges(live.iter().chain(&truth), pixels);
        let mut chart = Self::builder(area).build_cartesian_2d(x, y)?;
        chart
            .configure_mesh()
            .x_desc("x (navigation frame), m")
            .y_desc("y, m")
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 16))
            .draw()?;
        let ellipse_style = TRACK_COLOUR.mix(0.5).stroke_width(1);
        for (k, s) in ellipse_states(&self.live, t0_ns).into_iter().enumerate() {
            let label = if k == 0 { "1-sigma" } else { "" };
            draw_path(&mut chart, &ellipse(s), ellipse_style, label)?;
        }
        if !truth.is_empty() {
            draw_path(&mut chart, &truth, TRUTH_COLOUR.stroke_width(2), "truth")?;
        }
        draw_path(&mut chart, &live, TRACK_COLOUR.stroke_width(2), "live")?;
        if !revised.is_empty() {
            draw_path(
                &mut chart,
                &revised,
                REVISED_COLOUR.stroke_width(2),
                "revised",
            )?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 15))
            .draw()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_path_that_leaves_the_box_is_cut_at_its_edges() {
        let (x, y) = (0.0..10.0, 0.0..10.0);
        let path = [
            (1.0, 1.0),
            (5.0, 1.0),
            (15.0, 1.0),
            (15.0, 5.0),
            (5.0, 5.0),
            (5.0, 8.0),
        ];
        assert_eq!(
            clip(&path, &x, &y),
            vec![
                vec![(1.0, 1.0), (5.0, 1.0), (10.0, 1.0)],
                vec![(10.0, 5.0), (5.0, 5.0), (5.0, 8.0)],
            ]
        );
        assert!(clip(&[(20.0, 20.0), (30.0, 20.0)], &x, &y).is_empty());
    }

    #[test]
    fn ranges_keep_a_metre_the_same_on_both_axes() {
        let points = [(0.0, 0.0), (100.0, 10.0)];
        let (x, y) = equal_ranges(points.iter(), (1000, 500));
        let per_px = |r: &Range<f64>, px: f64| (r.end - r.start) / px;
        assert!((per_px(&x, 1000.0) - per_px(&y, 500.0)).abs() < 1e-9);
        assert!(x.start < 0.0 && x.end > 100.0 && y.start < 0.0 && y.end > 10.0);
    }
}
