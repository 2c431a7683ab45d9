//! Star tracker, odometer and barometer error models.

use crate::scenario::{BaroGrade, Scenario, StarTrackerGrade, Window};
use crate::truth::{Increments, TruthPoint};
use fusion::celestial::EarthOrientation;
use fusion::time::GpsTime;
use msgs::{BaroSample, OdometerSample, StarTrackerSample};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha20Rng;
use rand_distr::StandardNormal;

const ARCSEC_TO_RAD: f64 = std::f64::consts::PI / 180.0 / 3600.0;

/// Header status bit of a star-tracker sample in an outage.
pub const STAR_STATUS_OUTAGE: u32 = 1;

/// Nominal star-tracker mounting (docs/ARCHITECTURE.md, frames and conventions): sensor from body by 180° about body x,
/// `v_s = C_s_b · v_b`.
pub fn c_s_b_nominal() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0))
}

/// Paper 000 misalignment `M = R_z(κ1)·R_x(κ2)·R_y(κ3)` (κ in rad).
pub fn kappa_matrix(kappa_rad: &[f64; 3]) -> Matrix3<f64> {
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), kappa_rad[0]);
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), kappa_rad[1]);
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), kappa_rad[2]);
    (rz * rx * ry).into_inner()
}

/// Star-tracker simulator.
#[derive(Debug, Clone)]
pub struct StarTrackerSim {
    grade: StarTrackerGrade,
    outages: Vec<Window>,
    eop: EarthOrientation,
    /// True mounting, `v_s = c_s_b · v_b`.
    pub c_s_b: Matrix3<f64>,
    rng: ChaCha20Rng,
    /// Thermal error and boresight bias of `[world.star_tracker]`.
    world: Option<crate::world::aiding::StarTrackerWorld>,
    /// This unit's white noise over the data sheet's, cross and roll (`[world.units]`).
    noise_factors: [f64; 2],
}

impl StarTrackerSim {
    /// The star tracker of the scenario (stream `"star_tracker"`).
    pub fn new(scn: &Scenario) -> Self {
        let unit = scn.aiding_unit("star_tracker");
        let k = scn.spec.star_tracker.mounting_kappa_deg;
        let kappa = [k[0].to_radians(), k[1].to_radians(), k[2].to_radians()];
        Self {
            grade: scn.star_tracker,
            outages: scn.spec.star_tracker.outages.clone(),
            eop: scn.spec.earth_orientation,
            c_s_b: c_s_b_nominal() * kappa_matrix(&kappa),
            rng: crate::sensor_rng(scn.spec.scenario.seed, "star_tracker"),
            world: scn.spec.world.and_then(|w| w.star_tracker()).map(|s| {
                crate::world::aiding::StarTrackerWorld::new(
                    &s,
                    crate::sensor_rng(scn.spec.scenario.seed, "world_star"),
                )
            }),
            noise_factors: [unit.noise_factors[0], unit.noise_factors[1]],
        }
    }

    /// True DCM ICRF → sensor at GPS time `t_gps_ns` for the truth point:
    /// `C_s_i = C_s_b · C_b_n · C_n_e · C_e_i(t)`.
    pub fn c_s_i_true(&self, t_gps_ns: i64, truth: &TruthPoint) -> Matrix3<f64> {
        let c_e_i = fusion::celestial::c_e_i(GpsTime { ns: t_gps_ns }, &self.eop);
        self.c_s_b * truth.c_n_b.transpose() * truth.c_e_n.transpose() * c_e_i
    }

    /// Sample at `t_s` since the epoch (GPS `t_gps_ns`). The sample reports the data sheet's
    /// σ, as a star tracker does; its error has this unit's.
    pub fn sample(&mut self, t_s: f64, t_gps_ns: i64, truth: &TruthPoint) -> StarTrackerSample {
        let g = self.grade;
        let sc = g.sigma_cross_arcsec * ARCSEC_TO_RAD;
        let sr = g.sigma_roll_arcsec * ARCSEC_TO_RAD;
        let (uc, ur) = (sc * self.noise_factors[0], sr * self.noise_factors[1]);
        let n: [f64; 3] = [
            self.rng.sample(StandardNormal),
            self.rng.sample(StandardNormal),
            self.rng.sample(StandardNormal),
        ];
        let stars = self.rng.random_range(g.min_stars..=g.max_stars);
        let mut out = StarTrackerSample {
            sigma_cross_rad: sc,
            sigma_roll_rad: sr,
            ..Default::default()
        };
        out.header.time_ns = t_gps_ns;
        let world_err = self.world.as_mut().map(|w| w.error_s_rad(t_s));
        if self.outages.iter().any(|w| w.contains(t_s)) {
            out.header.status = STAR_STATUS_OUTAGE;
            out.q_sensor_icrf = [1.0, 0.0, 0.0, 0.0];
            return out;
        }
        let c = self.c_s_i_true(t_gps_ns, truth);
        let q_true = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(c));
        // Attitude error: a small rotation about the sensor axes (z = optical axis).
        let err = UnitQuaternion::from_scaled_axis(Vector3::new(uc * n[0], uc * n[1], ur * n[2]));
        let mut q = match world_err {
            Some(e) => err * UnitQuaternion::from_scaled_axis(Vector3::from(e)) * q_true,
            None => err * q_true,
        };
        if q.w < 0.0 {
            q = UnitQuaternion::new_unchecked(-q.into_inner());
        }
        out.q_sensor_icrf = fusion::attitude::quat_to_wire(&q);
        out.n_stars = stars;
        out.valid = 1;
        out
    }
}

/// Odometer simulator: the wheel's rolling distance (body x, or the world's wheel) with a
/// scale-factor error and white speed noise.
#[derive(Debug, Clone)]
pub struct OdometerSim {
    /// This unit's scale-factor error, ppm: the data sheet's value, or with `[world.units]`
    /// a draw with it as 1-σ.
    scale_factor_error_ppm: f64,
    /// This unit's white speed noise, m/s.
    speed_noise_m_s: f64,
    rng: ChaCha20Rng,
}

impl OdometerSim {
    /// The odometer of the scenario (stream `"odometer"`).
    pub fn new(scn: &Scenario) -> Self {
        let u = scn.aiding_unit("odometer");
        Self {
            scale_factor_error_ppm: scn.odometer.scale_factor_error_ppm * u.constant_normals[0],
            speed_noise_m_s: scn.odometer.speed_noise_m_s * u.noise_factors[0],
            rng: crate::sensor_rng(scn.spec.scenario.seed, "odometer"),
        }
    }

    /// This unit's scale-factor error, ppm.
    pub fn scale_factor_error_ppm(&self) -> f64 {
        self.scale_factor_error_ppm
    }

    /// Sample for the interval integrals `inc` ending at GPS `t_gps_ns`.
    pub fn sample(&mut self, t_gps_ns: i64, inc: &Increments) -> OdometerSample {
        let n: f64 = self.rng.sample(StandardNormal);
        let dist = (1.0 + self.scale_factor_error_ppm * 1e-6) * inc.odometer_distance_m
            + self.speed_noise_m_s * n * inc.dt_s;
        let mut out = OdometerSample {
            dt_s: inc.dt_s,
            distance_m: dist,
            speed_m_s: if inc.dt_s > 0.0 { dist / inc.dt_s } else { 0.0 },
            ..Default::default()
        };
        out.header.time_ns = t_gps_ns;
        out
    }
}

/// Barometer simulator: ISA pressure at the ellipsoidal height plus bias (+ random walk) and
/// white noise.
#[derive(Debug, Clone)]
pub struct BaroSim {
    grade: BaroGrade,
    /// This unit's constant bias, Pa: the data sheet's value, or with `[world.units]` a draw
    /// with it as 1-σ.
    bias_pa: f64,
    /// This unit's white noise, Pa.
    noise_pa: f64,
    bias_rw_pa: f64,
    last_t_s: Option<f64>,
    rng: ChaCha20Rng,
    /// The air of `[world.baro]` and the sensor bay's temperature profile.
    world: Option<(
        crate::world::aiding::BaroWorld,
        crate::scenario::TemperatureProfile,
    )>,
}

impl BaroSim {
    /// The barometer of the scenario (stream `"baro"`).
    pub fn new(scn: &Scenario) -> Self {
        let u = scn.aiding_unit("baro");
        Self {
            grade: scn.baro,
            bias_pa: scn.baro.bias_pa * u.constant_normals[0],
            noise_pa: scn.baro.noise_pa * u.noise_factors[0],
            bias_rw_pa: 0.0,
            last_t_s: None,
            rng: crate::sensor_rng(scn.spec.scenario.seed, "baro"),
            world: scn.spec.world.and_then(|w| w.baro()).map(|s| {
                let mut rng = crate::sensor_rng(scn.spec.scenario.seed, "world_baro");
                (
                    crate::world::aiding::BaroWorld::new(&s, &mut rng),
                    scn.spec.imu.temperature,
                )
            }),
        }
    }

    /// Sample at `t_s` since the epoch (GPS `t_gps_ns`).
    pub fn sample(&mut self, t_s: f64, t_gps_ns: i64, truth: &TruthPoint) -> BaroSample {
        let n: f64 = self.rng.sample(StandardNormal);
        let w: f64 = self.rng.sample(StandardNormal);
        if let Some(prev) = self.last_t_s {
            self.bias_rw_pa += self.grade.bias_rw_pa_per_rt_s * (t_s - prev).max(0.0).sqrt() * w;
        }
        self.last_t_s = Some(t_s);
        let h = truth.geodetic.height_m;
        let (air_pa, air_k) = match &self.world {
            Some((w, bay)) => {
                let (p, t) = w.air(h, t_s);
                (
                    p + w.sensor_error_pa(crate::imu::temperature_c(bay, t_s)),
                    t,
                )
            }
            None => (
                fusion::atmosphere::isa_pressure_pa(h),
                fusion::atmosphere::isa_temperature_k(h),
            ),
        };
        let mut out = BaroSample {
            pressure_pa: air_pa + self.bias_pa + self.bias_rw_pa + self.noise_pa * n,
            temperature_c: air_k - 273.15,
            ..Default::default()
        };
        out.header.time_ns = t_gps_ns;
        out
    }
}
