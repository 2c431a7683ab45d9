//! The counting global allocator shared by the no-allocation tests: it forwards to the system
//! allocator and counts `alloc`/`realloc` calls made on threads that called
//! [`track_this_thread`] — only the test's own thread, so that the harness's other threads
//! (still setting up when a fast test starts) cannot make the count flaky.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Set on the test thread: only its allocations are counted.
    static TRACKED: Cell<bool> = const { Cell::new(false) };
}

fn note() {
    if TRACKED.try_with(Cell::get).unwrap_or(false) {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
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

/// Count the allocations of the calling thread from now on.
pub fn track_this_thread() {
    TRACKED.with(|t| t.set(true));
}

/// Allocations counted so far.
pub fn count() -> usize {
    ALLOCATIONS.load(Ordering::SeqCst)
}
