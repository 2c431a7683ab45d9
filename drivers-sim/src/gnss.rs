//! GNSS simulation: a Walker constellation on circular Keplerian orbits and a receiver model
//! (two-state clock, pseudorange and Doppler noise, C/N0 from elevation, dual-baseline carrier
//! phase differences).
//!
//! Baseline carrier phases: the phase difference across each baseline is `b·u/λ + ε` plus, with
//! `[world.carrier_phase]`, the receiver's unknown integer of the satellite and baseline (new
//! at each acquisition, changed by cycle slips) with its lock time ([`crate::world::carrier_phase`]);
//! without it the integer is already resolved (zero), as the matched fixture needs. With
//! `[world.phase_multipath]` each difference also carries the two antennas' multipath
//! ([`crate::world::phase_multipath`]), which the receiver's reported phase σ leaves out.
//!
//! Two receivers:
//! * **Matched** (no `[world]` in the scenario): white pseudorange noise of the grade's σ and
//!   a fix consistent with it, `(HᵀH)⁻¹Hᵀε` with covariance exactly `σ²(HᵀH)⁻¹` — a fixture
//!   for the filter's algebra.
//! * **Real** (with `[world]`): the pseudoranges carry the world's errors ([`crate::world`]:
//!   ionosphere, troposphere, multipath, non-line-of-sight echoes (late and weak),
//!   broadcast clock and orbit, code noise by C/N0, the
//!   oscillator, the antenna lever arm and latency). The receiver corrects them with its own
//!   models — the broadcast Klobuchar ionosphere (IS-GPS-200 §20.3.3.5.2.5, coefficients of a
//!   real broadcast) and Saastamoinen with a standard atmosphere and the cosecant mapping —
//!   reports per satellite the σ of its own error budget ([`crate::scenario::UereModel`]),
//!   and solves its fix by weighted least squares from exactly those pseudoranges, excluding
//!   the ones its RAIM/FDE finds inconsistent ([`fusion::gnss_ls::solve_excluding_faults`]),
//!   with the covariance `(HᵀWH)⁻¹` of its budget, not of the truth.
//!   Its error therefore stays correlated for minutes, as a real receiver's does.
//!
//! Orbits are propagated in an inertial frame whose axes coincide with ECEF at the GPS epoch
//! (1980-01-06T00:00:00) and rotated into ECEF with the WGS-84 Earth rate. Pseudoranges are
//! transmission-time consistent: the satellite position at `t_tx = t_rx − τ` is rotated by the
//! Earth's rotation during `τ` into the ECEF frame of reception (Sagnac).

use crate::scenario::{ConstellationSpec, GnssGrade, Scenario, UereModel, Window};
use crate::truth::TruthPoint;
use crate::world::GnssWorld;
use crate::world::carrier_phase::{PhaseTracking, TrackedPhase};
use crate::world::phase_multipath::PhaseMultipath;
use crate::world::receiver_clock::TwoStateClock;
use fusion::earth::WGS84;
use fusion::gnss_corrections as corr;
use msgs::{GnssSample, GnssSatellite, MAX_SATELLITES, SPEED_OF_LIGHT_M_S};
use nalgebra::{Matrix4, Vector3, Vector4};
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

/// Largest simulated constellation: satellites in orbit (PRN 1..=128). A sample carries at
/// most [`MAX_SATELLITES`] of them: the receiver's channels ([`GnssSim::tracked_channels`]).
pub const MAX_CONSTELLATION: usize = 128;

/// Elevation of line-of-sight unit vector `u_e` (ECEF) seen from NED frame `c_e_n`, rad.
pub fn elevation_rad(c_e_n: &nalgebra::Matrix3<f64>, u_e: &Vector3<f64>) -> f64 {
    let u_n = c_e_n.transpose() * u_e;
    (-u_n.z).clamp(-1.0, 1.0).asin()
}

/// The broadcast Klobuchar coefficients the simulated receiver corrects with: those of a
/// real GPS navigation message (2020-06-25, as broadcast and logged in a RINEX header).
pub const BROADCAST_KLOBUCHAR: corr::KlobucharCoefficients = corr::KlobucharCoefficients {
    alpha: [4.6566e-09, 1.4901e-08, -5.9605e-08, -1.1921e-07],
    beta: [8.1920e+04, 9.8304e+04, -6.5536e+04, -5.2429e+05],
};

/// Probability of the receiver's fault detection test (a false exclusion in one epoch in
/// 1000 of a consistent one).
pub const RECEIVER_FDE_PROBABILITY: f64 = 0.999;

/// Relative humidity of the receiver's standard atmosphere (RTKLIB's default, 0.7).
pub const RECEIVER_HUMIDITY: f64 = 0.7;

/// What the receiver model knows but does not publish (for tests and truth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssEpochTruth {
    /// Receiver clock bias, m.
    pub clock_bias_m: f64,
    /// Receiver clock drift, m/s.
    pub clock_drift_m_s: f64,
    /// Geometric range of each published satellite (same order), m.
    pub geometric_range_m: [f64; MAX_SATELLITES],
    /// Antenna position at the measurement instant, ECEF, m.
    pub antenna_r_e_m: Vector3<f64>,
    /// The integer each published satellite's baseline phases (AB, CD) carry, cycles (0
    /// without `[world.carrier_phase]`).
    pub phase_ambiguity_cycles: [[i64; 2]; MAX_SATELLITES],
    /// The multipath each published satellite's baseline phases carry, cycles (0 without
    /// `[world.phase_multipath]`).
    pub phase_multipath_cycles: [[f64; 2]; MAX_SATELLITES],
}

/// The lock time published with the phases (0 without them).
fn lock_time(phase_flag: u32, tracked: &TrackedPhase) -> [f64; 2] {
    if phase_flag & FLAG_PHASE != 0 {
        tracked.lock_time_s
    } else {
        [0.0; 2]
    }
}

/// The GNSS receiver simulator.
#[derive(Debug, Clone)]
pub struct GnssSim {
    constellation: Constellation,
    grade: GnssGrade,
    outages: Vec<Window>,
    rng: ChaCha20Rng,
    clock: TwoStateClock,
    /// Antenna lever arm, body axes, m (zero without `[world.gnss_antenna]`).
    lever_arm_b_m: Vector3<f64>,
    last_t_s: Option<f64>,
    /// The world and the receiver's error budget (real receiver), or None (matched).
    world: Option<(GnssWorld, UereModel)>,
    last_fix: Option<(Vector3<f64>, f64)>,
    /// Carrier-phase tracking of the baselines (integers, slips, lock time).
    phase_tracking: PhaseTracking,
    /// Multipath of the baseline phases (`[world.phase_multipath]`).
    phase_multipath: Option<PhaseMultipath>,
}

impl GnssSim {
    /// The receiver of the scenario with its clock drawn from the `"gnss"` stream and, with a
    /// `[world]`, the world's processes from the `"world"` stream (the echoes from
    /// `"world_nlos"`).
    pub fn new(scn: &Scenario) -> Self {
        let mut rng = crate::sensor_rng(scn.spec.scenario.seed, "gnss");
        let g = scn.gnss;
        let b: f64 = rng.sample(StandardNormal);
        let d: f64 = rng.sample(StandardNormal);
        let constellation = Constellation::new(scn.spec.gnss.constellation);
        // This receiver as a unit of its model (`[world.units]`): its oscillator's Allan
        // coefficients and its code tracking noise scattered about their class.
        let unit = scn.aiding_unit("gnss");
        let (q_b_m2_s, q_d_m2_s3) = match scn.spec.world.and_then(|w| w.receiver_clock()) {
            Some(osc) => (
                osc.phase_psd_m2_s() * unit.oscillator_factors[0],
                osc.frequency_psd_m2_s3() * unit.oscillator_factors[1],
            ),
            None => (g.clock_bias_psd_m2_s, g.clock_drift_psd_m2_s3),
        };
        // Scenario validation guarantees the budget exists when the world's errors are on.
        let world = scn
            .spec
            .world
            .filter(|w| w.gnss_errors_on())
            .zip(g.uere)
            .map(|(mut w, u)| {
                if let Some(c) = &mut w.code_noise {
                    c.sigma_at_45_dbhz_m *= unit.noise_factors[0];
                }
                let seed = scn.spec.scenario.seed;
                let (rng_w, rng_nlos) = (
                    crate::sensor_rng(seed, "world"),
                    crate::sensor_rng(seed, "world_nlos"),
                );
                (GnssWorld::new(w, constellation.len(), rng_w, rng_nlos), u)
            });
        // Its own stream: switching the effect changes no other realisation.
        let phase_tracking = PhaseTracking::new(
            scn.spec.world.and_then(|w| w.carrier_phase()),
            constellation.len(),
            crate::sensor_rng(scn.spec.scenario.seed, "world_carrier_phase"),
        );
        let phase_multipath = scn.spec.world.and_then(|w| w.phase_multipath()).map(|s| {
            PhaseMultipath::new(
                s,
                constellation.len(),
                crate::sensor_rng(scn.spec.scenario.seed, "world_phase_multipath"),
            )
        });
        Self {
            phase_tracking,
            phase_multipath,
            constellation,
            grade: g,
            outages: scn.spec.gnss.outages.clone(),
            rng,
            clock: TwoStateClock {
                q_b_m2_s,
                q_d_m2_s3,
                bias_m: b * g.clock_bias_initial_sigma_m,
                drift_m_s: d * g.clock_drift_initial_sigma_m_s,
            },
            lever_arm_b_m: scn
                .spec
                .world
                .map_or_else(Vector3::zeros, |w| w.lever_arm_b_m()),
            last_t_s: None,
            world,
            last_fix: None,
        }
    }

    /// The constellation.
    pub fn constellation(&self) -> &Constellation {
        &self.constellation
    }

    /// Slip and acquisition counts of the carrier-phase tracking so far (truth).
    pub fn phase_slip_counts(&self) -> crate::world::carrier_phase::SlipCounts {
        self.phase_tracking.counts()
    }

    /// The world of a real receiver (None for the matched one).
    pub fn world(&self) -> Option<&GnssWorld> {
        self.world.as_ref().map(|(w, _)| w)
    }

    /// Receiver output at `t_s` since the scenario epoch (GPS time `t_gps_ns` of the
    /// measurement instant) for the truth point `truth` (the IMU's), with the hidden truth of
    /// the epoch.
    pub fn sample(
        &mut self,
        t_s: f64,
        t_gps_ns: i64,
        truth: &TruthPoint,
    ) -> (GnssSample, GnssEpochTruth) {
        if let Some(prev) = self.last_t_s {
            self.clock.step(t_s - prev, &mut self.rng);
            if let Some((w, _)) = &mut self.world {
                w.step(t_s - prev);
            }
            if let Some(m) = &mut self.phase_multipath {
                m.step(t_s - prev);
            }
        }
        self.last_t_s = Some(t_s);
        self.phase_tracking.begin_epoch(t_s);
        if self.world.is_some() {
            self.sample_real(t_s, t_gps_ns, truth)
        } else {
            self.sample_matched(t_s, t_gps_ns, truth)
        }
    }

    fn header(&self, t_s: f64, t_gps_ns: i64) -> (GnssSample, bool) {
        let g = self.grade;
        let mut out = GnssSample::default();
        out.header.time_ns = t_gps_ns;
        out.baseline_length_m = g.baseline_length_m;
        out.wavelength_m = SPEED_OF_LIGHT_M_S / g.carrier_frequency_hz;
        let outage = self.outages.iter().any(|w| w.contains(t_s));
        if outage {
            out.header.status = STATUS_OUTAGE;
        }
        (out, outage)
    }

    /// Carrier-phase differences of the two body baselines for satellite `i`'s line of sight
    /// `u` at elevation `el_rad` (cycles), as the receiver publishes them: with the integer
    /// `tracked` carries and the world's phase multipath, which is returned too (cycles, for
    /// the hidden truth; zeros without phases).
    fn baseline_phases(
        &self,
        (i, el_rad): (usize, f64),
        c_e_b: &nalgebra::Matrix3<f64>,
        u: &Vector3<f64>,
        draws: &[f64; 4],
        tracked: &TrackedPhase,
    ) -> (u32, [f64; 2], [f64; 2]) {
        let g = self.grade;
        let wavelength = SPEED_OF_LIGHT_M_S / g.carrier_frequency_hz;
        let mut phase = [0.0; 2];
        if g.baseline_length_m[0] > 0.0 && g.baseline_length_m[1] > 0.0 {
            let baselines_e = [
                c_e_b * Vector3::new(g.baseline_length_m[0], 0.0, 0.0),
                c_e_b * Vector3::new(0.0, g.baseline_length_m[1], 0.0),
            ];
            let multipath_m = self
                .phase_multipath
                .as_ref()
                .map_or([0.0; 2], |m| m.error_m(i, el_rad));
            for (k, b) in baselines_e.iter().enumerate() {
                phase[k] = (b.dot(u) + multipath_m[k]) / wavelength
                    + g.phase_sigma_cycles * draws[2 + k]
                    + tracked.ambiguity_cycles[k] as f64;
            }
            return (FLAG_PHASE, phase, multipath_m.map(|m| m / wavelength));
        }
        (0, phase, [0.0; 2])
    }

    /// Antenna phase centre position and velocity (ECEF) for the truth point.
    fn antenna(
        &self,
        truth: &TruthPoint,
        c_e_b: &nalgebra::Matrix3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        crate::world::antenna::antenna_state(
            &truth.r_e_m,
            &truth.v_e_m_s(),
            c_e_b,
            &truth.w_ib_b_rad_s,
            &self.lever_arm_b_m,
        )
    }

    /// The satellites the receiver tracks at reception time `t_rx_s` from the antenna `r_rx`
    /// (ECEF, m) under the NED frame `c_e_n`, as bit `i` for satellite `i`: every one above the
    /// elevation mask `mask_rad` while they fit the sample's [`MAX_SATELLITES`] channels, else
    /// the highest of them (a multi-constellation sky holds more than a receiver reports; the
    /// low ones are the first it drops, and their multipath and atmosphere are the worst).
    /// A constellation no larger than the channels needs no pre-pass: all of it.
    fn tracked_channels(
        &self,
        t_rx_s: f64,
        r_rx: &Vector3<f64>,
        c_e_n: &nalgebra::Matrix3<f64>,
        mask_rad: f64,
    ) -> u128 {
        let n = self.constellation.len();
        if n <= MAX_SATELLITES {
            return u128::MAX;
        }
        let mut visible = [(0.0f64, 0usize); MAX_CONSTELLATION];
        let mut k = 0;
        for i in 0..n.min(MAX_CONSTELLATION) {
            let (r_s, _, range) = self.constellation.at_reception(i, t_rx_s, r_rx);
            let el = elevation_rad(c_e_n, &((r_s - r_rx) / range));
            if el >= mask_rad {
                visible[k] = (el, i);
                k += 1;
            }
        }
        let visible = &mut visible[..k];
        // Highest first; equal elevations by PRN (a total order: no NaN above the mask).
        visible.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        visible
            .iter()
            .take(MAX_SATELLITES)
            .fold(0u128, |bits, &(_, i)| bits | (1 << i))
    }

    fn draws(&mut self) -> [f64; 4] {
        [
            self.rng.sample(StandardNormal),
            self.rng.sample(StandardNormal),
            self.rng.sample(StandardNormal),
            self.rng.sample(StandardNormal),
        ]
    }

    /// The matched receiver: white errors of the grade's σ, fix error `(HᵀH)⁻¹Hᵀε`.
    fn sample_matched(
        &mut self,
        t_s: f64,
        t_gps_ns: i64,
        truth: &TruthPoint,
    ) -> (GnssSample, GnssEpochTruth) {
        let g = self.grade;
        let t_rx_s = t_gps_ns as f64 * 1e-9;
        let c_e_b = truth.c_e_n * truth.c_n_b;
        let (r_rx, v_rx) = self.antenna(truth, &c_e_b);
        let mask = g.elevation_mask_deg.to_radians();
        let (mut out, outage) = self.header(t_s, t_gps_ns);
        let mut hidden = GnssEpochTruth {
            clock_bias_m: self.clock.bias_m,
            clock_drift_m_s: self.clock.drift_m_s,
            geometric_range_m: [0.0; MAX_SATELLITES],
            antenna_r_e_m: r_rx,
            phase_ambiguity_cycles: [[0; 2]; MAX_SATELLITES],
            phase_multipath_cycles: [[0.0; 2]; MAX_SATELLITES],
        };
        let mut hth = Matrix4::<f64>::zeros();
        let mut ht_pr = Vector4::<f64>::zeros();
        let mut ht_rr = Vector4::<f64>::zeros();
        let channels = self.tracked_channels(t_rx_s, &r_rx, &truth.c_e_n, mask);
        let mut n = 0usize;
        for i in 0..self.constellation.len() {
            // Fixed draw order for every satellite, visible or not.
            let draws = self.draws();
            if outage || n >= MAX_SATELLITES || channels & (1 << i) == 0 {
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
            let cn0 = g.cn0_horizon_dbhz + (g.cn0_zenith_dbhz - g.cn0_horizon_dbhz) * el.sin();
            let tracked = self.phase_tracking.track(i, cn0);
            let (phase_flag, phase, multipath_cycles) =
                self.baseline_phases((i, el), &c_e_b, &u, &draws, &tracked);
            out.satellites[n] = GnssSatellite {
                prn: i as u32 + 1,
                flags: FLAG_PSEUDORANGE | FLAG_DOPPLER | phase_flag,
                pseudorange_m: range + self.clock.bias_m + e_pr,
                range_rate_m_s: rate + self.clock.drift_m_s + e_rr,
                cn0_dbhz: cn0,
                sigma_pseudorange_m: g.pseudorange_sigma_m,
                sigma_range_rate_m_s: g.range_rate_sigma_m_s,
                sat_pos_ecef_m: [r_s.x, r_s.y, r_s.z],
                sat_vel_ecef_m_s: [v_s.x, v_s.y, v_s.z],
                baseline_phase_cycles: phase,
                phase_lock_time_s: lock_time(phase_flag, &tracked),
            };
            hidden.geometric_range_m[n] = range;
            hidden.phase_ambiguity_cycles[n] = tracked.ambiguity_cycles;
            hidden.phase_multipath_cycles[n] = multipath_cycles;
            let h = Vector4::new(-u.x, -u.y, -u.z, 1.0);
            hth += h * h.transpose();
            ht_pr += h * e_pr;
            ht_rr += h * e_rr;
            n += 1;
        }
        out.n_satellites = n as u32;
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

    /// The real receiver: the world's errors, the receiver's own corrections, its own σ and a
    /// weighted least-squares fix of the corrected pseudoranges.
    fn sample_real(
        &mut self,
        t_s: f64,
        t_gps_ns: i64,
        truth: &TruthPoint,
    ) -> (GnssSample, GnssEpochTruth) {
        let g = self.grade;
        let t_rx_s = t_gps_ns as f64 * 1e-9;
        let c_e_b = truth.c_e_n * truth.c_n_b;
        let Some(uere) = self.world.as_ref().map(|(_, u)| *u) else {
            return self.sample_matched(t_s, t_gps_ns, truth);
        };
        let (r_rx, v_rx) = self.antenna(truth, &c_e_b);
        let geo = truth.geodetic;
        let mask = g.elevation_mask_deg.to_radians();
        // The receiver's own models: broadcast ionosphere, standard-atmosphere troposphere.
        let gps_sow = t_rx_s.rem_euclid(604_800.0);
        // Local time of the world's ionosphere: GPS time of day (GPS − UTC = 18 s shifts the
        // diurnal curve by 0.005 h, far below its width).
        let s_of_day = t_rx_s.rem_euclid(86_400.0);
        let zenith = corr::saastamoinen_zenith(
            geo.lat_rad,
            geo.height_m,
            &corr::standard_atmosphere(geo.height_m, RECEIVER_HUMIDITY),
        );
        let (mut out, outage) = self.header(t_s, t_gps_ns);
        let mut hidden = GnssEpochTruth {
            clock_bias_m: self.clock.bias_m,
            clock_drift_m_s: self.clock.drift_m_s,
            geometric_range_m: [0.0; MAX_SATELLITES],
            antenna_r_e_m: r_rx,
            phase_ambiguity_cycles: [[0; 2]; MAX_SATELLITES],
            phase_multipath_cycles: [[0.0; 2]; MAX_SATELLITES],
        };
        let mut obs = fusion::gnss_ls::Observations::default();
        let channels = self.tracked_channels(t_rx_s, &r_rx, &truth.c_e_n, mask);
        let mut n = 0usize;
        for i in 0..self.constellation.len() {
            let draws = self.draws();
            if outage || n >= MAX_SATELLITES || channels & (1 << i) == 0 {
                continue;
            }
            let (r_s, v_s, range) = self.constellation.at_reception(i, t_rx_s, &r_rx);
            let u = (r_s - r_rx) / range;
            let u_n = truth.c_e_n.transpose() * u;
            let el = (-u_n.z).clamp(-1.0, 1.0).asin();
            if el < mask {
                continue;
            }
            let az = u_n.y.atan2(u_n.x).rem_euclid(std::f64::consts::TAU);
            let cn0 = g.cn0_horizon_dbhz + (g.cn0_zenith_dbhz - g.cn0_horizon_dbhz) * el.sin();
            // Received through an echo only: late by the excess path, weaker by the loss.
            let (nlos_excess_m, cn0) = match self.world.as_mut().and_then(|(w, _)| w.nlos(i, el)) {
                Some((excess_m, loss_db)) => (excess_m, cn0 - loss_db),
                None => (0.0, cn0),
            };
            let Some((world, _)) = &self.world else {
                unreachable!()
            };
            let errors = world.range_errors(
                i,
                (geo.lat_rad, geo.lon_rad),
                geo.height_m,
                (az, el),
                s_of_day,
                g.carrier_frequency_hz,
            );
            let sigma_code = world.code_noise_sigma_m(cn0).unwrap_or(0.0);
            let r_s_broadcast = r_s + world.orbit_error_e_m(i, &r_s, &v_s);
            let klobuchar = corr::iono_delay_at(
                BROADCAST_KLOBUCHAR.l1_delay_m(&geo, az, el, gps_sow),
                g.carrier_frequency_hz,
            );
            let tropo = corr::slant_troposphere_m(&zenith, el);
            // A correction for a delay the world does not have is left out (`has_atmosphere`).
            let (iono_on, tropo_on) = world.has_atmosphere();
            let pseudorange = range
                + self.clock.bias_m
                + errors.total_m()
                + nlos_excess_m
                + sigma_code * draws[0]
                - if iono_on { klobuchar } else { 0.0 }
                - if tropo_on { tropo } else { 0.0 };
            let e_rr = g.range_rate_sigma_m_s * draws[1];
            let rate = (v_s - v_rx).dot(&u);
            let tracked = self.phase_tracking.track(i, cn0);
            let (phase_flag, phase, multipath_cycles) =
                self.baseline_phases((i, el), &c_e_b, &u, &draws, &tracked);
            let sigma_pr = uere.sigma_m(el, cn0, klobuchar);
            let sat = GnssSatellite {
                prn: i as u32 + 1,
                flags: FLAG_PSEUDORANGE | FLAG_DOPPLER | phase_flag,
                pseudorange_m: pseudorange,
                range_rate_m_s: rate + self.clock.drift_m_s + e_rr,
                cn0_dbhz: cn0,
                sigma_pseudorange_m: sigma_pr,
                sigma_range_rate_m_s: g.range_rate_sigma_m_s,
                sat_pos_ecef_m: r_s_broadcast.into(),
                sat_vel_ecef_m_s: v_s.into(),
                baseline_phase_cycles: phase,
                phase_lock_time_s: lock_time(phase_flag, &tracked),
            };
            out.satellites[n] = sat;
            hidden.geometric_range_m[n] = range;
            hidden.phase_ambiguity_cycles[n] = tracked.ambiguity_cycles;
            hidden.phase_multipath_cycles[n] = multipath_cycles;
            // Every value is finite and the satellite at orbital distance: push cannot fail.
            let _ = obs.push(fusion::gnss_ls::SatelliteObservation {
                prn: sat.prn,
                sat_pos_ecef_m: r_s_broadcast,
                sat_vel_ecef_m_s: v_s,
                pseudorange_m: pseudorange,
                sigma_pseudorange_m: sigma_pr,
                has_range_rate: true,
                range_rate_m_s: sat.range_rate_m_s,
                sigma_range_rate_m_s: g.range_rate_sigma_m_s,
            });
            n += 1;
        }
        out.n_satellites = n as u32;
        if n >= 4 {
            let (r0, b0) = self.last_fix.unwrap_or((Vector3::zeros(), 0.0));
            let settings = fusion::gnss_ls::LsSettings {
                initial_r_e_m: r0,
                initial_clock_bias_m: b0,
                ..Default::default()
            };
            // The receiver's RAIM/FDE: a χ² test of its residuals against its own σ, the
            // worst range by Baarda's w-test excluded while six or more remain. The message
            // keeps every pseudorange (tight coupling judges them itself).
            if let Ok(fix) = fusion::gnss_ls::solve_excluding_faults(
                &obs,
                &settings,
                RECEIVER_FDE_PROBABILITY,
                5,
            )
            .map(|s| s.fix)
            {
                let p = fix.position.r_e_m;
                out.fix_valid = 1;
                out.pos_ecef_m = p.into();
                out.pdop = fix.position.dop.pdop;
                for r in 0..3 {
                    for c in 0..3 {
                        out.pos_cov_ecef_m2[3 * r + c] = fix.position.cov_r_e_m2[(r, c)];
                    }
                }
                if let Some(v) = fix.velocity {
                    out.vel_ecef_m_s = v.v_e_m_s.into();
                    for r in 0..3 {
                        for c in 0..3 {
                            out.vel_cov_ecef_m2_s2[3 * r + c] = v.cov_v_e_m2_s2[(r, c)];
                        }
                    }
                }
                self.last_fix = Some((p, fix.position.clock_bias_m));
            }
        }
        (out, hidden)
    }
}
