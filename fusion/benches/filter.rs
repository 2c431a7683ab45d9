//! Criterion benches of the error-state Kalman filter: the per-IMU-step transition
//! accumulation, one covariance propagation, each measurement update, and the end-to-end
//! throughput of `Navigator::push_imu` at 200 Hz with every aiding on (GNSS tight with 8
//! satellites at 1 Hz, star tracker 5 Hz, odometer 20 Hz, baro 20 Hz, ZUPT while static),
//! printed as IMU samples per second (the goal is ≥ 200 000 on one core).

use criterion::{Criterion, criterion_group, criterion_main};
use msgs::{BaroSample, GnssSample, ImuSample, OdometerSample, StarTrackerSample};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use sextant_fusion::earth::{Geodetic, WGS84, geodetic_to_ecef};
use sextant_fusion::ekf::{self, ActiveStates, Covariance, ErrorStateEkf, GateTable};
use sextant_fusion::frames::Rotation;
use sextant_fusion::navigator::{GnssMode, ImuSpec, Navigator, NavigatorConfig};
use sextant_fusion::strapdown::{NavState, q_e_n};
use std::hint::black_box;
use std::time::Instant;

#[path = "../tests/common/samples.rs"]
mod samples;

fn setup() -> (ErrorStateEkf, NavState) {
    let g = Geodetic {
        lat_rad: 55.655f64.to_radians(),
        lon_rad: 37.534f64.to_radians(),
        height_m: 180.0,
    };
    let nav = NavState::from_geodetic(
        &WGS84,
        &g,
        &Vector3::new(10.0, 2.0, 0.1),
        &UnitQuaternion::from_euler_angles(0.01, -0.02, 0.7),
    );
    let mut p0 = Covariance::identity() * 1e-6;
    for i in 0..6 {
        p0[(i, i)] = 4.0;
    }
    let mut noise = ImuSpec::default().process_noise();
    noise.clock_bias_psd_m2_s = 0.1;
    noise.clock_drift_psd_m2_s3 = 0.01;
    (ErrorStateEkf::new(p0, noise, ActiveStates::ALL), nav)
}

const T0: i64 = 1_400_000_000_000_000_000;

/// A static site feeding a navigator with every sensor (exact measurements: the cost of an
/// update does not depend on the noise).
struct Feed {
    r_e: Vector3<f64>,
    q_e_b: UnitQuaternion<f64>,
    c_s_b: Matrix3<f64>,
    pressure: f64,
    sats: [Vector3<f64>; 8],
    k: i64,
}

impl Feed {
    fn new() -> Self {
        let site = Geodetic {
            lat_rad: 55.655f64.to_radians(),
            lon_rad: 37.534f64.to_radians(),
            height_m: 180.0,
        };
        let r_e = geodetic_to_ecef(&WGS84, &site);
        // Eight satellites 20 000 km away at elevations 20°–80°, spread in azimuth.
        let sats = samples::sky(site.lat_rad, site.lon_rad, &r_e, 0.8, 20.0, 8.0);
        Self {
            r_e,
            q_e_b: q_e_n(site.lat_rad, site.lon_rad)
                * UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7),
            c_s_b: Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0),
            pressure: sextant_fusion::atmosphere::isa_pressure_pa(site.height_m),
            sats,
            k: 0,
        }
    }

    /// The samples of one 200 Hz IMU step: the IMU sample and the aiding due at it.
    fn step(&mut self) -> Step {
        self.k += 1;
        let k = self.k;
        let seq = k as u64;
        let t = T0 + k * 5_000_000;
        let mut out = Step {
            imu: samples::static_imu(t, seq, 0.005, &self.r_e, &self.q_e_b),
            gnss: None,
            star: None,
            baro: None,
            odo: None,
        };
        if k % 200 == 0 {
            let g = samples::raw_gnss(t, seq, &self.r_e, &self.sats, 100.0, 0.5);
            out.gnss = Some(Box::new(samples::with_fix(g, &self.r_e)));
        }
        if k % 40 == 0 {
            out.star = Some(samples::star(t, seq, &self.c_s_b, &self.q_e_b));
        }
        if k % 10 == 0 {
            out.baro = Some(samples::baro(t, seq, self.pressure));
            out.odo = Some(samples::odometer_at_rest(t, seq, 0.05));
        }
        out
    }
}

/// The samples of one IMU step.
struct Step {
    imu: ImuSample,
    gnss: Option<Box<GnssSample>>,
    star: Option<StarTrackerSample>,
    baro: Option<BaroSample>,
    odo: Option<OdometerSample>,
}

impl Step {
    fn push(&self, nav: &mut Navigator) {
        if let Some(g) = &self.gnss {
            nav.push_gnss(g).unwrap();
        }
        if let Some(s) = &self.star {
            nav.push_star_tracker(s).unwrap();
        }
        if let Some(b) = &self.baro {
            nav.push_baro(b).unwrap();
        }
        if let Some(o) = &self.odo {
            nav.push_odometer(o).unwrap();
        }
        black_box(nav.push_imu(&self.imu).unwrap());
    }
}

/// Navigator throughput with every aiding; `nonorthogonality` switches the three gyro
/// non-orthogonality states (31 states with, 28 without: the cost of the group).
fn throughput(nonorthogonality: bool) {
    let mut cfg = NavigatorConfig {
        alignment_s: 5.0,
        gnss_mode: GnssMode::Tight,
        ..NavigatorConfig::default()
    };
    cfg.states.boresight = true;
    cfg.states.gyro_misalignment = nonorthogonality;
    let mut nav = Navigator::new(cfg).unwrap();
    let mut feed = Feed::new();
    for _ in 0..(20 * 200) {
        feed.step().push(&mut nav);
    }
    assert!(nav.is_navigating());
    // The samples are built before the clock starts: only the navigator is timed.
    let n = 100 * 200;
    let steps: Vec<Step> = (0..n).map(|_| feed.step()).collect();
    let t = Instant::now();
    for s in &steps {
        s.push(&mut nav);
    }
    let s = t.elapsed().as_secs_f64();
    let h = nav.health();
    println!(
        "navigator throughput, 200 Hz IMU with all aiding (tight GNSS 8 sats 1 Hz, stars 5 Hz with boresight, \
         odometer 20 Hz, baro 20 Hz, ZUPT), gyro non-orthogonality states {}: {:.0} IMU samples/s \
         ({:.2} µs per sample); fused: gnss {}, star {}, odo {}, baro {}, zupt {}",
        if nonorthogonality { "on" } else { "off" },
        n as f64 / s,
        s / n as f64 * 1e6,
        h[msgs::SensorId::Gnss as usize].fused,
        h[msgs::SensorId::StarTracker as usize].fused,
        h[msgs::SensorId::Odometer as usize].fused,
        h[msgs::SensorId::Baro as usize].fused,
        nav.zupt_health().fused,
    );
}

fn bench(c: &mut Criterion) {
    throughput(true);
    throughput(false);
    let (mut f, nav) = setup();
    let f_b = Vector3::new(0.1, 0.0, -9.81);
    let w_b = Vector3::new(0.01, 0.002, 0.05);
    c.bench_function("ekf_accumulate_imu_step", |b| {
        b.iter(|| f.accumulate(black_box(&nav), black_box(&f_b), &w_b, 0.005))
    });
    let (mut f, nav) = setup();
    c.bench_function("ekf_propagate_covariance_50ms", |b| {
        b.iter(|| {
            for _ in 0..10 {
                f.accumulate(black_box(&nav), black_box(&f_b), &w_b, 0.005);
            }
            f.propagate_covariance(&WGS84, &nav.r_e)
        })
    });
    let (mut f, nav) = setup();
    c.bench_function("ekf_predict_every_step_200hz", |b| {
        b.iter(|| f.predict(&WGS84, black_box(&nav), black_box(&f_b), &w_b, 0.005))
    });
    let (f, nav) = setup();
    let gates = GateTable::new(0.999);
    let cov = Matrix3::identity() * 4.0;
    let z = nav.r_e + Vector3::new(1.0, -1.0, 0.5);
    c.bench_function("update_gnss_position", |b| {
        b.iter(|| {
            let m = ekf::gnss_position(black_box(&nav), &ekf::GnssAntenna::AT_IMU, &z, &cov);
            ekf::update(&f.p, &m, gates.threshold(3))
        })
    });
    let zv = nav.v_e + Vector3::new(0.01, 0.0, 0.0);
    let covv = Matrix3::identity() * 1e-4;
    c.bench_function("update_gnss_velocity", |b| {
        b.iter(|| {
            let m = ekf::gnss_velocity(black_box(&nav), &ekf::GnssAntenna::AT_IMU, &zv, &covv);
            ekf::update(&f.p, &m, gates.threshold(3))
        })
    });
    let r_s = nav.r_e * 4.0;
    let v_s = Vector3::new(1000.0, -2000.0, 500.0);
    let pr = (r_s - nav.r_e).norm() + 1.0;
    c.bench_function("update_pseudorange", |b| {
        b.iter(|| {
            let m = ekf::gnss_pseudorange(
                black_box(&nav),
                &ekf::GnssAntenna::AT_IMU,
                &r_s,
                pr,
                0.0,
                3.0,
            );
            ekf::update(&f.p, &m, gates.threshold(1))
        })
    });
    c.bench_function("update_range_rate", |b| {
        b.iter(|| {
            let m = ekf::gnss_range_rate(
                black_box(&nav),
                &ekf::GnssAntenna::AT_IMU,
                &r_s,
                &v_s,
                100.0,
                0.0,
                0.05,
            );
            ekf::update(&f.p, &m, gates.threshold(1))
        })
    });
    let c_s_b = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
    let c_e_i = UnitQuaternion::from_euler_angles(0.0, 0.0, 1.0)
        .to_rotation_matrix()
        .into_inner();
    let c_s_i = c_s_b * nav.q_e_b.to_rotation_matrix().into_inner().transpose() * c_e_i;
    let q = UnitQuaternion::from_matrix(&c_s_i);
    let kappa = Vector3::new(1e-3, -2e-3, 5e-4);
    let (c_e_i_t, c_s_b_t) = (
        Rotation::from_dcm_unchecked(c_e_i),
        Rotation::from_dcm_unchecked(c_s_b),
    );
    c.bench_function("update_star_tracker_boresight", |b| {
        b.iter(|| {
            let m = ekf::star_attitude(black_box(&nav), &q, &c_e_i_t, &c_s_b_t, &kappa, 1e-5, 1e-4);
            ekf::update(&f.p, &m, gates.threshold(3))
        })
    });
    c.bench_function("update_baro", |b| {
        b.iter(|| {
            let m = ekf::baro_height(black_box(&nav), &WGS84, 181.0, 0.0, 0.5);
            ekf::update(&f.p, &m, gates.threshold(1))
        })
    });
    c.bench_function("update_odometer_nhc", |b| {
        b.iter(|| {
            let m = ekf::odometer_nhc(
                black_box(&nav),
                &ekf::WheelContact::AT_IMU,
                0.0,
                10.2,
                0.05,
                0.05,
            );
            ekf::update(&f.p, &m, gates.threshold(3))
        })
    });
    c.bench_function("update_zupt", |b| {
        b.iter(|| {
            let m = ekf::zero_velocity(black_box(&nav), 0.005);
            ekf::update(&f.p, &m, gates.threshold(3))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
