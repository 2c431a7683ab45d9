//! Logging of every Sextant process: `tracing` to stderr, filtered by `RUST_LOG` (default
//! `info`), where **a failed write is never fatal**.
//!
//! A process's stderr is its log file (`sextant run` redirects it into `OUT/logs/`), so a full
//! disk makes every write to it fail with ENOSPC. `tracing-subscriber` reports such a failure
//! with `eprintln!`, which panics when stderr itself is the failing file — a full disk would
//! kill every process through its log. Here the failure is swallowed and counted instead
//! ([`lost_lines`]): navigation matters more than its log, and the writes resume by
//! themselves when space returns.

use std::io::Write;
use std::sync::atomic::{AtomicU64, Ordering};

static LOST: AtomicU64 = AtomicU64::new(0);

/// Log lines (or status-line updates) that could not be written since the process started.
pub fn lost_lines() -> u64 {
    LOST.load(Ordering::Relaxed)
}

/// stderr whose write errors are counted in [`lost_lines`] and reported as success, so that
/// no caller (tracing, a status line) ever fails or panics because of its log.
#[derive(Debug, Clone, Copy, Default)]
pub struct LossyStderr;

impl Write for LossyStderr {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if std::io::stderr().write_all(buf).is_err() {
            LOST.fetch_add(1, Ordering::Relaxed);
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        if std::io::stderr().flush().is_err() {
            LOST.fetch_add(1, Ordering::Relaxed);
        }
        Ok(())
    }
}

/// Write `text` to stderr at once (no newline added); a failure is counted, never raised.
pub fn stderr_text(text: &str) {
    let mut e = LossyStderr;
    let _ = e.write_all(text.as_bytes());
    let _ = e.flush();
}

/// Write `text` and a newline to stdout; a failure (full disk, closed pipe) is ignored, so that
/// printing a table never ends the process (`println!` panics on a failed write).
pub fn stdout_line(text: &str) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{text}");
    let _ = out.flush();
}

/// Install the process's `tracing` subscriber: stderr through [`LossyStderr`], filter from
/// `RUST_LOG` (default `info`), and no internal-error reports (they go through `eprintln!`);
/// iceoryx2's own log at its errors only unless its environment variable says otherwise.
/// A second call is a no-op.
pub fn init() {
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Error);
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(|| LossyStderr)
        .log_internal_errors(false)
        .try_init();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lossy_stderr_reports_success() {
        let mut e = LossyStderr;
        assert_eq!(e.write(b"").unwrap(), 0);
        assert!(e.flush().is_ok());
    }
}
