//! Real-time settings of the fusion daemon's filter thread, for a computer dedicated to
//! navigation (`[fusion.realtime]`): the thread pinned to one CPU (no migration, a warm cache),
//! scheduled SCHED_FIFO above every time-shared process (a build or a log rotation cannot
//! preempt it), and the process's memory locked in RAM (no page fault that waits for a disk on
//! the path from IMU sample to solution).
//!
//! Applied to the calling thread only (the filter thread, after the recorder's and the
//! checkpoint writer's threads have started, so that those keep the normal policy and any
//! CPU); memory locking is process-wide. A setting the operating system refuses stops the
//! daemon with an error naming the setting, the system's reason and what grants it: a
//! computer configured for real time that silently runs without it would be worse.

use serde::{Deserialize, Serialize};

/// `[fusion.realtime]` (absent: none of it).
#[derive(Debug, Clone, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RealtimeSection {
    /// Pin the filter thread to this CPU (0-based, as in `/proc/cpuinfo`); absent: any CPU.
    #[serde(default)]
    pub cpu: Option<usize>,
    /// Run the filter thread under SCHED_FIFO at this priority, 1 ..= 99 (above every
    /// time-shared thread; keep it below the kernel's own real-time threads, e.g. 50);
    /// absent: the normal time-sharing policy.
    #[serde(default)]
    pub priority: Option<u8>,
    /// Lock the process's memory, present and future, in RAM (`mlockall`).
    #[serde(default)]
    pub lock_memory: bool,
}

impl RealtimeSection {
    /// Whether any setting is asked for.
    pub fn any(&self) -> bool {
        self.cpu.is_some() || self.priority.is_some() || self.lock_memory
    }

    /// Check the values (not whether the system grants them): the message for the key
    /// `fusion.realtime.*` it names.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if let Some(p) = self.priority
            && !(1..=99).contains(&p)
        {
            return Err((
                "fusion.realtime.priority",
                format!("must be a SCHED_FIFO priority 1 ..= 99, got {p}"),
            ));
        }
        Ok(())
    }
}

/// Why a real-time setting could not be applied. `errno` is the system's error number
/// (printed as its text).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RealtimeError {
    /// The CPU asked for does not exist or is not available to this process.
    #[error(
        "fusion.realtime.cpu = {cpu}: not a CPU this process may run on (it may use CPUs {allowed})"
    )]
    NoSuchCpu {
        /// The CPU asked for.
        cpu: usize,
        /// The CPUs allowed, as a count of the lowest ones (`0..allowed`) when contiguous.
        allowed: CpuRange,
    },
    /// `sched_setaffinity` refused.
    #[error("fusion.realtime.cpu = {cpu}: the system refused to pin the filter thread: {}", errno_text(*.errno))]
    Affinity {
        /// The CPU asked for.
        cpu: usize,
        /// The system's error number.
        errno: i32,
    },
    /// `sched_setscheduler(SCHED_FIFO)` refused.
    #[error(
        "fusion.realtime.priority = {priority}: the system refused SCHED_FIFO: {}; it needs CAP_SYS_NICE or a real-time priority limit of at least {priority} (`ulimit -r`, `LimitRTPRIO=` in the systemd unit)",
        errno_text(*.errno)
    )]
    Priority {
        /// The priority asked for.
        priority: u8,
        /// The system's error number.
        errno: i32,
    },
    /// `mlockall` refused.
    #[error(
        "fusion.realtime.lock_memory: the system refused to lock the daemon's memory: {}; it needs CAP_IPC_LOCK or a locked-memory limit above the daemon's size (`ulimit -l`, `LimitMEMLOCK=` in the systemd unit)",
        errno_text(*.errno)
    )]
    LockMemory {
        /// The system's error number.
        errno: i32,
    },
}

/// The CPUs a process may use, `first ..= last`, for messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CpuRange {
    /// Lowest allowed CPU.
    pub first: usize,
    /// Highest allowed CPU.
    pub last: usize,
}

impl std::fmt::Display for CpuRange {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}–{}", self.first, self.last)
    }
}

/// The system's text for an error number (for the messages of the scheduling errors).
pub(crate) fn errno_text(errno: i32) -> String {
    std::io::Error::from_raw_os_error(errno).to_string()
}

/// The calling thread's last system error number (0 if none).
pub(crate) fn last_errno() -> i32 {
    std::io::Error::last_os_error().raw_os_error().unwrap_or(0)
}

/// The CPUs the calling thread may run on now.
fn allowed_cpus() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; sched_getaffinity writes at most its
    // size into the set we own.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return Vec::new();
        }
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect()
    }
}

/// Apply `rt` to the calling thread (and, for memory, the process), in the order memory, CPU,
/// priority. Returns at the first refusal; what was applied before it stays applied (the
/// daemon stops on the error anyway).
pub fn apply(rt: &RealtimeSection) -> Result<(), RealtimeError> {
    if rt.lock_memory {
        // SAFETY: mlockall takes flags only.
        if unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) } != 0 {
            return Err(RealtimeError::LockMemory {
                errno: last_errno(),
            });
        }
    }
    if let Some(cpu) = rt.cpu {
        let allowed = allowed_cpus();
        if !allowed.contains(&cpu) {
            return Err(RealtimeError::NoSuchCpu {
                cpu,
                allowed: CpuRange {
                    first: allowed.first().copied().unwrap_or(0),
                    last: allowed.last().copied().unwrap_or(0),
                },
            });
        }
        // SAFETY: as in `allowed_cpus`; `cpu` < CPU_SETSIZE since it is in the allowed set.
        let r = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
        };
        if r != 0 {
            return Err(RealtimeError::Affinity {
                cpu,
                errno: last_errno(),
            });
        }
    }
    if let Some(priority) = rt.priority {
        let param = libc::sched_param {
            sched_priority: i32::from(priority),
        };
        // SAFETY: pid 0 = the calling thread; the parameter is a valid struct we own.
        if unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) } != 0 {
            return Err(RealtimeError::Priority {
                priority,
                errno: last_errno(),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cpu_the_process_may_not_use_is_refused_by_name() {
        let rt = RealtimeSection {
            cpu: Some(100_000),
            ..Default::default()
        };
        let e = apply(&rt).unwrap_err();
        assert!(
            matches!(e, RealtimeError::NoSuchCpu { cpu: 100_000, .. }),
            "{e}"
        );
        assert!(
            e.to_string().starts_with("fusion.realtime.cpu = 100000"),
            "{e}"
        );
    }

    #[test]
    fn refusals_name_the_setting_the_reason_and_the_remedy() {
        let e = RealtimeError::Priority {
            priority: 50,
            errno: libc::EPERM,
        }
        .to_string();
        assert!(e.contains("fusion.realtime.priority = 50"), "{e}");
        assert!(e.contains("Operation not permitted"), "{e}");
        assert!(
            e.contains("CAP_SYS_NICE") && e.contains("LimitRTPRIO"),
            "{e}"
        );
        let e = RealtimeError::LockMemory {
            errno: libc::ENOMEM,
        }
        .to_string();
        assert!(
            e.contains("fusion.realtime.lock_memory") && e.contains("LimitMEMLOCK"),
            "{e}"
        );
    }

    #[test]
    fn priorities_outside_sched_fifo_are_invalid() {
        for (p, ok) in [(0u8, false), (1, true), (99, true), (100, false)] {
            let rt = RealtimeSection {
                priority: Some(p),
                ..Default::default()
            };
            assert_eq!(rt.validate().is_ok(), ok, "{p}");
        }
        assert!(!RealtimeSection::default().any());
    }

    /// Pinning to a CPU the thread may use works without privileges (on a thread of its own,
    /// so that the test harness's threads keep their CPUs).
    #[test]
    fn pinning_to_an_allowed_cpu_takes_effect() {
        let cpu = *allowed_cpus().last().unwrap();
        std::thread::spawn(move || {
            apply(&RealtimeSection {
                cpu: Some(cpu),
                ..Default::default()
            })
            .unwrap();
            assert_eq!(allowed_cpus(), vec![cpu]);
        })
        .join()
        .unwrap();
    }
}
