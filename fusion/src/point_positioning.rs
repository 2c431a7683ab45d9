//! Single-epoch GPS point positioning from raw code and Doppler measurements and broadcast
//! ephemerides: satellite states at transmission ([`crate::broadcast_ephemeris`]), propagation
//! corrections ([`crate::gnss_corrections`]), an elevation mask, per-satellite weights, and
//! the least-squares fix of [`crate::gnss_ls`].
//!
//! Measurement model, after corrections (the one [`crate::gnss_ls`] solves):
//! `ρ_c = ρ + c Δt_sv − c T_GD − I − T = |R_z(ω_e τ) s(t_tx) − r| + b + ε`, with
//! * `Δt_sv` the broadcast satellite clock offset including the relativistic term;
//! * `T_GD` only for single-frequency L1 (the broadcast clock refers to the L1/L2
//!   ionosphere-free combination, IS-GPS-200 §20.3.3.3.3.2);
//! * `I` the Klobuchar L1 delay (single frequency) or nothing (ionosphere-free: `ρ` is then
//!   the combination of L1 and L2 codes);
//! * `T` the Saastamoinen slant delay (cosecant mapping);
//! * `R_z(ω_e τ)` the Earth rotation during the flight time `τ` (Sagnac).
//!
//! Elevations, corrections and the Earth rotation depend on the receiver position, so the fix
//! is iterated: a first solution with every satellite and no propagation corrections (from
//! the Earth's centre), then re-solved with the elevation mask and corrections evaluated at
//! the previous solution until it moves by less than [`OUTER_TOLERANCE_M`] (2–3 passes).
//! This is the same fixed point as re-evaluating the corrections inside the Gauss–Newton
//! iterations, which is what RTKLIB's single-point mode does.
//!
//! Weights: a variance per satellite,
//! `σ² = σ_URA² + k_IF² (σ_th² 10^((C/N0_ref − C/N0)/10) + (σ_mp / sin el)²) + (f_I I)² + (σ_Tz / sin el)²`
//! — broadcast orbit/clock accuracy, code thermal noise growing as the carrier-to-noise density
//! falls, multipath growing towards the horizon, the residual of the Klobuchar model (it
//! removes about half the ionospheric delay, IS-GPS-200 §20.3.3.5.2.5) and of the standard
//! atmosphere troposphere; `k_IF` = 2.98 for the ionosphere-free combination.
//!
//! Pure and allocation-free: fixed arrays of [`MAX_SATELLITES`].

use crate::broadcast_ephemeris::{
    self as be, GpsEphemeris, SPEED_OF_LIGHT_M_S, SatelliteState, select_ephemeris,
};
use crate::earth::{self, Geodetic};
use crate::gnss_corrections::{
    self as gc, F_L1_HZ, F_L2_HZ, KlobucharCoefficients, azimuth_elevation,
};
use crate::gnss_ls::{self, GnssFix, GnssLsError, LsSettings, Observations, SatelliteObservation};
use crate::time::GpsTime;
use msgs::MAX_SATELLITES;
use nalgebra::Vector3;

/// The outer iteration stops when the position moved by less than this, m.
pub const OUTER_TOLERANCE_M: f64 = 1e-3;
/// Flight time assumed before any position is known, s (a GPS satellite at the zenith is
/// 67 ms away, at the horizon 86 ms).
const INITIAL_FLIGHT_TIME_S: f64 = 0.075;

/// Which ionospheric treatment the fix uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Ionosphere {
    /// Single frequency (L1 C/A code) without an ionospheric correction.
    None,
    /// Single frequency with the broadcast Klobuchar model.
    Klobuchar(KlobucharCoefficients),
    /// Dual frequency: the L1/L2 ionosphere-free code combination.
    IonoFree,
}

/// Standard deviations of the weighting model (module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorModel {
    /// Code thermal noise at the reference carrier-to-noise density, m.
    pub thermal_m: f64,
    /// Reference carrier-to-noise density of `thermal_m`, dB-Hz.
    pub cn0_ref_dbhz: f64,
    /// Code multipath at the zenith (scaled by 1/sin el), m.
    pub multipath_zenith_m: f64,
    /// Fraction of the modelled ionospheric delay taken as its residual error.
    pub iono_fraction: f64,
    /// Zenith troposphere model error (scaled by 1/sin el), m.
    pub troposphere_zenith_m: f64,
    /// Range-rate noise at the zenith (scaled by 1/sin el), m/s.
    pub range_rate_zenith_m_s: f64,
}

impl Default for ErrorModel {
    fn default() -> Self {
        Self {
            thermal_m: 0.3,
            cn0_ref_dbhz: 45.0,
            multipath_zenith_m: 0.3,
            iono_fraction: 0.5,
            troposphere_zenith_m: 0.05,
            range_rate_zenith_m_s: 0.05,
        }
    }
}

/// Settings of a point-positioning fix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointPositioningSettings {
    /// Satellites below this elevation are not used, rad.
    pub elevation_mask_rad: f64,
    /// Ionospheric treatment.
    pub ionosphere: Ionosphere,
    /// Whether the Saastamoinen troposphere is applied.
    pub troposphere: bool,
    /// Relative humidity (0–1) of the standard atmosphere.
    pub relative_humidity: f64,
    /// Weighting model.
    pub errors: ErrorModel,
    /// Outer iterations (corrections and mask re-evaluated) at most.
    pub max_outer_iterations: usize,
    /// Least-squares settings (the starting point is overwritten by the outer iteration).
    pub ls: LsSettings,
}

impl Default for PointPositioningSettings {
    fn default() -> Self {
        Self {
            elevation_mask_rad: 10f64.to_radians(),
            ionosphere: Ionosphere::None,
            troposphere: true,
            relative_humidity: 0.7,
            errors: ErrorModel::default(),
            max_outer_iterations: 8,
            ls: LsSettings::default(),
        }
    }
}

/// One satellite's raw measurements at an epoch.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CodeMeasurement {
    /// GPS PRN.
    pub prn: u8,
    /// L1 C/A pseudorange, m.
    pub p1_m: f64,
    /// L2 pseudorange (needed for [`Ionosphere::IonoFree`]), m.
    pub p2_m: Option<f64>,
    /// L1 Doppler, Hz (positive for an approaching satellite).
    pub doppler_l1_hz: Option<f64>,
    /// L1 carrier-to-noise density, dB-Hz (`None`: the reference value is assumed).
    pub cn0_dbhz: Option<f64>,
}

/// What the fix made of one satellite.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct UsedSatellite {
    /// GPS PRN.
    pub prn: u8,
    /// Satellite at transmission rotated into the ECEF frame of reception.
    pub state: SatelliteState,
    /// Transmission time minus reception time (receiver clock), s.
    pub transmission_offset_s: f64,
    /// Azimuth, rad.
    pub azimuth_rad: f64,
    /// Elevation, rad.
    pub elevation_rad: f64,
    /// Ionospheric delay removed, m (0 for the ionosphere-free combination).
    pub iono_m: f64,
    /// Tropospheric delay removed, m.
    pub tropo_m: f64,
    /// Pseudorange entering the solution (corrected), m.
    pub corrected_pseudorange_m: f64,
    /// Its 1-σ, m.
    pub sigma_m: f64,
    /// Whether a range rate was used.
    pub has_range_rate: bool,
    /// Range rate corrected for the satellite clock drift, m/s.
    pub corrected_range_rate_m_s: f64,
    /// Its 1-σ, m/s.
    pub sigma_range_rate_m_s: f64,
    /// Carrier-to-noise density, dB-Hz (0 if unknown).
    pub cn0_dbhz: f64,
}

/// A point-positioning solution of one epoch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointSolution {
    /// The least-squares fix (antenna position, clock, velocity, DOPs, residuals).
    pub fix: GnssFix,
    /// The satellites used, in the order of the residuals of `fix`.
    pub used: [UsedSatellite; MAX_SATELLITES],
    /// Number of entries of `used`.
    pub n_used: usize,
    /// Satellites skipped for lack of a valid healthy ephemeris.
    pub n_without_ephemeris: usize,
    /// Satellites skipped for lack of the second frequency (ionosphere-free only).
    pub n_without_l2: usize,
    /// Satellites below the elevation mask.
    pub n_below_mask: usize,
    /// Outer iterations made.
    pub outer_iterations: usize,
}

impl PointSolution {
    /// The used satellites.
    pub fn used(&self) -> &[UsedSatellite] {
        &self.used[..self.n_used]
    }
}

/// Why a point-positioning fix failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PointPositioningError {
    /// The least-squares solution failed (too few satellites, geometry, convergence).
    #[error("least squares: {0}")]
    LeastSquares(#[from] GnssLsError),
    /// The outer iteration did not settle.
    #[error(
        "corrections did not settle in {iterations} iterations (last move {last_move_m:.3e} m)"
    )]
    NoConvergence {
        /// Iterations made.
        iterations: usize,
        /// Position change of the last iteration, m.
        last_move_m: f64,
    },
}

/// A satellite with an ephemeris, before the receiver position is known.
#[derive(Clone, Copy, Default)]
struct Candidate {
    m: CodeMeasurement,
    /// Pseudorange before propagation corrections, satellite clock (and T_GD) applied.
    clock_corrected_m: f64,
    offset_s: f64,
    tx: SatelliteState,
    ura_m: f64,
}

/// Fix one epoch received at receiver time `t_rx` from the measurements `meas` with the
/// ephemerides `ephemerides`.
pub fn solve_epoch(
    t_rx: GpsTime,
    meas: &[CodeMeasurement],
    ephemerides: &[GpsEphemeris],
    settings: &PointPositioningSettings,
) -> Result<PointSolution, PointPositioningError> {
    let iono_free = matches!(settings.ionosphere, Ionosphere::IonoFree);
    let mut cands = [Candidate::default(); MAX_SATELLITES];
    let mut n_cand = 0;
    let (mut n_without_ephemeris, mut n_without_l2) = (0, 0);
    for m in meas {
        let Some(eph) = select_ephemeris(ephemerides, m.prn, t_rx) else {
            n_without_ephemeris += 1;
            continue;
        };
        let code = if iono_free {
            match m.p2_m {
                Some(p2) => gc::iono_free(m.p1_m, p2, F_L1_HZ, F_L2_HZ),
                None => {
                    n_without_l2 += 1;
                    continue;
                }
            }
        } else {
            m.p1_m
        };
        if n_cand == MAX_SATELLITES {
            break;
        }
        let (offset_s, tx) = eph.at_transmission(t_rx, m.p1_m);
        let tgd_m = if iono_free {
            0.0
        } else {
            SPEED_OF_LIGHT_M_S * eph.tgd_s
        };
        cands[n_cand] = Candidate {
            m: *m,
            clock_corrected_m: code + SPEED_OF_LIGHT_M_S * tx.clock_bias_s - tgd_m,
            offset_s,
            tx,
            ura_m: eph.ura_m,
        };
        n_cand += 1;
    }
    let cands = &cands[..n_cand];
    let e = &settings.errors;
    let k_if = if iono_free {
        gc::iono_free_noise_factor(F_L1_HZ, F_L2_HZ)
    } else {
        1.0
    };
    let mut used = [UsedSatellite::default(); MAX_SATELLITES];
    let mut position: Option<Vector3<f64>> = None;
    let mut clock_m = 0.0;
    let mut last_move = f64::INFINITY;
    for outer in 1..=settings.max_outer_iterations {
        let rx: Option<(Vector3<f64>, Geodetic)> =
            position.map(|r| (r, earth::ecef_to_geodetic(&settings.ls.ellipsoid, &r)));
        let zenith = rx.map(|(_, g)| {
            gc::saastamoinen_zenith(
                g.lat_rad,
                g.height_m,
                &gc::standard_atmosphere(g.height_m, settings.relative_humidity),
            )
        });
        let mut obs = Observations::default();
        let mut n_used = 0;
        let mut n_below_mask = 0;
        for c in cands {
            let (state, az, el, iono, tropo) = match rx {
                None => (
                    be::rotate_to_reception(&c.tx, INITIAL_FLIGHT_TIME_S),
                    0.0,
                    std::f64::consts::FRAC_PI_2,
                    0.0,
                    0.0,
                ),
                Some((r, g)) => {
                    let state = be::rotate_to_reception(&c.tx, be::flight_time_s(&c.tx, &r));
                    let (az, el) = azimuth_elevation(&g, &r, &state.pos_ecef_m);
                    if el < settings.elevation_mask_rad {
                        n_below_mask += 1;
                        continue;
                    }
                    let iono = match settings.ionosphere {
                        Ionosphere::Klobuchar(k) => {
                            k.l1_delay_m(&g, az, el, be::seconds_of_week(t_rx))
                        }
                        _ => 0.0,
                    };
                    let tropo = match (settings.troposphere, zenith) {
                        (true, Some(z)) => gc::slant_troposphere_m(&z, el),
                        _ => 0.0,
                    };
                    (state, az, el, iono, tropo)
                }
            };
            let sin_el = el.sin().max(0.05);
            let cn0 = c.m.cn0_dbhz.unwrap_or(e.cn0_ref_dbhz);
            let var = c.ura_m * c.ura_m
                + k_if
                    * k_if
                    * (e.thermal_m * e.thermal_m * 10f64.powf((e.cn0_ref_dbhz - cn0) / 10.0)
                        + (e.multipath_zenith_m / sin_el).powi(2))
                + (e.iono_fraction * iono).powi(2)
                + (e.troposphere_zenith_m / sin_el).powi(2);
            let sigma = var.sqrt();
            let wavelength = SPEED_OF_LIGHT_M_S / F_L1_HZ;
            let rr =
                c.m.doppler_l1_hz
                    .map(|d| -wavelength * d + SPEED_OF_LIGHT_M_S * c.tx.clock_drift_s_s);
            let sigma_rr = e.range_rate_zenith_m_s / sin_el;
            let corrected = c.clock_corrected_m - iono - tropo;
            obs.push(SatelliteObservation {
                prn: c.m.prn as u32,
                sat_pos_ecef_m: state.pos_ecef_m,
                sat_vel_ecef_m_s: state.vel_ecef_m_s,
                pseudorange_m: corrected,
                sigma_pseudorange_m: sigma,
                has_range_rate: rr.is_some(),
                range_rate_m_s: rr.unwrap_or(0.0),
                sigma_range_rate_m_s: sigma_rr,
            })?;
            used[n_used] = UsedSatellite {
                prn: c.m.prn,
                state,
                transmission_offset_s: c.offset_s,
                azimuth_rad: az,
                elevation_rad: el,
                iono_m: iono,
                tropo_m: tropo,
                corrected_pseudorange_m: corrected,
                sigma_m: sigma,
                has_range_rate: rr.is_some(),
                corrected_range_rate_m_s: rr.unwrap_or(0.0),
                sigma_range_rate_m_s: sigma_rr,
                cn0_dbhz: c.m.cn0_dbhz.unwrap_or(0.0),
            };
            n_used += 1;
        }
        let ls = LsSettings {
            initial_r_e_m: position.unwrap_or(settings.ls.initial_r_e_m),
            initial_clock_bias_m: clock_m,
            ..settings.ls
        };
        let fix = gnss_ls::solve_position(&obs, &ls)?;
        let r = fix.r_e_m;
        last_move = position.map_or(f64::INFINITY, |p| (r - p).norm());
        position = Some(r);
        clock_m = fix.clock_bias_m;
        if last_move < OUTER_TOLERANCE_M {
            // Velocity once, with the lines of sight of the final position.
            let velocity = match gnss_ls::solve_velocity(&obs, &fix) {
                Ok(v) => Some(v),
                Err(GnssLsError::TooFewSatellites { .. }) => None,
                Err(e) => return Err(e.into()),
            };
            return Ok(PointSolution {
                fix: GnssFix {
                    position: fix,
                    velocity,
                },
                used,
                n_used,
                n_without_ephemeris,
                n_without_l2,
                n_below_mask,
                outer_iterations: outer,
            });
        }
    }
    Err(PointPositioningError::NoConvergence {
        iterations: settings.max_outer_iterations,
        last_move_m: last_move,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::broadcast_ephemeris::{OMEGA_E_GPS_RAD_S, from_week_seconds};
    use crate::time::NS_PER_S;

    /// A constellation of near-GPS orbits: six planes, four satellites each, with the
    /// eccentricity, harmonic terms and clock of a real G05 upload.
    fn constellation(toe: GpsTime) -> Vec<GpsEphemeris> {
        let mut v = Vec::new();
        for plane in 0..6 {
            for slot in 0..4 {
                let prn = (plane * 4 + slot + 1) as u8;
                v.push(GpsEphemeris {
                    prn,
                    toc: toe,
                    toe,
                    af0_s: -1.5e-5 + 1e-5 * prn as f64,
                    af1_s_s: -8e-13,
                    af2_s_s2: 1e-20,
                    crs_m: -104.7,
                    delta_n_rad_s: 4.7e-9,
                    m0_rad: slot as f64 * std::f64::consts::FRAC_PI_2 + plane as f64 * 0.5,
                    cuc_rad: -5.3e-6,
                    e: 0.006 + 0.001 * slot as f64,
                    cus_rad: 9.9e-6,
                    sqrt_a_sqrt_m: 5153.69,
                    cic_rad: -1.3e-7,
                    omega0_rad: plane as f64 * std::f64::consts::PI / 3.0,
                    cis_rad: 1.2e-7,
                    i0_rad: 0.9532,
                    crc_m: 187.7,
                    omega_rad: 0.8,
                    omega_dot_rad_s: -8.1e-9,
                    idot_rad_s: 6e-12,
                    ura_m: 2.0,
                    tgd_s: -1.1e-8 + 1e-9 * slot as f64,
                    fit_interval_h: 4.0,
                    ..Default::default()
                });
            }
        }
        v
    }

    /// Forward model: the code a receiver at `r` (clock bias `b_m`, static) would measure at
    /// receiver time `t_rcv`, with delays `iono_l1(el, az)` and troposphere.
    fn synthesize(
        t_rcv: GpsTime,
        r: &Vector3<f64>,
        b_m: f64,
        ephs: &[GpsEphemeris],
        k: &KlobucharCoefficients,
    ) -> Vec<CodeMeasurement> {
        let g = earth::ecef_to_geodetic(&earth::WGS84, r);
        let z = gc::saastamoinen_zenith(
            g.lat_rad,
            g.height_m,
            &gc::standard_atmosphere(g.height_m, 0.7),
        );
        let c = SPEED_OF_LIGHT_M_S;
        let mut out = Vec::new();
        for eph in ephs {
            // Reception in GPS time is the receiver time minus its clock bias.
            let rx_offset = -b_m / c;
            let mut tau = 0.07;
            for _ in 0..10 {
                let s = eph.state_at(t_rcv, rx_offset - tau);
                let th = OMEGA_E_GPS_RAD_S * tau;
                let (sn, cs) = th.sin_cos();
                let p = Vector3::new(
                    cs * s.pos_ecef_m.x + sn * s.pos_ecef_m.y,
                    -sn * s.pos_ecef_m.x + cs * s.pos_ecef_m.y,
                    s.pos_ecef_m.z,
                );
                tau = (p - r).norm() / c;
            }
            let s = eph.state_at(t_rcv, rx_offset - tau);
            let rot = be::rotate_to_reception(&s, tau);
            let (az, el) = azimuth_elevation(&g, r, &rot.pos_ecef_m);
            if el < 15f64.to_radians() {
                continue;
            }
            let i1 = k.l1_delay_m(&g, az, el, be::seconds_of_week(t_rcv));
            let t = gc::slant_troposphere_m(&z, el);
            // ρ = c (t_rcv − t_sv), t_sv = t_tx + Δt_sv; L1 code late by T_GD, L2 by γ T_GD.
            let base = c * (tau + b_m / c - s.clock_bias_s) + t;
            let gamma = (F_L1_HZ / F_L2_HZ).powi(2);
            out.push(CodeMeasurement {
                prn: eph.prn,
                p1_m: base + c * eph.tgd_s + i1,
                p2_m: Some(base + gamma * c * eph.tgd_s + gamma * i1),
                doppler_l1_hz: None,
                cn0_dbhz: Some(45.0),
            });
        }
        out
    }

    /// Noise-free measurements synthesized with the full model are inverted to the receiver
    /// position and clock, single frequency with Klobuchar and dual frequency alike: the
    /// transmission time, satellite clock, T_GD, Earth rotation, ionosphere and troposphere are
    /// each large enough (metres to tens of metres) that a sign or a frame error would show.
    #[test]
    fn inverts_the_forward_model() {
        let toe = from_week_seconds(2111, 345_600.0);
        let ephs = constellation(toe);
        let k = KlobucharCoefficients {
            alpha: [1.1e-8, 1.5e-8, -6e-8, -1.2e-7],
            beta: [9e4, 9.8e4, -6.5e4, -5.2e5],
        };
        let r = Vector3::new(3_582_105.291, 532_589.731, 5_232_754.805);
        let b = 123_456.7;
        for dt in [0, 1200, 3000] {
            let t_rcv = toe.add_ns(dt * NS_PER_S + 1_234_567);
            let meas = synthesize(t_rcv, &r, b, &ephs, &k);
            assert!(meas.len() >= 6, "{} satellites", meas.len());
            for ionosphere in [Ionosphere::Klobuchar(k), Ionosphere::IonoFree] {
                let settings = PointPositioningSettings {
                    ionosphere,
                    elevation_mask_rad: 14f64.to_radians(),
                    ..Default::default()
                };
                let sol = solve_epoch(t_rcv, &meas, &ephs, &settings).unwrap();
                let e = (sol.fix.position.r_e_m - r).norm();
                assert!(e < 2e-3, "{ionosphere:?} t+{dt}: error {e} m");
                assert!((sol.fix.position.clock_bias_m - b).abs() < 2e-3);
                assert_eq!(sol.n_used, meas.len());
                assert!(sol.outer_iterations <= 5, "{}", sol.outer_iterations);
            }
            // Without the ionospheric correction the same data give a metres-level error.
            let settings = PointPositioningSettings::default();
            let sol = solve_epoch(t_rcv, &meas, &ephs, &settings).unwrap();
            assert!((sol.fix.position.r_e_m - r).norm() > 1.0);
        }
    }

    #[test]
    fn missing_data_is_counted_not_fatal() {
        let toe = from_week_seconds(2111, 345_600.0);
        let ephs = constellation(toe);
        let r = Vector3::new(3_582_105.291, 532_589.731, 5_232_754.805);
        let mut meas = synthesize(toe, &r, 0.0, &ephs, &KlobucharCoefficients::default());
        meas[0].p2_m = None;
        meas.push(CodeMeasurement {
            prn: 31,
            p1_m: 2.2e7,
            ..Default::default()
        });
        let settings = PointPositioningSettings {
            ionosphere: Ionosphere::IonoFree,
            ..Default::default()
        };
        let sol = solve_epoch(toe, &meas, &ephs, &settings).unwrap();
        assert_eq!(sol.n_without_ephemeris, 1);
        assert_eq!(sol.n_without_l2, 1);
        assert!(matches!(
            solve_epoch(toe, &meas[..3], &ephs, &settings),
            Err(PointPositioningError::LeastSquares(
                GnssLsError::TooFewSatellites { .. }
            ))
        ));
    }
}
