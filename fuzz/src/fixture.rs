//! The navigator fixture shared by the fuzz target [`crate::samples`] and its proptest twin in
//! `tests/tests/bad_input.rs`, which includes this file with `#[path]`: `fuzz/` is its own
//! workspace outside the main one (so that `cargo test --workspace` neither builds nor runs
//! it), so neither crate can depend on the other without pulling it into the other's build.
//! Needs only `fusion`, `msgs` and `toml`, which both have.

use fusion::navigator::{Navigator, NavigatorConfig};
use msgs::{GnssSample, ImuSample};

/// A static navigator that has aligned (2 s of level, north-facing IMU at 200 Hz at 55.7° N,
/// 37.5° E, 200 m, with a GNSS fix of that site at 1 Hz) under the filter tuning `filter_toml`
/// (the text of `config/filter.toml`), and the last IMU sample it took; an error names what
/// failed.
pub fn aligned_static_navigator(filter_toml: &str) -> Result<(Navigator, ImuSample), String> {
    let mut cfg: NavigatorConfig =
        toml::from_str(filter_toml).map_err(|e| format!("filter.toml: {e}"))?;
    cfg.alignment_s = 2.0;
    let mut nav = Navigator::new(cfg).map_err(|e| format!("filter.toml: {e}"))?;
    // ECEF of the site from the WGS-84 closed form.
    let (lat, lon, h) = (55.7f64.to_radians(), 37.5f64.to_radians(), 200.0);
    let (a, e2) = (6_378_137.0, 6.694_379_990_14e-3);
    let rn = a / (1.0 - e2 * lat.sin().powi(2)).sqrt();
    let r = [
        (rn + h) * lat.cos() * lon.cos(),
        (rn + h) * lat.cos() * lon.sin(),
        (rn * (1.0 - e2) + h) * lat.sin(),
    ];
    let t0 = 1_398_556_800_000_000_000i64;
    let dt = 0.005;
    // Level, heading north: f_b = (0, 0, -g), ω_ib^b = Ω(cos φ, 0, -sin φ).
    let w = 7.292_115e-5;
    let mut last = ImuSample::default();
    for k in 1..=600i64 {
        let mut s = ImuSample::default();
        s.header.seq = k as u64;
        s.header.time_ns = t0 + k * 5_000_000;
        s.dt_s = dt;
        s.delta_angle_rad = [w * lat.cos() * dt, 0.0, -w * lat.sin() * dt];
        s.delta_velocity_m_s = [0.0, 0.0, -9.8155 * dt];
        if k % 200 == 1 {
            let mut g = GnssSample::default();
            g.header.seq = k as u64;
            g.header.time_ns = s.header.time_ns;
            g.fix_valid = 1;
            g.pos_ecef_m = r;
            g.pos_cov_ecef_m2 = [4.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 4.0];
            let _ = nav.push_gnss(&g);
        }
        let _ = nav.push_imu(&s);
        last = s;
    }
    if !nav.is_navigating() {
        return Err("the fixture did not finish its alignment".into());
    }
    Ok((nav, last))
}

/// Position, velocity and covariance of `nav` are all finite.
pub fn state_is_finite(nav: &Navigator) -> bool {
    let x = nav.nav_state();
    x.r_e.iter().all(|v| v.is_finite())
        && x.v_e.iter().all(|v| v.is_finite())
        && nav.covariance().iter().all(|v| v.is_finite())
}
