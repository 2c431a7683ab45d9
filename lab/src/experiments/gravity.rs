//! Experiment `gravity` (paper 002's gravity with the Earth's oblateness, in the corrected J2 form
//! of SEEDS.md): the three gravity models of [`fusion::earth`] over geodetic latitude 0–90° and
//! height 0–20 km (longitude 0; every model is axially symmetric).
//!
//! - **J2**: `g_x,y = −GM/r³ [1 + 3/2 J2 (a/r)² (1 − 5z²/r²)] x,y`,
//!   `g_z = −GM/r³ [1 + 3/2 J2 (a/r)² (3 − 5z²/r²)] z`, plus the centrifugal term;
//! - **normal**: Somigliana on the ellipsoid with the second-order free-air correction, along
//!   the ellipsoid normal (the reference: it is the full normal field of the level ellipsoid,
//!   to which J2 is the first zonal term);
//! - **point mass**: `−GM r/r³` plus the centrifugal term.
//!
//! Figures: magnitude differences (m/s², also in mGal = 1e-5 m/s²) and the deflection of each
//! model's gravity vector from the ellipsoid normal (arcsec, positive when gravity leans
//! north), their maxima over the grid and where they occur. The J2 model differs from the
//! normal field by the higher zonal terms (J4 ≈ −2.4e-6 …): about 12 mGal at most and about
//! 1 arcsec of deflection on the ellipsoid. Above it the J2 deflection grows with height
//! (≈ 4 arcsec at 20 km, 56°): that is the curvature of the normal plumb line
//! (≈ 0.17″ · h[km] · sin 2φ), real physics that the normal model, which keeps gravity along
//! the ellipsoid normal at every height, leaves out. The point mass ignores the flattening entirely: tens of thousands of mGal and
//! about 10 arcmin of deflection at mid latitudes (the gravity then points to the centre, not
//! along the normal), which is why it is for comparison only.

use super::plot::{Chart, Line, color, line_chart};
use super::{Experiment, ExperimentError, fmt_f64};
use fusion::earth::{Geodetic, GravityModel, WGS84, c_e_n, geodetic_to_ecef, gravity_ecef};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One m/s² in mGal.
const MGAL_PER_M_S2: f64 = 1e5;
/// One radian in arcsec.
const ARCSEC_PER_RAD: f64 = 180.0 * 3600.0 / std::f64::consts::PI;

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Latitude step, deg (grid 0…90°).
    pub latitude_step_deg: f64,
    /// Height step, m (grid 0…`max_height_m`).
    pub height_step_m: f64,
    /// Highest height, m.
    pub max_height_m: f64,
}

impl Default for Settings {
    /// 0.5° × 500 m, up to 20 km.
    fn default() -> Self {
        Self {
            latitude_step_deg: 0.5,
            height_step_m: 500.0,
            max_height_m: 20_000.0,
        }
    }
}

/// A figure of a grid point, for plotting.
type PointFigure = dyn Fn(&Point) -> f64;

/// Gravity of each model at one grid point, compared with the normal gravity.
#[derive(Debug, Clone, Copy)]
struct Point {
    lat_deg: f64,
    height_m: f64,
    /// |g| − |γ| for J2 and point mass, m/s².
    mag_diff_j2_m_s2: f64,
    mag_diff_pm_m_s2: f64,
    /// |g_pm| − |g_j2|, m/s².
    mag_diff_pm_j2_m_s2: f64,
    /// Deflection from the ellipsoid normal (northward positive), arcsec.
    defl_j2_arcsec: f64,
    defl_pm_arcsec: f64,
    /// Angle between the point-mass and J2 vectors, arcsec.
    angle_pm_j2_arcsec: f64,
    /// Normal gravity magnitude, m/s².
    normal_m_s2: f64,
}

fn evaluate(lat_deg: f64, height_m: f64) -> Point {
    let ell = WGS84;
    let g = Geodetic {
        lat_rad: lat_deg.to_radians(),
        lon_rad: 0.0,
        height_m,
    };
    let r = geodetic_to_ecef(&ell, &g);
    let gj = gravity_ecef(&ell, GravityModel::J2, &r);
    let gn = gravity_ecef(&ell, GravityModel::Normal, &r);
    let gp = gravity_ecef(&ell, GravityModel::PointMass, &r);
    let c = c_e_n(g.lat_rad, g.lon_rad);
    let north: Vector3<f64> = c.column(0).into();
    let down: Vector3<f64> = c.column(2).into();
    let defl = |v: &Vector3<f64>| v.dot(&north).atan2(v.dot(&down)) * ARCSEC_PER_RAD;
    Point {
        lat_deg,
        height_m,
        mag_diff_j2_m_s2: gj.norm() - gn.norm(),
        mag_diff_pm_m_s2: gp.norm() - gn.norm(),
        mag_diff_pm_j2_m_s2: gp.norm() - gj.norm(),
        defl_j2_arcsec: defl(&gj),
        defl_pm_arcsec: defl(&gp),
        angle_pm_j2_arcsec: gp.angle(&gj) * ARCSEC_PER_RAD,
        normal_m_s2: gn.norm(),
    }
}

/// The largest |figure| over the grid, where it occurs (before any unit scaling).
#[derive(Debug, Clone, Copy)]
struct GridMaximum {
    /// The signed figure at the maximum of its magnitude.
    value: f64,
    lat_deg: f64,
    height_m: f64,
}

/// Maximum of |f(p)| over the grid (which is never empty) with its location.
fn max_abs(points: &[Point], f: impl Fn(&Point) -> f64) -> GridMaximum {
    points
        .iter()
        .map(|p| (f(p), p))
        .max_by(|a, b| a.0.abs().total_cmp(&b.0.abs()))
        .map_or(
            GridMaximum {
                value: f64::NAN,
                lat_deg: f64::NAN,
                height_m: f64::NAN,
            },
            |(value, p)| GridMaximum {
                value,
                lat_deg: p.lat_deg,
                height_m: p.height_m,
            },
        )
}

/// A maximum magnitude difference over the grid, in mGal, and where it occurs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MaximumMgal {
    /// |difference|, mGal.
    pub value_mgal: f64,
    /// The difference with its sign, mGal.
    pub signed_value: f64,
    /// Geodetic latitude of the maximum, deg.
    pub at_latitude_deg: f64,
    /// Height of the maximum, m.
    pub at_height_m: f64,
}

impl From<GridMaximum> for MaximumMgal {
    fn from(m: GridMaximum) -> Self {
        Self {
            value_mgal: m.value.abs() * MGAL_PER_M_S2,
            signed_value: m.value * MGAL_PER_M_S2,
            at_latitude_deg: m.lat_deg,
            at_height_m: m.height_m,
        }
    }
}

/// A maximum angle over the grid, in arcsec, and where it occurs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MaximumArcsec {
    /// |angle|, arcsec.
    pub value_arcsec: f64,
    /// The angle with its sign (deflections: north positive), arcsec.
    pub signed_value: f64,
    /// Geodetic latitude of the maximum, deg.
    pub at_latitude_deg: f64,
    /// Height of the maximum, m.
    pub at_height_m: f64,
}

impl From<GridMaximum> for MaximumArcsec {
    fn from(m: GridMaximum) -> Self {
        Self {
            value_arcsec: m.value.abs(),
            signed_value: m.value,
            at_latitude_deg: m.lat_deg,
            at_height_m: m.height_m,
        }
    }
}

/// The models at sea level at one latitude.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SeaLevelRow {
    /// Geodetic latitude, deg.
    pub latitude_deg: f64,
    /// Normal gravity magnitude, m/s².
    pub normal_gravity_m_s2: f64,
    /// |g| J2 − normal, mGal.
    pub j2_minus_normal_mgal: f64,
    /// |g| point mass − normal, mGal.
    pub point_mass_minus_normal_mgal: f64,
    /// J2 gravity's deflection from the ellipsoid normal (north +), arcsec.
    pub j2_deflection_from_normal_arcsec: f64,
    /// Point-mass gravity's deflection from the ellipsoid normal (north +), arcsec.
    pub point_mass_deflection_from_normal_arcsec: f64,
}

/// The figures of `gravity` (`summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `"gravity"`.
    pub experiment: String,
    /// The paper reproduced, `"002"`.
    pub paper: String,
    /// `"WGS-84"`.
    pub ellipsoid: String,
    /// Latitudes of the grid, deg.
    pub latitude_range_deg: [f64; 2],
    /// Latitude step, deg.
    pub latitude_step_deg: f64,
    /// Heights of the grid, m.
    pub height_range_m: [f64; 2],
    /// Height step, m.
    pub height_step_m: f64,
    /// Number of grid points.
    pub grid_points: usize,
    /// max ||g| J2 − |γ||, m/s².
    pub max_abs_magnitude_difference_j2_minus_normal_m_s2: f64,
    /// The same in mGal, with its location.
    pub max_abs_magnitude_difference_j2_minus_normal_mgal: MaximumMgal,
    /// Largest deflection of J2 gravity from the ellipsoid normal.
    pub max_abs_deflection_j2_from_normal_arcsec: MaximumArcsec,
    /// max ||g| point mass − |γ||, m/s².
    pub max_abs_magnitude_difference_point_mass_minus_normal_m_s2: f64,
    /// The same in mGal, with its location.
    pub max_abs_magnitude_difference_point_mass_minus_normal_mgal: MaximumMgal,
    /// Largest deflection of point-mass gravity from the ellipsoid normal.
    pub max_abs_deflection_point_mass_from_normal_arcsec: MaximumArcsec,
    /// max ||g| point mass − |g| J2|, mGal, with its location.
    pub max_abs_magnitude_difference_point_mass_minus_j2_mgal: MaximumMgal,
    /// Largest angle between the point-mass and J2 vectors.
    pub max_angle_point_mass_vs_j2_arcsec: MaximumArcsec,
    /// The models at sea level at latitudes 0, 15, …, 90°.
    pub sea_level_every_15_deg: Vec<SeaLevelRow>,
}

experiment!(
    /// `sextant experiment gravity`.
    Gravity,
    "gravity",
    "Paper 002: J2 gravity against normal gravity and a point mass"
);

/// The measurement with `settings` into the existing `out_dir` (plots); returns the summary
/// ([`Experiment::run_with`] writes it to `summary.json`).
fn measure(
    settings: &Settings,
    out_dir: &Path,
    _progress: bool,
) -> Result<Summary, ExperimentError> {
    if !(settings.latitude_step_deg > 0.0
        && settings.height_step_m > 0.0
        && settings.max_height_m >= 0.0
        && settings.max_height_m.is_finite())
    {
        return Err(ExperimentError::Measurement(format!(
            "invalid grid settings {settings:?}"
        )));
    }
    let n_lat = (90.0 / settings.latitude_step_deg).round() as usize;
    let n_h = (settings.max_height_m / settings.height_step_m).round() as usize;
    let mut points = Vec::with_capacity((n_lat + 1) * (n_h + 1));
    for i in 0..=n_lat {
        let lat = (i as f64 * settings.latitude_step_deg).min(90.0);
        for j in 0..=n_h {
            let h = (j as f64 * settings.height_step_m).min(settings.max_height_m);
            points.push(evaluate(lat, h));
        }
    }
    let at_sea_level = (0..=6)
        .map(|k| {
            let p = evaluate(15.0 * k as f64, 0.0);
            SeaLevelRow {
                latitude_deg: p.lat_deg,
                normal_gravity_m_s2: p.normal_m_s2,
                j2_minus_normal_mgal: p.mag_diff_j2_m_s2 * MGAL_PER_M_S2,
                point_mass_minus_normal_mgal: p.mag_diff_pm_m_s2 * MGAL_PER_M_S2,
                j2_deflection_from_normal_arcsec: p.defl_j2_arcsec,
                point_mass_deflection_from_normal_arcsec: p.defl_pm_arcsec,
            }
        })
        .collect();
    let j2_magnitude = max_abs(&points, |p| p.mag_diff_j2_m_s2);
    let pm_magnitude = max_abs(&points, |p| p.mag_diff_pm_m_s2);
    let summary = Summary {
        experiment: Gravity::NAME.into(),
        paper: "002".into(),
        ellipsoid: "WGS-84".into(),
        latitude_range_deg: [0.0, 90.0],
        latitude_step_deg: settings.latitude_step_deg,
        height_range_m: [0.0, settings.max_height_m],
        height_step_m: settings.height_step_m,
        grid_points: points.len(),
        max_abs_magnitude_difference_j2_minus_normal_m_s2: j2_magnitude.value.abs(),
        max_abs_magnitude_difference_j2_minus_normal_mgal: j2_magnitude.into(),
        max_abs_deflection_j2_from_normal_arcsec: max_abs(&points, |p| p.defl_j2_arcsec).into(),
        max_abs_magnitude_difference_point_mass_minus_normal_m_s2: pm_magnitude.value.abs(),
        max_abs_magnitude_difference_point_mass_minus_normal_mgal: pm_magnitude.into(),
        max_abs_deflection_point_mass_from_normal_arcsec: max_abs(&points, |p| p.defl_pm_arcsec)
            .into(),
        max_abs_magnitude_difference_point_mass_minus_j2_mgal: max_abs(&points, |p| {
            p.mag_diff_pm_j2_m_s2
        })
        .into(),
        max_angle_point_mass_vs_j2_arcsec: max_abs(&points, |p| p.angle_pm_j2_arcsec).into(),
        sea_level_every_15_deg: at_sea_level,
    };

    let heights = [0.0, 10_000.0, settings.max_height_m];
    let curves = |f: &PointFigure| -> Vec<Line> {
        heights
            .iter()
            .enumerate()
            .map(|(k, &h)| {
                Line::solid(
                    format!("h = {:.0} km", h / 1000.0),
                    (0..=n_lat)
                        .map(|i| {
                            let p = evaluate((i as f64 * settings.latitude_step_deg).min(90.0), h);
                            (p.lat_deg, f(&p))
                        })
                        .collect(),
                    color(k),
                )
            })
            .collect()
    };
    let charts: [(&str, &str, &str, &PointFigure); 4] = [
        (
            "gravity_magnitude_j2_minus_normal_mgal.png",
            "|g| J2 − normal gravity (Somigliana + free air)",
            "magnitude difference [mGal]",
            &|p| p.mag_diff_j2_m_s2 * MGAL_PER_M_S2,
        ),
        (
            "gravity_magnitude_point_mass_minus_normal_mgal.png",
            "|g| point mass − normal gravity (Somigliana + free air)",
            "magnitude difference [mGal]",
            &|p| p.mag_diff_pm_m_s2 * MGAL_PER_M_S2,
        ),
        (
            "gravity_deflection_j2_from_normal_arcsec.png",
            "J2 gravity: deflection from the ellipsoid normal (north +)",
            "deflection [arcsec]",
            &|p| p.defl_j2_arcsec,
        ),
        (
            "gravity_deflection_point_mass_from_normal_arcsec.png",
            "Point-mass gravity: deflection from the ellipsoid normal (north +)",
            "deflection [arcsec]",
            &|p| p.defl_pm_arcsec,
        ),
    ];
    for (file, title, y_label, f) in charts {
        line_chart(
            &out_dir.join(file),
            &Chart::linear(title, "geodetic latitude [deg]", y_label, &curves(f)),
        )?;
    }
    Ok(summary)
}

/// Human table: maxima over the grid and the sea-level profile.
pub fn table(summary: &Summary) -> String {
    let s = summary;
    let mut out = String::new();
    out.push_str(
        "Gravity models over latitude 0–90°, height 0–20 km (reference: normal gravity)\n",
    );
    out.push_str(&format!(
        "{:<44} {:>12} {:>9} {:>10}\n",
        "maximum |difference|", "value", "lat [°]", "h [m]"
    ));
    let mgal = |m: &MaximumMgal| (m.value_mgal, m.at_latitude_deg, m.at_height_m);
    let arcsec = |m: &MaximumArcsec| (m.value_arcsec, m.at_latitude_deg, m.at_height_m);
    for (label, (value, lat, h)) in [
        (
            "J2 − normal, magnitude [mGal]",
            mgal(&s.max_abs_magnitude_difference_j2_minus_normal_mgal),
        ),
        (
            "J2 deflection from normal [arcsec]",
            arcsec(&s.max_abs_deflection_j2_from_normal_arcsec),
        ),
        (
            "point mass − normal, magnitude [mGal]",
            mgal(&s.max_abs_magnitude_difference_point_mass_minus_normal_mgal),
        ),
        (
            "point-mass deflection from normal [arcsec]",
            arcsec(&s.max_abs_deflection_point_mass_from_normal_arcsec),
        ),
        (
            "point mass − J2, magnitude [mGal]",
            mgal(&s.max_abs_magnitude_difference_point_mass_minus_j2_mgal),
        ),
        (
            "angle point mass vs J2 [arcsec]",
            arcsec(&s.max_angle_point_mass_vs_j2_arcsec),
        ),
    ] {
        out.push_str(&format!(
            "{:<44} {:>12} {:>9} {:>10}\n",
            label,
            fmt_f64(value, 3, false),
            fmt_f64(lat, 1, false),
            fmt_f64(h, 0, false),
        ));
    }
    out.push_str(&format!(
        "\n{:>8} {:>14} {:>12} {:>12} {:>12} {:>12}\n",
        "lat [°]", "γ [m/s²]", "J2−γ [mGal]", "PM−γ [mGal]", "J2 defl [\"]", "PM defl [\"]"
    ));
    for row in &s.sea_level_every_15_deg {
        out.push_str(&format!(
            "{:>8} {:>14} {:>12} {:>12} {:>12} {:>12}\n",
            fmt_f64(row.latitude_deg, 0, false),
            fmt_f64(row.normal_gravity_m_s2, 7, false),
            fmt_f64(row.j2_minus_normal_mgal, 2, false),
            fmt_f64(row.point_mass_minus_normal_mgal, 0, false),
            fmt_f64(row.j2_deflection_from_normal_arcsec, 3, false),
            fmt_f64(row.point_mass_deflection_from_normal_arcsec, 1, false),
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn model_differences_are_as_expected() {
        let dir = crate::experiments::test_dir("gravity");
        let s = Gravity::run(&dir, false).expect("run");
        eprintln!("{}", table(&s));
        // J2 against the full normal field: only the higher zonal terms differ.
        let j2_mgal = s
            .max_abs_magnitude_difference_j2_minus_normal_mgal
            .value_mgal;
        let j2_defl = s.max_abs_deflection_j2_from_normal_arcsec.value_arcsec;
        assert!(j2_mgal > 0.1 && j2_mgal < 20.0, "{j2_mgal} mGal");
        // ≈ 1″ from the higher zonal terms plus ≈ 0.17″/km · 20 km · sin 2φ of plumb-line
        // curvature that the normal model (gravity along the ellipsoid normal) leaves out.
        assert!(j2_defl < 6.0, "{j2_defl} arcsec");
        let mut sea_level_max: f64 = 0.0;
        for i in 0..=90 {
            sea_level_max = sea_level_max.max(evaluate(i as f64, 0.0).defl_j2_arcsec.abs());
        }
        assert!(sea_level_max < 2.0, "{sea_level_max} arcsec at h = 0");
        // The point mass ignores the flattening: γ_p − GM/b² ≈ −3200 mGal at the pole,
        // γ_e − (GM/a² − ω²a) ≈ +1600 mGal at the equator.
        let pm_mgal = s
            .max_abs_magnitude_difference_point_mass_minus_normal_mgal
            .value_mgal;
        assert!(pm_mgal > 2000.0 && pm_mgal < 5000.0, "{pm_mgal} mGal");
        let pm_defl = s
            .max_abs_deflection_point_mass_from_normal_arcsec
            .value_arcsec;
        assert!(pm_defl > 300.0 && pm_defl < 1000.0, "{pm_defl} arcsec");
        // Symmetry: no deflection on the equator and at the pole.
        for lat in [0.0, 90.0] {
            let p = evaluate(lat, 5000.0);
            assert!(
                p.defl_j2_arcsec.abs() < 1e-6 && p.defl_pm_arcsec.abs() < 1e-6,
                "{p:?}"
            );
        }
        for png in [
            "gravity_magnitude_j2_minus_normal_mgal.png",
            "gravity_magnitude_point_mass_minus_normal_mgal.png",
            "gravity_deflection_j2_from_normal_arcsec.png",
            "gravity_deflection_point_mass_from_normal_arcsec.png",
            "summary.json",
        ] {
            assert!(dir.join(png).is_file(), "{png}");
        }
        // summary.json reads back as the summary.
        let json = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
        assert_eq!(serde_json::from_str::<Summary>(&json).expect("parse"), s);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
