//! PNG plots of an [`Analysis`]: position errors and attitude error against time (GNSS outages
//! shaded), and the horizontal trajectory of truth and solution.

use crate::analysis::Series;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Errors while plotting.
#[derive(Debug, thiserror::Error)]
#[error("plot {path}: {detail}")]
pub struct PlotError {
    /// The file.
    pub path: PathBuf,
    /// What failed.
    pub detail: String,
}

fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = v
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        return (lo - 0.5, hi + 0.5);
    }
    let m = (hi - lo) * 0.05;
    (lo - m, hi + m)
}

type DynErr = Box<dyn std::error::Error>;

fn time_plot(
    path: &Path,
    title: &str,
    y_label: &str,
    s: &Series,
    lines: &[(&str, &[f64], RGBColor)],
) -> Result<(), DynErr> {
    crate::fonts::register();
    let root = BitMapBackend::new(path, (1000, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let (x0, x1) = range(s.t_s.iter().copied());
    let (y0, y1) = range(lines.iter().flat_map(|(_, v, _)| v.iter().copied()));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("time since start [s]")
        .y_desc(y_label)
        .draw()?;
    for &(a, b) in &s.outages_s {
        chart.draw_series(std::iter::once(Rectangle::new(
            [(a.max(x0), y0), (b.min(x1), y1)],
            RGBColor(255, 200, 120).mix(0.4).filled(),
        )))?;
    }
    let series = lines
        .iter()
        .map(|&(name, v, color)| (name, s.t_s.iter().copied().zip(v.iter().copied()), color));
    draw_labelled_lines(&mut chart, series)?;
    root.present()?;
    Ok(())
}

/// Draw each `(label, points, colour)` as a line with its entry in the legend, then the legend.
fn draw_labelled_lines<'a, 'n, DB: DrawingBackend + 'a, P: Iterator<Item = (f64, f64)>>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    lines: impl IntoIterator<Item = (&'n str, P, RGBColor)>,
) -> Result<(), DynErr>
where
    DB::ErrorType: 'static,
{
    for (name, points, color) in lines {
        chart
            .draw_series(LineSeries::new(points, color))?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

fn trajectory_plot(path: &Path, s: &Series) -> Result<(), DynErr> {
    crate::fonts::register();
    let root = BitMapBackend::new(path, (800, 800)).into_drawing_area();
    root.fill(&WHITE)?;
    let all_e = s.truth_ne_m.iter().chain(&s.nav_ne_m).map(|p| p.1);
    let all_n = s.truth_ne_m.iter().chain(&s.nav_ne_m).map(|p| p.0);
    let (mut e0, mut e1) = range(all_e);
    let (mut n0, mut n1) = range(all_n);
    // Equal scales on both axes.
    let half = ((e1 - e0).max(n1 - n0)) / 2.0;
    let (ec, nc) = ((e0 + e1) / 2.0, (n0 + n1) / 2.0);
    (e0, e1, n0, n1) = (ec - half, ec + half, nc - half, nc + half);
    let mut chart = ChartBuilder::on(&root)
        .caption("trajectory: truth and solution", ("sans-serif", 22))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(e0..e1, n0..n1)?;
    chart
        .configure_mesh()
        .x_desc("east [m]")
        .y_desc("north [m]")
        .draw()?;
    fn east_north(pts: &[(f64, f64)]) -> impl Iterator<Item = (f64, f64)> + '_ {
        pts.iter().map(|&(n, e)| (e, n))
    }
    draw_labelled_lines(
        &mut chart,
        [
            ("truth", east_north(&s.truth_ne_m), BLACK),
            ("solution", east_north(&s.nav_ne_m), BLUE),
        ],
    )?;
    root.present()?;
    Ok(())
}

/// Write `position_error.png`, `attitude_error.png` and `trajectory.png` into `dir`; returns
/// the files written.
pub fn write_plots(dir: &Path, s: &Series) -> Result<Vec<PathBuf>, PlotError> {
    let wrap = |path: &Path, r: Result<(), DynErr>| {
        r.map_err(|e| PlotError {
            path: path.to_path_buf(),
            detail: e.to_string(),
        })
    };
    let mut out = Vec::new();
    let p = dir.join("position_error.png");
    wrap(
        &p,
        time_plot(
            &p,
            "position error against truth (GNSS outages shaded)",
            "error [m]",
            s,
            &[
                ("horizontal", &s.horizontal_m, BLUE),
                ("vertical (up)", &s.vertical_m, RED),
            ],
        ),
    )?;
    out.push(p);
    let p = dir.join("attitude_error.png");
    wrap(
        &p,
        time_plot(
            &p,
            "attitude error angle against truth",
            "error [deg]",
            s,
            &[("attitude", &s.attitude_deg, BLUE)],
        ),
    )?;
    out.push(p);
    let p = dir.join("trajectory.png");
    wrap(&p, trajectory_plot(&p, s))?;
    out.push(p);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plots_are_written() {
        let dir = std::env::temp_dir().join(format!("sextant-plots-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let n = 100;
        let s = Series {
            t_s: (0..n).map(f64::from).collect(),
            horizontal_m: (0..n).map(|k| f64::from(k).sin().abs()).collect(),
            vertical_m: (0..n).map(|k| f64::from(k).cos()).collect(),
            attitude_deg: (0..n).map(|k| 0.01 * f64::from(k)).collect(),
            truth_ne_m: (0..n).map(|k| (f64::from(k), 0.0)).collect(),
            nav_ne_m: (0..n).map(|k| (f64::from(k), 0.5)).collect(),
            outages_s: vec![(20.0, 40.0)],
            t0_ns: 0,
        };
        let files = write_plots(&dir, &s).unwrap();
        for f in files {
            let b = std::fs::read(&f).unwrap();
            assert_eq!(&b[1..4], b"PNG", "{}", f.display());
        }
        // Empty series do not fail.
        write_plots(&dir, &Series::default()).unwrap();
    }
}
