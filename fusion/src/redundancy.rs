//! Redundant (skewed) inertial channels: least-squares combination and parity-space fault
//! detection, isolation and exclusion (paper 004, "structural redundancy", eqs. (1)–(7)).
//!
//! # Measurement model (paper eqs. (3)–(5))
//! `N` single-axis gyro + accelerometer channels with unit sensitive axes `e_i` in body axes
//! (the paper's truncated pyramid: `e_i = (cosα cosβ_i, cosα sinβ_i, sinα)`, β_i = 45° + i·90°)
//! measure `z = H x + ε`, `H` the `N×3` stack of `e_iᵀ`, `x` the body delta-angle (or
//! delta-velocity) over one IMU interval. The least-squares estimate is (eqs. (6), (7))
//! `x̂ = (HᵀH)⁻¹ Hᵀ z`, with error covariance `σ² (HᵀH)⁻¹` for white channel noise σ.
//!
//! # Parity space (not in the paper; the classical Potter & Suman / Sturza formulation the
//! paper cites for fault tolerance)
//! The projector on the left null space of `H`, `P = I − H (HᵀH)⁻¹ Hᵀ` (symmetric, idempotent,
//! rank `N − 3`), removes the motion: `P z = P ε`. With white channel noise of variance `s²`,
//! `zᵀ P z / s² = ‖P z‖² / s²` is χ² with `N − 3` degrees of freedom (no explicit basis `V` of the
//! null space is needed since `VᵀV = P`). A fault `f` on channel `j` adds `P e_j f`.
//! - Detection (N ≥ 4): the statistic exceeds the χ²(N−3) quantile of the configured false-alarm
//!   probability in `persistence_blocks` consecutive test blocks.
//! - Isolation (N ≥ 5): the generalized likelihood ratio picks `argmax_i r_i² / P_ii` with
//!   `r = P z`; by Cauchy–Schwarz `P_ij² ≤ P_ii P_jj`, so the faulty channel wins unless two
//!   columns of `P` are parallel. With N = 4, `P` has rank 1 and all its columns are parallel:
//!   every channel explains a fault equally well, so N = 4 detects but cannot isolate (as the
//!   paper says: isolation needs 5).
//! - Exclusion: the isolated channel's row of `H` is zeroed, `(HᵀH)⁻¹Hᵀ` and `P` are rebuilt, and
//!   navigation continues with N − 1 channels (detection continues while N − 1 ≥ 4).
//!
//! # Test blocks and thresholds
//! Channel increments are summed over blocks of `block_samples` IMU intervals, which averages
//! white noise down while a bias-type fault grows linearly. The variance of one channel's block
//! sum is `M σ²` (σ per interval) plus, because scale-factor and axis errors of the channels are
//! not in `H`, `(κ ‖X̂‖)²` with `X̂` the block's combined increment and κ the relative
//! scale/axis error (an adaptive threshold: a turn or a 1 g load moves the parity vector by
//! that much without any fault). Constant channel biases give a constant parity offset, learnt
//! over the first `learn_blocks` blocks (when the sensor is assumed healthy, e.g. on the
//! ground) and subtracted; after an exclusion the offset is re-projected: with `m` the mask of
//! remaining channels, `P' m(b) = P' m(P b)` because `P'` annihilates `m(H c)`.
//!
//! Everything is fixed size (`MAX_IMU_CHANNELS` = 8 rows, unused rows zero): no allocation per
//! step.

use crate::FusionError;
use crate::ekf::chi2_quantile;
use msgs::MAX_IMU_CHANNELS;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Number of channel slots (`msgs::MAX_IMU_CHANNELS`).
pub const MAX_CHANNELS: usize = MAX_IMU_CHANNELS;

/// `MAX_CHANNELS × 3` measurement matrix (rows of unused or excluded channels are zero).
pub type HMatrix = SMatrix<f64, MAX_CHANNELS, 3>;
/// `3 × MAX_CHANNELS` least-squares combination `(HᵀH)⁻¹Hᵀ`.
pub type LsMatrix = SMatrix<f64, 3, MAX_CHANNELS>;
/// `MAX_CHANNELS × MAX_CHANNELS` parity projector.
pub type ParityProjector = SMatrix<f64, MAX_CHANNELS, MAX_CHANNELS>;
/// One value per channel slot.
pub type ChannelVector = SVector<f64, MAX_CHANNELS>;

/// Unit axes of the paper's pyramid: `n` channels at azimuths β_k = 45° + k·360°/n (90° steps
/// for n = 4) and elevation `alpha_rad` above the body x-y plane, body axes.
/// α = asin(1/√3) = 35.26° makes four axes isotropic (`HᵀH = (4/3) I`).
pub fn pyramid_axes(n: usize, alpha_rad: f64) -> [[f64; 3]; MAX_CHANNELS] {
    let mut axes = [[0.0; 3]; MAX_CHANNELS];
    let n = n.min(MAX_CHANNELS);
    let (sa, ca) = alpha_rad.sin_cos();
    for (k, a) in axes.iter_mut().enumerate().take(n) {
        let beta = (45.0_f64 + k as f64 * 360.0 / n as f64).to_radians();
        *a = [ca * beta.cos(), ca * beta.sin(), sa];
    }
    axes
}

/// The three orthogonal body axes as channels (the conventional triad).
pub fn orthogonal_axes() -> [[f64; 3]; MAX_CHANNELS] {
    let mut axes = [[0.0; 3]; MAX_CHANNELS];
    axes[0] = [1.0, 0.0, 0.0];
    axes[1] = [0.0, 1.0, 0.0];
    axes[2] = [0.0, 0.0, 1.0];
    axes
}

/// Measurement matrix of the channels in `active` (bit i = channel i used).
pub fn measurement_matrix(axes: &[[f64; 3]; MAX_CHANNELS], active: u32) -> HMatrix {
    let mut h = HMatrix::zeros();
    for (i, a) in axes.iter().enumerate() {
        if active & (1 << i) != 0 {
            h[(i, 0)] = a[0];
            h[(i, 1)] = a[1];
            h[(i, 2)] = a[2];
        }
    }
    h
}

/// `(HᵀH)⁻¹`: the least-squares error covariance of the combined vector per unit channel
/// variance, body axes. None if the active axes do not span 3-D.
pub fn ls_covariance_per_unit_variance(h: &HMatrix) -> Option<Matrix3<f64>> {
    let hth = h.transpose() * h;
    // Reject near-coplanar layouts: condition through the determinant of the normal matrix
    // relative to its scale (trace³/27 for an isotropic one).
    let tr = hth.trace();
    if tr.is_nan() || tr <= 0.0 || hth.determinant() < 1e-9 * tr * tr * tr {
        return None;
    }
    hth.try_inverse()
}

/// Settings of the fault detection, isolation and exclusion.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FdiConfig {
    /// 1-σ white noise of one gyro channel's delta-angle over one IMU interval, rad
    /// (ARW·√dt combined with the quantisation LSB·dt/√12).
    pub gyro_sigma_rad: f64,
    /// 1-σ white noise of one accelerometer channel's delta-velocity over one interval, m/s.
    pub accel_sigma_m_s: f64,
    /// Relative scale-factor + axis error of a gyro channel (κ of the adaptive threshold).
    pub gyro_relative_sigma: f64,
    /// Relative scale-factor + axis error of an accelerometer channel.
    pub accel_relative_sigma: f64,
    /// IMU intervals summed into one test block.
    pub block_samples: u32,
    /// False-alarm probability of one block's χ² test.
    pub false_alarm_probability: f64,
    /// Consecutive blocks over the threshold before a fault is declared (and, with N ≥ 5,
    /// the same channel isolated in each of them before it is excluded).
    pub persistence_blocks: u32,
    /// Blocks averaged at the start to learn the fault-free parity offset (channel biases).
    pub learn_blocks: u32,
    /// After learning, healthy blocks keep tracking the offset with this time constant in
    /// blocks (follows temperature and random-walk bias drift; 0 = frozen). A drift-ramp
    /// fault of slope `r` still shows as a lag `r · track_blocks · block length`.
    pub track_blocks: u32,
    /// Exclude an isolated channel (false: detect and report only).
    pub exclude: bool,
}

impl Default for FdiConfig {
    fn default() -> Self {
        Self {
            gyro_sigma_rad: 1e-5,
            accel_sigma_m_s: 2e-4,
            gyro_relative_sigma: 3e-3,
            accel_relative_sigma: 3e-3,
            block_samples: 100,
            false_alarm_probability: 1e-4,
            persistence_blocks: 2,
            learn_blocks: 30,
            track_blocks: 600,
            exclude: true,
        }
    }
}

impl FdiConfig {
    /// Check ranges.
    pub fn validate(&self) -> Result<(), FusionError> {
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(FusionError::Config(format!(
                    "redundancy.{name} must be finite and > 0, got {v}"
                )))
            }
        };
        pos("gyro_sigma_rad", self.gyro_sigma_rad)?;
        pos("accel_sigma_m_s", self.accel_sigma_m_s)?;
        for (n, v) in [
            ("gyro_relative_sigma", self.gyro_relative_sigma),
            ("accel_relative_sigma", self.accel_relative_sigma),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(FusionError::Config(format!(
                    "redundancy.{n} must be finite and ≥ 0, got {v}"
                )));
            }
        }
        if !(self.false_alarm_probability > 0.0 && self.false_alarm_probability < 0.5) {
            return Err(FusionError::Config(format!(
                "redundancy.false_alarm_probability must be in (0, 0.5), got {}",
                self.false_alarm_probability
            )));
        }
        if self.block_samples == 0 || self.persistence_blocks == 0 {
            return Err(FusionError::Config(
                "redundancy.block_samples and persistence_blocks must be ≥ 1".into(),
            ));
        }
        Ok(())
    }
}

/// `[redundancy]` of the filter tuning (`config/filter.toml`): the FDI settings from which the
/// navigator builds its [`FdiConfig`] for the IMU's sample interval (the per-interval noise
/// depends on it, so it cannot be fixed in the file).
///
/// Per-interval channel noise (one channel's increment over `dt`):
/// `σ² = ARW²·dt + (q·dt)²/12`, with the ARW (VRW for the accelerometers) of `[imu]` and `q`
/// the channel's quantisation step of the rate (specific-force) output: the increment is the
/// quantised rate times `dt`, whose rounding error is uniform over one step — variance
/// `(q·dt)²/12` — and independent from sample to sample when the white noise dithers it
/// (noise σ per sample ≳ q/2; the MEMS grade of paper 004: gyro 0.68 q, accelerometer 0.77 q).
/// For that grade at 100 Hz (q = 0.073 °/s, 1.95 mg) quantisation adds 18 % (gyro) and 14 %
/// (accelerometer) to the white-noise variance; left out, the χ² threshold of the parity test
/// is too low by that much and the false-alarm rate rises by an order of magnitude.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RedundancyConfig {
    /// False-alarm probability of one test block's χ² test.
    pub false_alarm_probability: f64,
    /// Exclude the channel that isolation names (N ≥ 5); false: detect, isolate and report
    /// only, never exclude.
    pub exclude: bool,
    /// Quantisation step of one gyro channel's rate output, deg/s (0: not quantised). A
    /// `b`-bit ADC over ±FS: 2·FS/2^b (12 bits over ±150 °/s: 0.0732 °/s).
    pub gyro_quantum_deg_s: f64,
    /// Quantisation step of one accelerometer channel's specific-force output, mg (0: not
    /// quantised; 12 bits over ±4 g: 1.953 mg).
    pub accel_quantum_mg: f64,
    /// Relative scale-factor + axis error of a gyro channel (κ of the adaptive threshold).
    pub gyro_relative_sigma: f64,
    /// Relative scale-factor + axis error of an accelerometer channel.
    pub accel_relative_sigma: f64,
    /// IMU intervals summed into one test block.
    pub block_samples: u32,
    /// Consecutive blocks over the threshold before a fault is declared.
    pub persistence_blocks: u32,
    /// Blocks averaged at the start to learn the fault-free parity offset.
    pub learn_blocks: u32,
    /// Time constant of the offset tracking after learning, blocks (0 = frozen).
    pub track_blocks: u32,
}

impl Default for RedundancyConfig {
    fn default() -> Self {
        let f = FdiConfig::default();
        Self {
            false_alarm_probability: f.false_alarm_probability,
            exclude: f.exclude,
            gyro_quantum_deg_s: 0.0,
            accel_quantum_mg: 0.0,
            gyro_relative_sigma: f.gyro_relative_sigma,
            accel_relative_sigma: f.accel_relative_sigma,
            block_samples: f.block_samples,
            persistence_blocks: f.persistence_blocks,
            learn_blocks: f.learn_blocks,
            track_blocks: f.track_blocks,
        }
    }
}

/// Standard gravity, m/s² per g (for the mg quantum).
const G0_M_S2: f64 = 9.806_65;

impl RedundancyConfig {
    /// The FDI settings for channels with angle random walk `arw_rad_sqrt_s` (rad/√s),
    /// velocity random walk `vrw_m_s_sqrt_s` (m/s/√s) sampled every `dt_s` seconds: the
    /// per-interval σ combines the white noise and the quantisation (type docs).
    pub fn fdi_config(&self, arw_rad_sqrt_s: f64, vrw_m_s_sqrt_s: f64, dt_s: f64) -> FdiConfig {
        let qg = self.gyro_quantum_deg_s.to_radians() * dt_s;
        let qa = self.accel_quantum_mg * 1e-3 * G0_M_S2 * dt_s;
        FdiConfig {
            gyro_sigma_rad: (arw_rad_sqrt_s.powi(2) * dt_s + qg * qg / 12.0).sqrt(),
            accel_sigma_m_s: (vrw_m_s_sqrt_s.powi(2) * dt_s + qa * qa / 12.0).sqrt(),
            gyro_relative_sigma: self.gyro_relative_sigma,
            accel_relative_sigma: self.accel_relative_sigma,
            block_samples: self.block_samples,
            false_alarm_probability: self.false_alarm_probability,
            persistence_blocks: self.persistence_blocks,
            learn_blocks: self.learn_blocks,
            track_blocks: self.track_blocks,
            exclude: self.exclude,
        }
    }

    /// Check ranges; the error names the key (`filter.redundancy.<key>`).
    pub fn validate(&self) -> Result<(), FusionError> {
        let bad = |key: &str, what: &str| {
            Err(FusionError::Config(format!(
                "filter.redundancy.{key} {what}"
            )))
        };
        for (k, v) in [
            ("gyro_quantum_deg_s", self.gyro_quantum_deg_s),
            ("accel_quantum_mg", self.accel_quantum_mg),
            ("gyro_relative_sigma", self.gyro_relative_sigma),
            ("accel_relative_sigma", self.accel_relative_sigma),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(k, &format!("must be a finite number >= 0, got {v}"));
            }
        }
        if !(self.false_alarm_probability > 0.0 && self.false_alarm_probability < 0.5) {
            return bad(
                "false_alarm_probability",
                &format!("must be in (0, 0.5), got {}", self.false_alarm_probability),
            );
        }
        if self.block_samples == 0 {
            return bad("block_samples", "must be >= 1");
        }
        if self.persistence_blocks == 0 {
            return bad("persistence_blocks", "must be >= 1");
        }
        Ok(())
    }
}

/// Health of the redundant unit, as reported on `sextant/status`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RedundancyStatus {
    /// Channels configured.
    pub n_channels: u32,
    /// Bit i = channel i excluded.
    pub excluded_mask: u32,
    /// Bit i = channel i flagged by the last test block (all active channels when a fault is
    /// detected but cannot be isolated).
    pub suspect_mask: u32,
    /// Faults declared (each run of `persistence_blocks` exceedances counts once).
    pub faults_detected: u32,
    /// Test blocks evaluated.
    pub blocks_tested: u64,
    /// Blocks whose gyro or accelerometer statistic exceeded the threshold.
    pub blocks_over_threshold: u64,
    /// Last gyro parity statistic (χ² with `dof` degrees of freedom if healthy).
    pub last_gyro_statistic: f64,
    /// Last accelerometer parity statistic.
    pub last_accel_statistic: f64,
    /// Degrees of freedom of the parity test (active channels − 3; 0 = no test).
    pub dof: u32,
    /// Time of the IMU sample closing the block in which the last fault was declared, as
    /// the caller's step counter (number of `step` calls).
    pub last_detection_step: u64,
}

/// Block accumulator and state of one sensor kind (gyro or accelerometer).
#[derive(Debug, Clone, Copy)]
struct ParityState {
    sum_z: ChannelVector,
    sum_x: Vector3<f64>,
    offset: ChannelVector,
    learn_sum: ChannelVector,
    /// Mean combined block increment while learning (the scale/axis errors at that motion
    /// are in the offset; the adaptive term uses the change from it).
    x_learn: Vector3<f64>,
    sigma: f64,
    relative_sigma: f64,
}

impl ParityState {
    fn new(sigma: f64, relative_sigma: f64) -> Self {
        Self {
            sum_z: ChannelVector::zeros(),
            sum_x: Vector3::zeros(),
            offset: ChannelVector::zeros(),
            learn_sum: ChannelVector::zeros(),
            x_learn: Vector3::zeros(),
            sigma,
            relative_sigma,
        }
    }
}

/// Outcome of one block test of one sensor kind.
#[derive(Debug, Clone, Copy)]
struct BlockTest {
    statistic: f64,
    over: bool,
    /// GLR-most-likely channel (valid when isolation is possible).
    argmax: usize,
}

/// The redundant IMU: least-squares combination plus parity-space FDI, fixed size.
#[derive(Debug, Clone)]
pub struct RedundantImu {
    config: FdiConfig,
    axes: [[f64; 3]; MAX_CHANNELS],
    n: usize,
    active: u32,
    ls: LsMatrix,
    projector: ParityProjector,
    /// χ² quantile per degree of freedom (index = dof, 0 unused).
    thresholds: [f64; MAX_CHANNELS],
    gyro: ParityState,
    accel: ParityState,
    in_block: u32,
    blocks: u64,
    steps: u64,
    consecutive: u32,
    candidate: Option<usize>,
    candidate_run: u32,
    in_fault: bool,
    status: RedundancyStatus,
}

impl RedundantImu {
    /// Channels with unit axes `axes[..n]` (body frame). Needs 3 ≤ n ≤ 8 axes spanning 3-D.
    pub fn new(axes: &[[f64; 3]], config: FdiConfig) -> Result<Self, FusionError> {
        config.validate()?;
        let n = axes.len();
        if !(3..=MAX_CHANNELS).contains(&n) {
            return Err(FusionError::Config(format!(
                "redundancy: need 3..={MAX_CHANNELS} channels, got {n}"
            )));
        }
        let mut a = [[0.0; 3]; MAX_CHANNELS];
        for (i, (dst, src)) in a.iter_mut().zip(axes).enumerate() {
            let v = Vector3::from(*src);
            let norm = v.norm();
            if !(norm.is_finite() && (norm - 1.0).abs() < 1e-6) {
                return Err(FusionError::Config(format!(
                    "redundancy: channel {i} axis {src:?} is not a unit vector"
                )));
            }
            *dst = *src;
        }
        let mut thresholds = [0.0; MAX_CHANNELS];
        for (k, t) in thresholds.iter_mut().enumerate().skip(1) {
            *t = chi2_quantile(k as u32, 1.0 - config.false_alarm_probability);
        }
        let active = (1u32 << n) - 1;
        let mut s = Self {
            config,
            axes: a,
            n,
            active,
            ls: LsMatrix::zeros(),
            projector: ParityProjector::zeros(),
            thresholds,
            gyro: ParityState::new(config.gyro_sigma_rad, config.gyro_relative_sigma),
            accel: ParityState::new(config.accel_sigma_m_s, config.accel_relative_sigma),
            in_block: 0,
            blocks: 0,
            steps: 0,
            consecutive: 0,
            candidate: None,
            candidate_run: 0,
            in_fault: false,
            status: RedundancyStatus {
                n_channels: n as u32,
                ..Default::default()
            },
        };
        if !s.rebuild() {
            return Err(FusionError::Config(
                "redundancy: channel axes do not span three dimensions".into(),
            ));
        }
        Ok(s)
    }

    /// Rebuild `(HᵀH)⁻¹Hᵀ` and `P` for the active set; false if it no longer spans 3-D.
    fn rebuild(&mut self) -> bool {
        let h = measurement_matrix(&self.axes, self.active);
        let Some(inv) = ls_covariance_per_unit_variance(&h) else {
            return false;
        };
        self.ls = inv * h.transpose();
        let mut p = ParityProjector::identity() - h * self.ls;
        for i in 0..MAX_CHANNELS {
            if self.active & (1 << i) == 0 {
                // Inactive slots take no part: zero row and column.
                for j in 0..MAX_CHANNELS {
                    p[(i, j)] = 0.0;
                    p[(j, i)] = 0.0;
                }
            }
        }
        self.projector = p;
        self.status.dof = self.active.count_ones().saturating_sub(3);
        true
    }

    /// Channels in use (bit mask).
    pub fn active_mask(&self) -> u32 {
        self.active
    }

    /// Configured number of channels.
    pub fn n_channels(&self) -> usize {
        self.n
    }

    /// The current least-squares combination matrix `(HᵀH)⁻¹Hᵀ`.
    pub fn ls_matrix(&self) -> &LsMatrix {
        &self.ls
    }

    /// The current parity projector `P`.
    pub fn projector(&self) -> &ParityProjector {
        &self.projector
    }

    /// Health counters and masks.
    pub fn status(&self) -> RedundancyStatus {
        self.status
    }

    /// Whether the axes of this unit equal `axes[..n]` (used to detect a layout change).
    pub fn same_layout(&self, axes: &[[f64; 3]]) -> bool {
        axes.len() == self.n && axes.iter().zip(&self.axes).all(|(a, b)| a == b)
    }

    /// Least-squares combination of channel values `z` (slots beyond the active set ignored).
    pub fn combine(&self, z: &ChannelVector) -> Vector3<f64> {
        self.ls * self.mask(z)
    }

    fn mask(&self, z: &ChannelVector) -> ChannelVector {
        let mut m = *z;
        for i in 0..MAX_CHANNELS {
            if self.active & (1 << i) == 0 {
                m[i] = 0.0;
            }
        }
        m
    }

    /// One IMU interval: channel delta-angles (rad) and delta-velocities (m/s), `n` values
    /// each. Returns the combined body delta-angle and delta-velocity after FDI of any block
    /// that this interval closes. Allocates nothing.
    pub fn step(&mut self, gyro_rad: &[f64], accel_m_s: &[f64]) -> (Vector3<f64>, Vector3<f64>) {
        let mut zg = ChannelVector::zeros();
        let mut za = ChannelVector::zeros();
        for i in 0..self.n.min(gyro_rad.len()).min(accel_m_s.len()) {
            zg[i] = gyro_rad[i];
            za[i] = accel_m_s[i];
        }
        self.step_vectors(&zg, &za)
    }

    /// [`RedundantImu::step`] with channel vectors.
    pub fn step_vectors(
        &mut self,
        zg: &ChannelVector,
        za: &ChannelVector,
    ) -> (Vector3<f64>, Vector3<f64>) {
        self.steps += 1;
        let zg = self.mask(zg);
        let za = self.mask(za);
        let d_theta = self.ls * zg;
        let d_v = self.ls * za;
        if self.status.dof > 0 {
            self.gyro.sum_z += zg;
            self.gyro.sum_x += d_theta;
            self.accel.sum_z += za;
            self.accel.sum_x += d_v;
            self.in_block += 1;
            if self.in_block >= self.config.block_samples {
                self.close_block();
            }
        }
        (d_theta, d_v)
    }

    fn test(&self, st: &ParityState) -> BlockTest {
        let m = f64::from(self.config.block_samples);
        let r = self.projector * st.sum_z - st.offset;
        let kx = st.relative_sigma * (st.sum_x - st.x_learn).norm();
        let var = m * st.sigma * st.sigma + kx * kx;
        let statistic = r.norm_squared() / var;
        let dof = self.status.dof as usize;
        let over = statistic > self.thresholds[dof];
        let mut argmax = 0;
        let mut best = -1.0;
        for i in 0..MAX_CHANNELS {
            let pii = self.projector[(i, i)];
            if self.active & (1 << i) != 0 && pii > 1e-12 {
                let g = r[i] * r[i] / pii;
                if g > best {
                    best = g;
                    argmax = i;
                }
            }
        }
        BlockTest {
            statistic,
            over,
            argmax,
        }
    }

    fn close_block(&mut self) {
        self.in_block = 0;
        self.blocks += 1;
        let learn = u64::from(self.config.learn_blocks);
        if self.blocks <= learn {
            // Learn the fault-free parity offset of the constant channel biases.
            let rg = self.projector * self.gyro.sum_z;
            let ra = self.projector * self.accel.sum_z;
            self.gyro.learn_sum += rg;
            self.accel.learn_sum += ra;
            self.gyro.x_learn += self.gyro.sum_x / learn as f64;
            self.accel.x_learn += self.accel.sum_x / learn as f64;
            if self.blocks == learn {
                self.gyro.offset = self.gyro.learn_sum / learn as f64;
                self.accel.offset = self.accel.learn_sum / learn as f64;
            }
            self.reset_sums();
            return;
        }
        let g = self.test(&self.gyro);
        let a = self.test(&self.accel);
        if !(g.over || a.over) && self.config.track_blocks > 0 {
            let w = 1.0 / f64::from(self.config.track_blocks);
            for st in [&mut self.gyro, &mut self.accel] {
                let r = self.projector * st.sum_z;
                st.offset += (r - st.offset) * w;
            }
        }
        self.reset_sums();
        self.status.blocks_tested += 1;
        self.status.last_gyro_statistic = g.statistic;
        self.status.last_accel_statistic = a.statistic;
        if !(g.over || a.over) {
            self.consecutive = 0;
            self.candidate = None;
            self.candidate_run = 0;
            self.in_fault = false;
            self.status.suspect_mask = 0;
            return;
        }
        self.status.blocks_over_threshold += 1;
        self.consecutive += 1;
        let can_isolate = self.status.dof >= 2;
        // The kind with the larger normalized statistic names the channel.
        let pick = if g.over && (!a.over || g.statistic >= a.statistic) {
            g.argmax
        } else {
            a.argmax
        };
        if can_isolate {
            self.status.suspect_mask = 1 << pick;
            if self.candidate == Some(pick) {
                self.candidate_run += 1;
            } else {
                self.candidate = Some(pick);
                self.candidate_run = 1;
            }
        } else {
            self.status.suspect_mask = self.active;
        }
        let k = self.config.persistence_blocks;
        if self.consecutive >= k && !self.in_fault {
            self.in_fault = true;
            self.status.faults_detected += 1;
            self.status.last_detection_step = self.steps;
        }
        if can_isolate && self.config.exclude && self.candidate_run >= k {
            self.exclude(pick);
        }
    }

    fn reset_sums(&mut self) {
        for st in [&mut self.gyro, &mut self.accel] {
            st.sum_z = ChannelVector::zeros();
            st.sum_x = Vector3::zeros();
        }
    }

    /// Remove channel `i` from the solution (both its gyro and its accelerometer: the paper's
    /// channels are combined modules). Keeps navigating with the rest if they span 3-D.
    pub fn exclude(&mut self, i: usize) {
        if i >= self.n || self.active & (1 << i) == 0 {
            return;
        }
        let before = self.active;
        self.active &= !(1 << i);
        if !self.rebuild() {
            self.active = before;
            self.rebuild();
            return;
        }
        self.status.excluded_mask |= 1 << i;
        self.status.suspect_mask = 0;
        // Re-project the learnt offsets onto the new parity space.
        let offs = [self.gyro.offset, self.accel.offset];
        self.gyro.offset = self.projector * self.mask(&offs[0]);
        self.accel.offset = self.projector * self.mask(&offs[1]);
        self.consecutive = 0;
        self.candidate = None;
        self.candidate_run = 0;
        self.in_fault = false;
        self.in_block = 0;
        self.reset_sums();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha20Rng;
    use rand_distr::StandardNormal;

    fn isotropic_alpha() -> f64 {
        (1.0 / 3.0_f64.sqrt()).asin()
    }

    fn axes_slice(axes: &[[f64; 3]; MAX_CHANNELS], n: usize) -> Vec<[f64; 3]> {
        axes[..n].to_vec()
    }

    fn channels(axes: &[[f64; 3]; MAX_CHANNELS], n: usize, x: &Vector3<f64>) -> ChannelVector {
        let mut z = ChannelVector::zeros();
        for i in 0..n {
            z[i] = Vector3::from(axes[i]).dot(x);
        }
        z
    }

    #[test]
    fn noise_free_channels_are_combined_exactly() {
        for (n, alpha) in [(4, 28.7_f64.to_radians()), (5, isotropic_alpha()), (6, 0.3)] {
            let axes = pyramid_axes(n, alpha);
            let imu = RedundantImu::new(&axes_slice(&axes, n), FdiConfig::default()).unwrap();
            let x = Vector3::new(0.01, -0.02, 0.005);
            let err = (imu.combine(&channels(&axes, n, &x)) - x).norm();
            // Exact up to rounding: a few ulps of |x|.
            assert!(err < 1e-16, "n = {n}: {err}");
        }
    }

    #[test]
    fn ls_noise_of_isotropic_pyramid_is_sqrt_three_quarters() {
        // Closed form: HᵀH = Σ e_i e_iᵀ; for the pyramid Σcos²β_k = Σsin²β_k = n/2 and the
        // cross terms vanish, so HᵀH = diag(2cos²α, 2cos²α, 4sin²α) for n = 4; with
        // sin²α = 1/3 it is (4/3) I and the per-axis noise is σ·√(3/4) against σ for the
        // orthogonal triad (trace 9/4 against 3).
        let h4 = measurement_matrix(&pyramid_axes(4, isotropic_alpha()), 0b1111);
        let c4 = ls_covariance_per_unit_variance(&h4).unwrap();
        for i in 0..3 {
            assert!((c4[(i, i)] - 0.75).abs() < 1e-12);
        }
        assert!((c4.trace() - 2.25).abs() < 1e-12);
        let h3 = measurement_matrix(&orthogonal_axes(), 0b111);
        let c3 = ls_covariance_per_unit_variance(&h3).unwrap();
        assert!((c3.trace() - 3.0).abs() < 1e-12);
        // The paper's α = 28.7°: x, y get 1/(2cos²α) = 0.650, z 1/(4 sin²α) = 1.085.
        let a = 28.7_f64.to_radians();
        let hp = measurement_matrix(&pyramid_axes(4, a), 0b1111);
        let cp = ls_covariance_per_unit_variance(&hp).unwrap();
        assert!((cp[(0, 0)] - 1.0 / (2.0 * a.cos().powi(2))).abs() < 1e-12);
        assert!((cp[(2, 2)] - 1.0 / (4.0 * a.sin().powi(2))).abs() < 1e-12);

        // Monte Carlo: 20 000 draws; the sample variance of a χ²-like estimate has relative
        // σ √(2/20000) = 1 %, so 5 % is a 5-σ bound.
        let n = 4;
        let axes = pyramid_axes(n, isotropic_alpha());
        let imu = RedundantImu::new(&axes_slice(&axes, n), FdiConfig::default()).unwrap();
        let mut rng = ChaCha20Rng::seed_from_u64(4);
        let mut var = Vector3::zeros();
        let draws = 20_000;
        for _ in 0..draws {
            let mut z = ChannelVector::zeros();
            for i in 0..n {
                z[i] = rng.sample(StandardNormal);
            }
            let x = imu.combine(&z);
            var += x.component_mul(&x);
        }
        var /= draws as f64;
        for i in 0..3 {
            assert!((var[i] - 0.75).abs() < 0.05 * 0.75, "axis {i}: {}", var[i]);
        }
    }

    #[test]
    fn projector_is_symmetric_idempotent_and_annihilates_motion() {
        let n = 5;
        let axes = pyramid_axes(n, 0.5);
        let imu = RedundantImu::new(&axes_slice(&axes, n), FdiConfig::default()).unwrap();
        let p = imu.projector();
        assert!((p - p.transpose()).norm() < 1e-14);
        assert!((p * p - p).norm() < 1e-13);
        assert!((p.trace() - 2.0).abs() < 1e-12, "rank N − 3");
        let z = channels(&axes, n, &Vector3::new(1.0, 2.0, 3.0));
        assert!((p * z).norm() < 1e-13);
    }

    fn white_run(
        imu: &mut RedundantImu,
        rng: &mut ChaCha20Rng,
        axes: &[[f64; 3]; MAX_CHANNELS],
        steps: usize,
        fault: impl Fn(usize, &mut ChannelVector),
    ) {
        let cfg = imu.config;
        let n = imu.n_channels();
        let x = Vector3::new(1e-4, -2e-4, 5e-5);
        let xa = Vector3::new(0.0, 0.0, -0.098);
        for k in 0..steps {
            let mut zg = channels(axes, n, &x);
            let mut za = channels(axes, n, &xa);
            for i in 0..n {
                let a: f64 = rng.sample(StandardNormal);
                let b: f64 = rng.sample(StandardNormal);
                zg[i] += cfg.gyro_sigma_rad * a;
                za[i] += cfg.accel_sigma_m_s * b;
            }
            fault(k, &mut zg);
            imu.step_vectors(&zg, &za);
        }
    }

    #[test]
    fn false_alarm_rate_matches_chi_square_probability() {
        // Pure white noise, no scale errors (κ = 0): each block statistic is χ²(N−3), and each
        // block over the threshold is a false alarm with probability p = 0.01 (the gyro and
        // accelerometer tests are independent: the block is over with 1 − (1 − p)²). With
        // 2000 blocks the count is binomial with mean 2000·0.0199 = 39.8 and σ = 6.2; the
        // bounds are ±4σ. The offset learning is off (no bias), so it cannot absorb anything.
        let cfg = FdiConfig {
            gyro_relative_sigma: 0.0,
            accel_relative_sigma: 0.0,
            block_samples: 10,
            false_alarm_probability: 0.01,
            persistence_blocks: 1,
            learn_blocks: 0,
            track_blocks: 0,
            exclude: false,
            ..Default::default()
        };
        for n in [4, 5] {
            let axes = pyramid_axes(n, isotropic_alpha());
            let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
            let mut rng = ChaCha20Rng::seed_from_u64(40 + n as u64);
            white_run(&mut imu, &mut rng, &axes, 20_000, |_, _| {});
            let st = imu.status();
            assert_eq!(st.blocks_tested, 2000);
            let p_block = 1.0 - (1.0 - 0.01f64).powi(2);
            let mean = 2000.0 * p_block;
            let sd = (2000.0 * p_block * (1.0 - p_block)).sqrt();
            let got = st.blocks_over_threshold as f64;
            assert!(
                (got - mean).abs() < 4.0 * sd,
                "n = {n}: {got} over, expected {mean:.1} ± {sd:.1}"
            );
            // Persistence 1: every run of consecutive exceedances is one declared fault.
            let runs = u64::from(st.faults_detected);
            assert!(runs <= st.blocks_over_threshold && runs as f64 > 0.8 * got);
            assert_eq!(st.excluded_mask, 0);
        }
    }

    #[test]
    fn bias_step_is_detected_isolated_and_excluded_in_stated_time() {
        // A bias step of b rad per interval on channel j adds M·b·P e_j to the block parity.
        // Its noncentrality is λ = (M b)² P_jj / (M σ²). With N = 5 isotropic-ish cone
        // (α = 35.26°) P_jj = 1 − 3/5 = 0.4 for every channel (trace 2 shared equally by
        // symmetry). Choose b so that λ = 100 (10 σ_parity of the block in the fault
        // direction): the χ²(2) quantile at 1e-4 is 18.4, so the detection probability per
        // block is > 0.9999 and detection (persistence 2) happens within the block in which
        // the step falls (partial) plus 2 full blocks: ≤ 3 blocks = 300 intervals.
        let cfg = FdiConfig {
            gyro_relative_sigma: 0.0,
            accel_relative_sigma: 0.0,
            learn_blocks: 0,
            ..Default::default()
        };
        let n = 5;
        let axes = pyramid_axes(n, isotropic_alpha());
        let m = f64::from(cfg.block_samples);
        let pjj = 0.4;
        let b = (100.0 * cfg.gyro_sigma_rad.powi(2) / (m * pjj)).sqrt();
        for j in 0..n {
            let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
            assert!((imu.projector()[(j, j)] - pjj).abs() < 1e-12);
            let mut rng = ChaCha20Rng::seed_from_u64(7 + j as u64);
            let onset = 5_050;
            white_run(&mut imu, &mut rng, &axes, 5_400, |k, z| {
                if k >= onset {
                    z[j] += b;
                }
            });
            let st = imu.status();
            assert_eq!(st.excluded_mask, 1 << j, "channel {j}");
            assert_eq!(st.faults_detected, 1);
            let delay = st.last_detection_step as i64 - onset as i64;
            assert!((0..=300).contains(&delay), "delay {delay}");
            assert_eq!(imu.active_mask().count_ones(), 4);
            // Navigation continues exactly with the 4 remaining channels.
            let x = Vector3::new(0.3, 0.2, 0.1);
            let mut z = channels(&axes, n, &x);
            z[j] += 1.0;
            assert!((imu.combine(&z) - x).norm() < 1e-14);
        }
    }

    #[test]
    fn four_channels_detect_but_cannot_isolate() {
        // N = 4: P has rank 1, every column parallel: the fault is flagged on all channels and
        // nothing is excluded.
        let cfg = FdiConfig {
            gyro_relative_sigma: 0.0,
            accel_relative_sigma: 0.0,
            learn_blocks: 0,
            ..Default::default()
        };
        let n = 4;
        let axes = pyramid_axes(n, 28.7_f64.to_radians());
        let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
        let mut rng = ChaCha20Rng::seed_from_u64(9);
        let b = 20.0 * cfg.gyro_sigma_rad;
        white_run(&mut imu, &mut rng, &axes, 2_000, |k, z| {
            if k >= 1_000 {
                z[2] += b;
            }
        });
        let st = imu.status();
        assert_eq!(st.faults_detected, 1);
        assert_eq!(st.excluded_mask, 0);
        assert_eq!(st.suspect_mask, 0b1111);
    }

    #[test]
    fn learnt_offset_removes_constant_biases() {
        // Channel biases of 30 σ per interval would saturate the test; after learning the
        // offset the false-alarm count is back to the χ² level (≤ 5 of 500 blocks at 1e-4 is
        // generous: expected 0.1).
        let cfg = FdiConfig {
            gyro_relative_sigma: 0.0,
            accel_relative_sigma: 0.0,
            learn_blocks: 20,
            exclude: false,
            ..Default::default()
        };
        let n = 5;
        let axes = pyramid_axes(n, 0.4);
        let mut imu = RedundantImu::new(&axes_slice(&axes, n), cfg).unwrap();
        let mut rng = ChaCha20Rng::seed_from_u64(11);
        let bias = [3.0, -1.0, 0.5, 2.0, -2.5];
        white_run(&mut imu, &mut rng, &axes, 52_000, |_, z| {
            for i in 0..5 {
                z[i] += bias[i] * 10.0 * cfg.gyro_sigma_rad;
            }
        });
        let st = imu.status();
        assert_eq!(st.blocks_tested, 500);
        assert!(st.blocks_over_threshold <= 5, "{st:?}");
    }

    #[test]
    fn rejects_bad_layouts() {
        let coplanar = [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.6, 0.8, 0.0],
            [-0.6, 0.8, 0.0],
        ];
        assert!(RedundantImu::new(&coplanar, FdiConfig::default()).is_err());
        assert!(RedundantImu::new(&coplanar[..2], FdiConfig::default()).is_err());
        let not_unit = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(RedundantImu::new(&not_unit, FdiConfig::default()).is_err());
    }
}
