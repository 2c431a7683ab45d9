//! SIGINT/SIGTERM handling for every Sextant process: a handler that sets a flag (iceoryx2's own
//! signal handling is disabled in `msgs::ipc::Bus`). The handler is installed without
//! `SA_RESTART`, so a blocking WaitSet wait returns at once with an interrupt.

use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
use std::sync::atomic::{AtomicBool, AtomicI32, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);
static LAST_SIGNAL: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_signal(sig: nix::libc::c_int) {
    // Only async-signal-safe operations here: two atomic stores.
    LAST_SIGNAL.store(sig, Ordering::SeqCst);
    STOP.store(true, Ordering::SeqCst);
}

/// Errors installing the handlers.
#[derive(Debug, thiserror::Error)]
#[error("cannot install the {signal} handler: {source}")]
pub struct SignalError {
    /// The signal.
    pub signal: &'static str,
    /// The OS error.
    pub source: nix::Error,
}

/// Install the SIGINT and SIGTERM handlers, and ignore SIGXFSZ (a write beyond the file-size
/// limit then fails with EFBIG, which the recorder handles like a full disk, instead of killing
/// the process); returns the flag the handlers set.
pub fn install() -> Result<&'static AtomicBool, SignalError> {
    // SAFETY: SIG_IGN installs no code.
    unsafe { nix::sys::signal::signal(Signal::SIGXFSZ, SigHandler::SigIgn) }.map_err(|source| {
        SignalError {
            signal: "SIGXFSZ",
            source,
        }
    })?;
    let action = SigAction::new(
        SigHandler::Handler(on_signal),
        SaFlags::empty(),
        SigSet::empty(),
    );
    for (sig, name) in [(Signal::SIGINT, "SIGINT"), (Signal::SIGTERM, "SIGTERM")] {
        // SAFETY: the handler only stores to atomics, which is async-signal-safe.
        unsafe { sigaction(sig, &action) }.map_err(|source| SignalError {
            signal: name,
            source,
        })?;
    }
    Ok(&STOP)
}

/// The stop flag (set by the handlers, or by [`request_stop`]).
pub fn stop_flag() -> &'static AtomicBool {
    &STOP
}

/// Ask the process to stop, as a signal would.
pub fn request_stop() {
    STOP.store(true, Ordering::SeqCst);
}

/// The number of the last signal received (0 = none).
pub fn last_signal() -> i32 {
    LAST_SIGNAL.load(Ordering::SeqCst)
}
