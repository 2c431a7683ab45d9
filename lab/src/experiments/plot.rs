//! Line charts (PNG, plotters) for the experiments: any number of named polylines on linear or
//! logarithmic axes. Non-finite points, and non-positive ones on a logarithmic axis, are left
//! out (and split the line) rather than failing the plot.

use super::ExperimentError;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use std::path::Path;

/// Colours cycled through by [`color`].
const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// The `i`-th colour of the palette.
pub fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// One polyline.
#[derive(Debug, Clone)]
pub struct Line {
    /// Legend entry.
    pub label: String,
    /// Points (x, y) in the chart's units.
    pub points: Vec<(f64, f64)>,
    /// Colour.
    pub color: RGBColor,
    /// Dashed (for references, expectations) instead of solid.
    pub dashed: bool,
    /// Draw a circle at each point (for sparse data such as step sizes).
    pub markers: bool,
}

impl Line {
    /// A solid line without markers.
    pub fn solid(label: impl Into<String>, points: Vec<(f64, f64)>, color: RGBColor) -> Self {
        Self {
            label: label.into(),
            points,
            color,
            dashed: false,
            markers: false,
        }
    }

    /// A dashed line without markers (a reference, an expectation).
    pub fn dashed(label: impl Into<String>, points: Vec<(f64, f64)>, color: RGBColor) -> Self {
        Self {
            dashed: true,
            ..Self::solid(label, points, color)
        }
    }

    /// The same line with a circle at each point.
    pub fn with_markers(self) -> Self {
        Self {
            markers: true,
            ..self
        }
    }
}

/// The points of a table of results where both coordinates are finite, in order (a figure
/// that is not finite is undefined: `null` in `summary.json`), so that the line joins the
/// defined points instead of breaking at the undefined ones.
pub fn finite_points(points: impl IntoIterator<Item = (f64, f64)>) -> Vec<(f64, f64)> {
    points
        .into_iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .collect()
}

/// The points `(x[i], y[i])` of two equally sampled series (the shorter one's length).
pub fn xy(x: &[f64], y: &[f64]) -> Vec<(f64, f64)> {
    x.iter().copied().zip(y.iter().copied()).collect()
}

/// A chart: title, axis labels (with units) and scales, lines.
#[derive(Debug, Clone)]
pub struct Chart<'a> {
    /// Caption.
    pub title: &'a str,
    /// X axis label, with unit.
    pub x_label: &'a str,
    /// Y axis label, with unit.
    pub y_label: &'a str,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// The lines.
    pub lines: &'a [Line],
}

impl<'a> Chart<'a> {
    /// A chart with linear axes.
    pub fn linear(title: &'a str, x_label: &'a str, y_label: &'a str, lines: &'a [Line]) -> Self {
        Self {
            title,
            x_label,
            y_label,
            log_x: false,
            log_y: false,
            lines,
        }
    }

    /// A chart with a linear x axis and a logarithmic y axis.
    pub fn log_y(title: &'a str, x_label: &'a str, y_label: &'a str, lines: &'a [Line]) -> Self {
        Self {
            log_y: true,
            ..Self::linear(title, x_label, y_label, lines)
        }
    }
}

type DynErr = Box<dyn std::error::Error>;

/// Draw `chart` into the PNG file `path` (1000 × 600 px).
pub fn line_chart(path: &Path, chart: &Chart) -> Result<(), ExperimentError> {
    let panel = Panel {
        chart: chart.clone(),
        y_from_zero: false,
    };
    panel_chart(path, std::slice::from_ref(&panel), 1, (1000, 600))
}

/// One panel of [`panel_chart`].
pub struct Panel<'a> {
    /// The chart.
    pub chart: Chart<'a>,
    /// Start a linear y axis at zero (so that a flat curve looks flat).
    pub y_from_zero: bool,
}

/// Draw `panels`, `columns` per row, into the PNG file `path` of `size` pixels.
pub fn panel_chart(
    path: &Path,
    panels: &[Panel],
    columns: usize,
    size: (u32, u32),
) -> Result<(), ExperimentError> {
    let plot_err = |e: &dyn std::fmt::Display| ExperimentError::Plot {
        path: path.to_path_buf(),
        detail: e.to_string(),
    };
    crate::fonts::register();
    let root = BitMapBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE).map_err(|e| plot_err(&e))?;
    let columns = columns.max(1);
    let rows = panels.len().div_ceil(columns).max(1);
    let areas = root.split_evenly((rows, columns));
    for (area, panel) in areas.iter().zip(panels) {
        render(area, &panel.chart, panel.y_from_zero).map_err(|e| plot_err(&e))?;
    }
    root.present().map_err(|e| plot_err(&e))?;
    Ok(())
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

/// One chart on `area`: axis ranges from the usable points, linear or logarithmic axes.
fn render(area: &Area, chart: &Chart, y_from_zero: bool) -> Result<(), DynErr> {
    let usable = |v: f64, log: bool| v.is_finite() && (!log || v > 0.0);
    let (x0, x1) = range(
        chart
            .lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| p.0))
            .filter(|&x| usable(x, chart.log_x)),
        chart.log_x,
    );
    let (y0, y1) = range(
        chart
            .lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| p.1))
            .filter(|&y| usable(y, chart.log_y)),
        chart.log_y,
    );
    let y0 = if y_from_zero && !chart.log_y {
        y0.min(0.0)
    } else {
        y0
    };
    match (chart.log_x, chart.log_y) {
        (false, false) => draw(area, chart, x0..x1, y0..y1),
        (true, false) => draw(area, chart, (x0..x1).log_scale(), y0..y1),
        (false, true) => draw(area, chart, x0..x1, (y0..y1).log_scale()),
        (true, true) => draw(area, chart, (x0..x1).log_scale(), (y0..y1).log_scale()),
    }
}

/// Axis range of the values with a margin (5 % linear, a factor 1.3 logarithmic).
fn range(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return if log { (0.1, 10.0) } else { (0.0, 1.0) };
    }
    if log {
        if hi / lo < 1.0 + 1e-9 {
            return (lo / 2.0, hi * 2.0);
        }
        return (lo / 1.3, hi * 1.3);
    }
    if hi - lo < 1e-12 * (1.0 + hi.abs()) {
        return (lo - 0.5, hi + 0.5);
    }
    let m = (hi - lo) * 0.05;
    (lo - m, hi + m)
}

/// Tick label: shortest round-trip form of the value rounded to 6 significant digits
/// (scientific outside 1e-3…1e5); on a logarithmic axis only mantissas 1, 2 and 5 are labelled
/// (the other key points stay as grid lines), so that labels never overlap.
fn tick_label(v: f64, log: bool) -> String {
    if !v.is_finite() {
        return String::new();
    }
    if v == 0.0 {
        return "0".into();
    }
    let exp = v.abs().log10().floor();
    let mantissa = v.abs() / 10f64.powf(exp);
    if log
        && ![1.0, 2.0, 5.0, 10.0]
            .iter()
            .any(|m| (mantissa - m).abs() < 1e-6)
    {
        return String::new();
    }
    let rounded: f64 = format!("{v:.5e}").parse().unwrap_or(v);
    if (-3.0..5.0).contains(&exp) {
        format!("{rounded}")
    } else {
        format!("{rounded:e}")
    }
}

fn draw<XR, YR>(area: &Area, chart: &Chart, xr: XR, yr: YR) -> Result<(), DynErr>
where
    XR: AsRangedCoord<Value = f64>,
    YR: AsRangedCoord<Value = f64>,
    XR::CoordDescType: ValueFormatter<f64>,
    YR::CoordDescType: ValueFormatter<f64>,
{
    let mut ctx = ChartBuilder::on(area)
        .caption(chart.title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(xr, yr)?;
    let (log_x, log_y) = (chart.log_x, chart.log_y);
    let fx = move |v: &f64| tick_label(*v, log_x);
    let fy = move |v: &f64| tick_label(*v, log_y);
    ctx.configure_mesh()
        .x_desc(chart.x_label)
        .y_desc(chart.y_label)
        .x_label_formatter(&fx)
        .y_label_formatter(&fy)
        .draw()?;
    for line in chart.lines {
        let c = line.color;
        let ok = |p: &(f64, f64)| {
            p.0.is_finite()
                && p.1.is_finite()
                && (!chart.log_x || p.0 > 0.0)
                && (!chart.log_y || p.1 > 0.0)
        };
        // Split into runs of usable points so that a gap is not bridged by a straight line.
        let mut runs: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
        for p in &line.points {
            if ok(p) {
                if let Some(run) = runs.last_mut() {
                    run.push(*p);
                }
            } else if runs.last().is_some_and(|r| !r.is_empty()) {
                runs.push(Vec::new());
            }
        }
        let style = ShapeStyle::from(&c).stroke_width(2);
        let mut first = true;
        for run in runs.into_iter().filter(|r| !r.is_empty()) {
            let anno = if line.dashed {
                ctx.draw_series(DashedLineSeries::new(run.iter().copied(), 8, 6, style))?
            } else {
                ctx.draw_series(LineSeries::new(run.iter().copied(), style))?
            };
            if first {
                anno.label(line.label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], c));
                first = false;
            }
            if line.markers {
                ctx.draw_series(run.iter().map(|&p| Circle::new(p, 4, c.filled())))?;
            }
        }
    }
    ctx.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(tick_label(0.30000000000000004, false), "0.3");
        assert_eq!(tick_label(0.30000000000000004, true), "");
        assert_eq!(tick_label(0.2, true), "0.2");
        assert_eq!(tick_label(5e-6, true), "5e-6");
        assert_eq!(tick_label(100.0, true), "100");
        assert_eq!(tick_label(-12.5, false), "-12.5");
        assert_eq!(tick_label(2.5e7, false), "2.5e7");
        assert_eq!(tick_label(0.0, false), "0");
    }

    #[test]
    fn finite_points_select_rows_and_skip_undefined_figures() {
        let rows = [
            ("a", 1.0, 2.0),
            ("b", 2.0, 3.0),
            ("a", 3.0, f64::NAN),
            ("a", 4.0, 5.0),
            ("a", f64::INFINITY, 6.0),
        ];
        assert_eq!(
            finite_points(rows.iter().filter(|r| r.0 == "a").map(|r| (r.1, r.2))),
            vec![(1.0, 2.0), (4.0, 5.0)]
        );
        assert_eq!(
            xy(&[1.0, 2.0, 3.0], &[4.0, 5.0]),
            vec![(1.0, 4.0), (2.0, 5.0)]
        );
    }

    #[test]
    fn draws_linear_and_log_charts_and_skips_bad_points() {
        let dir = super::super::test_dir("plot");
        std::fs::create_dir_all(&dir).expect("temp dir");
        let lines = [
            Line {
                label: "y = x²".into(),
                points: (1..50).map(|i| (i as f64, (i * i) as f64)).collect(),
                color: color(0),
                dashed: false,
                markers: true,
            },
            Line {
                label: "with gaps".into(),
                points: vec![
                    (1.0, 1.0),
                    (2.0, f64::NAN),
                    (3.0, -1.0),
                    (4.0, 5.0),
                    (5.0, 6.0),
                ],
                color: color(1),
                dashed: true,
                markers: false,
            },
        ];
        for (i, (lx, ly)) in [(false, false), (true, true), (false, true), (true, false)]
            .into_iter()
            .enumerate()
        {
            let path = dir.join(format!("chart_{i}.png"));
            line_chart(
                &path,
                &Chart {
                    title: "test",
                    x_label: "x [1]",
                    y_label: "y [1]",
                    log_x: lx,
                    log_y: ly,
                    lines: &lines,
                },
            )
            .expect("chart");
            let len = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
            assert!(len > 1000, "{path:?}: {len} bytes");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
