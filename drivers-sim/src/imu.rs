//! IMU error model: constant bias + random walk + temperature term, scale factor, misalignment,
//! angle/velocity random walk, ADC quantisation. Applied to the true increments of
//! [`crate::truth::TruthGenerator`].
//!
//! Every random draw comes from the IMU's own stream ([`crate::sensor_rng`] with name `"imu"`)
//! in a fixed order per interval, whether or not a term is zero, so that the truth process can
//! re-derive the true biases by running the same model.

use crate::scenario::{ImuGrade, Scenario, TemperatureProfile};
use crate::truth::Increments;
use nalgebra::{Matrix3, Vector3};
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;

/// Standard gravity used to convert µg and g, m/s².
pub const G0_M_S2: f64 = 9.806_65;
const DEG_H_TO_RAD_S: f64 = std::f64::consts::PI / 180.0 / 3600.0;
const ARCSEC_TO_RAD: f64 = std::f64::consts::PI / 180.0 / 3600.0;

fn gauss3(rng: &mut ChaCha20Rng) -> Vector3<f64> {
    let x: f64 = rng.sample(StandardNormal);
    let y: f64 = rng.sample(StandardNormal);
    let z: f64 = rng.sample(StandardNormal);
    Vector3::new(x, y, z)
}

/// Small-angle misalignment matrix `I + δ` of one triad, 1-σ `sigma_rad` per off-diagonal.
///
/// How a calibration sheet defines it (the body frame is realised by the sensors themselves,
/// there is no other physical reference for it):
/// - [`MisalignmentKind::Symmetric`], the gyro triad: the body frame is the orthogonal frame
///   closest to the gyro axes (polar decomposition `I + δ = R·(I + S)` with `R = I`), so δ is
///   a symmetric non-orthogonality `S` (three parameters). A rigid rotation of the gyro triad
///   relative to "body" is not an error of the IMU: the navigator's body frame *is* the
///   gyro-realised frame, and an external sensor sees that rotation as its own mounting
///   offset (the star tracker's boresight κ, a filter state).
/// - [`MisalignmentKind::Full`], the accelerometer triad: six independent off-diagonals,
///   i.e. its own non-orthogonality plus its rotation relative to the gyro-defined body
///   frame, both real navigation errors.
///
/// Six normal draws are made in either case (fixed draw order of the IMU stream); the
/// symmetric term is `(n_ij + n_ji)/√2` so that every off-diagonal keeps σ `sigma_rad`.
fn misalignment(rng: &mut ChaCha20Rng, sigma_rad: f64, kind: MisalignmentKind) -> Matrix3<f64> {
    let mut m = Matrix3::identity();
    for (i, j) in [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)] {
        let n: f64 = rng.sample(StandardNormal);
        m[(i, j)] = sigma_rad * n;
    }
    if kind == MisalignmentKind::Symmetric {
        for (i, j) in [(0, 1), (0, 2), (1, 2)] {
            let s = (m[(i, j)] + m[(j, i)]) * std::f64::consts::FRAC_1_SQRT_2;
            m[(i, j)] = s;
            m[(j, i)] = s;
        }
    }
    m
}

/// Which parameters of a triad's misalignment are physical (see [`misalignment`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum MisalignmentKind {
    /// Symmetric non-orthogonality only: the triad defines the body frame (gyros).
    Symmetric,
    /// Non-orthogonality and rotation relative to the body frame (accelerometers).
    Full,
}

/// Per-axis 1-σ errors of one sensor type (gyro or accelerometer) of a grade, SI units:
/// rad/s or m/s² for biases, per √s for random walks and white noise, rad for misalignment.
#[derive(Debug, Clone, Copy, PartialEq)]
struct SensorSigmas {
    bias: f64,
    bias_rw_per_rt_s: f64,
    temp_coeff: f64,
    scale: f64,
    misalignment_rad: f64,
    white_per_rt_s: f64,
    /// ADC least significant bit of the rate output (0 = none).
    lsb: f64,
    /// Count of the integrated output, rad or m/s (0 = none).
    increment_lsb: f64,
}

/// The grade's gyro and accelerometer 1-σ values in SI units (one conversion for the triad
/// and the redundant channels). The LSB spans `2·full_scale / 2^bits`.
fn grade_sigmas(grade: &ImuGrade) -> (SensorSigmas, SensorSigmas) {
    let g = &grade.gyro;
    let a = &grade.accel;
    let lsb = |bits: u32, full_scale: f64| {
        if bits > 0 {
            2.0 * full_scale / 2f64.powi(bits as i32)
        } else {
            0.0
        }
    };
    let ug = 1e-6 * G0_M_S2;
    (
        SensorSigmas {
            bias: g.bias_deg_h * DEG_H_TO_RAD_S,
            bias_rw_per_rt_s: g.bias_rw_deg_h_per_rt_h * DEG_H_TO_RAD_S / 60.0,
            temp_coeff: g.temp_coeff_deg_h_per_c * DEG_H_TO_RAD_S,
            scale: g.scale_factor_ppm * 1e-6,
            misalignment_rad: g.misalignment_arcsec * ARCSEC_TO_RAD,
            white_per_rt_s: g.arw_deg_per_rt_h.to_radians() / 60.0,
            lsb: lsb(g.adc_bits, g.full_scale_deg_s.to_radians()),
            increment_lsb: g.delta_angle_lsb_rad,
        },
        SensorSigmas {
            bias: a.bias_ug * ug,
            bias_rw_per_rt_s: a.bias_rw_ug_per_rt_h * ug / 60.0,
            temp_coeff: a.temp_coeff_ug_per_c * ug,
            scale: a.scale_factor_ppm * 1e-6,
            misalignment_rad: a.misalignment_arcsec * ARCSEC_TO_RAD,
            white_per_rt_s: a.vrw_ug_per_rt_hz * ug,
            lsb: lsb(a.adc_bits, a.full_scale_g * G0_M_S2),
            increment_lsb: a.delta_velocity_lsb_m_s,
        },
    )
}

/// The constant errors drawn for one triad of the orthogonal IMU, SI units (what its
/// calibration sheet would list). The output is `(I + diag(scale))·(I + misalignment)·x +
/// bias(t)·dt + noise`, with `bias(t) = bias + random walk + temp_coeff_per_c·(T − T_ref)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TriadConstants {
    /// Turn-on bias, body, rad/s (gyros) or m/s² (accelerometers).
    pub bias: Vector3<f64>,
    /// Temperature coefficient of the bias per axis, (rad/s)/°C or (m/s²)/°C.
    pub temp_coeff_per_c: Vector3<f64>,
    /// Scale-factor error per axis (dimensionless).
    pub scale: Vector3<f64>,
    /// Misalignment δ (zero diagonal, rad): symmetric for the gyros (they define the body
    /// frame), six independent terms for the accelerometers.
    pub misalignment: Matrix3<f64>,
}

/// Errors of one triad (gyros or accelerometers), SI units.
#[derive(Debug, Clone)]
struct TriadErrors {
    /// Constant bias, rad/s or m/s².
    bias0: Vector3<f64>,
    /// Random-walk part of the bias (state), rad/s or m/s².
    bias_rw: Vector3<f64>,
    /// Random-walk intensity, (rad/s)/√s or (m/s²)/√s.
    bias_rw_per_rt_s: f64,
    /// Temperature coefficient per axis, (rad/s)/°C or (m/s²)/°C.
    temp_coeff: Vector3<f64>,
    /// Scale-factor error per axis (dimensionless).
    scale: Vector3<f64>,
    /// Misalignment `I + δ`.
    mis: Matrix3<f64>,
    /// White noise intensity: rad/√s (ARW) or (m/s)/√s (VRW).
    white_per_rt_s: f64,
    /// ADC least significant bit of the rate output (0 = none), rad/s or m/s².
    lsb: f64,
    /// Count of the integrated output (0 = none), rad or m/s.
    increment_lsb: f64,
    /// What the output's counts have not yet carried of the integrated increments, per axis,
    /// rad or m/s (within half a count).
    residual: Vector3<f64>,
}

impl TriadErrors {
    /// Draw the constants of a triad with the per-axis 1-σ values `s` (draw order: bias,
    /// temperature coefficient, scale factor, misalignment).
    fn draw(rng: &mut ChaCha20Rng, s: &SensorSigmas, mis_kind: MisalignmentKind) -> Self {
        let bias0 = s.bias * gauss3(rng);
        let temp_coeff = s.temp_coeff * gauss3(rng);
        let scale = s.scale * gauss3(rng);
        let mis = misalignment(rng, s.misalignment_rad, mis_kind);
        Self {
            bias0,
            bias_rw: Vector3::zeros(),
            bias_rw_per_rt_s: s.bias_rw_per_rt_s,
            temp_coeff,
            scale,
            mis,
            white_per_rt_s: s.white_per_rt_s,
            lsb: s.lsb,
            increment_lsb: s.increment_lsb,
            residual: Vector3::zeros(),
        }
    }

    fn constants(&self) -> TriadConstants {
        TriadConstants {
            bias: self.bias0,
            temp_coeff_per_c: self.temp_coeff,
            scale: self.scale,
            misalignment: self.mis - Matrix3::identity(),
        }
    }

    fn bias(&self, dtemp_c: f64) -> Vector3<f64> {
        self.bias0 + self.bias_rw + self.temp_coeff * dtemp_c
    }

    /// Corrupt the true increment `x` (rad or m/s) over `dt` with `bias` and white draw `w`,
    /// then digitise it: the rate ADC, then the output counts (whose remainder carries over).
    fn apply(
        &mut self,
        x: &Vector3<f64>,
        dt: f64,
        bias: &Vector3<f64>,
        w: &Vector3<f64>,
    ) -> Vector3<f64> {
        let scaled = (Matrix3::from_diagonal(&(Vector3::repeat(1.0) + self.scale)) * self.mis) * x;
        let y = scaled + bias * dt + w * (self.white_per_rt_s * dt.sqrt());
        Vector3::from_fn(|i, _| {
            digitise(
                y[i],
                dt,
                self.lsb,
                self.increment_lsb,
                &mut self.residual[i],
            )
        })
    }
}

/// The random part of one IMU interval (draws already made).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IntervalErrors {
    /// Gyro bias applied over the interval (incl. temperature term), body axes, rad/s.
    pub gyro_bias_rad_s: Vector3<f64>,
    /// Accelerometer bias applied over the interval, body axes, m/s².
    pub accel_bias_m_s2: Vector3<f64>,
    /// Unit-normal white-noise draws for the gyros.
    gyro_white: Vector3<f64>,
    /// Unit-normal white-noise draws for the accelerometers.
    accel_white: Vector3<f64>,
}

/// Temperature of the sensor block at `t_s` since the epoch, °C.
pub fn temperature_c(p: &TemperatureProfile, t_s: f64) -> f64 {
    p.initial_c + p.rate_c_per_h * t_s / 3600.0
}

/// The IMU error model with its random state.
#[derive(Debug, Clone)]
pub struct ImuErrorModel {
    rng: ChaCha20Rng,
    gyro: TriadErrors,
    accel: TriadErrors,
    temperature: TemperatureProfile,
    reference_temperature_c: f64,
    /// The world's actual unit (`[world.imu]`): scatter, g-sensitivity, warm-up.
    unit: Option<crate::world::imu_unit::ImuUnit>,
    /// When false, [`ImuErrorModel::corrupt`] returns the truth unchanged (tests).
    pub enabled: bool,
}

impl ImuErrorModel {
    /// Draw the constant errors of the scenario's IMU from its stream.
    pub fn new(scn: &Scenario) -> Self {
        let mut m = Self::from_grade(
            &scn.imu,
            scn.spec.imu.temperature,
            crate::sensor_rng(scn.spec.scenario.seed, "imu"),
        );
        if let Some(spec) = scn.spec.world.and_then(|w| w.imu()) {
            let mut rng = crate::sensor_rng(scn.spec.scenario.seed, "world_imu");
            let mut rng_size = crate::sensor_rng(scn.spec.scenario.seed, "world_imu_size_effect");
            m.set_unit(
                crate::world::imu_unit::ImuUnit::new(&spec, &mut rng)
                    .with_size_effect(&spec, &mut rng_size),
            );
        }
        m
    }

    /// Make this model the world's actual `unit`: its noise densities and bias instability
    /// scaled by the unit's factors, its g-sensitivity and warm-up added.
    pub fn set_unit(&mut self, unit: crate::world::imu_unit::ImuUnit) {
        self.gyro.white_per_rt_s *= unit.gyro_noise_factor;
        self.accel.white_per_rt_s *= unit.accel_noise_factor;
        self.gyro.bias_rw_per_rt_s *= unit.gyro_bias_rw_factor;
        self.accel.bias_rw_per_rt_s *= unit.accel_bias_rw_factor;
        self.unit = Some(unit);
    }

    /// Draw the constant errors of `grade` from `rng`.
    pub fn from_grade(
        grade: &ImuGrade,
        temperature: TemperatureProfile,
        mut rng: ChaCha20Rng,
    ) -> Self {
        let (g, a) = grade_sigmas(grade);
        let gyro = TriadErrors::draw(&mut rng, &g, MisalignmentKind::Symmetric);
        let accel = TriadErrors::draw(&mut rng, &a, MisalignmentKind::Full);
        Self {
            rng,
            gyro,
            accel,
            temperature,
            reference_temperature_c: grade.reference_temperature_c,
            unit: None,
            enabled: true,
        }
    }

    /// The world's actual unit, when `[world.imu]` is on.
    pub fn unit(&self) -> Option<&crate::world::imu_unit::ImuUnit> {
        self.unit.as_ref()
    }

    /// The constant errors drawn for the gyro triad.
    pub fn gyro_constants(&self) -> TriadConstants {
        self.gyro.constants()
    }

    /// The constant errors drawn for the accelerometer triad.
    pub fn accel_constants(&self) -> TriadConstants {
        self.accel.constants()
    }

    /// Make the draws of the interval `(t_end_s − dt_s, t_end_s]` and advance the bias random
    /// walk. Returns the biases applied over that interval.
    pub fn next_interval(&mut self, t_end_s: f64, dt_s: f64) -> IntervalErrors {
        let dtemp =
            temperature_c(&self.temperature, t_end_s - 0.5 * dt_s) - self.reference_temperature_c;
        let (gyro_warmup, accel_warmup) =
            self.unit.map_or((Vector3::zeros(), Vector3::zeros()), |u| {
                u.warmup(t_end_s - 0.5 * dt_s)
            });
        let e = IntervalErrors {
            gyro_bias_rad_s: self.gyro.bias(dtemp) + gyro_warmup,
            accel_bias_m_s2: self.accel.bias(dtemp) + accel_warmup,
            gyro_white: gauss3(&mut self.rng),
            accel_white: gauss3(&mut self.rng),
        };
        let sq = dt_s.sqrt();
        let gw = gauss3(&mut self.rng);
        let aw = gauss3(&mut self.rng);
        self.gyro.bias_rw += gw * (self.gyro.bias_rw_per_rt_s * sq);
        self.accel.bias_rw += aw * (self.accel.bias_rw_per_rt_s * sq);
        e
    }

    /// Measured (delta-angle rad, delta-velocity m/s) from the true increments.
    pub fn corrupt(
        &mut self,
        e: &IntervalErrors,
        inc: &Increments,
    ) -> (Vector3<f64>, Vector3<f64>) {
        if !self.enabled {
            return (inc.delta_angle_b_rad, inc.delta_velocity_b_m_s);
        }
        // g-sensitive drift: ∫G·f dt = G·Δv over the interval.
        let delta_angle = match &self.unit {
            Some(u) => inc.delta_angle_b_rad + u.gyro_g_sensitivity * inc.delta_velocity_b_m_s,
            None => inc.delta_angle_b_rad,
        };
        // Size effect: the accelerometers' residual offsets on the rotating body.
        let delta_velocity = match &self.unit {
            Some(u) => {
                inc.delta_velocity_b_m_s
                    + u.size_effect_dv_b_m_s(&inc.delta_rate_b_rad_s, &inc.rate_outer_b_rad2_s)
            }
            None => inc.delta_velocity_b_m_s,
        };
        (
            self.gyro
                .apply(&delta_angle, inc.dt_s, &e.gyro_bias_rad_s, &e.gyro_white),
            self.accel.apply(
                &delta_velocity,
                inc.dt_s,
                &e.accel_bias_m_s2,
                &e.accel_white,
            ),
        )
    }
}

/// Errors of one single-axis sensor (gyro or accelerometer) of a redundant channel, SI units.
#[derive(Debug, Clone, Copy)]
struct AxisErrors {
    bias0: f64,
    bias_rw: f64,
    bias_rw_per_rt_s: f64,
    temp_coeff: f64,
    scale: f64,
    /// True sensitive axis (nominal axis tilted by the misalignment), unit, body frame.
    true_axis: Vector3<f64>,
    white_per_rt_s: f64,
    lsb: f64,
    increment_lsb: f64,
    /// What the output's counts have not yet carried, rad or m/s.
    residual: f64,
}

impl AxisErrors {
    /// Draw one single-axis sensor on nominal unit `axis` with the per-axis 1-σ values `s`
    /// (draw order: bias, temperature coefficient, scale factor, then the tilt).
    fn draw(rng: &mut ChaCha20Rng, axis: &Vector3<f64>, s: &SensorSigmas) -> Self {
        let g = gauss3(rng);
        let tilt = gauss3(rng) * s.misalignment_rad;
        // Two misalignment angles about axes perpendicular to the sensitive axis.
        let tilt_perp = tilt - axis * axis.dot(&tilt);
        let true_axis = (axis + tilt_perp.cross(axis)).normalize();
        Self {
            bias0: s.bias * g.x,
            bias_rw: 0.0,
            bias_rw_per_rt_s: s.bias_rw_per_rt_s,
            temp_coeff: s.temp_coeff * g.y,
            scale: s.scale * g.z,
            true_axis,
            white_per_rt_s: s.white_per_rt_s,
            lsb: s.lsb,
            increment_lsb: s.increment_lsb,
            residual: 0.0,
        }
    }
}

/// Digitise one axis's analog increment `y` (rad or m/s) over `dt`: the rate ADC of step
/// `lsb` (rad/s or m/s², 0 = none), then the output's whole counts of `increment_lsb` (rad
/// or m/s, 0 = none), whose remainder `residual` carries into the next interval.
fn digitise(y: f64, dt: f64, lsb: f64, increment_lsb: f64, residual: &mut f64) -> f64 {
    let y = if lsb > 0.0 {
        (y / dt / lsb).round() * lsb * dt
    } else {
        y
    };
    if increment_lsb > 0.0 {
        let v = y + *residual;
        let counted = (v / increment_lsb).round() * increment_lsb;
        *residual = v - counted;
        counted
    } else {
        y
    }
}

/// 1-σ of one interval's output error from white noise `white_per_rt_s` and an ADC step
/// `lsb` (uniform quantisation error, variance LSB²/12) over `dt_s`.
fn interval_sigma(white_per_rt_s: f64, lsb: f64, dt_s: f64) -> f64 {
    let w = white_per_rt_s * dt_s.sqrt();
    let q = lsb * dt_s / 12f64.sqrt();
    (w * w + q * q).sqrt()
}

/// One redundant channel's share of its actual unit (`[world.imu]`), SI units.
#[derive(Debug, Clone, Copy)]
struct ChannelUnit {
    /// Gyro g-sensitivity along the channel's axis, (rad/s) per (m/s²), body frame.
    gyro_g_sensitivity: Vector3<f64>,
    /// Gyro warm-up bias at power-on, rad/s.
    gyro_warmup_rad_s: f64,
    /// Accelerometer warm-up bias at power-on, m/s².
    accel_warmup_m_s2: f64,
    /// Warm-up time constant, s.
    warmup_tau_s: f64,
}

impl ChannelUnit {
    /// At `t_s` after power-on, over an interval with body velocity increment `dv_b_m_s`:
    /// gyro warm-up bias (rad/s), accelerometer warm-up bias (m/s²) and the g-sensitive
    /// drift's delta-angle `∫gᵀf dt = gᵀΔv` (rad).
    fn errors(&self, t_s: f64, dv_b_m_s: &Vector3<f64>) -> (f64, f64, f64) {
        let d = (-t_s.max(0.0) / self.warmup_tau_s).exp();
        (
            self.gyro_warmup_rad_s * d,
            self.accel_warmup_m_s2 * d,
            self.gyro_g_sensitivity.dot(dv_b_m_s),
        )
    }
}

/// Per-interval outputs of the redundant channels.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ChannelOutputs {
    /// Number of channels.
    pub n: usize,
    /// Gyro delta-angles, rad.
    pub delta_angle_rad: [f64; msgs::MAX_IMU_CHANNELS],
    /// Accelerometer delta-velocities, m/s.
    pub delta_velocity_m_s: [f64; msgs::MAX_IMU_CHANNELS],
    /// Channel temperatures, °C.
    pub temperature_c: [f64; msgs::MAX_IMU_CHANNELS],
    /// Bias applied to each gyro channel over the interval (incl. temperature and failures
    /// of bias type), rad/s.
    pub gyro_bias_rad_s: [f64; msgs::MAX_IMU_CHANNELS],
    /// Bias applied to each accelerometer channel, m/s².
    pub accel_bias_m_s2: [f64; msgs::MAX_IMU_CHANNELS],
}

/// Error model of N redundant single-axis gyro + accelerometer channels (paper 004).
///
/// Each channel's gyro and accelerometer get the grade's per-axis 1-σ values, drawn
/// independently: constant bias, bias random walk, temperature coefficient (bias changes by
/// `coeff · (T − T_ref)`, T the channel temperature), scale factor, axis misalignment (the
/// true sensitive axis is the nominal one tilted by two angles of σ `misalignment_arcsec`),
/// white noise (ARW/VRW) and 12-bit (grade `adc_bits`) quantisation of the rate output over
/// ±`full_scale` (mems grade: ±150 °/s, LSB 0.073 °/s; ±4 g, LSB 1.95 mg). Failures from the
/// scenario are applied after quantisation (a stuck channel repeats its last healthy output).
///
/// Draws come from the stream `"imu_channels"`, so the orthogonal triad's stream `"imu"` and
/// every default run are unchanged.
///
/// With `[world.imu]` each channel is an actual unit, not its data sheet
/// ([`ChannelErrorModel::set_units`]): every single-axis sensor is a separate part, so each
/// channel draws its own unit (stream `"world_imu_channels"`).
#[derive(Debug, Clone)]
pub struct ChannelErrorModel {
    rng: ChaCha20Rng,
    axes: Vec<[f64; 3]>,
    gyro: Vec<AxisErrors>,
    accel: Vec<AxisErrors>,
    /// The grade's per-axis values, as the data sheet states them.
    data_sheet: (SensorSigmas, SensorSigmas),
    /// Per channel, the world's actual unit (empty without `[world.imu]`).
    units: Vec<ChannelUnit>,
    temperature: TemperatureProfile,
    temperature_offsets_c: Vec<f64>,
    reference_temperature_c: f64,
    failures: Vec<crate::scenario::ChannelFailure>,
    last_healthy: ChannelOutputs,
    /// When false, outputs are the exact projections of the truth (tests).
    pub enabled: bool,
}

impl ChannelErrorModel {
    /// The channels of the scenario, or None if `[imu.channels]` is absent; with
    /// `[world.imu]`, each channel its own actual unit.
    pub fn new(scn: &Scenario) -> Option<Self> {
        let ch = scn.spec.imu.channels.as_ref()?;
        let mut m = Self::from_grade(
            &ch.unit_axes(),
            &scn.imu,
            scn.spec.imu.temperature,
            &ch.temperature_offsets_c,
            &ch.failures,
            crate::sensor_rng(scn.spec.scenario.seed, "imu_channels"),
        );
        m.set_world_units(scn, scn.spec.scenario.seed);
        Some(m)
    }

    /// When `scn` has `[world.imu]`, make every channel an actual unit drawn for `seed`
    /// ([`ChannelErrorModel::set_units`] from the stream `"world_imu_channels"`).
    pub fn set_world_units(&mut self, scn: &Scenario, seed: u64) {
        if let Some(spec) = scn.spec.world.and_then(|w| w.imu()) {
            self.set_units(&spec, crate::sensor_rng(seed, "world_imu_channels"));
        }
    }

    /// Make each channel an actual unit of `spec`, drawn in channel order from `rng`: its
    /// gyro's and accelerometer's noise densities and bias random walks scaled by the unit's
    /// factors, the gyro's g-sensitivity `e_iᵀ·G` (the unit's matrix seen along the channel's
    /// nominal axis `e_i`, so each element keeps its 1-σ) and both warm-up transients
    /// projected on `e_i`.
    pub fn set_units(&mut self, spec: &crate::world::imu_unit::ImuUnitSpec, mut rng: ChaCha20Rng) {
        self.units.clear();
        for (i, ax) in self.axes.iter().enumerate() {
            let u = crate::world::imu_unit::ImuUnit::new(spec, &mut rng);
            let e = Vector3::from(*ax);
            self.gyro[i].white_per_rt_s *= u.gyro_noise_factor;
            self.accel[i].white_per_rt_s *= u.accel_noise_factor;
            self.gyro[i].bias_rw_per_rt_s *= u.gyro_bias_rw_factor;
            self.accel[i].bias_rw_per_rt_s *= u.accel_bias_rw_factor;
            self.units.push(ChannelUnit {
                gyro_g_sensitivity: u.gyro_g_sensitivity.transpose() * e,
                gyro_warmup_rad_s: e.dot(&u.gyro_warmup_rad_s),
                accel_warmup_m_s2: e.dot(&u.accel_warmup_m_s2),
                warmup_tau_s: u.warmup_tau_s,
            });
        }
    }

    /// Channels on unit `axes` with the per-axis errors of `grade`, drawn from `rng`.
    pub fn from_grade(
        axes: &[[f64; 3]],
        grade: &ImuGrade,
        temperature: TemperatureProfile,
        temperature_offsets_c: &[f64],
        failures: &[crate::scenario::ChannelFailure],
        mut rng: ChaCha20Rng,
    ) -> Self {
        let (g, a) = grade_sigmas(grade);
        let mut gyro = Vec::with_capacity(axes.len());
        let mut accel = Vec::with_capacity(axes.len());
        for ax in axes {
            let e = Vector3::from(*ax);
            gyro.push(AxisErrors::draw(&mut rng, &e, &g));
            accel.push(AxisErrors::draw(&mut rng, &e, &a));
        }
        Self {
            rng,
            axes: axes.to_vec(),
            gyro,
            accel,
            data_sheet: (g, a),
            units: Vec::new(),
            temperature,
            temperature_offsets_c: temperature_offsets_c.to_vec(),
            reference_temperature_c: grade.reference_temperature_c,
            failures: failures.to_vec(),
            last_healthy: ChannelOutputs::default(),
            enabled: true,
        }
    }

    /// Nominal unit axes, body frame.
    pub fn axes(&self) -> &[[f64; 3]] {
        &self.axes
    }

    /// 1-σ white noise of one gyro channel's delta-angle over `dt_s` (ARW and quantisation),
    /// rad, and of one accelerometer channel's delta-velocity, m/s, as the data sheet states
    /// them: what a user configuring the FDI knows. The quantisation error is taken as
    /// uniform over one LSB (variance LSB²/12), which holds when the noise dithers.
    pub fn interval_sigmas(&self, dt_s: f64) -> (f64, f64) {
        let (g, a) = &self.data_sheet;
        (
            interval_sigma(g.white_per_rt_s, g.lsb, dt_s),
            interval_sigma(a.white_per_rt_s, a.lsb, dt_s),
        )
    }

    /// The same as [`ChannelErrorModel::interval_sigmas`] for channel `i` as the world made
    /// it (its unit's noise densities; the data sheet's without `[world.imu]`), or None when
    /// there is no channel `i`. Truth: for tests and analysis, never for configuring a filter.
    pub fn actual_interval_sigmas(&self, i: usize, dt_s: f64) -> Option<(f64, f64)> {
        let (g, a) = (self.gyro.get(i)?, self.accel.get(i)?);
        Some((
            interval_sigma(g.white_per_rt_s, g.lsb, dt_s),
            interval_sigma(a.white_per_rt_s, a.lsb, dt_s),
        ))
    }

    /// Channel outputs of the interval `(t_end_s − dt, t_end_s]` with true body increments
    /// `inc`. Draw order per interval: for each channel, gyro white, accel white, gyro bias
    /// walk, accel bias walk (always drawn, so the stream does not depend on the failures),
    /// then one draw per active noise-burst failure.
    pub fn sample(&mut self, t_end_s: f64, inc: &Increments) -> ChannelOutputs {
        let dt = inc.dt_s;
        let t_mid = t_end_s - 0.5 * dt;
        let block_t = temperature_c(&self.temperature, t_mid);
        let n = self.axes.len();
        let mut out = ChannelOutputs {
            n,
            ..Default::default()
        };
        let sq = dt.sqrt();
        for i in 0..n {
            let temp = block_t + self.temperature_offsets_c.get(i).copied().unwrap_or(0.0);
            let dtemp = temp - self.reference_temperature_c;
            out.temperature_c[i] = temp;
            let wg: f64 = self.rng.sample(StandardNormal);
            let wa: f64 = self.rng.sample(StandardNormal);
            let rg: f64 = self.rng.sample(StandardNormal);
            let ra: f64 = self.rng.sample(StandardNormal);
            let (g, a) = (&mut self.gyro[i], &mut self.accel[i]);
            if !self.enabled {
                let e = Vector3::from(self.axes[i]);
                out.delta_angle_rad[i] = e.dot(&inc.delta_angle_b_rad);
                out.delta_velocity_m_s[i] = e.dot(&inc.delta_velocity_b_m_s);
                continue;
            }
            let (warm_g, warm_a, g_sens) = self.units.get(i).map_or((0.0, 0.0, 0.0), |u| {
                u.errors(t_mid, &inc.delta_velocity_b_m_s)
            });
            let gb = g.bias0 + g.bias_rw + g.temp_coeff * dtemp + warm_g;
            let ab = a.bias0 + a.bias_rw + a.temp_coeff * dtemp + warm_a;
            out.gyro_bias_rad_s[i] = gb;
            out.accel_bias_m_s2[i] = ab;
            let yg = (1.0 + g.scale) * g.true_axis.dot(&inc.delta_angle_b_rad)
                + g_sens
                + gb * dt
                + g.white_per_rt_s * sq * wg;
            let ya = (1.0 + a.scale) * a.true_axis.dot(&inc.delta_velocity_b_m_s)
                + ab * dt
                + a.white_per_rt_s * sq * wa;
            out.delta_angle_rad[i] = digitise(yg, dt, g.lsb, g.increment_lsb, &mut g.residual);
            out.delta_velocity_m_s[i] = digitise(ya, dt, a.lsb, a.increment_lsb, &mut a.residual);
            g.bias_rw += g.bias_rw_per_rt_s * sq * rg;
            a.bias_rw += a.bias_rw_per_rt_s * sq * ra;
        }
        let ug = 1e-6 * G0_M_S2;
        let mut healthy = out;
        for f in &self.failures {
            if f.channel >= n || !f.active(t_mid) {
                continue;
            }
            use crate::scenario::{FailedSensor, FailureKind};
            let unit = match f.sensor {
                FailedSensor::Gyro => DEG_H_TO_RAD_S,
                FailedSensor::Accel => ug,
            };
            let add = match f.kind {
                FailureKind::Stuck => None,
                FailureKind::BiasStep => Some(f.magnitude * unit * dt),
                FailureKind::DriftRamp => Some(f.magnitude * unit * (t_mid - f.start_s) * dt),
                FailureKind::NoiseBurst => {
                    let w: f64 = self.rng.sample(StandardNormal);
                    Some(f.magnitude * unit * dt * w)
                }
            };
            let (val, last, bias) = match f.sensor {
                FailedSensor::Gyro => (
                    &mut out.delta_angle_rad[f.channel],
                    self.last_healthy.delta_angle_rad[f.channel],
                    &mut out.gyro_bias_rad_s[f.channel],
                ),
                FailedSensor::Accel => (
                    &mut out.delta_velocity_m_s[f.channel],
                    self.last_healthy.delta_velocity_m_s[f.channel],
                    &mut out.accel_bias_m_s2[f.channel],
                ),
            };
            match add {
                None => {
                    *val = last;
                    // Keep repeating the frozen value.
                    match f.sensor {
                        FailedSensor::Gyro => healthy.delta_angle_rad[f.channel] = last,
                        FailedSensor::Accel => healthy.delta_velocity_m_s[f.channel] = last,
                    }
                }
                Some(d) => {
                    *val += d;
                    if f.kind != FailureKind::NoiseBurst {
                        *bias += d / dt;
                    }
                }
            }
        }
        self.last_healthy = healthy;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::imu_unit::{ImuUnit, ImuUnitSpec};
    use std::path::Path;

    fn uav() -> Scenario {
        let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/scenarios/uav.toml");
        Scenario::load(&p).unwrap_or_else(|e| panic!("{e}"))
    }

    /// `[world.imu]` on the redundant channels: each channel is its own part. Against the
    /// data sheet's model of the same seed (same `"imu_channels"` draws), the world's differs
    /// by exactly each channel's unit, re-drawn here from `"world_imu_channels"`: noise
    /// densities and bias random walks scaled by its factors; at power-on, over an interval
    /// with specific force, its gyro output offset by `e_iᵀ·G·Δv + e_iᵀ·b_w·dt` and its
    /// accelerometer's by `e_iᵀ·a_w·dt`. The σ a user configures the FDI with stays the data
    /// sheet's.
    #[test]
    fn redundant_channels_are_each_their_own_unit() {
        let scn = uav();
        let spec = scn
            .spec
            .world
            .and_then(|w| w.imu())
            .expect("uav's [world.imu]");
        let seed = scn.spec.scenario.seed;
        let mut world = ChannelErrorModel::new(&scn).expect("channels");
        let mut sheet = ChannelErrorModel::new(&crate::matched::scenario(scn.clone())).unwrap();
        let n = world.axes().len();
        let mut rng = crate::sensor_rng(seed, "world_imu_channels");
        let units: Vec<ImuUnit> = (0..n).map(|_| ImuUnit::new(&spec, &mut rng)).collect();
        for (i, u) in units.iter().enumerate() {
            let (w, s) = (&world.gyro[i], &sheet.gyro[i]);
            assert_eq!(w.white_per_rt_s, s.white_per_rt_s * u.gyro_noise_factor);
            assert_eq!(
                w.bias_rw_per_rt_s,
                s.bias_rw_per_rt_s * u.gyro_bias_rw_factor
            );
            let (w, s) = (&world.accel[i], &sheet.accel[i]);
            assert_eq!(w.white_per_rt_s, s.white_per_rt_s * u.accel_noise_factor);
            assert_eq!(
                w.bias_rw_per_rt_s,
                s.bias_rw_per_rt_s * u.accel_bias_rw_factor
            );
            assert_ne!(
                world.actual_interval_sigmas(i, 0.01),
                sheet.actual_interval_sigmas(i, 0.01)
            );
        }
        assert_eq!(world.interval_sigmas(0.01), sheet.interval_sigmas(0.01));

        // The deterministic terms, without noise and quantisation: 1.5 g along a tilted
        // direction for one 10 ms interval at power-on.
        for m in [&mut world, &mut sheet] {
            for e in m.gyro.iter_mut().chain(m.accel.iter_mut()) {
                e.white_per_rt_s = 0.0;
                e.lsb = 0.0;
                e.increment_lsb = 0.0;
            }
        }
        let dt = 0.01;
        let inc = Increments {
            dt_s: dt,
            delta_angle_b_rad: Vector3::new(1e-4, -2e-4, 3e-4),
            delta_velocity_b_m_s: Vector3::new(3.0, -4.0, -12.0).normalize() * 1.5 * G0_M_S2 * dt,
            distance_x_m: 0.0,
            odometer_distance_m: 0.0,
            ..Default::default()
        };
        let (w, s) = (world.sample(dt, &inc), sheet.sample(dt, &inc));
        for (i, u) in units.iter().enumerate() {
            let e = Vector3::from(world.axes()[i]);
            let (gw, aw) = u.warmup(0.5 * dt);
            let want_g =
                e.dot(&(u.gyro_g_sensitivity * inc.delta_velocity_b_m_s)) + e.dot(&gw) * dt;
            let got_g = w.delta_angle_rad[i] - s.delta_angle_rad[i];
            assert!(
                (got_g - want_g).abs() < 1e-18,
                "gyro {i}: {got_g} vs {want_g}"
            );
            assert!(
                want_g.abs() > 1e-9,
                "gyro {i}: the unit's terms are visible"
            );
            let got_a = w.delta_velocity_m_s[i] - s.delta_velocity_m_s[i];
            assert!((got_a - e.dot(&aw) * dt).abs() < 1e-15, "accel {i}");
            assert!((w.gyro_bias_rad_s[i] - s.gyro_bias_rad_s[i] - e.dot(&gw)).abs() < 1e-20);
        }
    }

    /// A unit axis sees each element of the unit's g-sensitivity matrix, and each warm-up
    /// axis, with its 1-σ: over 4000 single-channel parts on e = (0.6, 0, 0.8), E[g_x²] = σ_G²
    /// and E[b_w²] = σ_w² within 4 standard errors.
    #[test]
    fn channel_projection_keeps_the_unit_sigmas() {
        let scn = uav();
        let spec = ImuUnitSpec {
            warmup_tau_s: 1e9,
            ..scn.spec.world.and_then(|w| w.imu()).unwrap()
        };
        let deg_h_per_g = DEG_H_TO_RAD_S / G0_M_S2;
        let (mut g2, mut w2) = (Vec::new(), Vec::new());
        for seed in 0..4000u64 {
            let mut m = ChannelErrorModel::from_grade(
                &[[0.6, 0.0, 0.8]],
                &scn.imu,
                scn.spec.imu.temperature,
                &[],
                &[],
                crate::sensor_rng(seed, "imu_channels"),
            );
            m.set_units(&spec, crate::sensor_rng(seed, "world_imu_channels"));
            g2.push(m.units[0].gyro_g_sensitivity.x.powi(2));
            w2.push(m.units[0].gyro_warmup_rad_s.powi(2));
        }
        let checks = [
            (g2, spec.gyro_g_sensitivity_deg_h_per_g * deg_h_per_g),
            (w2, spec.gyro_warmup_deg_h * DEG_H_TO_RAD_S),
        ];
        for (sq, sigma) in checks {
            let (v, se) = crate::world::gauss_markov::mean_and_standard_error(&sq);
            assert!(
                (v - sigma * sigma).abs() < 4.0 * se,
                "{v} vs {}",
                sigma * sigma
            );
        }
    }
}
