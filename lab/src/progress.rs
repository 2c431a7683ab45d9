//! Progress bars of the offline commands (replay, report, the analysis after a run or replay,
//! import, export, experiments), on stderr. A bar is drawn only when stderr is a terminal and
//! `sextant --quiet` was not given ([`set_quiet`]), so that logs, pipes and tests get none.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};

static QUIET: AtomicBool = AtomicBool::new(false);

/// Hide every progress bar from now on (`sextant --quiet`).
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// Whether bars are drawn: stderr is a terminal and quiet was not asked for.
pub fn enabled() -> bool {
    !QUIET.load(Ordering::Relaxed) && std::io::stderr().is_terminal()
}

fn styled(bar: indicatif::ProgressBar, template: &str, what: &str) -> indicatif::ProgressBar {
    if let Ok(style) = indicatif::ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(what.to_string());
    bar
}

/// A bar of `len` steps labelled `what`; hidden unless [`enabled`] and `show`.
pub fn steps(show: bool, len: u64, what: &str) -> indicatif::ProgressBar {
    if !(show && enabled()) {
        return indicatif::ProgressBar::hidden();
    }
    styled(
        indicatif::ProgressBar::new(len),
        "{msg:28} [{bar:40}] {percent:>3}% {elapsed_precise} eta {eta}",
        what,
    )
}

/// A bar over the `len` bytes of a file being read, labelled `what`; hidden unless
/// [`enabled`] and `show`.
pub fn bytes(show: bool, len: u64, what: &str) -> indicatif::ProgressBar {
    if !(show && enabled()) {
        return indicatif::ProgressBar::hidden();
    }
    styled(
        indicatif::ProgressBar::new(len),
        "{msg:28} [{bar:40}] {bytes}/{total_bytes} {elapsed_precise} eta {eta}",
        what,
    )
}

/// The size of the recording at `path` in bytes, over its segments (0 when it cannot be read:
/// the bar then shows bytes without a total).
pub fn file_len(path: &std::path::Path) -> u64 {
    crate::recording::recording_len(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quiet hides every bar, whatever the terminal.
    #[test]
    fn quiet_hides_the_bars() {
        set_quiet(true);
        assert!(!enabled());
        assert!(steps(true, 10, "x").is_hidden());
        assert!(bytes(true, 10, "x").is_hidden());
        set_quiet(false);
        assert!(steps(false, 10, "x").is_hidden());
    }
}
