//! KF-GINS's own configuration (its YAML, KF-GINS README "Configuration") for the files
//! `sextant export kfgins` writes, so that the peer runs on the same data with the same sensor
//! knowledge as Sextant: `KF-GINS kf-gins.yaml` in the export directory.
//!
//! - Start: KF-GINS does not align; it starts from a given state. It is given Sextant's first
//!   solution (the end of Sextant's own alignment: the same starting knowledge, its estimated
//!   biases and scale factors, its 1-σ), or, in a recording without solutions, the truth's first
//!   pose at or after the first IMU epoch (KF-GINS refuses to start before it) with the 1-σ of
//!   the filter's `[initial]` (zero biases: the truth's are not given).
//!   The level attitude σ is the RMS of Sextant's north and east ones, the heading σ its down.
//! - The IMU class of the filter's `[imu]` in KF-GINS's units: ARW °/√h, VRW m/s/√h, gyro bias
//!   °/h, accelerometer bias mGal, scale factors ppm. KF-GINS models the biases and scale
//!   factors as first-order Gauss–Markov processes of one correlation time T; Sextant as a
//!   prior σ plus a random walk q. A Gauss–Markov process of steady σ and time T drifts at
//!   first as a random walk of density √(2σ²/T), so T = 2σ²/q² matches the gyro's (the
//!   heading's error source); without a random walk the biases are constants, T = 10⁴ h.
//! - The antenna lever arm of the filter's `[gnss]` (body x forward, y right, z down, as
//!   KF-GINS's).

use super::text::{format_f64, format_seconds_ns, week_and_sow_ns};
use fusion::navigator::NavigatorConfig;
use fusion::time::GpsTime;
use msgs::{ImuSample, NavSolution, TruthSample};
use std::fmt::Write as _;

/// File name of KF-GINS's configuration in the export directory.
pub const KFGINS_CONFIG_FILE: &str = "kf-gins.yaml";

/// Correlation time given to KF-GINS when the filter's biases have no random walk, h.
pub const CONSTANT_BIAS_CORR_TIME_H: f64 = 1e4;

const DEG: f64 = std::f64::consts::PI / 180.0;
/// m/s² per mGal.
const MGAL: f64 = 1e-5;

/// The state KF-GINS starts from when the recording has no solution: the truth's first pose,
/// zero biases and scale factors, the 1-σ of the filter's `[initial]` and `[imu]`.
pub fn start_from_truth(truth: &TruthSample, cfg: &NavigatorConfig) -> NavSolution {
    let level = cfg.initial.level_sigma_min_deg * DEG;
    let mut s = NavSolution {
        header: truth.header,
        lat_rad: truth.lat_rad,
        lon_rad: truth.lon_rad,
        height_m: truth.height_m,
        vel_ned_m_s: truth.vel_ned_m_s,
        roll_pitch_heading_rad: truth.roll_pitch_heading_rad,
        pos_sigma_ned_m: [cfg.initial.position_sigma_m; 3],
        vel_sigma_ned_m_s: [cfg.initial.velocity_sigma_m_s; 3],
        att_sigma_ned_rad: [level, level, cfg.initial.heading_sigma_min_deg * DEG],
        gyro_bias_sigma_rad_s: [cfg.imu.gyro_bias_rad_s(); 3],
        accel_bias_sigma_m_s2: [cfg.imu.accel_bias_m_s2(); 3],
        ..Default::default()
    };
    s.header.time_ns = truth.header.time_ns;
    s
}

/// The IMU rate KF-GINS is told, Hz (an integer in its configuration): the median interval's.
pub fn imu_rate_hz(imu: &[ImuSample]) -> Option<u32> {
    let mut dt: Vec<f64> = imu
        .iter()
        .map(|s| s.dt_s)
        .filter(|d| *d > 0.0 && d.is_finite())
        .collect();
    if dt.is_empty() {
        return None;
    }
    let mid = dt.len() / 2;
    let (_, median, _) = dt.select_nth_unstable_by(mid, f64::total_cmp);
    Some((1.0 / *median).round() as u32)
}

/// KF-GINS's configuration: the files of the export directory, `start` and its 1-σ, the IMU
/// class and the lever arm of `cfg` (see the module comment).
pub fn config_text(cfg: &NavigatorConfig, imu_rate_hz: u32, start: &NavSolution) -> String {
    let v3 = |v: [f64; 3], k: f64| format!("[{}]", v.map(|x| format_f64(x * k)).join(", "));
    let v3s = |x: f64| v3([x; 3], 1.0);
    let noise = cfg.imu.process_noise();
    let gyro_bias_deg_h = cfg.imu.gyro_bias_deg_h;
    let gyro_rw_deg_h_sqrt_h = cfg.imu.gyro_bias_rw_deg_h_sqrt_h;
    let corr_time_h = if gyro_rw_deg_h_sqrt_h > 0.0 {
        2.0 * gyro_bias_deg_h * gyro_bias_deg_h / (gyro_rw_deg_h_sqrt_h * gyro_rw_deg_h_sqrt_h)
    } else {
        CONSTANT_BIAS_CORR_TIME_H
    };
    let [sn, se, sd] = start.att_sigma_ned_rad;
    let level_sigma = ((sn * sn + se * se) / 2.0).sqrt();
    let (_, sow_ns) = week_and_sow_ns(GpsTime::from_ns(start.header.time_ns));
    let mut t = String::from(
        "# KF-GINS configuration written by `sextant export kfgins`: run `KF-GINS kf-gins.yaml`\n\
         # in this directory.\n",
    );
    let mut line = |k: &str, v: String| {
        let _ = writeln!(t, "{k}: {v}");
    };
    line("imupath", "\"imu.txt\"".into());
    line("gnsspath", "\"gnss.txt\"".into());
    line("outputpath", "\".\"".into());
    line("imudatalen", "7".into());
    line("imudatarate", imu_rate_hz.to_string());
    line("starttime", format_seconds_ns(sow_ns));
    line("endtime", "-1".into());
    // Degrees as the result and trajectory files write them.
    let (lat_deg, lon_deg) = (start.lat_rad.to_degrees(), start.lon_rad.to_degrees());
    line("initpos", v3([lat_deg, lon_deg, start.height_m], 1.0));
    line("initvel", v3(start.vel_ned_m_s, 1.0));
    line(
        "initatt",
        v3(start.roll_pitch_heading_rad.map(f64::to_degrees), 1.0),
    );
    line("initgyrbias", v3(start.gyro_bias_rad_s, 3600.0 / DEG));
    line("initaccbias", v3(start.accel_bias_m_s2, 1.0 / MGAL));
    line("initgyrscale", v3(start.gyro_scale_ppm, 1.0));
    line("initaccscale", v3(start.accel_scale_ppm, 1.0));
    line("initposstd", v3(start.pos_sigma_ned_m, 1.0));
    line("initvelstd", v3(start.vel_sigma_ned_m_s, 1.0));
    line("initattstd", v3([level_sigma, level_sigma, sd], 1.0 / DEG));
    line("initbgstd", v3(start.gyro_bias_sigma_rad_s, 3600.0 / DEG));
    line("initbastd", v3(start.accel_bias_sigma_m_s2, 1.0 / MGAL));
    line("initsgstd", v3s(cfg.imu.gyro_scale_ppm));
    line("initsastd", v3s(cfg.imu.accel_scale_ppm));
    line("imunoise", String::new());
    line("  arw", v3s(noise.arw_rad_sqrt_s / DEG * 60.0));
    line("  vrw", v3s(noise.vrw_m_s_sqrt_s * 60.0));
    line("  gbstd", v3s(gyro_bias_deg_h));
    line("  abstd", v3s(cfg.imu.accel_bias_m_s2() / MGAL));
    line("  gsstd", v3s(cfg.imu.gyro_scale_ppm));
    line("  asstd", v3s(cfg.imu.accel_scale_ppm));
    line("  corrtime", format_f64(corr_time_h));
    line("antlever", v3(cfg.gnss.lever_arm_b_m, 1.0));
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    fn value<'a>(text: &'a str, key: &str) -> &'a str {
        text.lines()
            .find_map(|l| l.strip_prefix(&format!("{key}: ")))
            .unwrap_or_else(|| panic!("no {key} in\n{text}"))
    }

    fn numbers(s: &str) -> Vec<f64> {
        s.trim_matches(|c| c == '[' || c == ']')
            .split(',')
            .map(|x| x.trim().parse().unwrap())
            .collect()
    }

    /// The car's IMU class in KF-GINS's units, by hand: 20 µg/√Hz = 20e-6 · 9.80665 m/s/√s
    /// = 0.011768 m/s/√h; 50 µg = 49.03 mGal; T = 2 · 0.01² / 0.002² = 50 h.
    #[test]
    fn the_imu_class_is_converted_to_kfgins_units() {
        let mut cfg = NavigatorConfig::default();
        cfg.imu.arw_deg_sqrt_h = 0.002;
        cfg.imu.vrw_ug_sqrt_hz = 20.0;
        cfg.imu.gyro_bias_deg_h = 0.01;
        cfg.imu.gyro_bias_rw_deg_h_sqrt_h = 0.002;
        cfg.imu.accel_bias_ug = 50.0;
        cfg.imu.gyro_scale_ppm = 50.0;
        cfg.imu.accel_scale_ppm = 100.0;
        cfg.gnss.lever_arm_b_m = [0.3, 0.0, -1.5];
        let mut start = NavSolution {
            lat_rad: 55.655 * DEG,
            lon_rad: 37.534 * DEG,
            height_m: 200.0,
            roll_pitch_heading_rad: [0.1 * DEG, -0.2 * DEG, 30.0 * DEG],
            gyro_bias_rad_s: [0.0, 0.0, 0.005 * DEG / 3600.0],
            accel_bias_m_s2: [1e-4, 0.0, 0.0],
            att_sigma_ned_rad: [0.003 * DEG, 0.004 * DEG, 0.05 * DEG],
            ..Default::default()
        };
        // GPS week 2358, 421318.005 s of week.
        start.header.time_ns = (2358 * 604_800 + 421_318) * 1_000_000_000 + 5_000_000;
        let t = config_text(&cfg, 200, &start);
        let close = |got: &[f64], want: &[f64], tol: f64| {
            assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() <= tol, "{got:?} vs {want:?}");
            }
        };
        assert_eq!(value(&t, "starttime"), "421318.005000000");
        assert_eq!(value(&t, "imudatarate"), "200");
        close(&numbers(value(&t, "  arw")), &[0.002; 3], 1e-15);
        close(&numbers(value(&t, "  vrw")), &[0.011_767_98; 3], 1e-8);
        close(&numbers(value(&t, "  gbstd")), &[0.01; 3], 1e-15);
        close(&numbers(value(&t, "  abstd")), &[49.033_25; 3], 1e-9);
        close(&numbers(value(&t, "  gsstd")), &[50.0; 3], 0.0);
        close(&numbers(value(&t, "  asstd")), &[100.0; 3], 0.0);
        close(&[value(&t, "  corrtime").parse().unwrap()], &[50.0], 1e-9);
        close(&numbers(value(&t, "antlever")), &[0.3, 0.0, -1.5], 0.0);
        close(
            &numbers(value(&t, "initpos")),
            &[55.655, 37.534, 200.0],
            1e-12,
        );
        close(&numbers(value(&t, "initatt")), &[0.1, -0.2, 30.0], 1e-12);
        close(
            &numbers(value(&t, "initgyrbias")),
            &[0.0, 0.0, 0.005],
            1e-15,
        );
        close(&numbers(value(&t, "initaccbias")), &[10.0, 0.0, 0.0], 1e-12);
        // Level σ: the RMS of north and east.
        let level = ((0.003f64.powi(2) + 0.004f64.powi(2)) / 2.0).sqrt();
        close(
            &numbers(value(&t, "initattstd")),
            &[level, level, 0.05],
            1e-12,
        );
        // No random walk: constant biases.
        cfg.imu.gyro_bias_rw_deg_h_sqrt_h = 0.0;
        let t = config_text(&cfg, 200, &start);
        assert_eq!(
            value(&t, "  corrtime"),
            format_f64(CONSTANT_BIAS_CORR_TIME_H)
        );
    }

    #[test]
    fn the_rate_is_the_median_interval() {
        let mut imu = vec![ImuSample::default(); 5];
        for (s, dt) in imu.iter_mut().zip([0.005, 0.005, 0.01, 0.005, 0.0]) {
            s.dt_s = dt;
        }
        assert_eq!(imu_rate_hz(&imu), Some(200));
        assert_eq!(imu_rate_hz(&[]), None);
    }
}
