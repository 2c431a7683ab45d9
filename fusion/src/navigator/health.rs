//! Counters that are not per-sensor slots of `msgs::Status`: the pseudo-measurements (zero
//! velocity, non-holonomic constraints) and the navigator's own diagnostics.

/// Counters of the zero-velocity updates (not a sensor slot of `msgs::Status`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ZuptHealth {
    /// Zero-velocity updates fused.
    pub fused: u64,
    /// Zero-velocity updates rejected by the gate.
    pub rejected_gate: u64,
    /// NIS of the last one.
    pub last_nis: f64,
}

/// Counters of the non-holonomic constraint updates (zero lateral and vertical body
/// velocity, 2 dof; not a sensor slot of `msgs::Status`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NhcHealth {
    /// Updates fused.
    pub fused: u64,
    /// Updates rejected by the gate.
    pub rejected_gate: u64,
    /// NIS of the last one.
    pub last_nis: f64,
    /// Sum of the NIS of the fused ones (mean NIS = nis_sum / fused, ≈ 2 if consistent).
    pub nis_sum: f64,
}

/// Navigator counters that are not per-sensor (published on `msgs::Status`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct NavigatorDiagnostics {
    /// Least-squares GNSS fixes (paper 003 eq. 12–13) compared with the filter position.
    pub gnss_ls_checks: u64,
    /// Of those, the ones failing the 3-dof chi-square test.
    pub gnss_ls_disagreements: u64,
    /// Normalized squared position difference (3 dof) of the last cross-check.
    pub gnss_ls_last_nis: f64,
    /// PDOP of the last least-squares fix.
    pub gnss_ls_pdop: f64,
    /// Times the navigator started over (re-alignment).
    pub reinitializations: u64,
    /// Late samples that could not be replayed at their epoch because the IMU log no longer
    /// reached back to the checkpoint before them (an IMU faster than
    /// [`NavigatorConfig::max_imu_rate_hz`]): one per rewind; the samples are dropped and
    /// counted in their sensor's `dropped_late`, never fused at a wrong epoch.
    pub replays_impossible: u64,
}
