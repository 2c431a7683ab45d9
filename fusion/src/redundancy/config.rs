//! Settings of the redundant-channel fault detection, isolation and exclusion.

use crate::ConfigError;

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
    /// Blocks after learning during which the channels are still warming up (the parts'
    /// warm-up time from their data sheet; 0 = none): the offset tracks with
    /// `warmup_track_blocks` instead of `track_blocks`, the tests stay on.
    pub warmup_blocks: u32,
    /// Time constant of the offset tracking during the warm-up, blocks. A first-order
    /// tracker of time constant `T` follows a bias transient `b·e^{−t/τ}` with a lag
    /// `b·T/(τ − T)` (T < τ): a tenth of the warm-up's τ leaves a ninth of the transient.
    pub warmup_track_blocks: u32,
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
            warmup_blocks: 0,
            warmup_track_blocks: 30,
            exclude: true,
        }
    }
}

impl FdiConfig {
    /// Check ranges.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(ConfigError(format!(
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
                return Err(ConfigError(format!(
                    "redundancy.{n} must be finite and ≥ 0, got {v}"
                )));
            }
        }
        if !(self.false_alarm_probability > 0.0 && self.false_alarm_probability < 0.5) {
            return Err(ConfigError(format!(
                "redundancy.false_alarm_probability must be in (0, 0.5), got {}",
                self.false_alarm_probability
            )));
        }
        if self.block_samples == 0 || self.persistence_blocks == 0 {
            return Err(ConfigError(
                "redundancy.block_samples and persistence_blocks must be ≥ 1".into(),
            ));
        }
        if self.warmup_blocks > 0 && self.warmup_track_blocks == 0 {
            return Err(ConfigError(
                "redundancy.warmup_track_blocks must be ≥ 1 when warmup_blocks is set".into(),
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
    /// Blocks after learning during which the channels warm up (0 = none): the offset
    /// tracks with `warmup_track_blocks` (see [`FdiConfig::warmup_blocks`]).
    pub warmup_blocks: u32,
    /// Time constant of the offset tracking during the warm-up, blocks.
    pub warmup_track_blocks: u32,
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
            warmup_blocks: f.warmup_blocks,
            warmup_track_blocks: f.warmup_track_blocks,
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
            warmup_blocks: self.warmup_blocks,
            warmup_track_blocks: self.warmup_track_blocks,
            exclude: self.exclude,
        }
    }

    /// Check ranges; the error names the key (`filter.redundancy.<key>`).
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad =
            |key: &str, what: &str| Err(ConfigError(format!("filter.redundancy.{key} {what}")));
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
        if self.warmup_blocks > 0 && self.warmup_track_blocks == 0 {
            return bad(
                "warmup_track_blocks",
                "must be >= 1 when warmup_blocks is set",
            );
        }
        Ok(())
    }
}
