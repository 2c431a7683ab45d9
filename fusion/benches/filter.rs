//! Criterion benches of the error-state Kalman filter: one covariance prediction (IMU step)
//! and each measurement update.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use sextant_fusion::earth::{Geodetic, WGS84};
use sextant_fusion::ekf::{self, Covariance, ErrorStateEkf, GateTable};
use sextant_fusion::navigator::ImuSpec;
use sextant_fusion::strapdown::NavState;
use std::hint::black_box;

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
    (
        ErrorStateEkf::new(p0, ImuSpec::default().process_noise()),
        nav,
    )
}

fn bench(c: &mut Criterion) {
    let (mut f, nav) = setup();
    let f_b = Vector3::new(0.1, 0.0, -9.81);
    c.bench_function("ekf_predict_200hz", |b| {
        b.iter(|| f.predict(&WGS84, black_box(&nav), black_box(&f_b), 0.005))
    });
    let (f, nav) = setup();
    let gates = GateTable::new(0.999);
    let cov = Matrix3::identity() * 4.0;
    let z = nav.r_e + Vector3::new(1.0, -1.0, 0.5);
    c.bench_function("update_gnss_position", |b| {
        b.iter(|| {
            let m = ekf::gnss_position(black_box(&nav), &z, &cov);
            ekf::update(&f.p, &m, gates.threshold(3))
        })
    });
    let zv = nav.v_e + Vector3::new(0.01, 0.0, 0.0);
    let covv = Matrix3::identity() * 1e-4;
    c.bench_function("update_gnss_velocity", |b| {
        b.iter(|| {
            let m = ekf::gnss_velocity(black_box(&nav), &zv, &covv);
            ekf::update(&f.p, &m, gates.threshold(3))
        })
    });
    let c_s_b = Matrix3::new(1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0);
    let c_e_i = UnitQuaternion::from_euler_angles(0.0, 0.0, 1.0)
        .to_rotation_matrix()
        .into_inner();
    let c_s_i = c_s_b * nav.q_e_b.to_rotation_matrix().into_inner().transpose() * c_e_i;
    let q = UnitQuaternion::from_matrix(&c_s_i);
    c.bench_function("update_star_tracker", |b| {
        b.iter(|| {
            let m = ekf::star_attitude(black_box(&nav), &q, &c_e_i, &c_s_b, 1e-5, 1e-4);
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
            let m = ekf::odometer_nhc(black_box(&nav), 0.0, 10.2, 0.05, 0.05);
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
