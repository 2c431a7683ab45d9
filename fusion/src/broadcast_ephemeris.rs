//! GPS broadcast ephemeris: satellite ECEF position, velocity and clock offset at a GPS time,
//! and the transmission-time / Earth-rotation corrections a pseudorange needs.
//!
//! Equations of IS-GPS-200 (revision N):
//! * user algorithm for the ephemeris, §20.3.3.4.3 Table 20-IV: Kepler's equation solved by
//!   Newton's method, second-harmonic corrections `C_uc, C_us, C_rc, C_rs, C_ic, C_is`, the
//!   rate of inclination `IDOT`, the node rate `Ω̇` and the Earth's rotation `Ω̇_e` (the
//!   ascending node `Ω_0` refers to the start of the GPS week, hence the `−Ω̇_e t_oe` term);
//! * satellite velocity: the analytic time derivative of the same equations (the form of
//!   Remondi's note "Computing satellite velocity using the broadcast ephemeris", GPS
//!   Solutions 2004), checked here against a numerical derivative;
//! * clock, §20.3.3.3.3.1: `Δt_sv = a_f0 + a_f1 (t − t_oc) + a_f2 (t − t_oc)² + Δt_r` with the
//!   relativistic term `Δt_r = F e √A sin E_k`, `F = −2√μ / c²`;
//! * group delay, §20.3.3.3.3.2: a single-frequency L1 P(Y) or C/A user applies
//!   `(Δt_sv)_L1 = Δt_sv − T_GD`; the L1/L2 ionosphere-free combination needs no `T_GD`
//!   (the broadcast clock refers to it).
//!
//! Transmission time (§20.3.3.3.3.1): the satellite's own clock time of transmission is
//! `t_sv = t_rx − ρ/c` exactly (the pseudorange is the difference of the two clocks' readings
//! times `c`), and GPS time is `t = t_sv − Δt_sv(t)`, solved by fixed-point iteration (`Δt_sv`
//! changes by < 1e-12 s over the ~1e-3 s correction, two passes suffice).
//!
//! Earth rotation during the signal flight (Sagnac): the ephemeris gives the satellite in the
//! ECEF frame of the transmission instant; a receiver solving in the ECEF frame of reception
//! needs it rotated by `ω_e τ` about the z axis, `τ` the geometric flight time
//! ([`rotate_to_reception`]).
//!
//! Pure: no allocation, no I/O. Times are [`GpsTime`] (integer ns) plus an `f64` offset in
//! seconds, so that differences of a few hours keep sub-picosecond resolution.

use crate::time::{GpsTime, NS_PER_S};
use nalgebra::{Matrix3, Vector3};

/// WGS 84 gravitational constant used by the GPS ephemeris (IS-GPS-200 Table 20-IV), m³/s².
pub const GM_GPS_M3_S2: f64 = 3.986005e14;
/// WGS 84 Earth rotation rate used by the GPS ephemeris, rad/s.
pub const OMEGA_E_GPS_RAD_S: f64 = 7.2921151467e-5;
/// Speed of light in vacuum, m/s (IS-GPS-200 §20.3.4.3).
pub const SPEED_OF_LIGHT_M_S: f64 = 299_792_458.0;
/// Relativistic clock constant `F = −2√μ / c²`, s/√m (IS-GPS-200 §20.3.3.3.3.1: −4.442807633e-10).
pub const F_RELATIVISTIC_S_PER_SQRT_M: f64 = -4.442807633e-10;
/// Seconds in a GPS week.
pub const SECONDS_PER_WEEK: f64 = 604_800.0;

/// Kepler's equation is solved to this accuracy in the eccentric anomaly, rad (1e-15 rad is
/// 3e-8 m along a GPS orbit).
const KEPLER_TOLERANCE_RAD: f64 = 1e-15;
/// Newton iterations allowed for Kepler's equation (converges in ≤ 5 for e < 0.03).
const KEPLER_MAX_ITERATIONS: usize = 30;

/// One GPS LNAV broadcast ephemeris and clock record (the 29 parameters of a RINEX GPS
/// navigation message, subframes 1–3). Angles in radians (RINEX stores them in radians too),
/// times in GPS time.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GpsEphemeris {
    /// Satellite PRN (1–32).
    pub prn: u8,
    /// Clock reference epoch `t_oc`.
    pub toc: GpsTime,
    /// Clock bias `a_f0`, s.
    pub af0_s: f64,
    /// Clock drift `a_f1`, s/s.
    pub af1_s_s: f64,
    /// Clock drift rate `a_f2`, s/s².
    pub af2_s_s2: f64,
    /// Issue of data, ephemeris.
    pub iode: u32,
    /// Issue of data, clock.
    pub iodc: u32,
    /// Orbit radius sine correction `C_rs`, m.
    pub crs_m: f64,
    /// Mean motion difference `Δn`, rad/s.
    pub delta_n_rad_s: f64,
    /// Mean anomaly at reference time `M_0`, rad.
    pub m0_rad: f64,
    /// Argument of latitude cosine correction `C_uc`, rad.
    pub cuc_rad: f64,
    /// Eccentricity `e`.
    pub e: f64,
    /// Argument of latitude sine correction `C_us`, rad.
    pub cus_rad: f64,
    /// Square root of the semi-major axis `√A`, √m.
    pub sqrt_a_sqrt_m: f64,
    /// Ephemeris reference epoch `t_oe` (the week and seconds of week of the record).
    pub toe: GpsTime,
    /// Inclination cosine correction `C_ic`, rad.
    pub cic_rad: f64,
    /// Longitude of the ascending node at the start of the week `Ω_0`, rad.
    pub omega0_rad: f64,
    /// Inclination sine correction `C_is`, rad.
    pub cis_rad: f64,
    /// Inclination at reference time `i_0`, rad.
    pub i0_rad: f64,
    /// Orbit radius cosine correction `C_rc`, m.
    pub crc_m: f64,
    /// Argument of perigee `ω`, rad.
    pub omega_rad: f64,
    /// Rate of right ascension `Ω̇`, rad/s.
    pub omega_dot_rad_s: f64,
    /// Rate of inclination `IDOT`, rad/s.
    pub idot_rad_s: f64,
    /// User range accuracy (RINEX "SV accuracy"), m.
    pub ura_m: f64,
    /// Satellite health word (0 = all signals healthy).
    pub health: u32,
    /// L1/L2 group delay differential `T_GD`, s.
    pub tgd_s: f64,
    /// Curve-fit interval, hours (4 for the nominal upload).
    pub fit_interval_h: f64,
}

/// Satellite state at one GPS time, in the ECEF frame **of that same instant**.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SatelliteState {
    /// Antenna phase centre of the broadcast orbit (the ephemeris refers to it), ECEF, m.
    pub pos_ecef_m: Vector3<f64>,
    /// Velocity relative to the rotating ECEF frame, ECEF axes, m/s.
    pub vel_ecef_m_s: Vector3<f64>,
    /// Clock offset `Δt_sv` (satellite clock minus GPS time) including the relativistic term,
    /// excluding `T_GD`, s.
    pub clock_bias_s: f64,
    /// Clock drift `d(Δt_sv)/dt` including the relativistic term, s/s.
    pub clock_drift_s_s: f64,
    /// The relativistic part of `clock_bias_s`, `F e √A sin E_k`, s.
    pub relativistic_s: f64,
}

/// Seconds from `reference` to `t + offset_s`, exact in the integer part.
fn seconds_between(t: GpsTime, offset_s: f64, reference: GpsTime) -> f64 {
    t.seconds_since(reference) + offset_s
}

/// Seconds of the GPS week of a time (0 ≤ s < 604 800).
pub fn seconds_of_week(t: GpsTime) -> f64 {
    let week_ns = 604_800 * NS_PER_S;
    t.ns.rem_euclid(week_ns) as f64 * 1e-9
}

/// A GPS time from a (continuous) GPS week number and seconds of that week.
pub fn from_week_seconds(week: u32, seconds_of_week: f64) -> GpsTime {
    let whole = seconds_of_week.floor();
    let frac_ns = ((seconds_of_week - whole) * 1e9).round() as i64;
    GpsTime::from_ns((week as i64 * 604_800 + whole as i64) * NS_PER_S + frac_ns)
}

impl GpsEphemeris {
    /// Semi-major axis `A`, m.
    pub fn semi_major_axis_m(&self) -> f64 {
        self.sqrt_a_sqrt_m * self.sqrt_a_sqrt_m
    }

    /// Seconds from the ephemeris reference epoch `t_oe` to `t + offset_s` (`t_k`).
    pub fn time_from_toe_s(&self, t: GpsTime, offset_s: f64) -> f64 {
        seconds_between(t, offset_s, self.toe)
    }

    /// Whether `t` lies within half the curve-fit interval of `t_oe` (at least ±2 h, the
    /// nominal validity of a 4-hour fit; a zero fit interval in a file means "4 hours").
    pub fn is_valid_at(&self, t: GpsTime) -> bool {
        let half_s = (self.fit_interval_h.max(4.0)) * 1800.0;
        self.time_from_toe_s(t, 0.0).abs() <= half_s
    }

    /// Eccentric anomaly `E_k` at `t_k` seconds from `t_oe`, with the corrected mean motion.
    fn eccentric_anomaly(&self, tk: f64) -> (f64, f64) {
        let a = self.semi_major_axis_m();
        let n0 = (GM_GPS_M3_S2 / (a * a * a)).sqrt();
        let n = n0 + self.delta_n_rad_s;
        let m = self.m0_rad + n * tk;
        // Newton on f(E) = E − e sin E − M; starting at E = M converges for e ≪ 1.
        let mut ecc = m;
        for _ in 0..KEPLER_MAX_ITERATIONS {
            let step = (ecc - self.e * ecc.sin() - m) / (1.0 - self.e * ecc.cos());
            ecc -= step;
            if step.abs() < KEPLER_TOLERANCE_RAD {
                break;
            }
        }
        (ecc, n)
    }

    /// Satellite position, velocity and clock offset at GPS time `t + offset_s`, in the ECEF
    /// frame of that instant (IS-GPS-200 Table 20-IV and §20.3.3.3.3.1).
    pub fn state_at(&self, t: GpsTime, offset_s: f64) -> SatelliteState {
        let tk = self.time_from_toe_s(t, offset_s);
        let a = self.semi_major_axis_m();
        let (ecc, n) = self.eccentric_anomaly(tk);
        let (sin_e, cos_e) = ecc.sin_cos();
        let one_minus_ecos = 1.0 - self.e * cos_e;
        let sqrt_1_e2 = (1.0 - self.e * self.e).sqrt();
        // True anomaly and argument of latitude.
        let nu = (sqrt_1_e2 * sin_e).atan2(cos_e - self.e);
        let phi = nu + self.omega_rad;
        let (sin2p, cos2p) = (2.0 * phi).sin_cos();
        let du = self.cus_rad * sin2p + self.cuc_rad * cos2p;
        let dr = self.crs_m * sin2p + self.crc_m * cos2p;
        let di = self.cis_rad * sin2p + self.cic_rad * cos2p;
        let u = phi + du;
        let r = a * one_minus_ecos + dr;
        let inc = self.i0_rad + di + self.idot_rad_s * tk;
        // Position in the orbital plane.
        let (sin_u, cos_u) = u.sin_cos();
        let xp = r * cos_u;
        let yp = r * sin_u;
        // Longitude of the ascending node in ECEF at this instant.
        let omega_dot_e = self.omega_dot_rad_s - OMEGA_E_GPS_RAD_S;
        let node =
            self.omega0_rad + omega_dot_e * tk - OMEGA_E_GPS_RAD_S * seconds_of_week(self.toe);
        let (sin_o, cos_o) = node.sin_cos();
        let (sin_i, cos_i) = inc.sin_cos();
        let pos = Vector3::new(
            xp * cos_o - yp * cos_i * sin_o,
            xp * sin_o + yp * cos_i * cos_o,
            yp * sin_i,
        );
        // Time derivatives of the same chain.
        let e_dot = n / one_minus_ecos;
        let phi_dot = sqrt_1_e2 * e_dot / one_minus_ecos;
        let u_dot = phi_dot * (1.0 + 2.0 * (self.cus_rad * cos2p - self.cuc_rad * sin2p));
        let r_dot =
            a * self.e * sin_e * e_dot + 2.0 * phi_dot * (self.crs_m * cos2p - self.crc_m * sin2p);
        let i_dot = self.idot_rad_s + 2.0 * phi_dot * (self.cis_rad * cos2p - self.cic_rad * sin2p);
        let xp_dot = r_dot * cos_u - r * u_dot * sin_u;
        let yp_dot = r_dot * sin_u + r * u_dot * cos_u;
        let vel = Vector3::new(
            xp_dot * cos_o - yp_dot * cos_i * sin_o + yp * sin_i * sin_o * i_dot
                - pos.y * omega_dot_e,
            xp_dot * sin_o + yp_dot * cos_i * cos_o - yp * sin_i * cos_o * i_dot
                + pos.x * omega_dot_e,
            yp_dot * sin_i + yp * cos_i * i_dot,
        );
        // Clock: polynomial about t_oc plus the relativistic term of the eccentric orbit.
        let dt_c = seconds_between(t, offset_s, self.toc);
        let rel = F_RELATIVISTIC_S_PER_SQRT_M * self.e * self.sqrt_a_sqrt_m * sin_e;
        let rel_dot = F_RELATIVISTIC_S_PER_SQRT_M * self.e * self.sqrt_a_sqrt_m * cos_e * e_dot;
        SatelliteState {
            pos_ecef_m: pos,
            vel_ecef_m_s: vel,
            clock_bias_s: self.af0_s + self.af1_s_s * dt_c + self.af2_s_s2 * dt_c * dt_c + rel,
            clock_drift_s_s: self.af1_s_s + 2.0 * self.af2_s_s2 * dt_c + rel_dot,
            relativistic_s: rel,
        }
    }

    /// The satellite at the transmission of a signal received at receiver time `t_rx` with
    /// pseudorange `pseudorange_m`: returns the transmission time as an offset from `t_rx`
    /// (s, negative) and the state there (ECEF of the transmission instant).
    ///
    /// `t_sv = t_rx − ρ/c` is the satellite-clock reading at transmission; GPS time is
    /// `t = t_sv − Δt_sv(t)`, iterated to a fixed point.
    pub fn at_transmission(&self, t_rx: GpsTime, pseudorange_m: f64) -> (f64, SatelliteState) {
        let t_sv = -pseudorange_m / SPEED_OF_LIGHT_M_S;
        let mut offset = t_sv;
        for _ in 0..3 {
            let st = self.state_at(t_rx, offset);
            offset = t_sv - st.clock_bias_s;
        }
        (offset, self.state_at(t_rx, offset))
    }
}

/// Rotate a satellite state given in the ECEF frame of the transmission instant into the ECEF
/// frame of the reception instant, `flight_time_s` later (the Earth turned by `ω_e τ`
/// meanwhile): `x_rx = R_z(ω_e τ) x_tx` with `R_z(θ) = [[cos θ, sin θ, 0], [−sin θ, cos θ, 0],
/// [0, 0, 1]]`. The velocity (relative to ECEF) is rotated the same way.
pub fn rotate_to_reception(state: &SatelliteState, flight_time_s: f64) -> SatelliteState {
    let theta = OMEGA_E_GPS_RAD_S * flight_time_s;
    let (s, c) = theta.sin_cos();
    let rot = Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0);
    SatelliteState {
        pos_ecef_m: rot * state.pos_ecef_m,
        vel_ecef_m_s: rot * state.vel_ecef_m_s,
        ..*state
    }
}

/// Geometric flight time from a satellite (ECEF of transmission) to a receiver at `r_e_m`
/// (ECEF of reception), s: the fixed point of `τ = |R_z(ω_e τ) s − r| / c`.
pub fn flight_time_s(sat_tx: &SatelliteState, r_e_m: &Vector3<f64>) -> f64 {
    let mut tau = (sat_tx.pos_ecef_m - r_e_m).norm() / SPEED_OF_LIGHT_M_S;
    for _ in 0..3 {
        let rotated = rotate_to_reception(sat_tx, tau);
        tau = (rotated.pos_ecef_m - r_e_m).norm() / SPEED_OF_LIGHT_M_S;
    }
    tau
}

/// The ephemeris of satellite `prn` to use at time `t`: healthy, within its fit interval,
/// with the reference epoch `t_oe` closest to `t` (the latest upload on a tie).
pub fn select_ephemeris(
    ephemerides: &[GpsEphemeris],
    prn: u8,
    t: GpsTime,
) -> Option<&GpsEphemeris> {
    let mut best: Option<&GpsEphemeris> = None;
    for e in ephemerides
        .iter()
        .filter(|e| e.prn == prn && e.health == 0 && e.is_valid_at(t))
    {
        let d = e.time_from_toe_s(t, 0.0).abs();
        match best {
            Some(b) if b.time_from_toe_s(t, 0.0).abs() < d => {}
            _ => best = Some(e),
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// G05's ephemeris broadcast for 2020-06-25 00:00 GPS time (ESBC navigation file).
    fn g05() -> GpsEphemeris {
        let toc = GpsTime::from_ns((2111 * 604_800 + 345_600) * NS_PER_S);
        GpsEphemeris {
            prn: 5,
            toc,
            af0_s: -1.531792804599e-05,
            af1_s_s: -7.958078640513e-13,
            af2_s_s2: 0.0,
            iode: 12,
            iodc: 12,
            crs_m: -1.046875000000e+02,
            delta_n_rad_s: 4.706267463502e-09,
            m0_rad: 1.465137968214e+00,
            cuc_rad: -5.315989255905e-06,
            e: 5.968198296614e-03,
            cus_rad: 9.898096323013e-06,
            sqrt_a_sqrt_m: 5.153691232681e+03,
            toe: from_week_seconds(2111, 3.456e5),
            cic_rad: -1.285225152969e-07,
            omega0_rad: -2.702593756598e+00,
            cis_rad: 1.229345798492e-07,
            i0_rad: 9.531592011466e-01,
            crc_m: 1.876562500000e+02,
            omega_rad: 8.074291054860e-01,
            omega_dot_rad_s: -8.116766667340e-09,
            idot_rad_s: 6.071681481333e-12,
            ura_m: 2.0,
            health: 0,
            tgd_s: -1.117587089539e-08,
            fit_interval_h: 4.0,
        }
    }

    /// An ideal circular orbit: e = 0, no harmonic corrections, no node or inclination rate.
    fn circular() -> GpsEphemeris {
        GpsEphemeris {
            prn: 1,
            e: 0.0,
            sqrt_a_sqrt_m: 26_560_000f64.sqrt(),
            i0_rad: 55f64.to_radians(),
            omega0_rad: 0.3,
            m0_rad: 0.7,
            omega_rad: 0.0,
            toe: from_week_seconds(2000, 0.0),
            toc: from_week_seconds(2000, 0.0),
            af0_s: 1e-4,
            af1_s_s: 1e-11,
            ..Default::default()
        }
    }

    /// On a circular orbit the radius is A exactly, the inertial speed is √(μ/A) exactly, the
    /// relativistic clock term vanishes, and at t_oe (start of week) the node is Ω_0.
    #[test]
    fn circular_orbit_closed_forms() {
        let eph = circular();
        let a = eph.semi_major_axis_m();
        for k in 0..10 {
            let dt = k as f64 * 1234.5;
            let st = eph.state_at(eph.toe, dt);
            assert!(
                (st.pos_ecef_m.norm() - a).abs() < 1e-6,
                "radius {}",
                st.pos_ecef_m.norm()
            );
            // Inertial velocity = ECEF velocity + ω × r (ECEF axes).
            let w = Vector3::new(0.0, 0.0, OMEGA_E_GPS_RAD_S);
            let v_i = st.vel_ecef_m_s + w.cross(&st.pos_ecef_m);
            let v_circ = (GM_GPS_M3_S2 / a).sqrt();
            assert!(
                (v_i.norm() - v_circ).abs() < 1e-8,
                "speed {} vs {v_circ}",
                v_i.norm()
            );
            assert!(
                v_i.dot(&st.pos_ecef_m.normalize()).abs() < 1e-6,
                "velocity not tangential"
            );
            assert_eq!(st.relativistic_s, 0.0);
            assert!((st.clock_bias_s - (1e-4 + 1e-11 * dt)).abs() < 1e-18);
        }
        // At t_oe with u = M0 = 0.7 rad: the node lies at Ω_0 in the equator, and z = A sin u sin i.
        let st = eph.state_at(eph.toe, 0.0);
        assert!((st.pos_ecef_m.z - a * 0.7f64.sin() * 55f64.to_radians().sin()).abs() < 1e-6);
        // The node line (z = 0 crossing) direction: r at u = 0 is A (cos Ω0, sin Ω0, 0).
        let mut at_node = eph;
        at_node.m0_rad = 0.0;
        let p = at_node.state_at(at_node.toe, 0.0).pos_ecef_m;
        assert!((p - a * Vector3::new(0.3f64.cos(), 0.3f64.sin(), 0.0)).norm() < 1e-6);
    }

    /// The analytic velocity and clock drift equal the central difference of position and
    /// clock (step 0.5 s: truncation error ≈ |r⃛|h²/6 ≈ 3e-5 m/s for a GPS orbit).
    #[test]
    fn velocity_is_the_derivative_of_position() {
        let eph = g05();
        for k in 0..8 {
            let dt = -7000.0 + k as f64 * 2000.0;
            let h = 0.5;
            let st = eph.state_at(eph.toe, dt);
            let p1 = eph.state_at(eph.toe, dt + h);
            let p0 = eph.state_at(eph.toe, dt - h);
            let num = (p1.pos_ecef_m - p0.pos_ecef_m) / (2.0 * h);
            assert!(
                (st.vel_ecef_m_s - num).norm() < 1e-4,
                "dt {dt}: {}",
                st.vel_ecef_m_s - num
            );
            let clk = (p1.clock_bias_s - p0.clock_bias_s) / (2.0 * h);
            assert!(
                (st.clock_drift_s_s - clk).abs() < 1e-16,
                "{} vs {clk}",
                st.clock_drift_s_s
            );
            // A GPS satellite: |r| ≈ 26 560 km ± e·A, |v_ECEF| ≈ 3–4 km/s.
            let r = st.pos_ecef_m.norm();
            assert!((r - eph.semi_major_axis_m()).abs() < 0.0061 * eph.semi_major_axis_m());
            assert!((2500.0..4500.0).contains(&st.vel_ecef_m_s.norm()));
        }
    }

    /// G05 at the first ESBC epoch against RTKLIB 2.4.3 (rnx2rtkp trace level 4 of the same
    /// files prints `rs=` at mm and `dts=` in ns): 20 403 276.102, −4 547 594.508,
    /// 16 360 121.067 m; dts = −15 331.525 ns; transmission at 23:59:59.930143 GPS time.
    /// Pseudorange C1C 20 947 300.931 m received at 2020-06-25 00:00:00 (week 2111, 345 600 s).
    #[test]
    fn g05_matches_rtklib_at_the_first_esbc_epoch() {
        let eph = g05();
        let t_rx = from_week_seconds(2111, 345_600.0);
        let (offset, st) = eph.at_transmission(t_rx, 20_947_300.931);
        let rtklib = Vector3::new(20_403_276.102, -4_547_594.508, 16_360_121.067);
        assert!(
            (st.pos_ecef_m - rtklib).norm() < 2e-3,
            "{}",
            st.pos_ecef_m - rtklib
        );
        assert!(
            (st.clock_bias_s * 1e9 - -15_331.525).abs() < 2e-3,
            "{}",
            st.clock_bias_s * 1e9
        );
        assert!((offset - (59.930143 - 60.0)).abs() < 1e-6, "{offset}");
        // The relativistic term of e = 0.006 is a few ns: |F e √A| = 13.7 ns at most.
        assert!(st.relativistic_s.abs() <= 13.7e-9);
    }

    /// Rotation into the reception frame keeps the range from the Earth's axis and the
    /// z coordinate, turns the longitude by ω_e τ, and the flight time is a fixed point.
    #[test]
    fn earth_rotation_during_flight() {
        let st = g05().state_at(g05().toe, 0.0);
        let rot = rotate_to_reception(&st, 0.075);
        assert_eq!(rot.pos_ecef_m.z, st.pos_ecef_m.z);
        let rho = |v: &Vector3<f64>| v.x.hypot(v.y);
        assert!((rho(&rot.pos_ecef_m) - rho(&st.pos_ecef_m)).abs() < 1e-6);
        let dlon =
            rot.pos_ecef_m.y.atan2(rot.pos_ecef_m.x) - st.pos_ecef_m.y.atan2(st.pos_ecef_m.x);
        assert!((dlon + OMEGA_E_GPS_RAD_S * 0.075).abs() < 1e-15);
        // The chord 2 ρ_xy sin(θ/2) ≈ ω_e τ ρ_xy, ≈ 110 m for 75 ms: the Sagnac correction
        // (its projection on the line of sight is up to ~30 m of range).
        let shift = (rot.pos_ecef_m - st.pos_ecef_m).norm();
        let theta = OMEGA_E_GPS_RAD_S * 0.075;
        assert!(
            (shift - 2.0 * rho(&st.pos_ecef_m) * (theta / 2.0).sin()).abs() < 1e-6,
            "{shift}"
        );
        let r = Vector3::new(3_582_105.291, 532_589.731, 5_232_754.805);
        let tau = flight_time_s(&st, &r);
        let again = (rotate_to_reception(&st, tau).pos_ecef_m - r).norm() / SPEED_OF_LIGHT_M_S;
        assert!((tau - again).abs() < 1e-15);
    }

    #[test]
    fn ephemeris_selection() {
        let t = from_week_seconds(2111, 345_600.0);
        let mut later = g05();
        later.toe = from_week_seconds(2111, 345_600.0 + 7200.0);
        let mut sick = g05();
        sick.health = 1;
        let ephs = [later, g05(), sick];
        assert_eq!(select_ephemeris(&ephs, 5, t).unwrap().toe, g05().toe);
        assert_eq!(
            select_ephemeris(&ephs, 5, t.add_ns(5000 * NS_PER_S))
                .unwrap()
                .toe,
            later.toe
        );
        assert!(select_ephemeris(&ephs, 6, t).is_none());
        assert!(select_ephemeris(&[sick], 5, t).is_none());
        // Out of the ±2 h fit window.
        assert!(select_ephemeris(&[g05()], 5, t.add_ns(7201 * NS_PER_S)).is_none());
        assert_eq!(
            seconds_of_week(from_week_seconds(2111, 345_600.25)),
            345_600.25
        );
    }
}
