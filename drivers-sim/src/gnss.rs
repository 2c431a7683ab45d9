//! GNSS simulation: a Walker constellation on circular Keplerian orbits and a receiver model
//! (two-state clock, pseudorange and Doppler noise, C/N0 from elevation, dual-baseline carrier
//! phase differences, least-squares-consistent fix with covariance `σ²(HᵀH)⁻¹`).
//!
//! Orbits are propagated in an inertial frame whose axes coincide with ECEF at the GPS epoch
//! (1980-01-06T00:00:00) and rotated into ECEF with the WGS-84 Earth rate. Pseudoranges are
//! transmission-time consistent: the satellite position at `t_tx = t_rx − τ` is rotated by the
//! Earth's rotation during `τ` into the ECEF frame of reception (Sagnac).

use crate::scenario::{ConstellationSpec, GnssGrade, Scenario, Window};
use crate::truth::TruthPoint;
use fusion::earth::WGS84;
use msgs::{GnssSample, GnssSatellite, MAX_SATELLITES, SPEED_OF_LIGHT_M_S};
use nalgebra::{Matrix2, Matrix4, Vector2, Vector3, Vector4};
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;
use std::f64::consts::TAU;

/// Header status bit: receiver in an outage (no signals tracked).
pub const STATUS_OUTAGE: u32 = 1;
/// Satellite flag bits.
pub const FLAG_PSEUDORANGE: u32 = 1;
/// Doppler valid.
pub const FLAG_DOPPLER: u32 = 2;
/// Baseline phases valid.
pub const FLAG_PHASE: u32 = 4;

/// Rotation of ECEF coordinates by the Earth's rotation through angle `theta` (rad):
/// coordinates of a fixed inertial point in a frame rotated by `theta` about z.
fn rot3(theta: f64, v: &Vector3<f64>) -> Vector3<f64> {
    let (s, c) = theta.sin_cos();
    Vector3::new(c * v.x + s * v.y, -s * v.x + c * v.y, v.z)
}

/// A Walker `T/P/F` constellation on circular orbits.
#[derive(Debug, Clone)]
pub struct Constellation {
    spec: ConstellationSpec,
    mean_motion_rad_s: f64,
}

impl Constellation {
    /// The constellation of `spec` (μ and Earth rate of WGS-84).
    pub fn new(spec: ConstellationSpec) -> Self {
        let a = spec.semi_major_axis_m;
        Self {
            spec,
            mean_motion_rad_s: (WGS84.gm_m3_s2 / (a * a * a)).sqrt(),
        }
    }

    /// Number of satellites (PRN 1..=n).
    pub fn len(&self) -> usize {
        (self.spec.planes * self.spec.per_plane) as usize
    }

    /// Whether the constellation is empty (never for a validated scenario).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Position and velocity of satellite `i` (0-based) in ECEF at GPS time `t_s` (s since the
    /// GPS epoch), m and m/s (velocity relative to the rotating ECEF frame).
    pub fn sat_ecef(&self, i: usize, t_s: f64) -> (Vector3<f64>, Vector3<f64>) {
        let sp = &self.spec;
        let total = (sp.planes * sp.per_plane) as f64;
        let plane = (i as u32 / sp.per_plane) as f64;
        let slot = (i as u32 % sp.per_plane) as f64;
        let raan = sp.raan0_deg.to_radians() + plane * TAU / sp.planes as f64;
        let u0 = slot * TAU / sp.per_plane as f64 + plane * sp.phasing as f64 * TAU / total;
        let u = (u0 + (self.mean_motion_rad_s * t_s) % TAU) % TAU;
        let inc = sp.inclination_deg.to_radians();
        let a = sp.semi_major_axis_m;
        let (su, cu) = u.sin_cos();
        let (so, co) = raan.sin_cos();
        let (si, ci) = inc.sin_cos();
        let r_i = a * Vector3::new(cu * co - su * ci * so, cu * so + su * ci * co, su * si);
        let v_i = a
            * self.mean_motion_rad_s
            * Vector3::new(-su * co - cu * ci * so, -su * so + cu * ci * co, cu * si);
        let theta = (WGS84.omega_ie_rad_s * t_s) % TAU;
        let r_e = rot3(theta, &r_i);
        let v_e = rot3(theta, &v_i) - WGS84.omega_ie_e().cross(&r_e);
        (r_e, v_e)
    }

    /// Satellite position at transmission, rotated into the ECEF frame at reception time
    /// `t_rx_s`, its velocity likewise, and the geometric range from `r_rx` (m, m/s, m).
    pub fn at_reception(
        &self,
        i: usize,
        t_rx_s: f64,
        r_rx: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>, f64) {
        let mut tau = 0.075;
        let mut out = (Vector3::zeros(), Vector3::zeros(), 0.0);
        for _ in 0..4 {
            let (r, v) = self.sat_ecef(i, t_rx_s - tau);
            let th = WGS84.omega_ie_rad_s * tau;
            let r_rot = rot3(th, &r);
            let v_rot = rot3(th, &v);
            let range = (r_rot - r_rx).norm();
            out = (r_rot, v_rot, range);
            tau = range / SPEED_OF_LIGHT_M_S;
        }
        out
    }
}

/// Elevation of line-of-sight unit vector `u_e` (ECEF) seen from NED frame `c_e_n`, rad.
pub fn elevation_rad(c_e_n: &nalgebra::Matrix3<f64>, u_e: &Vector3<f64>) -> f64 {
    let u_n = c_e_n.transpose() * u_e;
    (-u_n.z).clamp(-1.0, 1.0).asin()
}

/// What the receiver model knows but does not publish (for tests and truth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssEpochTruth {
    /// Receiver clock bias, m.
    pub clock_bias_m: f64,
    /// Receiver clock drift, m/s.
    pub clock_drift_m_s: f64,
    /// Geometric range of each published satellite (same order), m.
    pub geometric_range_m: [f64; MAX_SATELLITES],
}

/// The GNSS receiver simulator.
#[derive(Debug, Clone)]
pub struct GnssSim {
    constellation: Constellation,
    grade: GnssGrade,
    outages: Vec<Window>,
    rng: ChaCha20Rng,
    clock_bias_m: f64,
    clock_drift_m_s: f64,
    last_t_s: Option<f64>,
}

impl GnssSim {
    /// The receiver of the scenario with its clock drawn from the `"gnss"` stream.
    pub fn new(scn: &Scenario) -> Self {
        let mut rng = crate::sensor_rng(scn.spec.scenario.seed, "gnss");
        let g = scn.gnss;
        let b: f64 = rng.sample(StandardNormal);
        let d: f64 = rng.sample(StandardNormal);
        Self {
            constellation: Constellation::new(scn.spec.gnss.constellation),
            grade: g,
            outages: scn.spec.gnss.outages.clone(),
            rng,
            clock_bias_m: b * g.clock_bias_initial_sigma_m,
            clock_drift_m_s: d * g.clock_drift_initial_sigma_m_s,
            last_t_s: None,
        }
    }

    /// The constellation.
    pub fn constellation(&self) -> &Constellation {
        &self.constellation
    }

    fn propagate_clock(&mut self, dt: f64) {
        let qb = self.grade.clock_bias_psd_m2_s;
        let qd = self.grade.clock_drift_psd_m2_s3;
        let q = Matrix2::new(
            qb * dt + qd * dt * dt * dt / 3.0,
            qd * dt * dt / 2.0,
            qd * dt * dt / 2.0,
            qd * dt,
        );
        let n1: f64 = self.rng.sample(StandardNormal);
        let n2: f64 = self.rng.sample(StandardNormal);
        let w = match q.cholesky() {
            Some(c) => c.l() * Vector2::new(n1, n2),
            None => Vector2::zeros(),
        };
        self.clock_bias_m += self.clock_drift_m_s * dt + w.x;
        self.clock_drift_m_s += w.y;
    }

    /// Receiver output at `t_s` since the scenario epoch (GPS time `t_gps_ns`) for the truth
    /// point `truth`, with the hidden truth of the epoch.
    pub fn sample(
        &mut self,
        t_s: f64,
        t_gps_ns: i64,
        truth: &TruthPoint,
    ) -> (GnssSample, GnssEpochTruth) {
        if let Some(prev) = self.last_t_s {
            self.propagate_clock(t_s - prev);
        }
        self.last_t_s = Some(t_s);
        let outage = self.outages.iter().any(|w| w.contains(t_s));
        let g = self.grade;
        let t_rx_s = t_gps_ns as f64 * 1e-9;
        let r_rx = truth.r_e_m;
        let v_rx = truth.v_e_m_s();
        let c_e_b = truth.c_e_n * truth.c_n_b;
        let wavelength = SPEED_OF_LIGHT_M_S / g.carrier_frequency_hz;
        let baselines_e = [
            c_e_b * Vector3::new(g.baseline_length_m[0], 0.0, 0.0),
            c_e_b * Vector3::new(0.0, g.baseline_length_m[1], 0.0),
        ];
        let mask = g.elevation_mask_deg.to_radians();
        let mut out = GnssSample::default();
        out.header.time_ns = t_gps_ns;
        out.baseline_length_m = g.baseline_length_m;
        out.wavelength_m = wavelength;
        let mut hidden = GnssEpochTruth {
            clock_bias_m: self.clock_bias_m,
            clock_drift_m_s: self.clock_drift_m_s,
            geometric_range_m: [0.0; MAX_SATELLITES],
        };
        let mut hth = Matrix4::<f64>::zeros();
        let mut ht_pr = Vector4::<f64>::zeros();
        let mut ht_rr = Vector4::<f64>::zeros();
        let mut n = 0usize;
        for i in 0..self.constellation.len() {
            // Fixed draw order for every satellite, visible or not.
            let draws: [f64; 4] = [
                self.rng.sample(StandardNormal),
                self.rng.sample(StandardNormal),
                self.rng.sample(StandardNormal),
                self.rng.sample(StandardNormal),
            ];
            if outage || n >= MAX_SATELLITES {
                continue;
            }
            let (r_s, v_s, range) = self.constellation.at_reception(i, t_rx_s, &r_rx);
            let u = (r_s - r_rx) / range;
            let el = elevation_rad(&truth.c_e_n, &u);
            if el < mask {
                continue;
            }
            let e_pr = g.pseudorange_sigma_m * draws[0];
            let e_rr = g.range_rate_sigma_m_s * draws[1];
            let rate = (v_s - v_rx).dot(&u);
            let mut flags = FLAG_PSEUDORANGE | FLAG_DOPPLER;
            let mut phase = [0.0; 2];
            if g.baseline_length_m[0] > 0.0 && g.baseline_length_m[1] > 0.0 {
                flags |= FLAG_PHASE;
                for (k, b) in baselines_e.iter().enumerate() {
                    phase[k] = b.dot(&u) / wavelength + g.phase_sigma_cycles * draws[2 + k];
                }
            }
            out.satellites[n] = GnssSatellite {
                prn: i as u32 + 1,
                flags,
                pseudorange_m: range + self.clock_bias_m + e_pr,
                range_rate_m_s: rate + self.clock_drift_m_s + e_rr,
                cn0_dbhz: g.cn0_horizon_dbhz + (g.cn0_zenith_dbhz - g.cn0_horizon_dbhz) * el.sin(),
                sigma_pseudorange_m: g.pseudorange_sigma_m,
                sigma_range_rate_m_s: g.range_rate_sigma_m_s,
                sat_pos_ecef_m: [r_s.x, r_s.y, r_s.z],
                sat_vel_ecef_m_s: [v_s.x, v_s.y, v_s.z],
                baseline_phase_cycles: phase,
            };
            hidden.geometric_range_m[n] = range;
            let h = Vector4::new(-u.x, -u.y, -u.z, 1.0);
            hth += h * h.transpose();
            ht_pr += h * e_pr;
            ht_rr += h * e_rr;
            n += 1;
        }
        out.n_satellites = n as u32;
        if outage {
            out.header.status = STATUS_OUTAGE;
        }
        if n >= 4
            && let Some(inv) = hth.try_inverse()
        {
            // Linearised least-squares fix from the same noisy measurements: its error is
            // (HᵀH)⁻¹Hᵀε, whose covariance is σ²(HᵀH)⁻¹.
            let dp = inv * ht_pr;
            let dv = inv * ht_rr;
            let p = r_rx + Vector3::new(dp.x, dp.y, dp.z);
            let v = v_rx + Vector3::new(dv.x, dv.y, dv.z);
            let s2p = g.pseudorange_sigma_m.powi(2);
            let s2v = g.range_rate_sigma_m_s.powi(2);
            for r in 0..3 {
                for c in 0..3 {
                    out.pos_cov_ecef_m2[3 * r + c] = s2p * inv[(r, c)];
                    out.vel_cov_ecef_m2_s2[3 * r + c] = s2v * inv[(r, c)];
                }
            }
            out.fix_valid = 1;
            out.pos_ecef_m = [p.x, p.y, p.z];
            out.vel_ecef_m_s = [v.x, v.y, v.z];
            out.pdop = (inv[(0, 0)] + inv[(1, 1)] + inv[(2, 2)]).sqrt();
        }
        (out, hidden)
    }
}
