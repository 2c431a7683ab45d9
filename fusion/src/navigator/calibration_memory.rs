//! Calibration memory: the sensor errors that persist across power cycles, taken from the
//! estimate a previous run ended with ([`NavSnapshot`]) as the prior of the next start.
//!
//! # What is remembered
//! The errors of the hardware rather than of the moment: gyro and accelerometer biases, scale
//! factors, the gyro non-orthogonality, the star-tracker boresight and the odometer scale
//! ([`REMEMBERED`]), with their joint covariance. Not remembered: position, velocity and
//! attitude (the vehicle may have moved while off), the baro bias (the weather changes it) and
//! the receiver clock (it restarts with the receiver).
//!
//! # Widening over the time off
//! Between the end of the last run and this start (`elapsed_s`, wall-clock time measured by
//! the caller: the sensors age in real time, whatever time base the runs use), a state that is
//! a random walk in the filter ([`crate::ekf`] dynamics) grows by `Q_c·Δt` as it would have
//! without measurements. A power cycle adds the turn-on repeatability of the data sheet
//! (`[calibration_memory]`): a bias that comes back on at a different value, a scale factor
//! that shifts with the thermal cycle, a boresight that moves with the mount, a tyre whose
//! pressure changed. So the remembered covariance is `P_saved + diag(Q_c·Δt + σ_rep²)`, its
//! cross-covariances kept.
//!
//! # Only where it is better than the data sheet
//! The prior of a state stays the data sheet's (mean zero, [`Navigator::sensor_prior`]) when the
//! widened memory is not tighter: a bias whose repeatability is its turn-on σ gains nothing
//! from memory, and a memory days old has walked off. The remembered states that are kept
//! form a principal block of a covariance, and the reverted ones get their prior variance
//! without cross terms, so the merged prior is positive semi-definite.

use super::*;

/// Calibration-memory settings (`[calibration_memory]` in `config/filter.toml`): how old a
/// memory may be and how much a power cycle changes each remembered error (1σ, data-sheet
/// turn-on to turn-on repeatability).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationMemoryConfig {
    /// Oldest memory used, days of wall-clock time since it was saved.
    pub max_age_days: f64,
    /// Gyro bias repeatability, deg/h.
    pub gyro_bias_repeatability_deg_h: f64,
    /// Accelerometer bias repeatability, µg.
    pub accel_bias_repeatability_ug: f64,
    /// Gyro scale-factor repeatability, ppm.
    pub gyro_scale_repeatability_ppm: f64,
    /// Accelerometer scale-factor repeatability, ppm.
    pub accel_scale_repeatability_ppm: f64,
    /// Gyro non-orthogonality repeatability (thermal cycles of the triad), arcsec.
    pub gyro_misalignment_repeatability_arcsec: f64,
    /// Star-tracker boresight repeatability (mount), deg per axis.
    pub boresight_repeatability_deg: f64,
    /// Odometer scale-factor repeatability (tyre pressure and load), dimensionless.
    pub odometer_scale_repeatability: f64,
}

impl Default for CalibrationMemoryConfig {
    fn default() -> Self {
        Self {
            max_age_days: 30.0,
            gyro_bias_repeatability_deg_h: 0.01,
            accel_bias_repeatability_ug: 50.0,
            gyro_scale_repeatability_ppm: 10.0,
            accel_scale_repeatability_ppm: 20.0,
            gyro_misalignment_repeatability_arcsec: 2.0,
            boresight_repeatability_deg: 0.001,
            odometer_scale_repeatability: 0.002,
        }
    }
}

impl CalibrationMemoryConfig {
    pub(super) fn validate(&self) -> Result<(), ConfigError> {
        check(
            pos(self.max_age_days) && self.max_age_days <= 3650.0,
            "calibration_memory.max_age_days",
            "must be in (0, 3650] days",
        )?;
        for (v, key) in [
            (
                self.gyro_bias_repeatability_deg_h,
                "calibration_memory.gyro_bias_repeatability_deg_h",
            ),
            (
                self.accel_bias_repeatability_ug,
                "calibration_memory.accel_bias_repeatability_ug",
            ),
            (
                self.gyro_scale_repeatability_ppm,
                "calibration_memory.gyro_scale_repeatability_ppm",
            ),
            (
                self.accel_scale_repeatability_ppm,
                "calibration_memory.accel_scale_repeatability_ppm",
            ),
            (
                self.gyro_misalignment_repeatability_arcsec,
                "calibration_memory.gyro_misalignment_repeatability_arcsec",
            ),
            (
                self.boresight_repeatability_deg,
                "calibration_memory.boresight_repeatability_deg",
            ),
            (
                self.odometer_scale_repeatability,
                "calibration_memory.odometer_scale_repeatability",
            ),
        ] {
            check(nonneg(v), key, "must be >= 0")?;
        }
        Ok(())
    }

    /// The repeatability variance of each remembered state (units of [`crate::ekf::idx`]).
    fn repeatability_variance(&self) -> StateVector {
        let mut r = StateVector::zeros();
        let bg = self.gyro_bias_repeatability_deg_h * DEG / 3600.0;
        let ba = self.accel_bias_repeatability_ug * 1e-6 * G0;
        let sg = self.gyro_scale_repeatability_ppm * 1e-6;
        let sa = self.accel_scale_repeatability_ppm * 1e-6;
        let k = self.boresight_repeatability_deg * DEG;
        let m = self.gyro_misalignment_repeatability_arcsec / 3600.0 * DEG;
        for i in 0..3 {
            r[idx::SGM + i] = m * m;
            r[idx::BG + i] = bg * bg;
            r[idx::BA + i] = ba * ba;
            r[idx::SG + i] = sg * sg;
            r[idx::SA + i] = sa * sa;
            r[idx::KAPPA + i] = k * k;
        }
        r[idx::ODO] = self.odometer_scale_repeatability.powi(2);
        r
    }
}

/// The error states a calibration memory carries (indices of [`crate::ekf::idx`]).
pub const REMEMBERED: [usize; 19] = [
    idx::BG,
    idx::BG + 1,
    idx::BG + 2,
    idx::BA,
    idx::BA + 1,
    idx::BA + 2,
    idx::ODO,
    idx::SG,
    idx::SG + 1,
    idx::SG + 2,
    idx::SA,
    idx::SA + 1,
    idx::SA + 2,
    idx::KAPPA,
    idx::KAPPA + 1,
    idx::KAPPA + 2,
    idx::SGM,
    idx::SGM + 1,
    idx::SGM + 2,
];

/// Why a calibration memory was not used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum CalibrationRefusal {
    /// Older than `calibration_memory.max_age_days`.
    #[error(
        "calibration is {age_days:.1} days old, more than calibration_memory.max_age_days = {max_age_days}"
    )]
    TooOld {
        /// Its age, days.
        age_days: f64,
        /// The configured bound, days.
        max_age_days: f64,
    },
    /// The time since it was saved is negative or not finite.
    #[error("time since the calibration was saved is {elapsed_s} s")]
    BadAge {
        /// What the caller gave, s.
        elapsed_s: f64,
    },
    /// Its content is invalid (the snapshot checks of [`NavSnapshot::validate`]).
    #[error(transparent)]
    Invalid(#[from] WarmStartRefusal),
}

/// The remembered sensor errors, widened for the time off (module docs): estimates and
/// covariance in the error-state layout, zero outside [`REMEMBERED`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct CalibrationPrior {
    x: StateVector,
    p: Covariance,
}

/// What a loaded calibration memory gives at the start: the remembered states and whether
/// each is tighter than its data-sheet prior (and so is used).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationLoaded {
    /// Per remembered state ([`REMEMBERED`] order): the widened σ over the data-sheet σ (at
    /// rest, gravity along body z). Below 1 the memory is used for that state, else the data
    /// sheet; infinite for a state the filter does not estimate.
    pub sigma_ratio: [f64; REMEMBERED.len()],
}

impl CalibrationLoaded {
    /// Remembered states that start from the memory.
    pub fn used(&self) -> usize {
        self.sigma_ratio.iter().filter(|r| **r < 1.0).count()
    }
}

impl Navigator {
    /// Take the sensor errors of `saved` (a previous run's final estimate, saved
    /// `elapsed_s` of wall-clock time ago) as the prior of this run's start (module docs).
    /// Call before the first sample. A checkpoint given to [`Self::warm_start`] and resumed
    /// takes precedence.
    pub fn load_calibration(
        &mut self,
        saved: &NavSnapshot,
        elapsed_s: f64,
    ) -> Result<CalibrationLoaded, CalibrationRefusal> {
        saved.validate()?;
        if !(elapsed_s.is_finite() && elapsed_s >= 0.0) {
            return Err(CalibrationRefusal::BadAge { elapsed_s });
        }
        let cfg = self.config.calibration_memory;
        let age_days = elapsed_s / 86_400.0;
        if age_days > cfg.max_age_days {
            return Err(CalibrationRefusal::TooOld {
                age_days,
                max_age_days: cfg.max_age_days,
            });
        }
        let saved_p = saved.covariance_matrix();
        let qc = self.filter_noise().qc_diagonal();
        let rep = cfg.repeatability_variance();
        let mut p = Covariance::zeros();
        for &i in &REMEMBERED {
            for &j in &REMEMBERED {
                p[(i, j)] = saved_p[(i, j)];
            }
            p[(i, i)] += qc[i] * elapsed_s + rep[i];
        }
        let mut x = StateVector::zeros();
        let v = |a: [f64; 3]| Vector3::from(a);
        x.fixed_rows_mut::<3>(idx::BG)
            .copy_from(&v(saved.gyro_bias_rad_s));
        x.fixed_rows_mut::<3>(idx::BA)
            .copy_from(&v(saved.accel_bias_m_s2));
        x[idx::ODO] = saved.odo_scale;
        x.fixed_rows_mut::<3>(idx::SG)
            .copy_from(&v(saved.gyro_scale));
        x.fixed_rows_mut::<3>(idx::SA)
            .copy_from(&v(saved.accel_scale));
        x.fixed_rows_mut::<3>(idx::KAPPA)
            .copy_from(&v(saved.kappa_rad));
        x.fixed_rows_mut::<3>(idx::SGM)
            .copy_from(&v(saved.gyro_misalignment_rad));
        let memory = CalibrationPrior { x, p };
        // The data sheet at rest (gravity along body z): the accelerometer-bias prior's
        // misalignment term depends on the attitude; the start compares again with its own.
        let prior = self.prior_variances(&self.data_sheet_prior(&Vector3::new(0.0, 0.0, -G0)));
        let active = self.active_states(false).mask();
        let mut sigma_ratio = [f64::INFINITY; REMEMBERED.len()];
        for (r, &i) in sigma_ratio.iter_mut().zip(&REMEMBERED) {
            if active[i] {
                *r = (p[(i, i)] / prior[i]).sqrt();
            }
        }
        self.calibration = Some(Box::new(memory));
        Ok(CalibrationLoaded { sigma_ratio })
    }

    /// The prior of the sensor-error states for a body sensing `f_b` (m/s²): the data sheet's
    /// ([`Self::data_sheet_prior`]), with the calibration memory where it is tighter (module
    /// docs). Returns the covariance (zero outside the sensor-error states) and the estimates
    /// the filter starts from (zero without memory).
    pub(super) fn sensor_prior(&self, f_b: &Vector3<f64>) -> (Covariance, StateVector) {
        let mut p0 = self.data_sheet_prior(f_b);
        let mut x0 = StateVector::zeros();
        let Some(mem) = &self.calibration else {
            return (p0, x0);
        };
        let active = self.active_states(false).mask();
        let prior = self.prior_variances(&p0);
        let kept = |i: usize| active[i] && mem.p[(i, i)] < prior[i];
        for &i in REMEMBERED.iter().filter(|&&i| kept(i)) {
            for &j in REMEMBERED.iter().filter(|&&j| kept(j)) {
                p0[(i, j)] = mem.p[(i, j)];
            }
            x0[i] = mem.x[i];
        }
        (p0, x0)
    }

    /// The data-sheet prior of the sensor-error states (`[imu]`, `[aiding]`), zero elsewhere,
    /// for a body sensing the specific force `f_b` (m/s²): the accelerometer misalignment (σ_m
    /// per off-diagonal, not a state) turns it into the error `M f_b`, whose axis-k part
    /// `Σ_{j≠k} M_kj f_j` has variance `σ_m² (|f|² − f_k²)`, a bias while `f_b` is gravity.
    /// The gyro non-orthogonality's prior is left to the filter (`ErrorStateEkf::new`). The
    /// region's gravity disturbance (`[gravity_disturbance]`) widens the accelerometer-bias
    /// block by its covariance in body axes, the vertical being along `f_b`.
    pub(super) fn data_sheet_prior(&self, f_b: &Vector3<f64>) -> Covariance {
        let imu = &self.config.imu;
        let mut p0 = Covariance::zeros();
        let sbg = imu.gyro_bias_rad_s().powi(2);
        let sba = imu.accel_bias_m_s2().powi(2);
        let s_mis = imu.misalignment_arcsec / 3600.0 * DEG;
        let sg = imu.gyro_scale_ppm * 1e-6;
        let sa = imu.accel_scale_ppm * 1e-6;
        for k in 0..3 {
            p0[(idx::BG + k, idx::BG + k)] = sbg;
            p0[(idx::BA + k, idx::BA + k)] =
                sba + s_mis * s_mis * (f_b.norm_squared() - f_b[k] * f_b[k]);
            p0[(idx::SG + k, idx::SG + k)] = sg * sg;
            p0[(idx::SA + k, idx::SA + k)] = sa * sa;
        }
        p0.fixed_view_mut::<3, 3>(idx::KAPPA, idx::KAPPA)
            .copy_from(&self.boresight_prior_covariance());
        let mut ba = p0.fixed_view_mut::<3, 3>(idx::BA, idx::BA);
        ba += self
            .config
            .gravity_disturbance
            .disturbance()
            .body_covariance(f_b);
        p0[(idx::BARO, idx::BARO)] = self.config.aiding.baro_bias_sigma_m.powi(2);
        p0[(idx::ODO, idx::ODO)] = self.config.aiding.odometer_scale_sigma.powi(2);
        p0
    }

    /// The data-sheet variance of each state: the diagonal of `p0` ([`Self::data_sheet_prior`])
    /// and, for the gyro non-orthogonality, the filter's own prior.
    fn prior_variances(&self, p0: &Covariance) -> StateVector {
        let mut v = p0.diagonal();
        let sgm = self.filter_noise().gyro_misalignment_rad;
        v.fixed_rows_mut::<3>(idx::SGM).fill(sgm * sgm);
        v
    }

    /// The boresight the star attitude is derived with from the calibration memory, when it
    /// is used for the boresight (estimate, covariance).
    pub(super) fn remembered_boresight(&self) -> Option<(Vector3<f64>, Matrix3<f64>)> {
        let (p0, x0) = self.sensor_prior(&Vector3::new(0.0, 0.0, -G0));
        let prior = self.boresight_prior_covariance();
        let p_kk = p0.fixed_view::<3, 3>(idx::KAPPA, idx::KAPPA).into_owned();
        (self.calibration.is_some() && (0..3).any(|k| p_kk[(k, k)] < prior[(k, k)]))
            .then(|| (x0.fixed_rows::<3>(idx::KAPPA).into_owned(), p_kk))
    }
}
