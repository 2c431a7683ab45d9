//! `sextant experiment world-budget`: how much navigation error each effect of the simulated
//! world causes on its own.
//!
//! The default scenario (`config/scenarios/vehicle.toml`) is run once on the matched world (no
//! `[world]`: every error is one the filter models, the filter installed at the IMU), once
//! with each effect its `[world]` describes switched on alone, and once with all of them; the
//! filter is the shipped tuning told the car of that world (`config/filter.toml`) for the
//! effects present
//! (`drivers_sim::matched::installed_for`: the antenna's lever arm and time tag only where the
//! world has the antenna, and so on). For each run: the solution's horizontal, vertical and
//! attitude error RMS after `from_s` and its mean position NEES, and the effect's share, the
//! RMS above the matched run's in quadrature, `√max(0, rms² − rms₀²)` (errors of independent
//! causes add in their squares; a share of 0 is an effect the filter absorbs completely).
//! One seed: the world's draws (weather, the unit's scatter, the satellites' errors) are the
//! scenario's, so a share is one draw of that effect, not its expectation.

use super::consistency::{filter_config, installed};
use super::plot::{Chart, Line, color, line_chart};
use super::{Experiment, ExperimentError, fmt_f64, measurement, progress_bar, scenario_file};
use drivers_sim::offline::{OfflineSim, RunPoint, run_navigator};
use drivers_sim::scenario::Scenario;
use drivers_sim::world::WorldSection;
use fusion::navigator::Navigator;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Settings of the experiment.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Scenario file in `config/scenarios` (it must have a `[world]`).
    pub scenario: String,
    /// Statistics from this time on, s since the scenario start (after alignment and
    /// convergence).
    pub from_s: f64,
    /// Scenario duration override, s (None: the file's).
    pub duration_s: Option<f64>,
    /// The effects to budget (None: every effect the scenario's `[world]` describes).
    pub effects: Option<Vec<&'static str>>,
}

impl Default for Settings {
    fn default() -> Self {
        Self {
            scenario: "vehicle.toml".into(),
            from_s: 150.0,
            duration_s: None,
            effects: None,
        }
    }
}

/// One run's figures.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Row {
    /// `"matched"`, an effect's table name, or `"whole world"`.
    pub world: String,
    /// Solution horizontal error RMS, m.
    pub horizontal_rms_m: f64,
    /// Solution vertical error RMS, m.
    pub vertical_rms_m: f64,
    /// Solution attitude error RMS (total angle), arcsec.
    pub attitude_rms_arcsec: f64,
    /// Mean position NEES (3 for a consistent filter).
    pub position_nees_mean: f64,
    /// Horizontal RMS above the matched run's, in quadrature, m.
    pub horizontal_share_m: f64,
    /// Vertical RMS above the matched run's, in quadrature, m.
    pub vertical_share_m: f64,
    /// Attitude RMS above the matched run's, in quadrature, arcsec.
    pub attitude_share_arcsec: f64,
}

/// The budget.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Summary {
    /// `"world-budget"`.
    pub experiment: String,
    /// Whether the data is simulated (always: the world is the simulator's).
    pub data: String,
    /// The scenario file.
    pub scenario: String,
    /// Statistics from this time on, s.
    pub from_s: f64,
    /// The scenario's duration, s.
    pub duration_s: f64,
    /// The matched run, each effect alone, the whole world.
    pub rows: Vec<Row>,
    /// Wall time of the experiment, s.
    pub wall_s: f64,
}

experiment!(
    /// `sextant experiment world-budget`.
    WorldBudget,
    "world-budget",
    "Error budget of the simulated world (each effect alone on the default scenario)"
);

/// (horizontal RMS m, vertical RMS m, attitude RMS arcsec, mean position NEES) after `from_s`.
fn one_run(scn: &Scenario, from_s: f64) -> Result<(f64, f64, f64, f64), ExperimentError> {
    let cfg = installed(scn, filter_config(&[])?)?;
    let sim = OfflineSim::new(scn);
    let epoch = sim.epoch_ns();
    let mut nav = Navigator::new(cfg).map_err(measurement)?;
    let (mut h2, mut v2, mut a2, mut nees, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0);
    run_navigator(sim, epoch, &mut nav, |p: &RunPoint| {
        if p.t_s < from_s {
            return;
        }
        let e = p.pos_err_ned_m();
        h2 += e.x * e.x + e.y * e.y;
        v2 += e.z * e.z;
        a2 += p.att_err_e_rad.norm_squared();
        nees += p.nees()[0];
        n += 1.0;
    })
    .map_err(measurement)?;
    if n == 0.0 {
        return Err(measurement(format!(
            "no solution after {from_s} s: the filter never navigated"
        )));
    }
    Ok((
        (h2 / n).sqrt(),
        (v2 / n).sqrt(),
        (a2 / n).sqrt().to_degrees() * 3600.0,
        nees / n,
    ))
}

fn measure(
    settings: &Settings,
    out_dir: &Path,
    progress: bool,
) -> Result<Summary, ExperimentError> {
    let wall = std::time::Instant::now();
    let mut base = Scenario::load(&scenario_file(&settings.scenario)).map_err(measurement)?;
    if let Some(d) = settings.duration_s {
        base.spec.scenario.duration_s = d;
    }
    let world: WorldSection = base.spec.world.ok_or_else(|| {
        measurement(format!(
            "{}: no [world] section, nothing to budget",
            settings.scenario
        ))
    })?;
    // The matched run, each effect the scenario has alone, the whole world.
    let mut worlds: Vec<(String, Option<WorldSection>)> = vec![("matched".into(), None)];
    let present = settings
        .effects
        .clone()
        .unwrap_or_else(|| world.effects_present());
    for name in &present {
        let alone = world.only(&[name]).map_err(measurement)?;
        worlds.push((name.to_string(), Some(alone)));
    }
    let whole = world.only(&present).map_err(measurement)?;
    worlds.push(("whole world".into(), Some(whole)));
    let bar = progress_bar(progress, worlds.len() as u64, "world-budget runs");
    let figures: Vec<(f64, f64, f64, f64)> = worlds
        .par_iter()
        .map(|(_, w)| {
            let mut scn = base.clone();
            scn.spec.world = *w;
            let r = one_run(&scn, settings.from_s);
            bar.inc(1);
            r
        })
        .collect::<Result<_, _>>()?;
    bar.finish_and_clear();
    let (h0, v0, a0, _) = figures[0];
    let share = |x: f64, x0: f64| (x * x - x0 * x0).max(0.0).sqrt();
    let rows: Vec<Row> = worlds
        .iter()
        .zip(&figures)
        .map(|((name, _), &(h, v, a, nees))| Row {
            world: name.clone(),
            horizontal_rms_m: h,
            vertical_rms_m: v,
            attitude_rms_arcsec: a,
            position_nees_mean: nees,
            horizontal_share_m: share(h, h0),
            vertical_share_m: share(v, v0),
            attitude_share_arcsec: share(a, a0),
        })
        .collect();
    plot(out_dir, &rows)?;
    Ok(Summary {
        experiment: WorldBudget::NAME.into(),
        data: "simulated".into(),
        scenario: format!("config/scenarios/{}", settings.scenario),
        from_s: settings.from_s,
        duration_s: base.spec.scenario.duration_s,
        rows,
        wall_s: wall.elapsed().as_secs_f64(),
    })
}

fn plot(out_dir: &Path, rows: &[Row]) -> Result<(), ExperimentError> {
    let pts = |f: fn(&Row) -> f64| -> Vec<(f64, f64)> {
        rows.iter()
            .enumerate()
            .map(|(i, r)| (i as f64, f(r)))
            .collect()
    };
    let lines = [
        Line::solid(
            "horizontal share, m",
            pts(|r| r.horizontal_share_m),
            color(0),
        )
        .with_markers(),
        Line::solid("vertical share, m", pts(|r| r.vertical_share_m), color(1)).with_markers(),
    ];
    let title = format!(
        "error above the matched world by effect (x: {})",
        rows.iter()
            .enumerate()
            .map(|(i, r)| format!("{i} {}", r.world))
            .collect::<Vec<_>>()
            .join(", ")
    );
    line_chart(
        &out_dir.join("world_budget.png"),
        &Chart::linear(
            &title,
            "run (0: matched, last: whole world)",
            "RMS share, m",
            &lines,
        ),
    )
}

/// The budget as a table.
pub fn table(summary: &Summary) -> String {
    let f = |x: f64, d: usize| fmt_f64(x, d, false);
    let mut s = format!(
        "world-budget (SIMULATED): {}, statistics from {} s to {} s; share = RMS above the \
         matched world's in quadrature\n{:<16} {:>8} {:>8} {:>9} {:>8} | {:>8} {:>8} {:>9}\n",
        summary.scenario,
        f(summary.from_s, 0),
        f(summary.duration_s, 0),
        "world",
        "H m",
        "V m",
        "att ″",
        "NEES",
        "H share",
        "V share",
        "att share"
    );
    for r in &summary.rows {
        s.push_str(&format!(
            "{:<16} {:>8} {:>8} {:>9} {:>8} | {:>8} {:>8} {:>9}\n",
            r.world,
            f(r.horizontal_rms_m, 3),
            f(r.vertical_rms_m, 3),
            f(r.attitude_rms_arcsec, 2),
            f(r.position_nees_mean, 2),
            f(r.horizontal_share_m, 3),
            f(r.vertical_share_m, 3),
            f(r.attitude_share_arcsec, 2),
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use drivers_sim::world::EFFECTS;

    /// A short budget of two effects: each has its row between the matched run and the whole
    /// world, the matched run's shares are zero by definition, the summary and the plot are
    /// written; the shipped car's world describes every effect.
    #[test]
    fn short_budget_has_a_row_per_effect() {
        let dir = super::super::test_dir("world-budget");
        let on = vec!["gnss_antenna", "baro"];
        let settings = Settings {
            from_s: 125.0,
            duration_s: Some(135.0),
            effects: Some(on.clone()),
            ..Settings::default()
        };
        let s = WorldBudget::run_with(&settings, &dir, false).unwrap();
        let car = Scenario::load(&scenario_file("vehicle.toml")).unwrap();
        let all = car.spec.world.unwrap().effects_present();
        assert_eq!(all, EFFECTS, "the car's world describes every effect");
        assert_eq!(s.rows.len(), on.len() + 2, "{}", table(&s));
        assert_eq!(s.rows[0].world, "matched");
        assert_eq!(s.rows.last().unwrap().world, "whole world");
        for (r, name) in s.rows[1..].iter().zip(&on) {
            assert_eq!(&r.world, name);
        }
        let m = &s.rows[0];
        assert_eq!(
            (
                m.horizontal_share_m,
                m.vertical_share_m,
                m.attitude_share_arcsec
            ),
            (0.0, 0.0, 0.0)
        );
        assert!(s.rows.iter().all(|r| r.horizontal_rms_m.is_finite()));
        assert!(dir.join("summary.json").exists());
        assert!(dir.join("world_budget.png").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
