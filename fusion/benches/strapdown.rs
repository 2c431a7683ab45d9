//! Time of one `Strapdown::step` per integrator (J2 gravity, coning/sculling on).

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{UnitQuaternion, Vector3};
use sextant_fusion::earth::{Geodetic, GravityModel, WGS84};
use sextant_fusion::strapdown::{
    Integrator, MechanizationConfig, NavState, Strapdown, stationary_increment,
};
use std::hint::black_box;

fn bench_step(c: &mut Criterion) {
    let site = Geodetic {
        lat_rad: 0.97,
        lon_rad: 0.65,
        height_m: 150.0,
    };
    let q_n_b = UnitQuaternion::from_euler_angles(0.01, -0.02, 1.0);
    for integrator in [Integrator::Euler, Integrator::Heun, Integrator::Rk4] {
        let config = MechanizationConfig {
            ellipsoid: WGS84,
            gravity: GravityModel::J2,
            integrator,
            coning_sculling: true,
        };
        let mut state = NavState::from_geodetic(&WGS84, &site, &Vector3::zeros(), &q_n_b);
        let inc = stationary_increment(&WGS84, GravityModel::J2, &state.r_e, &state.q_e_b, 0.005);
        let mut sd = Strapdown::new(config);
        c.bench_function(&format!("strapdown_step_{integrator:?}"), |b| {
            b.iter(|| sd.step(black_box(&mut state), black_box(&inc)))
        });
    }
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
