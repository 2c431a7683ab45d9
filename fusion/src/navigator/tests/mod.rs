//! Navigator tests on a synthetic static site ([`StaticSim`]).

use super::*;
use crate::strapdown::stationary_increment;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const T0: i64 = 1_400_000_000_000_000_000;

/// Synthetic static site: IMU increments from fusion::earth plus bias and white noise at
/// the configured navigation-grade densities, GNSS fixes with white noise.
pub struct StaticSim {
    ell: Ellipsoid,
    r_e: Vector3<f64>,
    q_e_b: UnitQuaternion<f64>,
    b_g: Vector3<f64>,
    b_a: Vector3<f64>,
    dt: f64,
    k: i64,
    rng: ChaCha8Rng,
    n_g: Normal<f64>,
    n_a: Normal<f64>,
    gnss_sigma: f64,
    imu_seq: u64,
    gnss_seq: u64,
    /// Mount vibration: (amplitude m/s², frequency Hz) of a harmonic per body axis, as the
    /// velocity increment of a displacement about a fixed point (zero mean velocity).
    pub vibration: [(f64, f64); 3],
}

impl StaticSim {
    pub fn new(seed: u64, rate_hz: f64) -> Self {
        let ell = WGS84;
        let g = Geodetic {
            lat_rad: 55.655 * DEG,
            lon_rad: 37.534 * DEG,
            height_m: 180.0,
        };
        let q_n_b = crate::attitude::q_n_b_from_rpy(0.01, -0.02, 0.7);
        let dt = 1.0 / rate_hz;
        let spec = ImuSpec::default();
        let pn = spec.process_noise();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let unit = Normal::new(0.0, 1.0).unwrap();
        let mut rv = |s: f64| {
            Vector3::new(
                unit.sample(&mut rng) * s,
                unit.sample(&mut rng) * s,
                unit.sample(&mut rng) * s,
            )
        };
        let b_g = rv(spec.gyro_bias_rad_s());
        let b_a = rv(spec.accel_bias_m_s2());
        Self {
            r_e: earth::geodetic_to_ecef(&ell, &g),
            q_e_b: q_e_n(g.lat_rad, g.lon_rad) * q_n_b,
            ell,
            b_g,
            b_a,
            dt,
            k: 0,
            rng,
            n_g: Normal::new(0.0, pn.arw_rad_sqrt_s * dt.sqrt()).unwrap(),
            n_a: Normal::new(0.0, pn.vrw_m_s_sqrt_s * dt.sqrt()).unwrap(),
            gnss_sigma: 2.0,
            imu_seq: 0,
            gnss_seq: 0,
            vibration: [(0.0, 0.0); 3],
        }
    }
    fn time_ns(&self) -> i64 {
        T0 + (self.k as f64 * self.dt * 1e9).round() as i64
    }
    pub fn next_imu(&mut self) -> ImuSample {
        self.k += 1;
        self.imu_seq += 1;
        let inc =
            stationary_increment(&self.ell, GravityModel::J2, &self.r_e, &self.q_e_b, self.dt);
        let mut s = ImuSample::default();
        s.header.time_ns = self.time_ns();
        s.header.seq = self.imu_seq;
        s.header.send_mono_ns = 42 + self.k as u64;
        s.dt_s = self.dt;
        let t = self.k as f64 * self.dt;
        for i in 0..3 {
            // Velocity of the vibration (A/ω)·sin(ωt): its increment over the interval.
            let (amp, hz) = self.vibration[i];
            let w = 2.0 * std::f64::consts::PI * hz;
            let v = |t: f64| {
                if hz > 0.0 {
                    amp / w * (w * t).sin()
                } else {
                    0.0
                }
            };
            s.delta_angle_rad[i] =
                inc.delta_angle_rad[i] + self.b_g[i] * self.dt + self.n_g.sample(&mut self.rng);
            s.delta_velocity_m_s[i] = inc.delta_velocity_m_s[i]
                + self.b_a[i] * self.dt
                + self.n_a.sample(&mut self.rng)
                + v(t)
                - v(t - self.dt);
        }
        s
    }
    pub fn gnss(&mut self) -> GnssSample {
        self.gnss_seq += 1;
        let n = Normal::new(0.0, self.gnss_sigma).unwrap();
        let nv = Normal::new(0.0, 0.02).unwrap();
        let mut g = GnssSample::default();
        g.header.time_ns = self.time_ns();
        g.header.seq = self.gnss_seq;
        g.fix_valid = 1;
        g.n_satellites = 8;
        for i in 0..3 {
            g.pos_ecef_m[i] = self.r_e[i] + n.sample(&mut self.rng);
            g.vel_ecef_m_s[i] = nv.sample(&mut self.rng);
            g.pos_cov_ecef_m2[4 * i] = self.gnss_sigma.powi(2);
            g.vel_cov_ecef_m2_s2[4 * i] = 0.02f64.powi(2);
        }
        g
    }
}

/// A baro sample at GPS `t_ns` reading the ISA pressure of `height_m` at 15 °C.
fn baro_at(t_ns: i64, seq: u64, height_m: f64) -> BaroSample {
    let mut b = BaroSample::default();
    b.header.time_ns = t_ns;
    b.header.seq = seq;
    b.pressure_pa = crate::atmosphere::isa_pressure_pa(height_m);
    b.temperature_c = 15.0;
    b
}

fn quick_config() -> NavigatorConfig {
    NavigatorConfig {
        alignment_s: 60.0,
        ..NavigatorConfig::default()
    }
}

/// Run a static scenario: IMU at `rate` Hz, GNSS at 1 Hz, for `seconds` in total.
/// Returns the navigator and the simulator.
fn run_static(seed: u64, rate: f64, seconds: f64, cfg: NavigatorConfig) -> (Navigator, StaticSim) {
    let mut nav = Navigator::new(cfg).unwrap();
    let mut sim = StaticSim::new(seed, rate);
    let per_s = rate.round() as i64;
    let steps = (seconds * rate).round() as i64;
    for k in 1..=steps {
        let imu = sim.next_imu();
        if k % per_s == 0 {
            // GNSS sample arrives just after the IMU sample of the same time.
            nav.push_imu(&imu).unwrap();
            let g = sim.gnss();
            nav.push_gnss(&g).unwrap();
        } else {
            nav.push_imu(&imu).unwrap();
        }
    }
    (nav, sim)
}

fn pos_error_and_nees(nav: &Navigator, sim: &StaticSim) -> (Vector3<f64>, f64) {
    let e = nav.nav_state().r_e - sim.r_e;
    let p: Matrix3<f64> = nav
        .covariance()
        .fixed_view::<3, 3>(idx::POS, idx::POS)
        .into_owned();
    let nees = e.dot(&(p.try_inverse().unwrap() * e));
    (e, nees)
}

#[test]
fn filter_toml_is_the_car_and_its_idealised_vehicle_the_default() {
    // The shipped filter is the default scenario's car: its installation and sensor classes,
    // which `idealised` takes back out to the built-in defaults.
    let car: NavigatorConfig =
        toml::from_str(include_str!("../../../../config/filter.toml")).unwrap();
    car.validate().unwrap();
    assert_eq!(car.gnss.lever_arm_b_m, [0.3, 0.0, -1.5]);
    assert_eq!(car.latency.gnss_s, 0.05);
    assert_eq!(car.aiding.baro_bias_rw_m_sqrt_s, 0.14);
    assert_eq!(car.vehicle.wheel_lever_arm_b_m, [-1.5, -0.8, 1.0]);
    let cfg = car.clone().idealised();
    assert_eq!(cfg, NavigatorConfig::default());
    assert_eq!(
        cfg.clone().idealised(),
        cfg,
        "the default vehicle is the idealised one"
    );
    cfg.validate().unwrap();
    let mut c = cfg.clone();
    c.latency.gnss_s = cfg.buffer_window_s;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("latency.gnss_s"), "{e}");
    let bad: Result<NavigatorConfig, _> = toml::from_str("alignment_s = 1.0\nbogus = 3\n");
    assert!(bad.unwrap_err().to_string().contains("bogus"));
    let mut c = NavigatorConfig::default();
    c.aiding.zupt_sigma_m_s = -1.0;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("filter.aiding.zupt_sigma_m_s"), "{e}");
    c = NavigatorConfig::default();
    c.gate_probability = f64::NAN;
    assert!(
        c.validate()
            .unwrap_err()
            .to_string()
            .contains("gate_probability")
    );
    c = NavigatorConfig::default();
    c.gnss.error_correlation_time_s = -60.0;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("gnss.error_correlation_time_s"), "{e}");
    c = NavigatorConfig::default();
    c.vehicle.wheel_lever_arm_b_m[2] = f64::INFINITY;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("filter.vehicle.wheel_lever_arm_b_m[2]"), "{e}");
    c = NavigatorConfig::default();
    c.vehicle.ride_frequency_hz = 0.0;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.contains("filter.vehicle.ride_frequency_hz"), "{e}");
    // A configuration written before the vehicle model loads, with the default car.
    let old: NavigatorConfig = toml::from_str("[aiding]\nnhc_sigma_m_s = 1e-5\n").unwrap();
    assert_eq!(old.vehicle, VehicleModel::default());
}

#[test]
fn a_star_tracker_roll_bias_is_a_boresight_state_about_the_optical_axis_only() {
    let car: NavigatorConfig =
        toml::from_str(include_str!("../../../../config/filter.toml")).unwrap();
    assert!(!car.states.boresight, "the car's mount is calibrated");
    let roll = car.aiding.star_roll_bias_sigma_arcsec / 3600.0 * DEG;
    assert!(roll > 0.0);
    let nav = Navigator::new(car.clone()).unwrap();
    assert!(nav.active_states(false).boresight, "the bias is estimated");
    // The head looks up (sensor z = −body z): the prior is about body z alone, which is the
    // first of the Euler angles (M(κ) = R_z(κ1)·R_x(κ2)·R_y(κ3)).
    let p = nav.boresight_prior_covariance();
    let expected = Matrix3::from_diagonal(&Vector3::new(roll * roll, 0.0, 0.0));
    let b = ekf::kappa_jacobian(&Vector3::zeros());
    let about_body = b * p * b.transpose();
    assert!(
        (about_body[(2, 2)] - roll * roll).abs() < 1e-30 && about_body[(0, 0)] == 0.0,
        "{about_body}"
    );
    assert!((p - expected).abs().max() < 1e-30, "{p}");
    let data_sheet = nav.data_sheet_prior(&Vector3::new(0.0, 0.0, -G0));
    assert_eq!(
        data_sheet.fixed_view::<3, 3>(idx::KAPPA, idx::KAPPA),
        p,
        "the start's prior"
    );
    // An uncalibrated mount adds its σ about every axis; the roll bias adds in variance.
    let mut loose = car.clone();
    loose.states.boresight = true;
    let mount = loose.aiding.boresight_sigma_deg * DEG;
    let p = Navigator::new(loose).unwrap().boresight_prior_covariance();
    let expected = Matrix3::from_diagonal(&Vector3::new(
        mount * mount + roll * roll,
        mount * mount,
        mount * mount,
    ));
    assert!((p - expected).abs().max() < 1e-24, "{p}");
    // Without star-tracker updates there is nothing to estimate it from; without the bias
    // (the built-in default, the matched world's star tracker) the group stays off.
    let mut no_stars = car.clone();
    no_stars.updates.star_tracker = false;
    assert!(
        !Navigator::new(no_stars)
            .unwrap()
            .active_states(false)
            .boresight
    );
    let idealised = Navigator::new(car.clone().idealised()).unwrap();
    assert!(!idealised.active_states(false).boresight);
    let mut bad = car;
    bad.aiding.star_roll_bias_sigma_arcsec = -1.0;
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("aiding.star_roll_bias_sigma_arcsec"), "{e}");
}

#[test]
fn the_static_detector_sees_a_stopped_car_through_its_engine_vibration() {
    // An idling four-cylinder engine (2100 rpm: order 2 at 70 Hz, 0.42 m/s² amplitude, order
    // 1 at 35 Hz) shakes the IMU of a car at rest: one 5 ms sample's specific force is off
    // gravity by ±0.35 m/s², seven times the test's 0.05 m/s². The mean over the 0.1 s block
    // is off by at most 2·A/(2πf)/T ≈ 0.02 m/s² (module docs of `navigator::zupt`).
    let cfg = quick_config();
    assert!(cfg.updates.zupt);
    let run = |vibration: [(f64, f64); 3], detector_per_sample: bool| {
        let mut cfg = cfg.clone();
        if detector_per_sample {
            cfg.aiding.zupt_interval_s = 0.0;
        }
        let mut nav = Navigator::new(cfg).unwrap();
        let mut sim = StaticSim::new(7, 200.0);
        sim.vibration = vibration;
        for k in 1..=(90 * 200) {
            nav.push_imu(&sim.next_imu()).unwrap();
            if k % 200 == 0 {
                nav.push_gnss(&sim.gnss()).unwrap();
            }
        }
        nav.zupt_health()
    };
    let idle = [(0.1, 35.0), (0.42, 70.0), (0.2, 140.0)];
    // Without vibration the block test and the per-sample test agree: updates every 0.1 s
    // from one window after navigation starts (60 s alignment, 90 s run).
    let still = run([(0.0, 0.0); 3], false);
    let still_per_sample = run([(0.0, 0.0); 3], true);
    assert!(still.fused > 250, "{still:?}");
    assert!(still_per_sample.fused > 250, "{still_per_sample:?}");
    // A sample-by-sample test never sees the idling car at rest; the block test does, and
    // its updates stay consistent (mean NIS per dof near 1 at most: the vibration's
    // velocity, below 1 mm/s, is inside the update's 5 mm/s σ).
    let shaken = run(idle, false);
    let shaken_per_sample = run(idle, true);
    assert_eq!(shaken_per_sample.fused, 0, "{shaken_per_sample:?}");
    assert_eq!(shaken.fused, still.fused, "{shaken:?} vs {still:?}");
    assert_eq!(shaken.rejected_gate, 0);
    assert!(
        shaken.nis_sum / (3.0 * shaken.fused as f64) < 1.5,
        "{shaken:?}"
    );
}

#[test]
fn vehicle_violation_is_the_derived_class_figure() {
    // The figures of the `[vehicle]` comment in config/filter.toml: at 20 m/s with the arm
    // [-1.5, -0.8, 1.0] on a straight road, vertical 0.080 m/s, lateral and forward 0.021
    // m/s, no manoeuvre part; in a turn at a_y = 3 m/s² the rear tyres' slip k_β·V·a_y, in a
    // speed change at a_x = 1 m/s² the squat k_p·V·a_x and the wheel slip k_s·V·a_x.
    let v = VehicleModel {
        wheel_lever_arm_b_m: [-1.5, -0.8, 1.0],
        ..VehicleModel::default()
    };
    let straight = v.violation_sigmas_m_s(20.0, 0.0, 0.0);
    let w = straight.white_m_s;
    assert!((w.z - 0.080).abs() < 5e-4, "{w}");
    assert!(
        (w.y - 0.021).abs() < 5e-4 && (w.x - 0.021).abs() < 5e-4,
        "{w}"
    );
    assert_eq!(straight.maneuver_m_s, Vector3::zeros());
    let turn = v.violation_sigmas_m_s(20.0, 0.0, -3.0);
    let slip = 0.4f64.to_radians() * 20.0 * 3.0;
    assert!((turn.maneuver_m_s.y - slip).abs() < 1e-12 && turn.white_m_s == w);
    let speed_up = v.violation_sigmas_m_s(20.0, 1.0, 0.0).maneuver_m_s;
    assert!((speed_up.z - 0.2f64.to_radians() * 20.0).abs() < 1e-12);
    assert!((speed_up.x - 0.005 * 20.0).abs() < 1e-12);
    // A wheel at the IMU: the ride's rates have no arm; heave, pitch and the mount's
    // vibration remain.
    let at_imu = VehicleModel::default().violation_sigmas_m_s(20.0, 0.0, 0.0);
    assert_eq!((at_imu.white_m_s.x, at_imu.white_m_s.y), (0.0015, 0.0015));
    assert!(at_imu.white_m_s.z > 0.07 && at_imu.white_m_s.z < w.z);
}

#[test]
fn cached_celestial_matrix_matches_full_model() {
    // Within the refresh interval the cached GCRS → ITRS differs from the full IAU
    // 2006/2000A matrix by < 0.2 mas (bound derived in CelestialCache's docs).
    let eop = EarthOrientation {
        dut1_s: 0.1,
        xp_rad: 1e-6,
        yp_rad: 2e-6,
    };
    let mut cache = CelestialCache::default();
    let mas = 1e-3 / 3600.0 * DEG;
    for k in 0..=8 {
        let t = GpsTime {
            ns: T0 + k * 15_000_000_000,
        };
        let full = crate::celestial::c_e_i(t, &eop);
        let cached = cache.c_e_i(t, &eop);
        let d = crate::celestial::dcm_angle_between(&full, &cached);
        assert!(d < 0.2 * mas, "k {k}: {} mas", d / mas);
    }
    assert!(cache.epoch.is_some_and(|e| e.ns > T0));
}

#[test]
fn aligns_then_navigates_with_gnss() {
    let (nav, sim) = run_static(1, 100.0, 120.0, quick_config());
    assert!(nav.is_navigating());
    assert_eq!(nav.mode(), NavMode::GnssInertial as u32);
    let h = nav.health();
    let g = &h[SensorId::Gnss as usize];
    assert_eq!(g.received, 120);
    assert!(g.fused >= 55, "{g:?}");
    assert_eq!(g.rejected_invalid, 0);
    let (e, _) = pos_error_and_nees(&nav, &sim);
    assert!(e.norm() < 3.0, "position error {e}");
    // Heading from gyrocompassing + filter within a few tenths of a degree.
    let q_n_b = nav.nav_state().q_n_b(&WGS84);
    let rpy = rpy_from_q_n_b(&q_n_b);
    assert!((rpy.z - 0.7).abs() < 0.2 * DEG, "heading {}", rpy.z / DEG);
    assert!((rpy.x - 0.01).abs() < 0.02 * DEG);
    assert!((rpy.y + 0.02).abs() < 0.02 * DEG);
}

#[test]
fn static_gnss_run_averages_position_and_is_consistent() {
    // Monte Carlo over independent seeds: position error at the end of a static run with
    // 1 Hz GNSS (σ = 2 m) after N fixes is of order σ/√N, and the position NEES summed over
    // the runs lies inside the two-sided 99.9 % chi-square bounds.
    let runs = 6;
    let mut nees_sum = 0.0;
    let mut err_rms = 0.0;
    let seconds = 360.0;
    let n_fixes = seconds - 60.0;
    for seed in 0..runs {
        let (nav, sim) = run_static(100 + seed, 100.0, seconds, quick_config());
        let (e, nees) = pos_error_and_nees(&nav, &sim);
        nees_sum += nees;
        err_rms += e.norm_squared();
        let sigma_ned = nav
            .covariance()
            .fixed_view::<3, 3>(0, 0)
            .diagonal()
            .map(f64::sqrt);
        eprintln!(
            "seed {seed}: |e| = {:.3} m, NEES = {nees:.2}, σ = {sigma_ned:?}",
            e.norm()
        );
    }
    let err_rms = (err_rms / runs as f64 / 3.0).sqrt();
    let dof = 3 * runs as u32;
    let lo = ekf::chi2_quantile(dof, 0.0005);
    let hi = ekf::chi2_quantile(dof, 0.9995);
    eprintln!(
        "per-axis RMS error {err_rms:.3} m (σ/√N = {:.3} m); NEES sum {nees_sum:.2} in [{lo:.2}, {hi:.2}]",
        2.0 / n_fixes.sqrt()
    );
    assert!(err_rms < 5.0 * 2.0 / n_fixes.sqrt(), "RMS {err_rms}");
    assert!(
        nees_sum > lo && nees_sum < hi,
        "NEES {nees_sum} outside [{lo}, {hi}]"
    );
}

#[test]
fn outlier_is_gated_and_counted() {
    let (mut nav, mut sim) = run_static(7, 100.0, 80.0, quick_config());
    let before = nav.nav_state().r_e;
    let imu = sim.next_imu();
    nav.push_imu(&imu).unwrap();
    let mut g = sim.gnss();
    g.pos_ecef_m[0] += 300.0;
    nav.push_gnss(&g).unwrap();
    let imu = sim.next_imu();
    nav.push_imu(&imu).unwrap();
    // The fix came after the IMU sample of its epoch: held out of the next step, fused by
    // the rewind after it (what the daemon does once the solution is published).
    nav.catch_up();
    let h = nav.health()[SensorId::Gnss as usize];
    assert!(h.rejected_gate >= 1, "{h:?}");
    assert!(h.last_nis > ekf::chi2_quantile(3, 0.999));
    assert!((nav.nav_state().r_e - before).norm() < 0.5);
}

#[test]
fn invalid_inputs_are_rejected_without_touching_the_state() {
    let (mut nav, mut sim) = run_static(9, 100.0, 65.0, quick_config());
    let state = *nav.nav_state();
    let p = *nav.covariance();
    let mut imu = sim.next_imu();
    let good = imu;
    imu.delta_velocity_m_s[1] = f64::NAN;
    assert!(nav.push_imu(&imu).is_err());
    imu = good;
    imu.dt_s = f64::INFINITY;
    assert!(nav.push_imu(&imu).is_err());
    imu = good;
    imu.delta_angle_rad[0] = 1.0; // 100 rad/s
    assert!(nav.push_imu(&imu).is_err());
    assert_eq!(*nav.nav_state(), state);
    assert_eq!(*nav.covariance(), p);
    assert_eq!(nav.health()[SensorId::Imu as usize].rejected_invalid, 3);
    // The good sample still goes through; then its duplicate and an older one do not.
    nav.push_imu(&good).unwrap();
    assert!(nav.push_imu(&good).is_err());
    let mut older = good;
    older.header.seq += 1;
    older.header.time_ns -= 1;
    assert!(matches!(
        nav.push_imu(&older),
        Err(Rejection {
            reason: RejectReason::TimeNotIncreasing { .. },
            ..
        })
    ));
    assert_eq!(nav.health()[SensorId::Imu as usize].rejected_invalid, 5);
    // GNSS with NaN, star tracker with a non-unit quaternion, baro with absurd pressure.
    let mut g = sim.gnss();
    g.pos_ecef_m[2] = f64::NAN;
    assert!(nav.push_gnss(&g).is_err());
    let mut st = StarTrackerSample::default();
    st.header.time_ns = good.header.time_ns;
    st.valid = 1;
    st.q_sensor_icrf = [2.0, 0.0, 0.0, 0.0];
    st.sigma_cross_rad = 1e-5;
    st.sigma_roll_rad = 1e-4;
    assert!(nav.push_star_tracker(&st).is_err());
    let mut b = BaroSample::default();
    b.header.time_ns = good.header.time_ns;
    b.pressure_pa = f64::INFINITY;
    assert!(nav.push_baro(&b).is_err());
    let mut o = OdometerSample::default();
    o.header.time_ns = good.header.time_ns;
    o.dt_s = 0.01;
    o.speed_m_s = f64::NAN;
    assert!(nav.push_odometer(&o).is_err());
    let h = nav.health();
    for s in [
        SensorId::Gnss,
        SensorId::StarTracker,
        SensorId::Baro,
        SensorId::Odometer,
    ] {
        assert_eq!(h[s as usize].rejected_invalid, 1, "{:?}", s);
    }
    // Nothing of it reached the filter.
    let next = sim.next_imu();
    let sol = nav.push_imu(&next).unwrap().unwrap();
    assert!(sol.pos_sigma_ned_m.iter().all(|s| s.is_finite()));
    assert!((nav.nav_state().r_e - sim.r_e).norm() < 5.0);
}

#[test]
fn late_gnss_sample_gives_the_in_time_update() {
    late_gnss_sample_matches_in_time(300_000_000);
}

/// The same with the fix late by almost the whole buffer window (0.98 s behind the filter's
/// epoch when it arrives, window 1 s): the checkpoint ring, sized from the window, still holds
/// a checkpoint before it.
#[test]
fn gnss_sample_late_by_almost_the_window_gives_the_in_time_update() {
    assert_eq!(quick_config().buffer_window_s, 1.0);
    assert_eq!(quick_config().checkpoint_capacity(), 106);
    late_gnss_sample_matches_in_time(990_000_000);
}

/// Two navigators fed the same static-site stream for `steps` IMU samples (IMU 100 Hz, baro
/// 10 Hz, GNSS 1 Hz): `a` gets every fix before the IMU sample of its time (in time); `b` gets
/// the fix of time `t` that `delay(t, b)` names that many ns later (asserted late: after the
/// IMU has passed its epoch), the others as `a`. Returns both and the late fixes delivered
/// (every one is, before the stream ends).
fn with_late_fixes(
    seed: u64,
    steps: usize,
    delay: impl Fn(i64, &Navigator) -> Option<i64>,
) -> (Navigator, Navigator, u32) {
    let fixes = LateFixes {
        cfg: quick_config(),
        seed,
        steps,
        fix_step: 0,
        stamp_after_ns: 0,
    };
    fixes.run(delay, |_| {})
}

/// The stream of [`with_late_fixes`] with its configuration, the fix's epoch at IMU step
/// `fix_step` of each second (0–99) and its stamp `stamp_after_ns` after that epoch (a
/// time-tag latency, declared or not in `cfg`).
struct LateFixes {
    cfg: NavigatorConfig,
    seed: u64,
    steps: usize,
    fix_step: usize,
    stamp_after_ns: i64,
}

impl LateFixes {
    /// Feed both navigators; `after_b` sees `b` after each of its IMU samples.
    fn run(
        &self,
        delay: impl Fn(i64, &Navigator) -> Option<i64>,
        mut after_b: impl FnMut(&mut Navigator),
    ) -> (Navigator, Navigator, u32) {
        let mut a = Navigator::new(self.cfg.clone()).unwrap();
        let mut b = Navigator::new(self.cfg.clone()).unwrap();
        let mut sim = StaticSim::new(self.seed, 100.0);
        let mut held: Option<(i64, GnssSample)> = None;
        let mut delayed = 0;
        for k in 1..=self.steps {
            let imu = sim.next_imu();
            let t = imu.header.time_ns;
            if k % 10 == 0 {
                let baro = baro_at(t, k as u64, 181.0);
                a.push_baro(&baro).unwrap();
                b.push_baro(&baro).unwrap();
            }
            if k % 100 == self.fix_step {
                let mut g = sim.gnss();
                g.header.time_ns += self.stamp_after_ns;
                a.push_gnss(&g).unwrap();
                match delay(t, &b) {
                    Some(d) => held = Some((t + d, g)),
                    None => b.push_gnss(&g).unwrap(),
                }
            }
            if let Some((when, g)) = held
                && t >= when
            {
                assert!(
                    g.header.time_ns - self.stamp_after_ns < b.time().ns,
                    "the sample must really be late"
                );
                b.push_gnss(&g).unwrap();
                held = None;
                delayed += 1;
            }
            a.push_imu(&imu).unwrap();
            b.push_imu(&imu).unwrap();
            after_b(&mut b);
        }
        assert!(held.is_none(), "a late fix still held at the end");
        (a, b, delayed)
    }
}

fn late_gnss_sample_matches_in_time(delay_ns: i64) {
    // Two navigators see the same static-site stream (IMU 100 Hz, baro 10 Hz, GNSS 1 Hz).
    // A gets each GNSS fix before the IMU sample of its time (in time); B gets the fix of
    // t = 75 s only `delay_ns` later (0.3 s: after 30 more IMU samples and 3 baro updates). B must
    // rewind to its checkpoint before 75 s, re-fuse the baro samples and replay the IMU:
    // the same floating-point operations in the same order, so the results agree to
    // rounding — asserted at 1e-9 m / 1e-12 m/s / 1e-12 rad and 1e-9 relative for the
    // covariance (the ops are identical; the bound only allows for a different
    // summation order should the compiler choose one).
    let late_at = T0 + 75_000_000_000;
    let (a, b, delayed) = with_late_fixes(31, 80 * 100, |t, _| (t == late_at).then_some(delay_ns));
    assert_eq!(delayed, 1);
    let (na, nb) = (a.nav_state(), b.nav_state());
    assert!(
        (na.r_e - nb.r_e).norm() < 1e-9,
        "{}",
        (na.r_e - nb.r_e).norm()
    );
    assert!((na.v_e - nb.v_e).norm() < 1e-12);
    assert!(na.q_e_b.angle_to(&nb.q_e_b) < 1e-12);
    let dp = (a.covariance() - b.covariance()).abs().max() / a.covariance().abs().max();
    assert!(dp < 1e-9, "covariance differs by {dp}");
    // Every sample counted once, the late one included.
    for s in [SensorId::Gnss, SensorId::Baro] {
        let (ha, hb) = (a.health()[s as usize], b.health()[s as usize]);
        assert_eq!(ha.fused, hb.fused, "{s:?}");
        assert_eq!(ha.nis_count, hb.nis_count, "{s:?}");
        assert_eq!(hb.dropped_late, 0);
    }
    // And the late fix did matter: without it the state differs.
    let mut c = Navigator::new(quick_config()).unwrap();
    let mut sim = StaticSim::new(31, 100.0);
    for k in 1..=(80 * 100) {
        let imu = sim.next_imu();
        if k % 10 == 0 {
            let baro = baro_at(imu.header.time_ns, k as u64, 181.0);
            c.push_baro(&baro).unwrap();
        }
        if k % 100 == 0 {
            let g = sim.gnss();
            if imu.header.time_ns != late_at {
                c.push_gnss(&g).unwrap();
            }
        }
        c.push_imu(&imu).unwrap();
    }
    assert!((c.nav_state().r_e - na.r_e).norm() > 1e-4);
}

/// A sample that arrives a few IMU steps after its epoch, where other aiding was due in time,
/// rewinds to the checkpoint taken before that epoch's updates: it replays only the steps after
/// its epoch, and the result is the in-time one bit for bit (the same operations in the same
/// order: the epoch's samples are fused again in their order after the checkpoint). Every
/// GNSS fix here (1 Hz, on a baro epoch) arrives two IMU samples (20 ms) late.
#[test]
fn a_sample_late_by_a_few_steps_rewinds_to_its_own_epoch() {
    let (a, b, late) = with_late_fixes(23, 90 * 100 + 50, |_, b| {
        b.is_navigating().then_some(20_000_000)
    });
    let late = u64::from(late);
    assert!(late >= 25, "{late} late fixes");
    let d = b.diagnostics();
    assert_eq!(d.rewinds, late);
    // The fix is held out of the step it arrived with; its rewind replays that step and the
    // one before: two per fix, none before the epoch.
    assert_eq!(d.replayed_imu_steps, 2 * late);
    assert_eq!(a.nav_state().r_e, b.nav_state().r_e);
    assert_eq!(a.nav_state().v_e, b.nav_state().v_e);
    assert_eq!(a.covariance(), b.covariance());
    for s in [SensorId::Gnss, SensorId::Baro] {
        let (ha, hb) = (a.health()[s as usize], b.health()[s as usize]);
        assert_eq!(ha.fused, hb.fused, "{s:?}");
        assert_eq!(ha.nis_count, hb.nis_count, "{s:?}");
    }
}

/// A sensor with a declared time-tag latency whose epochs fall between the covariance's 50 ms
/// propagations (GNSS valid 30 ms past each second, stamped 20 ms later and delivered at its
/// stamp, with the in-time baro at whole 100 ms): the covariance is also propagated at the
/// epoch where its next sample is expected (`cadence`), so the checkpoint before that epoch's
/// updates serves the sample's rewind, which replays only the two IMU steps after its epoch
/// once the sensor's cadence is known (from its third sample on); without it the rewind would
/// go back to the periodic checkpoint before the epoch and replay the epoch's step too. The
/// result is the in-time arrival's (the same declared latency, each fix pushed before the IMU
/// step of its epoch) bit for bit.
#[test]
fn a_late_sensor_between_propagations_rewinds_to_its_own_epoch() {
    const LATENCY_NS: i64 = 20_000_000;
    let mut cfg = quick_config();
    cfg.latency.gnss_s = LATENCY_NS as f64 * 1e-9;
    // Valid at 30 ms past the second, stamped and delivered 20 ms later.
    let fixes = LateFixes {
        cfg,
        seed: 29,
        steps: 90 * 100 + 50,
        fix_step: 3,
        stamp_after_ns: LATENCY_NS,
    };
    let mut replayed_per_rewind = Vec::new();
    let mut replayed = 0;
    let (a, b, late) = fixes.run(
        |_, _| Some(LATENCY_NS),
        |b| {
            b.catch_up();
            let now = b.diagnostics().replayed_imu_steps;
            if now > replayed {
                replayed_per_rewind.push(now - replayed);
            }
            replayed = now;
        },
    );
    assert!(late >= 90);
    assert_eq!(replayed_per_rewind.len() as u64, b.diagnostics().rewinds);
    assert!(replayed_per_rewind.len() >= 25, "{replayed_per_rewind:?}");
    assert!(
        replayed_per_rewind[2..].iter().all(|&n| n == 2),
        "{replayed_per_rewind:?}"
    );
    assert_eq!(a.nav_state().r_e, b.nav_state().r_e);
    assert_eq!(a.nav_state().v_e, b.nav_state().v_e);
    assert_eq!(a.nav_state().q_e_b, b.nav_state().q_e_b);
    assert_eq!(a.covariance(), b.covariance());
    let g = SensorId::Gnss as usize;
    assert_eq!(a.health()[g].fused, b.health()[g].fused);
    assert_eq!(b.health()[g].dropped_late, 0);
}

/// `catch_up` only moves the rewind of held late samples earlier: two navigators fed the
/// same stream with late samples (every baro sample and GNSS fix arrives after the IMU
/// sample of its epoch, some fixes 0.2 s late), one calling `catch_up` after every IMU
/// sample as the daemon does, give the same solution at every epoch, bit for bit (what
/// keeps an offline replay, which never calls it, bit-exact with the live daemon), and the
/// same health counters.
#[test]
fn catching_up_early_changes_no_solution() {
    let cfg = quick_config();
    let mut a = Navigator::new(cfg.clone()).unwrap();
    let mut b = Navigator::new(cfg).unwrap();
    let mut sim = StaticSim::new(17, 100.0);
    let mut aiding = StaticAiding::default();
    let (mut compared, mut rewinds_b) = (0, 0);
    for k in 1..=(90 * 100) {
        let imu = sim.next_imu();
        let sa = a.push_imu(&imu).unwrap();
        let sb = b.push_imu(&imu).unwrap();
        let before = b.diagnostics().rewinds;
        b.catch_up();
        rewinds_b += b.diagnostics().rewinds - before;
        assert_eq!(sa, sb, "epoch {k}");
        compared += u32::from(sa.is_some());
        aiding.after_imu(k, imu.header.time_ns, &mut sim, |input| {
            a.push(input).unwrap();
            b.push(input).unwrap();
        });
    }
    assert!(compared > 2500, "{compared} epochs compared");
    assert!(rewinds_b > 250, "catch_up rewound {rewinds_b} times");
    assert_eq!(a.health(), b.health());
}

/// The aiding of the static stream that two navigators are fed side by side: a baro sample
/// after every tenth IMU sample, a GNSS fix after every hundredth, every third fix 0.2 s late.
#[derive(Default)]
struct StaticAiding {
    /// Late fixes and when they are delivered (IMU time, ns).
    held: Vec<(i64, GnssSample)>,
}

impl StaticAiding {
    /// After the `k`-th IMU sample (time `t`, ns): hand `feed` the aiding due.
    fn after_imu(
        &mut self,
        k: usize,
        t: i64,
        sim: &mut StaticSim,
        mut feed: impl FnMut(Input<'_>),
    ) {
        if k.is_multiple_of(10) {
            feed(Input::Baro(&baro_at(t, k as u64, 181.0)));
        }
        if k.is_multiple_of(100) {
            let g = sim.gnss();
            if k.is_multiple_of(300) {
                self.held.push((t + 200_000_000, g));
            } else {
                feed(Input::Gnss(&g));
            }
        }
        while let Some(&(when, g)) = self.held.first() {
            if t < when {
                break;
            }
            feed(Input::Gnss(&g));
            self.held.remove(0);
        }
    }
}

/// A navigator fed without forming its solutions (`push_deferred`, as `replay --offline` feeds
/// it) and one that forms every solution (`push_imu`, as the daemon does) go through the same
/// states: a solution formed now and then from the first is bit for bit the second's of that
/// epoch, late samples and their rewinds included. The solution is that of the IMU sample just
/// pushed, so none is formed while aligning, after another input or after a rewind.
#[test]
fn solutions_formed_only_when_asked_are_those_of_every_epoch() {
    let cfg = quick_config();
    let mut a = Navigator::new(cfg.clone()).unwrap();
    let mut b = Navigator::new(cfg).unwrap();
    let mut sim = StaticSim::new(23, 100.0);
    let mut aiding = StaticAiding::default();
    let (mut formed, mut epochs) = (0, 0);
    for k in 1..=(90 * 100usize) {
        let imu = sim.next_imu();
        let t = imu.header.time_ns;
        let sa = a.push_imu(&imu).unwrap();
        let navigating = b.push_deferred(Input::Imu(&imu)).unwrap();
        assert_eq!(navigating, sa.is_some(), "epoch {k}");
        if !navigating {
            assert_eq!(b.solution(), None, "epoch {k}: no solution while aligning");
        } else {
            epochs += 1;
            if k.is_multiple_of(7) {
                // Asked twice: forming it changes nothing.
                assert_eq!(b.solution(), sa, "epoch {k}");
                assert_eq!(b.solution(), sa, "epoch {k}");
                formed += 1;
            }
        }
        aiding.after_imu(k, t, &mut sim, |input| {
            a.push(input).unwrap();
            assert!(!b.push_deferred(input).unwrap());
            assert_eq!(b.solution(), None, "epoch {k}: another input came");
        });
        if k.is_multiple_of(13) && navigating {
            b.catch_up();
            assert_eq!(b.solution(), None, "epoch {k}: after a rewind's turn");
        }
    }
    assert!(
        epochs > 2500 && formed > 350,
        "{epochs} epochs, {formed} formed"
    );
    assert!(b.diagnostics().rewinds > 25, "{:?}", b.diagnostics());
    assert_eq!(a.health(), b.health());
    assert_eq!(a.diagnostics(), b.diagnostics());
    let last = sim.next_imu();
    assert_eq!(
        a.push_imu(&last).unwrap(),
        b.push_imu(&last).unwrap(),
        "the state after the drive"
    );
}

/// A receiver that stamps its fix 50 ms after the epoch it measured, declared in
/// `[latency] gnss_s`: each fix is fused at its time of validity, so the navigator that gets
/// the late-stamped fixes (after the IMU has passed their epoch, as from a real receiver) ends
/// where the one that gets every fix in time at its epoch does, to rounding. Undeclared, the
/// same late stamps are fused 50 ms late and the states differ.
#[test]
fn declared_time_tag_latency_fuses_each_sample_at_its_time_of_validity() {
    const LATENCY_NS: i64 = 50_000_000;
    let run = |latency_s: f64, stamp_late: bool| {
        // A surveyed start and the end of the alignment between two fixes: a fix of the last
        // alignment epoch would otherwise go to the alignment in time and to the filter when
        // stamped late.
        let mut cfg = quick_config();
        cfg.alignment_s = 60.5;
        cfg.initial_position = Some(InitialPosition {
            lat_deg: 55.655,
            lon_deg: 37.534,
            height_m: 180.0,
        });
        cfg.latency.gnss_s = latency_s;
        let mut nav = Navigator::new(cfg).unwrap();
        let mut sim = StaticSim::new(32, 100.0);
        let mut held: Option<GnssSample> = None;
        for k in 1..=(80 * 100) {
            let imu = sim.next_imu();
            let t = imu.header.time_ns;
            if k % 10 == 0 {
                nav.push_baro(&baro_at(t, k as u64, 181.0)).unwrap();
            }
            // The last fix at 79 s: stamped late, it too arrives before the end.
            if k % 100 == 0 && k < 80 * 100 {
                let mut g = sim.gnss();
                if stamp_late {
                    g.header.time_ns += LATENCY_NS;
                    held = Some(g);
                } else {
                    nav.push_gnss(&g).unwrap();
                }
            }
            if let Some(g) = held
                && t >= g.header.time_ns
            {
                nav.push_gnss(&g).unwrap();
                held = None;
            }
            nav.push_imu(&imu).unwrap();
        }
        nav
    };
    let in_time = run(0.0, false);
    let declared = run(LATENCY_NS as f64 * 1e-9, true);
    let undeclared = run(0.0, true);
    let (a, b, c) = (
        in_time.nav_state(),
        declared.nav_state(),
        undeclared.nav_state(),
    );
    assert!((a.r_e - b.r_e).norm() < 1e-9, "{}", (a.r_e - b.r_e).norm());
    assert!((a.v_e - b.v_e).norm() < 1e-12);
    let dp = (in_time.covariance() - declared.covariance()).abs().max()
        / in_time.covariance().abs().max();
    assert!(dp < 1e-9, "covariance differs by {dp}");
    let g = SensorId::Gnss as usize;
    assert_eq!(in_time.health()[g].fused, declared.health()[g].fused);
    assert_eq!(declared.health()[g].dropped_late, 0);
    assert!((a.r_e - c.r_e).norm() > 1e-6, "the stamps matter");
}

/// Two navigators on the same 1 kHz static-site stream (baro 10 Hz, GNSS 1 Hz); B gets the
/// GNSS fixes of t = 75 s and 76 s only at 76.5 s, i.e. 1.5 s and 0.5 s late (in order, so
/// that the sensor's time still increases; never, with `deliver` false). Returns (A, B,
/// the number of late pushes); boxed, a navigator holds its queues inline.
fn late_fix_at_1_khz(cfg: NavigatorConfig, deliver: bool) -> (Box<Navigator>, Box<Navigator>, u32) {
    let mut a = Box::new(Navigator::new(cfg.clone()).unwrap());
    let mut b = Box::new(Navigator::new(cfg).unwrap());
    let mut sim = StaticSim::new(33, 1000.0);
    let mut held = Vec::new();
    let late_at = T0 + 75_000_000_000;
    let release = late_at + 1_500_000_000;
    let mut delayed = 0;
    for k in 1..=(78 * 1000) {
        let imu = sim.next_imu();
        let t = imu.header.time_ns;
        if k % 100 == 0 {
            let baro = baro_at(t, k as u64, 181.0);
            a.push_baro(&baro).unwrap();
            b.push_baro(&baro).unwrap();
        }
        if k % 1000 == 0 {
            let g = sim.gnss();
            a.push_gnss(&g).unwrap();
            if (late_at..release).contains(&t) {
                held.push(g);
            } else {
                b.push_gnss(&g).unwrap();
            }
        }
        if t == release && deliver {
            assert_eq!(
                held[0].header.time_ns + 1_500_000_000,
                b.time().ns + 1_000_000
            );
            for g in held.drain(..) {
                b.push(Input::Gnss(&g)).unwrap();
                delayed += 1;
            }
        }
        a.push(Input::Imu(&imu)).unwrap();
        b.push(Input::Imu(&imu)).unwrap();
    }
    (a, b, delayed)
}

#[test]
fn late_gnss_sample_at_1_khz_gives_the_in_time_update() {
    // As `late_gnss_sample_gives_the_in_time_update`, at 1 kHz with the longest window
    // (2 s) and a fix 1.5 s late: the IMU log must hold 1.6 s of steps (1 600 entries).
    let cfg = NavigatorConfig {
        alignment_s: 60.0,
        buffer_window_s: 2.0,
        ..NavigatorConfig::default()
    };
    let (a, b, delayed) = late_fix_at_1_khz(cfg, true);
    assert_eq!(delayed, 2);
    assert_eq!(b.diagnostics().replays_impossible, 0);
    let (na, nb) = (a.nav_state(), b.nav_state());
    let dr = (na.r_e - nb.r_e).norm();
    assert!(dr < 1e-9, "late fix changes the position by {dr} m");
    assert!((na.v_e - nb.v_e).norm() < 1e-12);
    assert!(na.q_e_b.angle_to(&nb.q_e_b) < 1e-12);
    let dp = (a.covariance() - b.covariance()).abs().max() / a.covariance().abs().max();
    assert!(dp < 1e-9, "covariance differs by {dp}");
    for s in [SensorId::Gnss, SensorId::Baro] {
        let (ha, hb) = (a.health()[s as usize], b.health()[s as usize]);
        assert_eq!(ha.fused, hb.fused, "{s:?}");
        assert_eq!(hb.dropped_late, 0, "{s:?}");
    }
}

#[test]
fn a_replay_the_imu_log_cannot_hold_is_counted_and_the_late_samples_dropped() {
    // The log sized for 100 Hz (206 steps) holds 0.2 s of a 1 kHz IMU: the fixes 1.5 s
    // and 0.5 s late cannot be replayed at their epoch. They must be dropped and counted
    // (not fused at the current epoch, the old silent behaviour): B ends exactly where a
    // navigator that never received them ends.
    let cfg = NavigatorConfig {
        alignment_s: 60.0,
        buffer_window_s: 2.0,
        max_imu_rate_hz: 100.0,
        ..NavigatorConfig::default()
    };
    assert_eq!(cfg.imu_log_capacity(), 206);
    let (a, b, delayed) = late_fix_at_1_khz(cfg.clone(), true);
    let (_, c, _) = late_fix_at_1_khz(cfg, false);
    assert_eq!(delayed, 2);
    assert_eq!(b.diagnostics().replays_impossible, 1);
    let (hb, hc) = (
        b.health()[sid(SensorId::Gnss)],
        c.health()[sid(SensorId::Gnss)],
    );
    assert_eq!(hb.dropped_late, 2);
    assert_eq!(hb.fused, hc.fused);
    assert_eq!(hb.fused + 2, a.health()[sid(SensorId::Gnss)].fused);
    assert!((b.nav_state().r_e - c.nav_state().r_e).norm() < 1e-9);
    assert_eq!(b.covariance(), c.covariance());
}

#[test]
fn an_imu_rate_the_log_cannot_hold_is_a_configuration_error() {
    let mut cfg = NavigatorConfig {
        buffer_window_s: 2.0,
        max_imu_rate_hz: 2000.0,
        ..NavigatorConfig::default()
    };
    assert_eq!(cfg.imu_log_capacity(), 4082);
    assert_eq!(cfg.checkpoint_capacity(), 206);
    cfg.validate().unwrap();
    cfg.max_imu_rate_hz = 40_000.0; // 88 000 steps
    let e = cfg.validate().unwrap_err();
    assert!(e.0.starts_with("filter.max_imu_rate_hz "), "{e}");
    cfg.max_imu_rate_hz = f64::NAN;
    assert!(Navigator::new(cfg).is_err());
}

#[test]
fn all_aiding_lost_is_free_inertial_with_growing_covariance() {
    // GNSS for 90 s, then nothing (no stars, baro or odometer in this sim; ZUPT off):
    // once the GNSS deadline (2 s) has passed the mode is free inertial and the position
    // covariance grows. Not monotonically per component — the Schuler loop trades
    // position variance for velocity variance (cos² νt) — but over 10 min the unstable
    // vertical channel alone (time constant √(R/2g) ≈ 570 s) and the horizontal drift make
    // it grow several-fold; assert at least 2×.
    let mut cfg = quick_config();
    cfg.updates.zupt = false;
    let (mut nav, mut sim) = run_static(41, 100.0, 90.0, cfg);
    assert_eq!(nav.mode(), NavMode::GnssInertial as u32);
    let trace = |n: &Navigator| {
        n.covariance()
            .fixed_view::<3, 3>(idx::POS, idx::POS)
            .trace()
    };
    let at_loss = trace(&nav);
    for _ in 0..(600 * 100) {
        let imu = sim.next_imu();
        nav.push_imu(&imu).unwrap();
    }
    assert_eq!(nav.mode(), NavMode::FreeInertial as u32);
    let end = trace(&nav);
    eprintln!("position variance trace {at_loss:.2} → {end:.2} m²");
    assert!(end > 2.0 * at_loss && end.is_finite());
}

#[test]
fn late_samples_are_dropped_and_solution_is_complete() {
    let (mut nav, mut sim) = run_static(11, 100.0, 70.0, quick_config());
    let stale = sim.gnss();
    for _ in 0..200 {
        let imu = sim.next_imu();
        nav.push_imu(&imu).unwrap();
    }
    let mut stale = stale;
    stale.header.seq = 1_000;
    stale.header.time_ns = nav.time().ns - 1_500_000_000;
    // Time still increases for the sensor (the previous fix was even older).
    let before = nav.health()[SensorId::Gnss as usize].dropped_late;
    nav.push_gnss(&stale).unwrap_or(());
    let imu = sim.next_imu();
    let sol = nav.push_imu(&imu).unwrap().unwrap();
    let h = nav.health()[SensorId::Gnss as usize];
    assert!(h.dropped_late > before || h.rejected_invalid > 0, "{h:?}");
    assert_eq!(sol.header.time_ns, imu.header.time_ns);
    assert_eq!(sol.imu_send_mono_ns, imu.header.send_mono_ns);
    assert!((sol.lat_rad - 55.655 * DEG).abs() < 1e-5);
    assert!(sol.q_ned_body.iter().all(|x| x.is_finite()));
    assert!(sol.att_sigma_ned_rad.iter().all(|x| *x > 0.0 && *x < 0.01));
    assert!((sol.roll_pitch_heading_rad[2] - 0.7).abs() < 0.01);
}

mod baro;
mod baseline;
