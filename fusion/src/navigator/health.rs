//! Health counters folded from update outcomes: the per-sensor slots of `msgs::Status`, the
//! pseudo-measurements (zero velocity, non-holonomic constraints) and the navigator's own
//! diagnostics. Whether an outcome is counted is an argument ([`Tally`]), not a state of the
//! navigator: a sample counts the first time it is fused, never again when a replay fuses it
//! at its epoch once more (module docs of [`super`], "Delayed fusion").

use msgs::SensorHealth;

/// Whether the outcome of an update enters the health counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Tally {
    /// First fusion of a sample, or a live zero-velocity update: counted.
    Count,
    /// A replay fusing again what was counted before: not counted twice.
    Skip,
}

impl Tally {
    /// The tally of a queued sample, from whether it was counted before (re-queued by a
    /// rewind).
    pub(super) fn first_time(counted_before: bool) -> Self {
        if counted_before {
            Self::Skip
        } else {
            Self::Count
        }
    }
}

/// Whose counters an update's outcome goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Counter {
    /// The sensor slot (index = `msgs::SensorId`).
    Sensor(usize),
    /// The zero-velocity update counters ([`ZuptHealth`]).
    Zupt,
}

/// What the counters keep of one gated update ([`crate::ekf::Residual`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Verdict {
    /// Normalized innovation squared.
    pub(super) nis: f64,
    /// Measurement dimension (the NIS's degrees of freedom).
    pub(super) dof: u64,
    /// Refused by the gate (or not usable): not fused.
    pub(super) rejected: bool,
}

impl Verdict {
    /// True when the update was fused.
    pub(super) fn accepted(self) -> bool {
        !self.rejected
    }
}

/// Fold one update of a sensor into its slot: NIS of the last update, gate rejections, and
/// over the accepted ones the NIS and dimension sums (mean NIS `nis_sum / nis_count` should be
/// ≈ the mean dimension `nis_dof_sum / nis_count` for a consistent filter).
pub(super) fn fold_sensor(h: &mut SensorHealth, v: Verdict) {
    h.last_nis = v.nis;
    if v.rejected {
        h.rejected_gate += 1;
    } else {
        h.nis_sum += v.nis;
        h.nis_count += 1;
        h.nis_dof_sum += v.dof;
    }
}

/// Counters of an update that is not a sensor slot of `msgs::Status`: the zero-velocity
/// updates (3 dof) and the non-holonomic constraints (zero lateral and vertical body velocity,
/// 2 dof).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ConstraintHealth {
    /// Updates fused.
    pub fused: u64,
    /// Updates rejected by the gate.
    pub rejected_gate: u64,
    /// NIS of the last one.
    pub last_nis: f64,
    /// Sum of the NIS of the fused ones (mean NIS = nis_sum / fused, ≈ dof if consistent).
    pub nis_sum: f64,
}

impl ConstraintHealth {
    /// Fold one update.
    pub(super) fn fold(&mut self, v: Verdict) {
        self.last_nis = v.nis;
        if v.rejected {
            self.rejected_gate += 1;
        } else {
            self.fused += 1;
            self.nis_sum += v.nis;
        }
    }
}

/// Counters of the zero-velocity updates.
pub type ZuptHealth = ConstraintHealth;

/// Counters of the non-holonomic constraint updates.
pub type NhcHealth = ConstraintHealth;

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
    /// IMU samples held (and rejected) as candidates of a new time base after a forward jump
    /// of their time of validity beyond the bridged gap; also counted in the IMU's
    /// `rejected_invalid`. A confirmed discontinuity holds `CONFIRM_SAMPLES − 1` of them; a
    /// candidate run cut short (another jump, a return to the old time base) holds fewer.
    pub imu_held_at_time_jump: u64,
    /// Late samples that could not be replayed at their epoch because the IMU log no longer
    /// reached back to the checkpoint before them (an IMU faster than
    /// [`NavigatorConfig::max_imu_rate_hz`]): one per rewind; the samples are dropped and
    /// counted in their sensor's `dropped_late`, never fused at a wrong epoch.
    pub replays_impossible: u64,
    /// Rewinds for late samples: the filter went back to a checkpoint and replayed the IMU
    /// steps since (a burst of late samples shares one). A sensor late by its latency at
    /// every sample rewinds at every sample.
    pub rewinds: u64,
    /// IMU steps processed again by those rewinds: the delayed fusion's extra work, beside
    /// the IMU's own `fused` count.
    pub replayed_imu_steps: u64,
    /// Alignments in motion (star-tracker attitude, GNSS position and velocity).
    pub motion_alignments: u64,
    /// Of those, the ones without a star attitude: heading from GNSS velocity
    /// ([`crate::yaw_gsf`]).
    pub gnss_heading_alignments: u64,
    /// Starts of navigation that resumed the sensor-error states from a snapshot.
    pub warm_starts: u64,
    /// Times the baro bias was acquired anew after `aiding.baro_reacquire_after` rejections
    /// in a row (the day's pressure far from the bias state's belief).
    pub baro_bias_reacquisitions: u64,
    /// Dual-baseline epochs given to the integer ambiguity resolution
    /// ([`crate::phase_ambiguity`]).
    pub baseline_epochs: u64,
    /// Of those, epochs whose attitude came from integer-fixed phases (queued for fusion).
    pub baseline_fixed: u64,
    /// Of the fixed epochs, those fixed by a new search (the first fix, after a rejected set
    /// or after losing the held satellites).
    pub baseline_search_fixes: u64,
    /// Epochs float only: the search could not validate an integer set (ratio test, no
    /// candidate); nothing fused.
    pub baseline_float_only: u64,
    /// Epochs rejected for another reason (too few satellites, χ² test, solver); nothing
    /// fused.
    pub baseline_rejected: u64,
    /// Held satellites dropped because the receiver's lock time restarted: a slip it
    /// flagged, or a reacquisition since the last epoch given (after an outage).
    pub baseline_slips_flagged: u64,
    /// Held satellites dropped by the residual test: slips the receiver did not flag.
    pub baseline_slips_detected: u64,
    /// Held integer sets rejected as a whole by the residual test (a wrong fix, or several
    /// slips at once).
    pub baseline_held_sets_rejected: u64,
    /// Receiver time of the first integer fix, GPS ns (0 before it).
    pub baseline_first_fix_ns: i64,
}
