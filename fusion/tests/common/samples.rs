//! Samples of a static vehicle shared by the no-allocation tests and the benches: its IMU
//! increments and exact aiding of every sensor (the cost of an update and what it allocates do
//! not depend on the noise). Each test binary uses a part of them.
#![allow(dead_code)]

use msgs::{BaroSample, GnssSample, ImuSample, OdometerSample, StarTrackerSample};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use sextant_fusion::celestial::{EarthOrientation, c_e_i};
use sextant_fusion::earth::{GravityModel, WGS84};
use sextant_fusion::strapdown::{q_e_n, stationary_increment};
use sextant_fusion::time::GpsTime;

/// `N` satellites 20 000 km from `r_e` (ECEF, m) at geodetic latitude and longitude
/// `lat_rad`, `lon_rad`: satellite `i` at azimuth `i·az_step_rad` and elevation
/// `el0_deg + i·el_step_deg`.
pub fn sky<const N: usize>(
    lat_rad: f64,
    lon_rad: f64,
    r_e: &Vector3<f64>,
    az_step_rad: f64,
    el0_deg: f64,
    el_step_deg: f64,
) -> [Vector3<f64>; N] {
    let c_e_n = q_e_n(lat_rad, lon_rad).to_rotation_matrix().into_inner();
    std::array::from_fn(|i| {
        let az = i as f64 * az_step_rad;
        let el = (el0_deg + el_step_deg * i as f64).to_radians();
        let u_n = Vector3::new(az.cos() * el.cos(), az.sin() * el.cos(), -el.sin());
        r_e + c_e_n * u_n * 2.0e7
    })
}

/// The IMU sample (J2 gravity) of a vehicle at rest at `r_e` (ECEF, m) with attitude `q_e_b`
/// over the interval `dt_s` ending at GPS `t_ns`.
pub fn static_imu(
    t_ns: i64,
    seq: u64,
    dt_s: f64,
    r_e: &Vector3<f64>,
    q_e_b: &UnitQuaternion<f64>,
) -> ImuSample {
    let inc = stationary_increment(&WGS84, GravityModel::J2, r_e, q_e_b, dt_s);
    let mut s = ImuSample::default();
    s.header.time_ns = t_ns;
    s.header.seq = seq;
    s.dt_s = dt_s;
    s.delta_angle_rad = inc.delta_angle_rad.into();
    s.delta_velocity_m_s = inc.delta_velocity_m_s.into();
    s
}

/// A GNSS sample with the raw measurements of a receiver at rest at `r_e` (ECEF, m) of the
/// satellites `sats` (ECEF, m): pseudoranges with the clock bias `clock_bias_m`, range rates
/// all equal to the clock drift `clock_drift_m_s`, σ 3 m and 5 cm/s; no fix.
pub fn raw_gnss(
    t_ns: i64,
    seq: u64,
    r_e: &Vector3<f64>,
    sats: &[Vector3<f64>],
    clock_bias_m: f64,
    clock_drift_m_s: f64,
) -> GnssSample {
    let mut g = GnssSample::default();
    g.header.time_ns = t_ns;
    g.header.seq = seq;
    g.n_satellites = sats.len() as u32;
    for (i, r_s) in sats.iter().enumerate() {
        let sat = &mut g.satellites[i];
        sat.prn = i as u32 + 1;
        sat.flags = 3;
        sat.pseudorange_m = (r_s - r_e).norm() + clock_bias_m;
        sat.range_rate_m_s = clock_drift_m_s;
        sat.sigma_pseudorange_m = 3.0;
        sat.sigma_range_rate_m_s = 0.05;
        sat.sat_pos_ecef_m = (*r_s).into();
    }
    g
}

/// Add the receiver's fix at `r_e` (ECEF, m; σ 2 m per axis, velocity σ 1 cm/s) to `g`.
pub fn with_fix(mut g: GnssSample, r_e: &Vector3<f64>) -> GnssSample {
    g.fix_valid = 1;
    g.pos_ecef_m = (*r_e).into();
    g.pos_cov_ecef_m2 = [4.0, 0.0, 0.0, 0.0, 4.0, 0.0, 0.0, 0.0, 4.0];
    g.vel_cov_ecef_m2_s2 = [1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4];
    g
}

/// The star tracker's exact attitude (sensor ← ICRF, IAU 2006/2000A with zero EOP) of a body
/// at `q_e_b` with the tracker mounted at `c_s_b`, at GPS `t_ns`: σ 4″ cross-boresight, 21″
/// about it.
pub fn star(
    t_ns: i64,
    seq: u64,
    c_s_b: &Matrix3<f64>,
    q_e_b: &UnitQuaternion<f64>,
) -> StarTrackerSample {
    let c_s_i = c_s_b
        * q_e_b.to_rotation_matrix().into_inner().transpose()
        * c_e_i(GpsTime { ns: t_ns }, &EarthOrientation::default());
    let q = UnitQuaternion::from_matrix(&c_s_i);
    let mut st = StarTrackerSample::default();
    st.header.time_ns = t_ns;
    st.header.seq = seq;
    st.q_sensor_icrf = [q.w, q.i, q.j, q.k];
    st.sigma_cross_rad = 2e-5;
    st.sigma_roll_rad = 1e-4;
    st.valid = 1;
    st.n_stars = 10;
    st
}

/// A baro sample of `pressure_pa` at 15 °C.
pub fn baro(t_ns: i64, seq: u64, pressure_pa: f64) -> BaroSample {
    let mut b = BaroSample::default();
    b.header.time_ns = t_ns;
    b.header.seq = seq;
    b.pressure_pa = pressure_pa;
    b.temperature_c = 15.0;
    b
}

/// An odometer sample at rest over the interval `dt_s`.
pub fn odometer_at_rest(t_ns: i64, seq: u64, dt_s: f64) -> OdometerSample {
    let mut o = OdometerSample::default();
    o.header.time_ns = t_ns;
    o.header.seq = seq;
    o.dt_s = dt_s;
    o
}
