//! Aiding observations as queued: the validated content of a sample in the form the
//! measurement updates take (ECEF, SI units).

use super::*;

/// GNSS fix as queued (raw satellites are not used by the loose coupling).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct GnssFix {
    pub(super) pos: Vector3<f64>,
    pub(super) vel: Vector3<f64>,
    pub(super) pos_cov: Matrix3<f64>,
    pub(super) vel_cov: Matrix3<f64>,
    pub(super) vel_valid: bool,
}

/// One satellite's raw measurements as queued for tight coupling.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct SatObs {
    pub(super) pos: Vector3<f64>,
    pub(super) vel: Vector3<f64>,
    pub(super) pseudorange_m: f64,
    pub(super) range_rate_m_s: f64,
    pub(super) sigma_pr_m: f64,
    pub(super) sigma_rr_m_s: f64,
    pub(super) has_pr: bool,
    pub(super) has_rr: bool,
}

/// GNSS epoch as queued: the fix (loose) and the usable satellites (tight).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct GnssObs {
    pub(super) fix: Option<GnssFix>,
    /// Dual-baseline attitude `C̃_e_b` and the covariance of its ECEF rotation error, rad².
    pub(super) attitude: Option<(Matrix3<f64>, Matrix3<f64>)>,
    pub(super) n_sats: usize,
    pub(super) sats: [SatObs; MAX_SATELLITES],
}

/// Satellite flag bits of `msgs::GnssSatellite::flags`.
pub(super) const SAT_FLAG_PSEUDORANGE: u32 = 1;

pub(super) const SAT_FLAG_DOPPLER: u32 = 2;

/// The satellites of a sample that are usable for tight coupling: finite values, a position
/// at orbital distance (|r| in 10 000–100 000 km), positive finite sigmas. Others are skipped
/// (never reach the filter). Allocates nothing.
pub(super) fn usable_satellites(s: &GnssSample) -> (usize, [SatObs; MAX_SATELLITES]) {
    let mut out = [SatObs::default(); MAX_SATELLITES];
    let mut n = 0;
    for sat in s
        .satellites
        .iter()
        .take((s.n_satellites as usize).min(MAX_SATELLITES))
    {
        let r_sat = Vector3::from(sat.sat_pos_ecef_m);
        let v_sat = Vector3::from(sat.sat_vel_ecef_m_s);
        let geometry_ok = r_sat.iter().all(|x| x.is_finite())
            && v_sat.iter().all(|x| x.is_finite())
            && (1.0e7..=1.0e8).contains(&r_sat.norm())
            && v_sat.norm() < 2.0e4;
        if !geometry_ok {
            continue;
        }
        let has_pr = sat.flags & SAT_FLAG_PSEUDORANGE != 0
            && sat.pseudorange_m.is_finite()
            && sat.pseudorange_m.abs() < 1.0e9
            && pos(sat.sigma_pseudorange_m)
            && sat.sigma_pseudorange_m < 1.0e4;
        let has_rr = sat.flags & SAT_FLAG_DOPPLER != 0
            && sat.range_rate_m_s.is_finite()
            && sat.range_rate_m_s.abs() < 1.0e5
            && pos(sat.sigma_range_rate_m_s)
            && sat.sigma_range_rate_m_s < 1.0e3;
        if !(has_pr || has_rr) {
            continue;
        }
        out[n] = SatObs {
            pos: r_sat,
            vel: v_sat,
            pseudorange_m: sat.pseudorange_m,
            range_rate_m_s: sat.range_rate_m_s,
            sigma_pr_m: sat.sigma_pseudorange_m,
            sigma_rr_m_s: sat.sigma_range_rate_m_s,
            has_pr,
            has_rr,
        };
        n += 1;
    }
    (n, out)
}

#[derive(Debug, Clone, Copy, Default)]
pub(super) struct StarObs {
    pub(super) q: [f64; 4],
    pub(super) sigma_cross: f64,
    pub(super) sigma_roll: f64,
}
