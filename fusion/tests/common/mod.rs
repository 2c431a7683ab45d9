//! The counting global allocator shared by the no-allocation tests: it forwards to the system
//! allocator and counts, per thread, the `alloc`/`realloc` calls made on threads that called
//! [`track_this_thread`] — only the test's own thread, so that the harness's other threads
//! (still setting up when a fast test starts, or running the other tests of the binary in
//! parallel) cannot make the count flaky. Each test uses a part of this module.
#![allow(dead_code)]

pub mod samples;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    /// Set on the test thread: only its allocations are counted.
    static TRACKED: Cell<bool> = const { Cell::new(false) };
    /// Allocations of this thread while tracked (per thread: the tests of the binary run on
    /// parallel threads, each counting its own).
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn note() {
    if TRACKED.try_with(Cell::get).unwrap_or(false) {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
    }
}

// SAFETY: forwards to the system allocator unchanged; only counts calls.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Count the allocations of the calling thread from now on, after checking that the counting
/// allocator is in place (a test that cannot see allocations would pass vacuously).
pub fn track_this_thread() {
    TRACKED.with(|t| t.set(true));
    let probe = count();
    let boxed = std::hint::black_box(Box::new([1.0_f64; 4]));
    assert!(count() > probe, "the counting allocator must work");
    drop(boxed);
}

/// A static site of the tests: its geodetic position, ECEF position (m) and the body → ECEF
/// attitude of a level vehicle heading 0.7 rad.
pub fn static_site(
    lat_deg: f64,
    lon_deg: f64,
    height_m: f64,
) -> (
    sextant_fusion::earth::Geodetic,
    nalgebra::Vector3<f64>,
    nalgebra::UnitQuaternion<f64>,
) {
    use sextant_fusion::earth::{Geodetic, WGS84, geodetic_to_ecef};
    let site = Geodetic {
        lat_rad: lat_deg.to_radians(),
        lon_rad: lon_deg.to_radians(),
        height_m,
    };
    let r_e = geodetic_to_ecef(&WGS84, &site);
    let q_e_b = sextant_fusion::strapdown::q_e_n(site.lat_rad, site.lon_rad)
        * nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, 0.7);
    (site, r_e, q_e_b)
}

/// Allocations counted so far on the calling thread.
pub fn count() -> usize {
    ALLOCATIONS.with(Cell::get)
}
