//! Line and bar plots rendered by plotters to an SVG string, for inlining into a report page.
//!
//! The data comes from fits and measurements, so it is taken as it is: non-finite points
//! are skipped (a line breaks there), a log-y plot skips values ≤ 0, and a plot with nothing
//! to draw is an empty frame saying so rather than an error. The SVG's text is drawn by the
//! viewer in its sans-serif font; plotters measures it (legend boxes, label areas) with the
//! DejaVu Sans embedded here, which it needs registered once under its `ab_glyph` feature.

use std::ops::Range;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::element::DashedPathElement;
use plotters::prelude::{
    ChartBuilder, DashedLineSeries, DrawingArea, EmptyElement, IntoDrawingArea, IntoLogRange, LineSeries, PathElement,
    Polygon, Rectangle, SVGBackend, SeriesLabelPosition, Text,
};
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{Color as _, FontStyle, IntoFont, RGBColor, ShapeStyle, TextStyle, register_font};

mod data;

use super::{Color, ReportError, format_number};
use data::{Run, decimate_band, decimate_line, extent, log_range, padded, runs};

/// DejaVu Sans, measured by plotters to lay out text (see `assets/README.md`).
const DEJAVU_SANS: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");
const FONT_FAMILY: &str = "sans-serif";
/// A log-y axis spans at most this many decades below its largest value; smaller values are
/// drawn on the bottom edge. A spectrum's numerical floor would otherwise flatten its peaks.
pub const LOG_Y_MAX_DECADES: f64 = 9.0;

const TITLE_PX: u32 = 18;
const AXIS_LABEL_PX: u32 = 15;
const TICK_PX: u32 = 13;
const LEGEND_PX: u32 = 13;
const MARKER_PX: u32 = 11;

/// One line of a [`LinePlot`]. `x` and `y` pair up to the shorter of the two.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub label: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub color: Color,
    pub dashed: bool,
}

impl Series {
    pub fn new(label: impl Into<String>, x: Vec<f64>, y: Vec<f64>, color: Color) -> Self {
        Series { label: label.into(), x, y, color, dashed: false }
    }

    pub fn dashed(mut self) -> Self {
        self.dashed = true;
        self
    }
}

/// A shaded area between `lo` and `hi` over `x`, such as a confidence band.
#[derive(Debug, Clone, PartialEq)]
pub struct Band {
    pub label: String,
    pub x: Vec<f64>,
    pub lo: Vec<f64>,
    pub hi: Vec<f64>,
    pub color: Color,
}

/// A plot of lines over shaded bands, with optional labelled vertical markers (for example
/// the modes found in a spectrum).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub bands: Vec<Band>,
    pub log_y: bool,
    /// Vertical lines at x, each with a short label; those outside the data's x range are
    /// not drawn.
    pub markers_x: Vec<(f64, String)>,
}

impl LinePlot {
    pub fn new(title: impl Into<String>, x_label: impl Into<String>, y_label: impl Into<String>) -> Self {
        LinePlot { title: title.into(), x_label: x_label.into(), y_label: y_label.into(), ..Default::default() }
    }
}

/// Grouped bars: one bar per series in each group. `bars[i].1[j]` is series `i` in group
/// `j`; missing or non-finite values leave a gap.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BarPlot {
    pub title: String,
    pub y_label: String,
    pub groups: Vec<String>,
    pub bars: Vec<(String, Vec<f64>)>,
}

fn ensure_font() -> Result<(), ReportError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT_FAMILY, FontStyle::Normal, DEJAVU_SANS).is_ok());
    if ok { Ok(()) } else { Err(ReportError::Font) }
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Runs `draw` on a white SVG canvas of `width` × `height` and returns the SVG text.
fn render(
    what: &str,
    width: u32,
    height: u32,
    draw: impl FnOnce(&DrawingArea<SVGBackend, Shift>) -> DrawResult,
) -> Result<String, ReportError> {
    ensure_font()?;
    let plot_error = |reason: String| ReportError::Plot { what: what.to_string(), reason };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width.max(100), height.max(80))).into_drawing_area();
        root.fill(&plotters::style::WHITE).map_err(|e| plot_error(e.to_string()))?;
        draw(&root).map_err(|e| plot_error(e.to_string()))?;
        root.present().map_err(|e| plot_error(e.to_string()))?;
    }
    Ok(svg)
}

fn rgb(color: Color) -> RGBColor {
    let (r, g, b) = color.rgb();
    RGBColor(r, g, b)
}

fn font(px: u32) -> TextStyle<'static> {
    (FONT_FAMILY, px).into_font().into()
}

/// A line plot's y axis: the range the data are clamped to, and how many labels at most.
struct YAxis {
    clamp: (f64, f64),
    labels: usize,
}

/// Each series' and band's runs, in the plot's order.
struct LineData {
    series: Vec<Vec<Run<1>>>,
    bands: Vec<Vec<Run<2>>>,
}

/// Renders `plot` as a `width` × `height` SVG. Never fails on the data: see the module doc.
/// Series and bands longer than two points per pixel column are decimated to their
/// envelope, which keeps a long record's SVG small without changing what it shows.
pub fn line_plot_svg(plot: &LinePlot, width: u32, height: u32) -> Result<String, ReportError> {
    let columns = width as usize;
    let data = LineData {
        series: plot
            .series
            .iter()
            .map(|s| runs(&s.x, [&s.y], plot.log_y).into_iter().map(|r| decimate_line(r, columns)).collect())
            .collect(),
        bands: plot
            .bands
            .iter()
            .map(|b| runs(&b.x, [&b.lo, &b.hi], plot.log_y).into_iter().map(|r| decimate_band(r, columns)).collect())
            .collect(),
    };
    let series_points = data.series.iter().flatten().flatten().map(|(x, y)| (*x, y[0]));
    let band_points = data.bands.iter().flatten().flatten().flat_map(|(x, y)| [(*x, y[0]), (*x, y[1])]);
    let points: Vec<(f64, f64)> = series_points.chain(band_points).collect();
    let x_extent = extent(points.iter().map(|p| p.0));
    let y_extent = extent(points.iter().map(|p| p.1));
    let x_range = match x_extent {
        Some((lo, hi)) if hi > lo => lo..hi,
        Some((lo, hi)) => padded(lo, hi, 0.0),
        None => 0.0..1.0,
    };
    render(&plot.title, width, height, |root| {
        if plot.log_y {
            let y_range = match y_extent {
                Some((lo, hi)) => log_range(lo, hi),
                None => 1.0..100.0,
            };
            let clamp = (y_range.start, y_range.end);
            // Plotters labels a log axis at 1..9 times each power of ten when it has room for
            // ten labels; the top of a decade then prints them over each other.
            let y = YAxis { clamp, labels: 5 };
            draw_line_plot(root, plot, &data, x_range, y_range.clone().log_scale(), y, points.is_empty())
        } else {
            let y_range = match y_extent {
                Some((lo, hi)) => padded(lo, hi, 0.05),
                None => 0.0..1.0,
            };
            let clamp = (y_range.start, y_range.end);
            draw_line_plot(root, plot, &data, x_range, y_range, YAxis { clamp, labels: 10 }, points.is_empty())
        }
    })
}

fn draw_line_plot<Y>(
    root: &DrawingArea<SVGBackend, Shift>,
    plot: &LinePlot,
    data: &LineData,
    x_range: Range<f64>,
    y_spec: Y,
    YAxis { clamp: (y_min, y_max), labels: y_labels }: YAxis,
    empty: bool,
) -> DrawResult
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let mut chart = ChartBuilder::on(root)
        .caption(&plot.title, font(TITLE_PX))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(68)
        .build_cartesian_2d(x_range.clone(), y_spec)?;
    chart
        .configure_mesh()
        .x_desc(&plot.x_label)
        .y_desc(&plot.y_label)
        .axis_desc_style(font(AXIS_LABEL_PX))
        .label_style(font(TICK_PX))
        .y_labels(y_labels)
        .x_label_formatter(&|v| format_number(*v, 4))
        .y_label_formatter(&|v| format_number(*v, 3))
        .light_line_style(plotters::style::BLACK.mix(0.04))
        .bold_line_style(plotters::style::BLACK.mix(0.12))
        .draw()?;
    if empty {
        note_in_middle(root, chart.plotting_area().get_pixel_range(), "no data to plot")?;
    }
    let clamp = |y: f64| y.clamp(y_min, y_max);

    let mut legend_labels = Vec::new();
    for (band, runs) in plot.bands.iter().zip(&data.bands) {
        legend_labels.push(band.label.clone());
        let color = rgb(band.color);
        let polygons = runs.iter().map(|run| {
            let upper = run.iter().map(|(x, y)| (*x, clamp(y[1])));
            let lower = run.iter().rev().map(|(x, y)| (*x, clamp(y[0])));
            Polygon::new(upper.chain(lower).collect::<Vec<_>>(), color.mix(0.25).filled())
        });
        chart
            .draw_series(polygons)?
            .label(&band.label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 20, y + 6)], color.mix(0.25).filled()));
    }

    let markers: Vec<&(f64, String)> = plot.markers_x.iter().filter(|(x, _)| x_range.contains(x)).collect();
    let marker_style = ShapeStyle::from(plotters::style::BLACK.mix(0.45)).stroke_width(1);
    for (i, (x, label)) in markers.iter().enumerate() {
        chart.draw_series(DashedLineSeries::new([(*x, y_min), (*x, y_max)], 4, 3, marker_style))?;
        // Three staggered rows keep labels of close markers apart.
        let row = (i % 3) as i32;
        let text = EmptyElement::at((*x, y_max))
            + Text::new(
                label.clone(),
                (3, 4 + row * (MARKER_PX as i32 + 2)),
                font(MARKER_PX).color(&RGBColor(60, 60, 60)),
            );
        chart.plotting_area().draw(&text)?;
    }

    for (series, runs) in plot.series.iter().zip(&data.series) {
        let color = rgb(series.color);
        let style = ShapeStyle::from(color).stroke_width(2);
        let label = if runs.is_empty() { format!("{} (no points)", series.label) } else { series.label.clone() };
        legend_labels.push(label.clone());
        let points = |run: &Run<1>| run.iter().map(|(x, y)| (*x, clamp(y[0]))).collect::<Vec<_>>();
        let mut first = true;
        // Each run is drawn on its own, so a skipped point breaks the line; the legend entry
        // hangs on the first (or on an empty series, so that a series with no points is
        // still named).
        for run in runs.iter().map(Some).chain(runs.is_empty().then_some(None)) {
            let pts = run.map(points).unwrap_or_default();
            let anno = if series.dashed {
                chart.draw_series(DashedLineSeries::new(pts, 7, 4, style))?
            } else {
                chart.draw_series(LineSeries::new(pts, style))?
            };
            if std::mem::take(&mut first) {
                let anno = anno.label(label.clone());
                if series.dashed {
                    anno.legend(move |(x, y)| DashedPathElement::new(vec![(x, y), (x + 20, y)], 5, 3, style));
                } else {
                    anno.legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
                }
            }
        }
    }

    if !plot.series.is_empty() || !plot.bands.is_empty() {
        let mut spans = Vec::new();
        for run in data.series.iter().flatten() {
            let px: Vec<(i32, i32)> = run.iter().map(|(x, y)| chart.backend_coord(&(*x, clamp(y[0])))).collect();
            spans.extend(px.windows(2).map(|w| (w[0].0, w[0].1.min(w[1].1), w[0].1.max(w[1].1))));
            spans.extend(px.first().map(|p| (p.0, p.1, p.1)));
        }
        for (x, y) in data.bands.iter().flatten().flatten() {
            let (px, lo) = chart.backend_coord(&(*x, clamp(y[0])));
            let (_, hi) = chart.backend_coord(&(*x, clamp(y[1])));
            spans.push((px, lo.min(hi), lo.max(hi)));
        }
        for (i, (x, label)) in markers.iter().enumerate() {
            let (px, py) = chart.backend_coord(&(*x, y_max));
            let row_py = py + 4 + (i % 3) as i32 * (MARKER_PX as i32 + 2);
            let width = root.estimate_text_size(label, &font(MARKER_PX)).map_or(40, |(w, _)| w as i32);
            spans.extend((0..=width / 4).map(|k| (px + 3 + 4 * k, row_py, row_py + MARKER_PX as i32)));
        }
        draw_legend(&mut chart, &legend_labels, &spans, CORNERS)?;
    }
    Ok(())
}

/// A vertical span of backend pixels, x, top..=bottom, where something is drawn.
type Span = (i32, i32, i32);

const CORNERS: &[SeriesLabelPosition] = &[
    SeriesLabelPosition::UpperRight,
    SeriesLabelPosition::UpperLeft,
    SeriesLabelPosition::LowerRight,
    SeriesLabelPosition::LowerLeft,
];

/// Draws the legend of the chart's labelled series in whichever of `corners` hides the
/// fewest `spans` (the first of equals), estimating its box as plotters lays it out (10 px
/// margins around the text, a 30 px swatch column, 5 px from the plotting area's edges).
fn draw_legend<'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut plotters::chart::ChartContext<'a, SVGBackend<'a>, CT>,
    labels: &[String],
    spans: &[Span],
    corners: &[SeriesLabelPosition],
) -> DrawResult {
    let area = chart.plotting_area();
    let (xs, ys) = area.get_pixel_range();
    let style = font(LEGEND_PX);
    let widest = labels.iter().filter_map(|l| area.estimate_text_size(l, &style).ok()).map(|(w, _)| w).max();
    let box_w = widest.unwrap_or(0) as i32 + 30 + 20;
    let box_h = labels.len() as i32 * (LEGEND_PX as i32 * 5 / 4 + 1) + 20;
    let hidden = |corner: &SeriesLabelPosition| {
        let x0 = match corner {
            SeriesLabelPosition::UpperLeft | SeriesLabelPosition::LowerLeft => xs.start + 5,
            _ => xs.end - box_w - 5,
        };
        let y0 = match corner {
            SeriesLabelPosition::LowerLeft | SeriesLabelPosition::LowerRight => ys.end - box_h - 5,
            _ => ys.start + 5,
        };
        let inside = |(x, top, bottom): &&Span| (x0..=x0 + box_w).contains(x) && *top <= y0 + box_h && *bottom >= y0;
        spans.iter().filter(inside).count()
    };
    let position = corners.iter().min_by_key(|c| hidden(c)).cloned().unwrap_or(SeriesLabelPosition::UpperRight);
    chart
        .configure_series_labels()
        .position(position)
        .label_font(font(LEGEND_PX))
        .background_style(plotters::style::WHITE.mix(0.85))
        .border_style(plotters::style::BLACK.mix(0.3))
        .draw()?;
    Ok(())
}

/// Writes `note` in the middle of the plotting area `area_px` (backend pixels).
fn note_in_middle(root: &DrawingArea<SVGBackend, Shift>, area_px: (Range<i32>, Range<i32>), note: &str) -> DrawResult {
    let (xs, ys) = area_px;
    let centre = ((xs.start + xs.end) / 2, (ys.start + ys.end) / 2);
    let grey = plotters::style::BLACK.mix(0.5);
    let style = font(AXIS_LABEL_PX).color(&grey).pos(Pos::new(HPos::Center, VPos::Center));
    root.draw(&Text::new(note.to_string(), centre, style))?;
    Ok(())
}

/// Renders `plot` as a `width` × `height` SVG of grouped bars from zero. Never fails on the
/// data: non-finite values leave gaps and a plot without any is an empty frame saying so.
pub fn bar_plot_svg(plot: &BarPlot, width: u32, height: u32) -> Result<String, ReportError> {
    let n_groups = plot.groups.len().max(1);
    let values = plot.bars.iter().flat_map(|(_, v)| v.iter().take(plot.groups.len()).copied());
    let y_extent = extent(values.filter(|v| v.is_finite()));
    let y_range = match y_extent {
        Some((lo, hi)) => {
            // Headroom above the tallest bar for the legend.
            let r = padded(lo.min(0.0), hi.max(0.0), 0.05 + 0.08 * plot.bars.len() as f64);
            (if lo >= 0.0 { 0.0 } else { r.start })..(if hi <= 0.0 { 0.0 } else { r.end })
        }
        None => 0.0..1.0,
    };
    let x_range = 0.0..n_groups as f64;
    render(&plot.title, width, height, |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(&plot.title, font(TITLE_PX))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(68)
            .build_cartesian_2d(x_range.clone(), y_range.clone())?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(0)
            .y_desc(&plot.y_label)
            .axis_desc_style(font(AXIS_LABEL_PX))
            .label_style(font(TICK_PX))
            // A tick at zero comes out of the axis arithmetic as ±1e-17.
            .y_label_formatter(&|v| {
                format_number(if v.abs() < 1e-9 * (y_range.end - y_range.start) { 0.0 } else { *v }, 3)
            })
            .light_line_style(plotters::style::BLACK.mix(0.04))
            .bold_line_style(plotters::style::BLACK.mix(0.12))
            .draw()?;
        if y_extent.is_none() {
            note_in_middle(root, chart.plotting_area().get_pixel_range(), "no data to plot")?;
        }

        // Group names under the axis, cut to their slot so that neighbours do not overlap.
        let slot_px = {
            let (a, _) = chart.backend_coord(&(0.0, 0.0));
            let (b, _) = chart.backend_coord(&(1.0, 0.0));
            (b - a).max(1) as u32
        };
        let label_style = font(TICK_PX).pos(Pos::new(HPos::Center, VPos::Top));
        for (j, group) in plot.groups.iter().enumerate() {
            let (px, _) = chart.backend_coord(&(j as f64 + 0.5, y_range.start));
            let (_, py) = chart.backend_coord(&(0.0, y_range.start));
            let text = fit_text(root, group, &label_style, slot_px.saturating_sub(6));
            root.draw(&Text::new(text, (px, py + 6), label_style.clone()))?;
        }

        let n_series = plot.bars.len().max(1);
        let width = 0.8 / n_series as f64;
        for (i, (label, values)) in plot.bars.iter().enumerate() {
            let color = Color::nth(i);
            let fill = rgb(color).filled();
            let rects =
                values.iter().take(plot.groups.len()).enumerate().filter(|(_, v)| v.is_finite()).map(move |(j, v)| {
                    let x0 = j as f64 + 0.1 + i as f64 * width;
                    Rectangle::new([(x0, 0.0), (x0 + width, *v)], fill)
                });
            chart
                .draw_series(rects)?
                .label(label)
                .legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 14, y + 6)], fill));
        }
        if y_range.start < 0.0 {
            let axis = ShapeStyle::from(plotters::style::BLACK.mix(0.6)).stroke_width(1);
            chart.draw_series(LineSeries::new([(0.0, 0.0), (n_groups as f64, 0.0)], axis))?;
        }
        if !plot.bars.is_empty() {
            let mut spans = Vec::new();
            for (i, (_, values)) in plot.bars.iter().enumerate() {
                for (j, v) in values.iter().take(plot.groups.len()).enumerate().filter(|(_, v)| v.is_finite()) {
                    let x0 = j as f64 + 0.1 + i as f64 * width;
                    let (left, top) = chart.backend_coord(&(x0, v.max(0.0)));
                    let (right, bottom) = chart.backend_coord(&(x0 + width, v.min(0.0)));
                    spans.extend((left..=right).step_by(3).map(|x| (x, top, bottom)));
                }
            }
            let labels: Vec<String> = plot.bars.iter().map(|(l, _)| l.clone()).collect();
            let corners = [SeriesLabelPosition::UpperRight, SeriesLabelPosition::UpperLeft];
            draw_legend(&mut chart, &labels, &spans, &corners)?;
        }
        Ok(())
    })
}

/// `text`, cut with an ellipsis to at most `max_px` wide as plotters measures it.
fn fit_text(root: &DrawingArea<SVGBackend, Shift>, text: &str, style: &TextStyle, max_px: u32) -> String {
    let fits = |t: &str| root.estimate_text_size(t, style).map(|(w, _)| w <= max_px).unwrap_or(true);
    if fits(text) {
        return text.to_string();
    }
    let chars: Vec<char> = text.chars().collect();
    (1..chars.len())
        .rev()
        .map(|n| format!("{}…", chars[..n].iter().collect::<String>()))
        .find(|t| fits(t))
        .unwrap_or_else(|| "…".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(haystack: &str, needle: &str) -> usize {
        haystack.matches(needle).count()
    }

    #[test]
    fn a_series_with_a_nan_is_drawn_in_two_pieces_and_named() {
        let mut plot = LinePlot::new("load", "t (ms)", "F (kN)");
        plot.series.push(Series::new(
            "measured <F>",
            vec![0.0, 1.0, 2.0, 3.0, 4.0],
            vec![0.0, 1.0, f64::NAN, 3.0, 2.0],
            Color::Blue,
        ));
        let svg = line_plot_svg(&plot, 600, 300).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..80.min(svg.len())]);
        assert!(svg.trim_end().ends_with("</svg>"));
        // plotters escapes the label itself.
        assert!(svg.contains("measured &lt;F&gt;"), "legend label missing");
        assert!(!svg.contains("<F>"));
        // Two runs (before and after the NaN) plus the legend's sample line.
        let blue = "stroke=\"#0072B2\"";
        assert_eq!(count(&svg, blue), 3, "{svg}");
    }

    #[test]
    fn a_log_plot_skips_zeros_and_negatives() {
        let mut plot = LinePlot { log_y: true, ..LinePlot::new("spectrum", "f (Hz)", "|F| (N)") };
        let x: Vec<f64> = (0..50).map(f64::from).collect();
        let y: Vec<f64> = x.iter().map(|&f| if f < 3.0 { 0.0 } else { 1e3 / f }).collect();
        plot.series.push(Series::new("measured", x.clone(), y, Color::Blue));
        plot.series.push(Series::new("all zero", x, vec![0.0; 50], Color::Orange).dashed());
        plot.markers_x.push((10.0, "10 Hz".into()));
        plot.markers_x.push((1e6, "off the axis".into()));
        let svg = line_plot_svg(&plot, 600, 300).unwrap();
        assert!(svg.contains("all zero (no points)"));
        assert!(svg.contains("10 Hz"));
        assert!(!svg.contains("off the axis"));
        assert!(!svg.contains("NaN") && !svg.contains("inf"), "non-finite coordinates leaked into the SVG");
    }

    #[test]
    fn a_long_record_is_drawn_as_its_envelope() {
        // A million samples of a 1 kHz sine at 1 MHz: 1000 periods over 600 columns.
        let t: Vec<f64> = (0..1_000_000).map(|i| f64::from(i) * 1e-6).collect();
        let y: Vec<f64> = t.iter().map(|t| (2.0 * std::f64::consts::PI * 1e3 * t).sin()).collect();
        let run: Run<1> = t.iter().zip(&y).map(|(t, y)| (*t, [*y])).collect();
        let kept = decimate_line(run, 600);
        assert!(kept.len() <= 1200, "{}", kept.len());
        // Every chunk spans more than a period, so the envelope reaches both peaks.
        assert!(kept.iter().all(|p| p.1[0].abs() > 0.999), "an inner point was kept");
        assert!(kept.windows(2).all(|w| w[0].0 < w[1].0), "the points left their order");

        let mut plot = LinePlot::new("long", "t (s)", "y");
        plot.series.push(Series::new("sine", t.clone(), y.clone(), Color::Blue));
        plot.bands.push(Band { label: "band".into(), x: t, lo: y.clone(), hi: y, color: Color::Orange });
        let svg = line_plot_svg(&plot, 600, 300).unwrap();
        assert!(svg.len() < 60_000, "{} bytes", svg.len());
    }

    /// A residual spectrum of 1.4 decades (report of the press clearance case): with ten
    /// labels plotters printed 20000 … 90000 over each other at the top of the decade.
    #[test]
    fn a_log_axis_does_not_crowd_its_labels() {
        let f: Vec<f64> = (1..200).map(|i| i as f64).collect();
        let a: Vec<f64> = f.iter().map(|x| 5e3 * (x / 8.0).exp().min(24.0)).collect();
        let mut plot = LinePlot { log_y: true, ..LinePlot::new("spectrum", "f (Hz)", "N") };
        plot.series.push(Series::new("residual", f, a, Color::Blue));
        let svg = line_plot_svg(&plot, 600, 300).unwrap();
        let labels = ["20000", "30000", "40000", "50000", "60000", "70000", "80000", "90000"];
        let label = |l: &str| svg.contains(&format!(">\n{l}\n</text>"));
        let shown: Vec<&str> = labels.iter().copied().filter(|l| label(l)).collect();
        assert!(shown.len() <= 2, "{shown:?}");
        assert!(label("10000"), "the power of ten is labelled");
    }

    #[test]
    fn a_log_axis_holds_at_least_two_powers_of_ten() {
        let r = log_range(12.0, 80.0);
        assert_eq!((r.start, r.end), (10.0, 100.0));
        let r = log_range(2500.0, 50_000.0);
        assert_eq!(r.start, 1000.0);
        assert!(r.end > 50_000.0 && r.end < 60_000.0, "{r:?}");
        let r = log_range(1e-20, 1.0);
        assert!(r.start > 1e-10 && r.start < 1e-9, "{LOG_Y_MAX_DECADES} decades at most: {r:?}");
    }

    #[test]
    fn a_plot_without_data_is_an_empty_frame_with_a_note() {
        let empty = LinePlot::new("nothing", "x", "y");
        assert!(line_plot_svg(&empty, 400, 250).unwrap().contains("no data to plot"));
        let mut all_nan = LinePlot { log_y: true, ..LinePlot::new("nothing", "x", "y") };
        all_nan.series.push(Series::new("s", vec![f64::NAN], vec![1.0], Color::Blue));
        assert!(line_plot_svg(&all_nan, 400, 250).unwrap().contains("no data to plot"));
        let bars = BarPlot { title: "none".into(), ..Default::default() };
        assert!(bar_plot_svg(&bars, 400, 250).unwrap().contains("no data to plot"));
    }

    #[test]
    fn a_band_is_one_filled_polygon_per_run_and_in_the_legend() {
        let mut plot = LinePlot::new("band", "x", "y");
        plot.bands.push(Band {
            label: "95 % band".into(),
            x: vec![0.0, 1.0, 2.0, 3.0, 4.0],
            lo: vec![0.0, 0.5, 1.0, f64::INFINITY, 1.0],
            hi: vec![1.0, 1.5, 2.0, 2.0, 2.0],
            color: Color::Orange,
        });
        let svg = line_plot_svg(&plot, 400, 250).unwrap();
        assert!(svg.contains("95 % band"));
        // The second run has a single point; it is still a (degenerate) polygon.
        assert_eq!(count(&svg, "<polygon"), 2, "{svg}");
    }

    #[test]
    fn bars_name_their_groups_and_series_and_skip_non_finite_values() {
        let plot = BarPlot {
            title: "error".into(),
            y_label: "rms (%)".into(),
            groups: vec!["blow 1".into(), "blow 2".into(), "a group name far too long to fit in its slot".into()],
            bars: vec![("fit".into(), vec![1.0, f64::NAN, 2.0]), ("held out".into(), vec![f64::NAN, 3.0])],
        };
        let svg = bar_plot_svg(&plot, 400, 250).unwrap();
        for text in ["blow 1", "blow 2", "fit", "held out", "…"] {
            assert!(svg.contains(text), "{text} missing");
        }
        assert!(!svg.contains("far too long to fit in its slot"));
        // Three finite bars, two legend swatches, the background, and the legend box's fill
        // and border.
        assert_eq!(count(&svg, "<rect"), 3 + 2 + 1 + 2, "{svg}");
    }
}
