//! The filter thread's time slice: the daemon asks the scheduler for a short one
//! ([`FILTER_SLICE_NS`]), by default and without privileges, for the latency from IMU sample
//! to solution on a computer whose cores are shared with drivers and tools.
//!
//! Why it helps: Linux's fair scheduler (EEVDF, since 6.6; custom slices since 6.12) runs the
//! task with the earliest virtual deadline, a task's deadline is its virtual runtime plus its
//! slice, and a waking task with a shorter slice than the running one may preempt it. The
//! filter thread sleeps between IMU samples and works a few microseconds on each, so a short
//! slice costs it nothing and lets it take its core at once when a sample wakes it, instead of
//! waiting for a driver or the recorder to use up a default slice (0.75–3 ms). Measured with
//! `sextant bench` at 1 kHz: the median latency at the bare iceoryx2 round trip's instead of
//! 1–3 µs above it, and the 99.9th percentile below it (README, "Benchmarks").
//!
//! A hint, not a guarantee (that is `[fusion.realtime]`): a kernel before 6.12 ignores it,
//! and one that refuses it (e.g. a sandbox filtering `sched_setattr`) leaves the default
//! slice; the daemon says so and runs as it would without.

/// Time slice the filter thread asks for, ns: the shortest the kernel grants (it clamps
/// requests to 0.1–100 ms).
pub const FILTER_SLICE_NS: u64 = 100_000;

use crate::realtime::{errno_text, last_errno};

/// Why the slice was not set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum TimeSliceError {
    /// `getpriority` failed (the thread's nice value, kept as it is).
    #[error("read the filter thread's nice value: {}", errno_text(*.errno))]
    Nice {
        /// The system's error number.
        errno: i32,
    },
    /// `sched_setattr` refused.
    #[error("ask for a {} µs time slice: {}", FILTER_SLICE_NS / 1000, errno_text(*.errno))]
    SetAttr {
        /// The system's error number.
        errno: i32,
    },
}

/// `struct sched_attr` of `sched_setattr(2)`, its first version (48 bytes): the kernel reads
/// `size` bytes and takes the fields it does not know as zero.
#[repr(C)]
#[derive(Default)]
struct SchedAttr {
    size: u32,
    sched_policy: u32,
    sched_flags: u64,
    sched_nice: i32,
    sched_priority: u32,
    sched_runtime: u64,
    sched_deadline: u64,
    sched_period: u64,
}

/// Ask for a [`FILTER_SLICE_NS`] time slice for the calling thread, keeping the normal
/// time-sharing policy and the thread's nice value. Call it from the filter thread before
/// `[fusion.realtime]` (a SCHED_FIFO priority set there replaces the policy and with it the
/// slice).
pub fn apply_short_slice() -> Result<(), TimeSliceError> {
    // getpriority may return -1 as a value: errno tells it from a failure.
    // SAFETY: __errno_location is the calling thread's errno; getpriority takes integers.
    let nice = unsafe {
        *libc::__errno_location() = 0;
        libc::getpriority(libc::PRIO_PROCESS, 0)
    };
    if nice == -1 && last_errno() != 0 {
        return Err(TimeSliceError::Nice {
            errno: last_errno(),
        });
    }
    let attr = SchedAttr {
        size: std::mem::size_of::<SchedAttr>() as u32,
        sched_policy: libc::SCHED_OTHER as u32,
        sched_nice: nice,
        sched_runtime: FILTER_SLICE_NS,
        ..Default::default()
    };
    // SAFETY: pid 0 is the calling thread; `attr` is a valid sched_attr we own with its size
    // set, read by the kernel only; flags 0.
    let r = unsafe { libc::syscall(libc::SYS_sched_setattr, 0, &attr as *const SchedAttr, 0) };
    if r != 0 {
        return Err(TimeSliceError::SetAttr {
            errno: last_errno(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The calling thread's slice as the scheduler reports it (`se.slice` of
    /// `/proc/thread-self/sched`, ns); `None` on a kernel that does not report it.
    fn reported_slice_ns() -> Option<u64> {
        let text = std::fs::read_to_string("/proc/thread-self/sched").ok()?;
        let line = text.lines().find(|l| l.starts_with("se.slice"))?;
        let v: f64 = line.split(':').nth(1)?.trim().parse().ok()?;
        Some(v as u64)
    }

    /// On a kernel with custom slices (6.12+: it reports `se.slice`) the thread's slice
    /// becomes the one asked for, and its nice value stays; on an older kernel the call is
    /// accepted and changes nothing (a thread of its own, so that the harness's keep theirs).
    #[test]
    fn the_filter_thread_gets_the_short_slice_and_keeps_its_nice_value() {
        std::thread::spawn(|| {
            // SAFETY: setpriority/getpriority take integers only; who = 0 is this thread.
            unsafe { libc::setpriority(libc::PRIO_PROCESS, 0, 3) };
            let before = reported_slice_ns();
            apply_short_slice().unwrap();
            assert_eq!(unsafe { libc::getpriority(libc::PRIO_PROCESS, 0) }, 3);
            let policy = unsafe { libc::sched_getscheduler(0) };
            assert_eq!(policy, libc::SCHED_OTHER);
            if let Some(before) = before {
                assert_ne!(before, FILTER_SLICE_NS, "the default slice is longer");
                assert_eq!(reported_slice_ns(), Some(FILTER_SLICE_NS));
            }
        })
        .join()
        .unwrap();
    }
}
