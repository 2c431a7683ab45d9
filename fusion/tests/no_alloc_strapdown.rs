//! Proves that `Strapdown::step` allocates nothing: a counting global allocator wraps the
//! system allocator for this test binary (`common`: the test's own thread only), and the
//! count must not move across steps with every integrator and gravity model (after a warm-up
//! step that fills the coning/sculling history).

use crate::common;
use common::{count, track_this_thread};
use nalgebra::{UnitQuaternion, Vector3};
use sextant_fusion::earth::{Geodetic, GravityModel, WGS84};
use sextant_fusion::strapdown::{
    Integrator, MechanizationConfig, NavState, Strapdown, stationary_increment,
};

#[test]
fn strapdown_step_allocates_nothing() {
    // Checks that the counter works: a heap allocation moves it.
    track_this_thread();
    let site = Geodetic {
        lat_rad: 0.97,
        lon_rad: 0.65,
        height_m: 150.0,
    };
    let q_n_b = UnitQuaternion::from_euler_angles(0.01, -0.02, 1.0);
    for integrator in [Integrator::Euler, Integrator::Heun, Integrator::Rk4] {
        for gravity in [
            GravityModel::J2,
            GravityModel::Normal,
            GravityModel::PointMass,
        ] {
            let config = MechanizationConfig {
                ellipsoid: WGS84,
                gravity,
                integrator,
                coning_sculling: true,
            };
            let mut state = NavState::from_geodetic(&WGS84, &site, &Vector3::zeros(), &q_n_b);
            let mut inc = stationary_increment(&WGS84, gravity, &state.r_e, &state.q_e_b, 0.005);
            inc.delta_angle_rad += Vector3::new(1e-4, -2e-4, 3e-4);
            let mut sd = Strapdown::new(config);
            sd.step(&mut state, &inc);
            let before = count();
            for _ in 0..100 {
                sd.step(&mut state, &inc);
            }
            let after = count();
            assert_eq!(after - before, 0, "{integrator:?}/{gravity:?} allocated");
            assert!(state.r_e.iter().all(|x| x.is_finite()));
        }
    }
}
