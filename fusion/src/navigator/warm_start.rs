//! Warm restart: the navigator's estimate as a plain value ([`NavSnapshot`]) that a daemon
//! writes to disk, and the resumption of a restarted navigator from it.
//!
//! # What a snapshot carries over a restart
//! Everything the filter has learnt that the sensors cannot give back at once: the gyro and
//! accelerometer biases, scale factors and non-orthogonality, the star-tracker boresight, the
//! baro bias, the odometer scale and the receiver clock, with their joint covariance. The
//! kinematic part (position, velocity, attitude) is in the snapshot too, but is not
//! extrapolated over the time the daemon was down: a vehicle that turns at 0.3 rad/s is 0.3 rad
//! off after one second, far outside the small-angle error model of the filter
//! ([`crate::ekf`]: ψ enters through `I − [ψ×]`, whose error is ψ²/2 — 4·10⁻² at 0.3 rad,
//! against a star tracker's 10⁻⁵). So the unknown motion over the gap is taken at its worst,
//! as unknown: the kinematic states restart from the alignment in motion
//! (`motion_align`: star-tracker attitude, GNSS position and velocity, each with its
//! own covariance), and the checkpoint's sensor-error states replace the priors.
//!
//! # Widening over the gap Δ = t_start − t_snapshot
//! The sensor-error states are random walks or constants ([`crate::ekf`] dynamics): over Δ
//! without measurements their covariance grows by `Q_c·Δ` (`ProcessNoise::qc_diagonal`),
//! their estimates stay. The receiver clock is the two-state model `b' = d`, so
//! `b ← b + d·Δ` with `Φ = [[1, Δ], [0, 1]]`: `P ← Φ P Φᵀ + [[q_b Δ + q_d Δ³/3, q_d Δ²/2],
//! [q_d Δ²/2, q_d Δ]]`. The cross-covariances between the sensor-error states and the new
//! kinematic states are zero (the new kinematics come from sensors whose errors are
//! independent of the IMU's), except the attitude–boresight term, which the star attitude
//! derives from the checkpoint's boresight covariance.
//!
//! # Refused snapshots
//! A snapshot older than [`WarmStartConfig::max_age_s`] at the first IMU sample, or from the
//! future (a different time base), is refused ([`WarmStartOutcome::Refused`]) and the
//! navigator aligns from its priors.

use super::*;

/// Warm restart settings (`[warm_start]` in `config/filter.toml`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct WarmStartConfig {
    /// Oldest snapshot (GPS time of the snapshot to the first IMU sample, and to the start of
    /// navigation) a restarted navigator resumes from, s.
    pub max_age_s: f64,
}

impl Default for WarmStartConfig {
    fn default() -> Self {
        Self { max_age_s: 60.0 }
    }
}

impl WarmStartConfig {
    pub(super) fn validate(&self) -> Result<(), ConfigError> {
        check(
            pos(self.max_age_s) && self.max_age_s <= 86_400.0,
            "warm_start.max_age_s",
            "must be in (0, 86400] s",
        )
    }
}

/// The navigator's estimate at one IMU epoch, for a warm restart: inertial state, every
/// sensor-error estimate and the full error-state covariance (layout in [`crate::ekf`]).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NavSnapshot {
    /// IMU epoch of the estimate, GPS nanoseconds.
    pub gps_time_ns: i64,
    /// Position, ECEF, m.
    pub r_e_m: [f64; 3],
    /// Velocity relative to the Earth, ECEF axes, m/s.
    pub v_e_m_s: [f64; 3],
    /// Attitude body → ECEF, quaternion `[w, x, y, z]`.
    pub q_e_b: [f64; 4],
    /// Gyro bias, body, rad/s.
    pub gyro_bias_rad_s: [f64; 3],
    /// Accelerometer bias, body, m/s².
    pub accel_bias_m_s2: [f64; 3],
    /// Baro height bias, m.
    pub baro_bias_m: f64,
    /// Odometer scale-factor error (dimensionless).
    pub odo_scale: f64,
    /// Gyro scale-factor errors, body axes (dimensionless).
    pub gyro_scale: [f64; 3],
    /// Accelerometer scale-factor errors, body axes (dimensionless).
    pub accel_scale: [f64; 3],
    /// Star-tracker boresight κ1..κ3, rad.
    pub kappa_rad: [f64; 3],
    /// Gyro non-orthogonality `(S_xy, S_xz, S_yz)`, rad.
    pub gyro_misalignment_rad: [f64; 3],
    /// Receiver clock bias × c, m.
    pub clock_bias_m: f64,
    /// Receiver clock drift × c, m/s.
    pub clock_drift_m_s: f64,
    /// Whether the clock states were estimated (tight coupling, initialised).
    pub clock_initialized: bool,
    /// Error-state covariance, row-major NX × NX (units of [`crate::ekf::idx`]).
    pub covariance: Vec<f64>,
}

/// Why a snapshot was not used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum WarmStartRefusal {
    /// Older than `warm_start.max_age_s`.
    #[error("snapshot is {age_s:.1} s old, more than warm_start.max_age_s = {max_age_s} s")]
    Stale {
        /// Age at the check, s.
        age_s: f64,
        /// The configured bound, s.
        max_age_s: f64,
    },
    /// Its time is after the IMU's (another time base).
    #[error("snapshot time is {ahead_s:.3} s after the first IMU sample")]
    FromTheFuture {
        /// How far ahead, s.
        ahead_s: f64,
    },
    /// The vehicle stood and the static alignment started navigation: its attitude is derived
    /// with zero sensor errors and correlated with them, so the snapshot's are not taken over.
    #[error("the vehicle stood: the static alignment started navigation from the priors")]
    StandingStart,
    /// A value is not finite, the quaternion is not unit, the covariance has the wrong size,
    /// is not symmetric or has a negative variance.
    #[error("snapshot content is invalid: {0}")]
    Invalid(&'static str),
}

/// What became of a snapshot given to [`Navigator::warm_start`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WarmStartOutcome {
    /// Held: fresh at the first IMU sample, waiting for the alignment in motion.
    Held,
    /// The sensor-error states were resumed at the start of navigation, `gap_s` after the
    /// snapshot.
    Resumed {
        /// Time from the snapshot to the start of navigation, s.
        gap_s: f64,
    },
    /// Not used; the navigator aligns from its priors.
    Refused(WarmStartRefusal),
}

impl NavSnapshot {
    /// Check the content (finite values, unit quaternion, a symmetric NX × NX covariance
    /// with non-negative variances).
    pub fn validate(&self) -> Result<(), WarmStartRefusal> {
        let bad = WarmStartRefusal::Invalid;
        let scalars = [
            self.baro_bias_m,
            self.odo_scale,
            self.clock_bias_m,
            self.clock_drift_m_s,
        ];
        let finite = self
            .r_e_m
            .iter()
            .chain(&self.v_e_m_s)
            .chain(&self.q_e_b)
            .chain(&self.gyro_bias_rad_s)
            .chain(&self.accel_bias_m_s2)
            .chain(&self.gyro_scale)
            .chain(&self.accel_scale)
            .chain(&self.kappa_rad)
            .chain(&self.gyro_misalignment_rad)
            .chain(&scalars)
            .chain(&self.covariance)
            .all(|x| x.is_finite());
        if !finite {
            return Err(bad("a value is not finite"));
        }
        let n = self.q_e_b.iter().map(|x| x * x).sum::<f64>().sqrt();
        if (n - 1.0).abs() > 1e-6 {
            return Err(bad("attitude quaternion is not unit"));
        }
        if self.covariance.len() != ekf::NX * ekf::NX {
            return Err(bad("covariance is not NX × NX"));
        }
        let p = self.covariance_matrix();
        for i in 0..ekf::NX {
            if p[(i, i)] < 0.0 {
                return Err(bad("negative variance"));
            }
            for j in 0..i {
                let scale = (p[(i, i)] * p[(j, j)]).sqrt().max(f64::MIN_POSITIVE);
                if (p[(i, j)] - p[(j, i)]).abs() > 1e-9 * scale {
                    return Err(bad("covariance is not symmetric"));
                }
            }
        }
        Ok(())
    }

    /// Time of the estimate.
    pub fn time(&self) -> GpsTime {
        GpsTime::from_ns(self.gps_time_ns)
    }

    pub(super) fn covariance_matrix(&self) -> Covariance {
        Covariance::from_row_slice(&self.covariance)
    }
}

impl Navigator {
    /// The current estimate as a [`NavSnapshot`] (None before navigation starts). The
    /// covariance is that of the last propagation (at most `covariance_interval_s` old).
    pub fn snapshot(&self) -> Option<NavSnapshot> {
        let mut out = NavSnapshot::default();
        self.snapshot_into(&mut out).then_some(out)
    }

    /// [`Navigator::snapshot`] written into `out` (false, `out` untouched, before navigation
    /// starts). Allocation-free once `out.covariance` has held a covariance: the daemon hands
    /// the same few snapshots back and forth with its checkpoint writer.
    pub fn snapshot_into(&self, out: &mut NavSnapshot) -> bool {
        if self.phase != Phase::Navigating {
            return false;
        }
        let e = &self.core.ekf;
        let v3 = |v: &Vector3<f64>| [v.x, v.y, v.z];
        let q = self.core.nav.q_e_b;
        out.gps_time_ns = self.time.ns;
        out.r_e_m = v3(&self.core.nav.r_e);
        out.v_e_m_s = v3(&self.core.nav.v_e);
        out.q_e_b = [q.w, q.i, q.j, q.k];
        out.gyro_bias_rad_s = v3(&e.gyro_bias_rad_s);
        out.accel_bias_m_s2 = v3(&e.accel_bias_m_s2);
        out.baro_bias_m = e.baro_bias_m;
        out.odo_scale = e.odo_scale;
        out.gyro_scale = v3(&e.gyro_scale);
        out.accel_scale = v3(&e.accel_scale);
        out.kappa_rad = v3(&e.kappa_rad);
        out.gyro_misalignment_rad = v3(&e.gyro_misalignment_rad);
        out.clock_bias_m = e.clock_bias_m;
        out.clock_drift_m_s = e.clock_drift_m_s;
        out.clock_initialized = self.core.clock_initialized;
        // Row-major: nalgebra stores column-major, so the transpose's storage order. P is
        // symmetric, but the file's layout is documented as row-major and read as such.
        out.covariance.clear();
        out.covariance
            .extend((0..e.p.nrows()).flat_map(|i| (0..e.p.ncols()).map(move |j| e.p[(i, j)])));
        true
    }

    /// Resume from `snapshot` (call before the first sample): its age is checked at the first
    /// IMU sample, and the sensor-error states are taken over when the alignment in motion
    /// starts navigation (module docs of this module). Invalid content is refused at once.
    pub fn warm_start(&mut self, snapshot: NavSnapshot) -> WarmStartOutcome {
        let outcome = match snapshot.validate() {
            Ok(()) => {
                self.warm = Some(snapshot);
                WarmStartOutcome::Held
            }
            Err(e) => WarmStartOutcome::Refused(e),
        };
        self.warm_outcome = Some(outcome);
        outcome
    }

    /// What became of the snapshot given to [`Self::warm_start`] (None: none was given).
    pub fn warm_start_outcome(&self) -> Option<WarmStartOutcome> {
        self.warm_outcome
    }

    /// At an IMU epoch `t` while aligning: refuse a held snapshot that is stale or from the
    /// future.
    pub(super) fn check_warm_start_age(&mut self, t: GpsTime) {
        let Some(w) = &self.warm else {
            return;
        };
        let age_s = (t - w.time()).seconds_f64();
        let max_age_s = self.config.warm_start.max_age_s;
        let refusal = if age_s < 0.0 {
            Some(WarmStartRefusal::FromTheFuture { ahead_s: -age_s })
        } else if age_s > max_age_s {
            Some(WarmStartRefusal::Stale { age_s, max_age_s })
        } else {
            None
        };
        if let Some(r) = refusal {
            self.warm = None;
            self.warm_outcome = Some(WarmStartOutcome::Refused(r));
        }
    }

    /// At the start of navigation at IMU epoch `t` (alignment in motion): take over the held
    /// snapshot's sensor-error states, widened over the gap (module docs of this module).
    pub(super) fn apply_warm_start(&mut self, t: GpsTime) {
        self.check_warm_start_age(t);
        let Some(w) = self.warm.take() else {
            return;
        };
        let gap_s = (t - w.time()).seconds_f64();
        let mut p_old = w.covariance_matrix();
        let qc = self.filter_noise().qc_diagonal();
        for i in idx::BG..ekf::NX {
            if i != idx::CLK && i != idx::CLK_DRIFT {
                p_old[(i, i)] += qc[i] * gap_s;
            }
        }
        let clock = w.clock_initialized && self.active_states(true).clock;
        if clock {
            let (qb, qd) = (
                self.config.aiding.clock_bias_psd_m2_s,
                self.config.aiding.clock_drift_psd_m2_s3,
            );
            // Φ P Φᵀ for Φ = I + Δ·e_b e_dᵀ: row and column CLK += Δ × row/column CLK_DRIFT.
            for j in 0..ekf::NX {
                let d = p_old[(idx::CLK_DRIFT, j)];
                p_old[(idx::CLK, j)] += gap_s * d;
            }
            for i in 0..ekf::NX {
                let d = p_old[(i, idx::CLK_DRIFT)];
                p_old[(i, idx::CLK)] += gap_s * d;
            }
            p_old[(idx::CLK, idx::CLK)] += qb * gap_s + qd * gap_s.powi(3) / 3.0;
            p_old[(idx::CLK, idx::CLK_DRIFT)] += qd * gap_s * gap_s / 2.0;
            p_old[(idx::CLK_DRIFT, idx::CLK)] += qd * gap_s * gap_s / 2.0;
            p_old[(idx::CLK_DRIFT, idx::CLK_DRIFT)] += qd * gap_s;
            self.core.ekf.set_active(self.active_states(true));
        }
        let n = ekf::NX - idx::BG;
        let block = p_old.view((idx::BG, idx::BG), (n, n)).into_owned();
        self.core
            .ekf
            .p
            .view_mut((idx::BG, idx::BG), (n, n))
            .copy_from(&block);
        if !clock {
            for i in [idx::CLK, idx::CLK_DRIFT] {
                self.core.ekf.p.row_mut(i).fill(0.0);
                self.core.ekf.p.column_mut(i).fill(0.0);
            }
        }
        // Groups switched off in this configuration keep zero covariance.
        for i in idx::BG..ekf::NX {
            if !self.core.ekf.is_active(i) {
                self.core.ekf.p.row_mut(i).fill(0.0);
                self.core.ekf.p.column_mut(i).fill(0.0);
            }
        }
        let e = &mut self.core.ekf;
        let v = Vector3::from;
        e.gyro_bias_rad_s = v(w.gyro_bias_rad_s);
        e.accel_bias_m_s2 = v(w.accel_bias_m_s2);
        e.baro_bias_m = w.baro_bias_m;
        e.odo_scale = w.odo_scale;
        e.gyro_scale = v(w.gyro_scale);
        e.accel_scale = v(w.accel_scale);
        e.kappa_rad = v(w.kappa_rad);
        e.gyro_misalignment_rad = v(w.gyro_misalignment_rad);
        if clock {
            e.clock_bias_m = w.clock_bias_m + w.clock_drift_m_s * gap_s;
            e.clock_drift_m_s = w.clock_drift_m_s;
            self.core.clock_initialized = true;
        }
        self.diagnostics.warm_starts += 1;
        self.warm_outcome = Some(WarmStartOutcome::Resumed { gap_s });
    }
}
