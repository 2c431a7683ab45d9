//! Proves that `Strapdown::step` allocates nothing: a counting global allocator wraps the
//! system allocator for this test binary, and the count must not move across steps with every
//! integrator and gravity model (after a warm-up step that fills the coning/sculling history).

use nalgebra::{UnitQuaternion, Vector3};
use sextant_fusion::earth::{Geodetic, GravityModel, WGS84};
use sextant_fusion::strapdown::{
    Integrator, MechanizationConfig, NavState, Strapdown, stationary_increment,
};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn strapdown_step_allocates_nothing() {
    // The counter works: a heap allocation moves it.
    let probe = ALLOCATIONS.load(Ordering::SeqCst);
    let boxed = std::hint::black_box(Box::new([1.0_f64; 4]));
    assert!(ALLOCATIONS.load(Ordering::SeqCst) > probe);
    drop(boxed);
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
            let before = ALLOCATIONS.load(Ordering::SeqCst);
            for _ in 0..100 {
                sd.step(&mut state, &inc);
            }
            let after = ALLOCATIONS.load(Ordering::SeqCst);
            assert_eq!(after - before, 0, "{integrator:?}/{gravity:?} allocated");
            assert!(state.r_e.iter().all(|x| x.is_finite()));
        }
    }
}
