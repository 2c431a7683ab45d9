//! Receiver-style least-squares GNSS fix (paper 003, eq. 12–13): position and receiver clock
//! bias by Gauss–Newton on the pseudoranges, then velocity and clock drift by linear weighted
//! least squares on the range rates (Doppler), with dilutions of precision and post-fit
//! residuals.
//!
//! Measurement model (the one `drivers-sim/src/gnss.rs` publishes in `msgs::GnssSatellite`):
//!
//! * pseudorange `ρ_i = |s_i − r| + b + ε_i`, where `s_i` is the satellite position at its
//!   transmission time **already rotated into the ECEF frame of reception** (the light-time /
//!   Sagnac correction is applied by whoever fills `sat_pos_ecef_m`, so this solver must not
//!   apply it again), `r` the antenna ECEF position, `b` the receiver clock bias in metres;
//! * range rate `ρ̇_i = (ṡ_i − v)·u_i + d + η_i`, with `u_i = (s_i − r)/|s_i − r|` the unit
//!   line of sight, `ṡ_i` the satellite velocity relative to ECEF (same frame), `v` the antenna
//!   ECEF velocity and `d` the clock drift in m/s.
//!
//! Linearised at the current estimate, both have the Jacobian row `h_i = [−u_iᵀ, 1]`
//! (eq. 12 of the paper; the stacked system `H δx = δρ` of eq. 13 is solved by weighted least
//! squares `δx = (HᵀWH)⁻¹HᵀW δρ`, `W = diag(1/σ_i²)`). The position problem is iterated until
//! the step is below [`LsSettings::tolerance_m`]; the velocity problem is linear once `u_i` is
//! known. The dilutions of precision come from the *unweighted* `Q = (HᵀH)⁻¹`
//! (GDOP = √tr Q, PDOP = √(Q_xx+Q_yy+Q_zz), HDOP/VDOP from the position block rotated into NED,
//! TDOP = √Q_bb); the covariances reported are the weighted `(HᵀWH)⁻¹`.
//!
//! [`solve_excluding_faults`] adds a receiver's snapshot fault detection and exclusion (a χ²
//! test of the residuals, Baarda's w-test to pick the range to exclude).
//!
//! Pure, stack only: observations live in fixed arrays of [`MAX_SATELLITES`], the normal
//! equations are 4×4.

use crate::earth::{self, Ellipsoid, Geodetic};
use crate::ekf::chi2_quantile;
use msgs::{GnssSample, MAX_SATELLITES};
use nalgebra::{Matrix3, Matrix4, Vector3, Vector4};

/// Satellite flag bit (msgs::GnssSatellite::flags): pseudorange valid.
pub const FLAG_PSEUDORANGE: u32 = 1;
/// Satellite flag bit: Doppler (range rate) valid.
pub const FLAG_DOPPLER: u32 = 2;

/// Why a least-squares fix could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GnssLsError {
    /// Fewer usable measurements than unknowns (4: three coordinates and the clock).
    #[error("{what}: {have} usable satellites, need at least {need}")]
    TooFewSatellites {
        /// Pseudorange or range rate.
        what: &'static str,
        /// Usable measurements.
        have: usize,
        /// Needed.
        need: usize,
    },
    /// The normal matrix is singular or so ill-conditioned that GDOP exceeds [`MAX_GDOP`].
    #[error("{what}: singular satellite geometry (GDOP {gdop:.3e})")]
    SingularGeometry {
        /// Pseudorange or range rate.
        what: &'static str,
        /// GDOP at the failing iteration (infinite when the matrix is not invertible).
        gdop: f64,
    },
    /// Gauss–Newton did not converge.
    #[error(
        "position fix did not converge in {iterations} iterations (last step {last_step_m:.3e} m)"
    )]
    NoConvergence {
        /// Iterations made.
        iterations: usize,
        /// Norm of the last position + clock step, m.
        last_step_m: f64,
    },
    /// A measurement value cannot be physical (NaN, infinity, non-positive σ).
    #[error("satellite {index} (PRN {prn}): invalid {field} = {value}")]
    InvalidObservation {
        /// Index in the observation list.
        index: usize,
        /// Satellite number.
        prn: u32,
        /// Which field.
        field: &'static str,
        /// Its value.
        value: f64,
    },
}

/// GDOP above which the geometry is declared singular.
pub const MAX_GDOP: f64 = 1.0e4;

/// One satellite's measurements and ephemeris-derived state, SI units, ECEF at reception.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SatelliteObservation {
    /// Satellite number (PRN), for error messages.
    pub prn: u32,
    /// Satellite position at transmission, rotated into ECEF at reception, m.
    pub sat_pos_ecef_m: Vector3<f64>,
    /// Satellite velocity relative to ECEF, same frame, m/s.
    pub sat_vel_ecef_m_s: Vector3<f64>,
    /// Pseudorange, m.
    pub pseudorange_m: f64,
    /// 1-σ pseudorange noise, m (> 0).
    pub sigma_pseudorange_m: f64,
    /// Whether `range_rate_m_s` is valid.
    pub has_range_rate: bool,
    /// Pseudorange rate (Doppler × −λ), m/s.
    pub range_rate_m_s: f64,
    /// 1-σ range-rate noise, m/s (> 0 when `has_range_rate`).
    pub sigma_range_rate_m_s: f64,
}

/// Up to [`MAX_SATELLITES`] observations of one epoch (fixed-size, no heap).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observations {
    sats: [SatelliteObservation; MAX_SATELLITES],
    n: usize,
}

impl Default for Observations {
    fn default() -> Self {
        Self {
            sats: [SatelliteObservation::default(); MAX_SATELLITES],
            n: 0,
        }
    }
}

impl Observations {
    /// The observations of a receiver message: every satellite among the first
    /// `n_satellites` whose pseudorange flag is set (range rate when its Doppler flag is set).
    /// Fails on a non-finite value or non-positive σ, naming the satellite and field.
    pub fn from_sample(sample: &GnssSample) -> Result<Self, GnssLsError> {
        let mut obs = Self::default();
        let n = (sample.n_satellites as usize).min(MAX_SATELLITES);
        for s in &sample.satellites[..n] {
            if s.flags & FLAG_PSEUDORANGE == 0 {
                continue;
            }
            let has_rr = s.flags & FLAG_DOPPLER != 0;
            obs.push(SatelliteObservation {
                prn: s.prn,
                sat_pos_ecef_m: Vector3::from(s.sat_pos_ecef_m),
                sat_vel_ecef_m_s: Vector3::from(s.sat_vel_ecef_m_s),
                pseudorange_m: s.pseudorange_m,
                sigma_pseudorange_m: s.sigma_pseudorange_m,
                has_range_rate: has_rr,
                range_rate_m_s: s.range_rate_m_s,
                sigma_range_rate_m_s: s.sigma_range_rate_m_s,
            })?;
        }
        Ok(obs)
    }

    /// Add one observation (ignored silently beyond [`MAX_SATELLITES`]: a receiver message
    /// cannot carry more). Fails on a non-finite value or non-positive σ.
    pub fn push(&mut self, o: SatelliteObservation) -> Result<(), GnssLsError> {
        let index = self.n;
        let bad = |field: &'static str, value: f64| GnssLsError::InvalidObservation {
            index,
            prn: o.prn,
            field,
            value,
        };
        for k in 0..3 {
            if !o.sat_pos_ecef_m[k].is_finite() {
                return Err(bad("sat_pos_ecef_m", o.sat_pos_ecef_m[k]));
            }
        }
        if !o.pseudorange_m.is_finite() {
            return Err(bad("pseudorange_m", o.pseudorange_m));
        }
        if !(o.sigma_pseudorange_m.is_finite() && o.sigma_pseudorange_m > 0.0) {
            return Err(bad("sigma_pseudorange_m", o.sigma_pseudorange_m));
        }
        if o.has_range_rate {
            for k in 0..3 {
                if !o.sat_vel_ecef_m_s[k].is_finite() {
                    return Err(bad("sat_vel_ecef_m_s", o.sat_vel_ecef_m_s[k]));
                }
            }
            if !o.range_rate_m_s.is_finite() {
                return Err(bad("range_rate_m_s", o.range_rate_m_s));
            }
            if !(o.sigma_range_rate_m_s.is_finite() && o.sigma_range_rate_m_s > 0.0) {
                return Err(bad("sigma_range_rate_m_s", o.sigma_range_rate_m_s));
            }
        }
        if self.n < MAX_SATELLITES {
            self.sats[self.n] = o;
            self.n += 1;
        }
        Ok(())
    }

    /// The valid observations.
    pub fn as_slice(&self) -> &[SatelliteObservation] {
        &self.sats[..self.n]
    }

    /// Number of observations.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Remove observation `i` (the later ones move up); out of range: nothing.
    pub fn remove(&mut self, i: usize) {
        if i < self.n {
            self.sats.copy_within(i + 1..self.n, i);
            self.n -= 1;
            self.sats[self.n] = SatelliteObservation::default();
        }
    }
}

/// Iteration settings of the position solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LsSettings {
    /// Stop when the position + clock step is below this, m.
    pub tolerance_m: f64,
    /// Give up after this many Gauss–Newton iterations.
    pub max_iterations: usize,
    /// Starting position, ECEF, m (the Earth's centre converges for any receiver near the
    /// surface: the ranges are ≈ 20 000 km, so the linearisation error of a 6 400 km start is
    /// removed in 4–6 iterations).
    pub initial_r_e_m: Vector3<f64>,
    /// Starting clock bias, m.
    pub initial_clock_bias_m: f64,
    /// Ellipsoid for the NED rotation of the DOPs and the geodetic output.
    pub ellipsoid: Ellipsoid,
}

impl Default for LsSettings {
    fn default() -> Self {
        Self {
            tolerance_m: 1e-4,
            max_iterations: 20,
            initial_r_e_m: Vector3::zeros(),
            initial_clock_bias_m: 0.0,
            ellipsoid: earth::WGS84,
        }
    }
}

/// Dilutions of precision (dimensionless) from the unweighted geometry `(HᵀH)⁻¹`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Dop {
    /// Geometric: √(σ²_x + σ²_y + σ²_z + σ²_b)/σ.
    pub gdop: f64,
    /// Position (3-D).
    pub pdop: f64,
    /// Horizontal (north + east).
    pub hdop: f64,
    /// Vertical (down).
    pub vdop: f64,
    /// Time (clock bias, in metres per metre of range noise).
    pub tdop: f64,
}

/// Position and clock-bias solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionFix {
    /// Antenna position, ECEF, m.
    pub r_e_m: Vector3<f64>,
    /// The same, geodetic.
    pub geodetic: Geodetic,
    /// Receiver clock bias, m (c·δt).
    pub clock_bias_m: f64,
    /// Covariance of `r_e_m`, ECEF, m² (weighted `(HᵀWH)⁻¹`).
    pub cov_r_e_m2: Matrix3<f64>,
    /// Variance of the clock bias, m².
    pub var_clock_bias_m2: f64,
    /// Covariance of `r_e_m` with the clock bias, m² (the off-diagonal column of the weighted
    /// `(HᵀWH)⁻¹`: position and clock errors are correlated through the common `1` column of
    /// `H`, strongly along the vertical for a sky-only geometry).
    pub cov_r_clock_m2: Vector3<f64>,
    /// Dilutions of precision.
    pub dop: Dop,
    /// Post-fit residuals `ρ_i − |s_i − r̂| − b̂` in observation order, m (first `n_used`).
    pub residuals_m: [f64; MAX_SATELLITES],
    /// Number of pseudoranges used.
    pub n_used: usize,
    /// Weighted sum of squared residuals Σ(r_i/σ_i)², χ² with n_used − 4 degrees of freedom.
    pub chi2: f64,
    /// Gauss–Newton iterations made.
    pub iterations: usize,
}

/// Velocity and clock-drift solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VelocityFix {
    /// Antenna velocity relative to ECEF, ECEF axes, m/s.
    pub v_e_m_s: Vector3<f64>,
    /// Receiver clock drift, m/s (c·δṫ).
    pub clock_drift_m_s: f64,
    /// Covariance of `v_e_m_s`, ECEF, (m/s)².
    pub cov_v_e_m2_s2: Matrix3<f64>,
    /// Variance of the clock drift, (m/s)².
    pub var_clock_drift_m2_s2: f64,
    /// Covariance of `v_e_m_s` with the clock drift, m²/s².
    pub cov_v_drift_m2_s2: Vector3<f64>,
    /// Post-fit range-rate residuals of the satellites with Doppler, in observation order
    /// (entries of satellites without Doppler are 0), m/s.
    pub residuals_m_s: [f64; MAX_SATELLITES],
    /// Number of range rates used.
    pub n_used: usize,
    /// Weighted sum of squared residuals, χ² with n_used − 4 degrees of freedom.
    pub chi2: f64,
}

/// A full fix: position/clock, and velocity/drift when at least four range rates exist.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GnssFix {
    /// Position and clock bias.
    pub position: PositionFix,
    /// Velocity and clock drift (`None` with fewer than four Dopplers).
    pub velocity: Option<VelocityFix>,
}

/// Jacobian row `[−uᵀ, 1]` and geometric range from `r` to satellite `s`.
fn row(s: &Vector3<f64>, r: &Vector3<f64>) -> (Vector4<f64>, Vector3<f64>, f64) {
    let d = s - r;
    let range = d.norm();
    let u = d / range;
    (Vector4::new(-u.x, -u.y, -u.z, 1.0), u, range)
}

/// GDOP of an unweighted normal inverse.
fn gdop_of(q: &Matrix4<f64>) -> f64 {
    q.trace().max(0.0).sqrt()
}

/// Invert a 4×4 normal matrix, or report singular geometry.
fn invert(n: &Matrix4<f64>, what: &'static str) -> Result<Matrix4<f64>, GnssLsError> {
    let inv = n
        .cholesky()
        .map(|c| c.inverse())
        .ok_or(GnssLsError::SingularGeometry {
            what,
            gdop: f64::INFINITY,
        })?;
    Ok(inv)
}

/// Position and clock bias by Gauss–Newton (paper 003 eq. 12–13) from the pseudoranges.
pub fn solve_position(
    obs: &Observations,
    settings: &LsSettings,
) -> Result<PositionFix, GnssLsError> {
    let sats = obs.as_slice();
    if sats.len() < 4 {
        return Err(GnssLsError::TooFewSatellites {
            what: "pseudorange",
            have: sats.len(),
            need: 4,
        });
    }
    let mut r = settings.initial_r_e_m;
    let mut b = settings.initial_clock_bias_m;
    let mut last_step = f64::INFINITY;
    let mut iterations = 0;
    while iterations < settings.max_iterations {
        iterations += 1;
        let mut n_w = Matrix4::zeros();
        let mut n_u = Matrix4::zeros();
        let mut y_w = Vector4::zeros();
        for s in sats {
            let (h, _, range) = row(&s.sat_pos_ecef_m, &r);
            let w = 1.0 / (s.sigma_pseudorange_m * s.sigma_pseudorange_m);
            let dz = s.pseudorange_m - range - b;
            n_w += w * h * h.transpose();
            n_u += h * h.transpose();
            y_w += w * dz * h;
        }
        // Rounding can let a rank-deficient matrix through Cholesky with tiny pivots: judge
        // the geometry by its GDOP instead.
        let gdop = gdop_of(&invert(&n_u, "pseudorange")?);
        if !(gdop.is_finite() && gdop < MAX_GDOP) {
            return Err(GnssLsError::SingularGeometry {
                what: "pseudorange",
                gdop,
            });
        }
        let inv = invert(&n_w, "pseudorange")?;
        let dx = inv * y_w;
        if !dx.iter().all(|v| v.is_finite()) {
            return Err(GnssLsError::SingularGeometry {
                what: "pseudorange",
                gdop: f64::INFINITY,
            });
        }
        r += Vector3::new(dx.x, dx.y, dx.z);
        b += dx.w;
        last_step = dx.norm();
        if last_step < settings.tolerance_m {
            break;
        }
    }
    if last_step >= settings.tolerance_m {
        return Err(GnssLsError::NoConvergence {
            iterations,
            last_step_m: last_step,
        });
    }
    // Geometry, covariance and residuals at the solution.
    let mut n_w = Matrix4::zeros();
    let mut n_u = Matrix4::zeros();
    let mut residuals = [0.0; MAX_SATELLITES];
    let mut chi2 = 0.0;
    for (i, s) in sats.iter().enumerate() {
        let (h, _, range) = row(&s.sat_pos_ecef_m, &r);
        let w = 1.0 / (s.sigma_pseudorange_m * s.sigma_pseudorange_m);
        n_w += w * h * h.transpose();
        n_u += h * h.transpose();
        residuals[i] = s.pseudorange_m - range - b;
        chi2 += w * residuals[i] * residuals[i];
    }
    let q = invert(&n_u, "pseudorange")?;
    let gdop = gdop_of(&q);
    if !(gdop.is_finite() && gdop < MAX_GDOP) {
        return Err(GnssLsError::SingularGeometry {
            what: "pseudorange",
            gdop,
        });
    }
    let p = invert(&n_w, "pseudorange")?;
    let geodetic = earth::ecef_to_geodetic(&settings.ellipsoid, &r);
    let c_e_n = earth::c_e_n(geodetic.lat_rad, geodetic.lon_rad);
    let q_e: Matrix3<f64> = q.fixed_view::<3, 3>(0, 0).into_owned();
    let q_n = c_e_n.transpose() * q_e * c_e_n;
    let dop = Dop {
        gdop,
        pdop: q_e.trace().max(0.0).sqrt(),
        hdop: (q_n[(0, 0)] + q_n[(1, 1)]).max(0.0).sqrt(),
        vdop: q_n[(2, 2)].max(0.0).sqrt(),
        tdop: q[(3, 3)].max(0.0).sqrt(),
    };
    Ok(PositionFix {
        r_e_m: r,
        geodetic,
        clock_bias_m: b,
        cov_r_e_m2: p.fixed_view::<3, 3>(0, 0).into_owned(),
        var_clock_bias_m2: p[(3, 3)],
        cov_r_clock_m2: p.fixed_view::<3, 1>(0, 3).into_owned(),
        dop,
        residuals_m: residuals,
        n_used: sats.len(),
        chi2,
        iterations,
    })
}

/// Velocity and clock drift by weighted least squares on the range rates, with the lines of
/// sight of the position solution `pos` (linear: no iteration needed).
pub fn solve_velocity(obs: &Observations, pos: &PositionFix) -> Result<VelocityFix, GnssLsError> {
    let mut n_w = Matrix4::zeros();
    let mut n_u = Matrix4::zeros();
    let mut y_w = Vector4::zeros();
    let mut used = 0;
    for s in obs.as_slice().iter().filter(|s| s.has_range_rate) {
        let (h, u, _) = row(&s.sat_pos_ecef_m, &pos.r_e_m);
        let w = 1.0 / (s.sigma_range_rate_m_s * s.sigma_range_rate_m_s);
        // ρ̇ − ṡ·u = −u·v + d
        let z = s.range_rate_m_s - s.sat_vel_ecef_m_s.dot(&u);
        n_w += w * h * h.transpose();
        n_u += h * h.transpose();
        y_w += w * z * h;
        used += 1;
    }
    if used < 4 {
        return Err(GnssLsError::TooFewSatellites {
            what: "range rate",
            have: used,
            need: 4,
        });
    }
    let gdop = gdop_of(&invert(&n_u, "range rate")?);
    if !(gdop.is_finite() && gdop < MAX_GDOP) {
        return Err(GnssLsError::SingularGeometry {
            what: "range rate",
            gdop,
        });
    }
    let p = invert(&n_w, "range rate")?;
    let x = p * y_w;
    if !x.iter().all(|v| v.is_finite()) {
        return Err(GnssLsError::SingularGeometry {
            what: "range rate",
            gdop: f64::INFINITY,
        });
    }
    let v = Vector3::new(x.x, x.y, x.z);
    let d = x.w;
    let mut residuals = [0.0; MAX_SATELLITES];
    let mut chi2 = 0.0;
    for (i, s) in obs.as_slice().iter().enumerate() {
        if !s.has_range_rate {
            continue;
        }
        let (_, u, _) = row(&s.sat_pos_ecef_m, &pos.r_e_m);
        residuals[i] = s.range_rate_m_s - (s.sat_vel_ecef_m_s - v).dot(&u) - d;
        chi2 += residuals[i] * residuals[i] / (s.sigma_range_rate_m_s * s.sigma_range_rate_m_s);
    }
    Ok(VelocityFix {
        v_e_m_s: v,
        clock_drift_m_s: d,
        cov_v_e_m2_s2: p.fixed_view::<3, 3>(0, 0).into_owned(),
        var_clock_drift_m2_s2: p[(3, 3)],
        cov_v_drift_m2_s2: p.fixed_view::<3, 1>(0, 3).into_owned(),
        residuals_m_s: residuals,
        n_used: used,
        chi2,
    })
}

/// Position/clock, then velocity/drift when at least four range rates exist.
pub fn solve(obs: &Observations, settings: &LsSettings) -> Result<GnssFix, GnssLsError> {
    let position = solve_position(obs, settings)?;
    let velocity = match solve_velocity(obs, &position) {
        Ok(v) => Some(v),
        Err(GnssLsError::TooFewSatellites { .. }) => None,
        Err(e) => return Err(e),
    };
    Ok(GnssFix { position, velocity })
}

/// A fix after snapshot fault detection and exclusion (a receiver's RAIM/FDE).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScreenedFix {
    /// The fix of the observations kept.
    pub fix: GnssFix,
    /// The observations kept.
    pub kept: Observations,
    /// How many were excluded.
    pub excluded: usize,
}

/// [`solve`] with snapshot fault detection and exclusion: while the weighted post-fit
/// residuals fail the χ² test (`n − 4` degrees of freedom at `probability`) and at least
/// `min_used + 1` pseudoranges remain, exclude the one with the largest Baarda w-statistic
/// `|r_i| / (σ_i·√(1 − h_ii))` — `h_ii = σ_i⁻²·H_i (HᵀWH)⁻¹ H_iᵀ`, the weighted hat matrix's
/// diagonal (Baarda, "A testing procedure for use in geodetic networks", 1968; Kaplan &
/// Hegarty, 3rd ed., §11.3.2 RAIM/FDE) — and solve again. One bad range among many is found;
/// where most of the few satellites are bad, the largest residual may point at a good one.
pub fn solve_excluding_faults(
    obs: &Observations,
    settings: &LsSettings,
    probability: f64,
    min_used: usize,
) -> Result<ScreenedFix, GnssLsError> {
    let mut best = ScreenedFix {
        fix: solve(obs, settings)?,
        kept: *obs,
        excluded: 0,
    };
    loop {
        let p = &best.fix.position;
        let n = best.kept.len();
        if n <= min_used.max(4) || p.chi2 <= chi2_quantile((n - 4) as u32, probability) {
            return Ok(best);
        }
        let mut q = Matrix4::zeros();
        q.fixed_view_mut::<3, 3>(0, 0).copy_from(&p.cov_r_e_m2);
        q.fixed_view_mut::<3, 1>(0, 3).copy_from(&p.cov_r_clock_m2);
        q.fixed_view_mut::<1, 3>(3, 0)
            .copy_from(&p.cov_r_clock_m2.transpose());
        q[(3, 3)] = p.var_clock_bias_m2;
        let mut worst = (f64::NEG_INFINITY, 0usize);
        for (i, o) in best.kept.as_slice().iter().enumerate() {
            let (h, _, _) = row(&o.sat_pos_ecef_m, &p.r_e_m);
            let var = o.sigma_pseudorange_m.powi(2);
            let hii = (h.transpose() * q * h)[(0, 0)] / var;
            let w = p.residuals_m[i].abs() / (var * (1.0 - hii).max(1e-9)).sqrt();
            if w > worst.0 {
                worst = (w, i);
            }
        }
        let mut kept = best.kept;
        kept.remove(worst.1);
        // A geometry the exclusion leaves singular keeps the fix it had.
        let Ok(fix) = solve(&kept, settings) else {
            return Ok(best);
        };
        best = ScreenedFix {
            fix,
            kept,
            excluded: best.excluded + 1,
        };
    }
}

/// [`solve`] on a receiver message with default settings.
pub fn solve_sample(sample: &GnssSample) -> Result<GnssFix, GnssLsError> {
    solve(&Observations::from_sample(sample)?, &LsSettings::default())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::earth::{WGS84, c_e_n, geodetic_to_ecef};
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    const SAT_RANGE_M: f64 = 20_200e3;

    fn site() -> (Vector3<f64>, Matrix3<f64>) {
        let g = Geodetic {
            lat_rad: 55.655f64.to_radians(),
            lon_rad: 37.534f64.to_radians(),
            height_m: 200.0,
        };
        (geodetic_to_ecef(&WGS84, &g), c_e_n(g.lat_rad, g.lon_rad))
    }

    /// Unit line of sight in NED from azimuth/elevation (rad).
    fn los_ned(az: f64, el: f64) -> Vector3<f64> {
        Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), -el.sin())
    }

    /// Satellites at range SAT_RANGE_M along the given (az, el) directions from `r`, moving
    /// with 3 km/s in assorted directions, and the exact measurements for receiver velocity
    /// `v`, clock bias `b`, drift `d`.
    fn synth(
        r: &Vector3<f64>,
        c: &Matrix3<f64>,
        dirs: &[(f64, f64)],
        v: &Vector3<f64>,
        b: f64,
        d: f64,
    ) -> Observations {
        let mut obs = Observations::default();
        for (i, &(az, el)) in dirs.iter().enumerate() {
            let u = c * los_ned(az, el);
            let s = r + SAT_RANGE_M * u;
            let sv = 3000.0 * Vector3::new((i as f64).cos(), (i as f64 * 1.7).sin(), 0.3);
            obs.push(SatelliteObservation {
                prn: i as u32 + 1,
                sat_pos_ecef_m: s,
                sat_vel_ecef_m_s: sv,
                pseudorange_m: (s - r).norm() + b,
                sigma_pseudorange_m: 1.5,
                has_range_rate: true,
                range_rate_m_s: (sv - v).dot(&u) + d,
                sigma_range_rate_m_s: 0.05,
            })
            .unwrap();
        }
        obs
    }

    /// Seven satellites with 1.5 m white noise: nothing is excluded from a consistent epoch
    /// (noise-free here, χ² = 0), and a 40 m echo on one of them (≈ 27σ) is found and
    /// excluded, leaving the fix within a few σ of the truth; a second bad range with only
    /// the minimum left is kept (no exclusion below `min_used + 1`).
    #[test]
    fn a_bad_range_is_excluded_and_a_clean_epoch_kept() {
        let (r, c) = site();
        let b = 1234.0;
        let clean = synth(&r, &c, &sky(), &Vector3::zeros(), b, 0.0);
        let s = LsSettings::default();
        let kept = solve_excluding_faults(&clean, &s, 0.999, 5).unwrap();
        assert_eq!(kept.excluded, 0);
        assert_eq!(kept.kept, clean);
        for bad in 0..clean.len() {
            let mut obs = clean;
            obs.sats[bad].pseudorange_m += 40.0;
            let f = solve_excluding_faults(&obs, &s, 0.999, 5).unwrap();
            assert_eq!(f.excluded, 1, "satellite {bad}");
            assert!(
                f.kept.as_slice().iter().all(|o| o.prn != obs.sats[bad].prn),
                "satellite {bad}: the bad one is out"
            );
            assert!((f.fix.position.r_e_m - r).norm() < 1e-6, "satellite {bad}");
            // Plain least squares keeps it: the fix is metres off.
            let plain = solve(&obs, &s).unwrap();
            assert!((plain.position.r_e_m - r).norm() > 1.0, "satellite {bad}");
        }
        // Five satellites, min_used 5: detection without exclusion.
        let mut five = clean;
        five.remove(6);
        five.remove(5);
        assert_eq!(five.len(), 5);
        five.sats[0].pseudorange_m += 40.0;
        assert_eq!(
            solve_excluding_faults(&five, &s, 0.999, 5)
                .unwrap()
                .excluded,
            0
        );
    }

    #[test]
    fn observations_remove_keeps_the_order() {
        let (r, c) = site();
        let mut obs = synth(&r, &c, &sky(), &Vector3::zeros(), 0.0, 0.0);
        let prns: Vec<u32> = obs.as_slice().iter().map(|o| o.prn).collect();
        obs.remove(2);
        obs.remove(99);
        let after: Vec<u32> = obs.as_slice().iter().map(|o| o.prn).collect();
        assert_eq!(after, [&prns[..2], &prns[3..]].concat());
    }

    fn sky() -> Vec<(f64, f64)> {
        crate::test_sky::SKY_AZ_EL_DEG
            .iter()
            .map(|&(a, e): &(f64, f64)| (a.to_radians(), e.to_radians()))
            .collect()
    }

    #[test]
    fn exact_recovery_on_noise_free_data() {
        let (r, c) = site();
        let v = Vector3::new(12.0, -3.0, 0.5);
        let (b, d) = (123_456.7, -2.5);
        let obs = synth(&r, &c, &sky(), &v, b, d);
        let fix = solve(&obs, &LsSettings::default()).unwrap();
        // Double-precision ranges of 2e7 m carry ~4e-9 m rounding; after GN to 1e-4 m steps the
        // final quadratic convergence leaves far below 1 µm.
        assert!(
            (fix.position.r_e_m - r).norm() < 1e-6,
            "{}",
            fix.position.r_e_m - r
        );
        assert!((fix.position.clock_bias_m - b).abs() < 1e-6);
        assert!(fix.position.iterations <= 10);
        for k in 0..fix.position.n_used {
            assert!(fix.position.residuals_m[k].abs() < 1e-6);
        }
        let vel = fix.velocity.unwrap();
        assert!((vel.v_e_m_s - v).norm() < 1e-9);
        assert!((vel.clock_drift_m_s - d).abs() < 1e-9);
        assert!((fix.position.geodetic.height_m - 200.0).abs() < 1e-6);
    }

    /// One satellite at the zenith and three on the horizon 120° apart (ENU/NED unit
    /// vectors exactly). With rows [−u, 1]: HᵀH = diag(3/2, 3/2) in N, E and the (D, clock)
    /// block [[1, 1], [1, 4]] (−u_D = +1 for the zenith satellite), whose inverse is
    /// [[4/3, −1/3], [−1/3, 1/3]]. Hence HDOP = √(2/3 + 2/3) = √(4/3), VDOP = √(4/3),
    /// TDOP = √(1/3), PDOP = √(8/3), GDOP = √3.
    #[test]
    fn dop_of_a_hand_computed_geometry() {
        let (r, c) = site();
        let dirs = [
            (0.0, std::f64::consts::FRAC_PI_2),
            (0.0, 0.0),
            (120f64.to_radians(), 0.0),
            (240f64.to_radians(), 0.0),
        ];
        let obs = synth(&r, &c, &dirs, &Vector3::zeros(), 10.0, 0.0);
        let fix = solve_position(&obs, &LsSettings::default()).unwrap();
        let d = fix.dop;
        let tol = 1e-9;
        assert!((d.hdop - (4.0f64 / 3.0).sqrt()).abs() < tol, "{d:?}");
        assert!((d.vdop - (4.0f64 / 3.0).sqrt()).abs() < tol, "{d:?}");
        assert!((d.tdop - (1.0f64 / 3.0).sqrt()).abs() < tol, "{d:?}");
        assert!((d.pdop - (8.0f64 / 3.0).sqrt()).abs() < tol, "{d:?}");
        assert!((d.gdop - 3f64.sqrt()).abs() < tol, "{d:?}");
        // Equal weights: the covariance is σ²·Q.
        assert!((fix.cov_r_e_m2.trace() - 1.5 * 1.5 * 8.0 / 3.0).abs() < 1e-9);
    }

    /// Position error ≈ PDOP·σ: over N trials the NEES eᵀP⁻¹e of the 3-D position is χ²(3),
    /// so its sum is χ²(3N) with mean 3N and σ = √(6N); we accept ±4σ. Independently,
    /// E|e|² = σ²·PDOP² exactly for a linear problem (the GN nonlinearity at σ = 1.5 m over
    /// 2e7 m ranges is ~1e-7 m); Var|e|² = 2Σλ_k² ≤ 2(Σλ_k)², so the mean of N trials lies
    /// within 4·√(2/N)·σ²PDOP² of σ²PDOP².
    #[test]
    fn noise_scales_with_pdop() {
        let (r, c) = site();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let base = synth(&r, &c, &sky(), &Vector3::zeros(), 50.0, 0.0);
        let n_trials = 2000;
        let (mut nees_sum, mut e2_sum, mut nees4_sum) = (0.0, 0.0, 0.0);
        let mut cross_sum = Vector3::zeros();
        let mut p4_last = Matrix4::zeros();
        let mut pdop = 0.0;
        let mut sigma2 = 0.0;
        for _ in 0..n_trials {
            let mut obs = base;
            for s in obs.sats[..obs.n].iter_mut() {
                let z: f64 = StandardNormal.sample(&mut rng);
                s.pseudorange_m += s.sigma_pseudorange_m * z;
            }
            let fix = solve_position(&obs, &LsSettings::default()).unwrap();
            let e = fix.r_e_m - r;
            nees_sum += e.dot(&(fix.cov_r_e_m2.try_inverse().unwrap() * e));
            // Joint position + clock NEES: χ²(4) only if the position↔clock covariance is
            // right (the clock error is strongly correlated with the vertical one).
            let mut p4 = Matrix4::zeros();
            p4.fixed_view_mut::<3, 3>(0, 0).copy_from(&fix.cov_r_e_m2);
            p4.fixed_view_mut::<3, 1>(0, 3)
                .copy_from(&fix.cov_r_clock_m2);
            p4.fixed_view_mut::<1, 3>(3, 0)
                .copy_from(&fix.cov_r_clock_m2.transpose());
            p4[(3, 3)] = fix.var_clock_bias_m2;
            let e4 = Vector4::new(e.x, e.y, e.z, fix.clock_bias_m - 50.0);
            nees4_sum += e4.dot(&(p4.try_inverse().unwrap() * e4));
            cross_sum += e * e4.w;
            p4_last = p4;
            e2_sum += e.norm_squared();
            pdop = fix.dop.pdop;
            sigma2 = 1.5f64 * 1.5;
        }
        let nf = n_trials as f64;
        assert!(
            (nees_sum - 3.0 * nf).abs() < 4.0 * (6.0 * nf).sqrt(),
            "NEES sum {nees_sum} vs {}",
            3.0 * nf
        );
        // Same argument with 4 dof: mean 4N, σ √(8N).
        assert!(
            (nees4_sum - 4.0 * nf).abs() < 4.0 * (8.0 * nf).sqrt(),
            "position+clock NEES sum {nees4_sum} vs {}",
            4.0 * nf
        );
        // The NEES mean cannot see a missing correlation (tr(D⁻¹P) = 4 for D = diag P), so the
        // cross-covariance is checked directly: the sample mean of e_k·e_b estimates P_kb with
        // standard error √((P_kk P_bb + P_kb²)/N); accept 4 of them.
        for k in 0..3 {
            let p_kb = p4_last[(k, 3)];
            let se = ((p4_last[(k, k)] * p4_last[(3, 3)] + p_kb * p_kb) / nf).sqrt();
            assert!(
                (cross_sum[k] / nf - p_kb).abs() < 4.0 * se,
                "axis {k}: sample cov {} vs P_kb {p_kb} (se {se})",
                cross_sum[k] / nf
            );
        }
        let expect = sigma2 * pdop * pdop;
        let mean_e2 = e2_sum / nf;
        assert!(
            (mean_e2 - expect).abs() < 4.0 * (2.0 / nf).sqrt() * expect,
            "mean |e|² {mean_e2} vs σ²PDOP² {expect}"
        );
    }

    #[test]
    fn typed_errors() {
        let (r, c) = site();
        let obs = synth(&r, &c, &sky()[..3], &Vector3::zeros(), 0.0, 0.0);
        assert!(matches!(
            solve_position(&obs, &LsSettings::default()),
            Err(GnssLsError::TooFewSatellites { have: 3, .. })
        ));
        // Four satellites in one direction cone collapse the geometry (all rows nearly equal).
        let same: Vec<(f64, f64)> = (0..5).map(|_| (0.3, 0.7)).collect();
        let obs = synth(&r, &c, &same, &Vector3::zeros(), 0.0, 0.0);
        assert!(matches!(
            solve_position(&obs, &LsSettings::default()),
            Err(GnssLsError::SingularGeometry { .. })
        ));
        let mut obs = Observations::default();
        let err = obs
            .push(SatelliteObservation {
                prn: 9,
                pseudorange_m: f64::NAN,
                sigma_pseudorange_m: 1.0,
                ..Default::default()
            })
            .unwrap_err();
        assert!(matches!(
            err,
            GnssLsError::InvalidObservation {
                prn: 9,
                field: "pseudorange_m",
                ..
            }
        ));
        let settings = LsSettings {
            max_iterations: 1,
            ..Default::default()
        };
        let obs = synth(&r, &c, &sky(), &Vector3::zeros(), 0.0, 0.0);
        assert!(matches!(
            solve_position(&obs, &settings),
            Err(GnssLsError::NoConvergence { .. })
        ));
        // Too few Dopplers: the fix has no velocity but the position is fine.
        let mut obs = synth(&r, &c, &sky(), &Vector3::zeros(), 0.0, 0.0);
        for s in obs.sats[..4].iter_mut() {
            s.has_range_rate = false;
        }
        let fix = solve(&obs, &LsSettings::default()).unwrap();
        assert!(fix.velocity.is_none());
    }
}
