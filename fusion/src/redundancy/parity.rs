//! Parity-space fault detection, isolation and exclusion of redundant inertial channels.
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
//! The offset then follows slow bias drift (temperature, random walk) through a first-order
//! tracker of time constant `track_blocks`; while the parts warm up after power-on
//! (`warmup_blocks`) with the shorter `warmup_track_blocks`, since a warm-up transient learnt
//! into the offset at power-on would otherwise stay in it for `track_blocks` and read as a
//! fault.
//!

use super::least_squares::{ls_covariance_per_unit_variance, measurement_matrix};
use super::{ChannelVector, FdiConfig, LsMatrix, MAX_CHANNELS, ParityProjector};
use crate::ConfigError;
use crate::ekf::chi2_quantile;
use nalgebra::Vector3;

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
    pub(super) config: FdiConfig,
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
    pub fn new(axes: &[[f64; 3]], config: FdiConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        let n = axes.len();
        if !(3..=MAX_CHANNELS).contains(&n) {
            return Err(ConfigError(format!(
                "redundancy: need 3..={MAX_CHANNELS} channels, got {n}"
            )));
        }
        let mut a = [[0.0; 3]; MAX_CHANNELS];
        for (i, (dst, src)) in a.iter_mut().zip(axes).enumerate() {
            let v = Vector3::from(*src);
            let norm = v.norm();
            if !(norm.is_finite() && (norm - 1.0).abs() < 1e-6) {
                return Err(ConfigError(format!(
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
            return Err(ConfigError(
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
        // During the parts' warm-up the offset follows their bias transient with the shorter
        // time constant; after it, slowly enough that a drift-ramp fault still shows.
        let track = if self.blocks - learn <= u64::from(self.config.warmup_blocks) {
            self.config.warmup_track_blocks
        } else {
            self.config.track_blocks
        };
        if !(g.over || a.over) && track > 0 {
            let w = 1.0 / f64::from(track);
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
