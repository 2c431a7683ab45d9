//! The service manager's notification protocol, `sd_notify(3)` (systemd; the same datagrams
//! are understood by other supervisors that implement it): newline-separated `KEY=VALUE`
//! assignments sent as one datagram to the `AF_UNIX` socket named by the environment variable
//! `NOTIFY_SOCKET` (a file-system path, or `@name` for the abstract namespace).
//!
//! `sextant run` plays the service manager for its own children (every driver and the fusion
//! daemon get a socket of their own and a `WATCHDOG_USEC`): a child whose pings stop is hung
//! and is killed and restarted. Drivers send `READY=1` and `WATCHDOG=1` ([`Service::ping`]).
//!
//! The fusion daemon, run as a `Type=notify` service (`dist/systemd/sextant-fusion.service`)
//! or under `sextant run`, sends
//! - `READY=1` once its bus endpoints and recording are open, i.e. once it can take sensor
//!   data: the drivers ordered after it may start. Not "once navigating": navigation needs
//!   those drivers' data, so waiting for it would deadlock a start-up ordered on readiness;
//!   the navigation state is in `STATUS=` instead;
//! - `STATUS=<mode>, <n> solutions, <m> records dropped` whenever the mode changes;
//! - `WATCHDOG=1` every half of `WATCHDOG_USEC` (the interval `sd_watchdog_enabled(3)`
//!   recommends), from the filter loop itself, so that a filter thread that hangs stops the
//!   pings and the service manager restarts it;
//! - `STOPPING=1` when it begins to shut down.
//!
//! Without `NOTIFY_SOCKET` (not started by a service manager) everything here is a no-op. A
//! failed send is logged once and otherwise ignored: the service manager's absence must never
//! stop navigation.

use std::os::unix::net::{SocketAddr, UnixDatagram};
use std::time::{Duration, Instant};

/// Errors of setting up the notification socket.
#[derive(Debug, thiserror::Error)]
pub enum NotifyError {
    /// `NOTIFY_SOCKET` is set but names no usable socket address.
    #[error("NOTIFY_SOCKET={value:?} is not a socket path or @abstract name: {detail}")]
    BadAddress {
        /// The variable's value.
        value: String,
        /// Why it is unusable.
        detail: String,
    },
    /// The datagram socket could not be created.
    #[error("cannot create the notification socket: {0}")]
    Socket(std::io::Error),
    /// A notification could not be sent.
    #[error("cannot send {state:?} to NOTIFY_SOCKET: {source}")]
    Send {
        /// The assignments that were not sent.
        state: String,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// A connection to the service manager's notification socket.
#[derive(Debug)]
pub struct Notifier {
    socket: UnixDatagram,
    addr: SocketAddr,
}

impl Notifier {
    /// The notifier named by `NOTIFY_SOCKET`, `Ok(None)` when the variable is unset or empty.
    pub fn from_env() -> Result<Option<Self>, NotifyError> {
        match std::env::var("NOTIFY_SOCKET") {
            Ok(v) if !v.is_empty() => Self::new(&v).map(Some),
            _ => Ok(None),
        }
    }

    /// A notifier sending to `address` (a path, or `@name` for the abstract namespace).
    pub fn new(address: &str) -> Result<Self, NotifyError> {
        let bad = |detail: String| NotifyError::BadAddress {
            value: address.to_string(),
            detail,
        };
        let addr = if let Some(name) = address.strip_prefix('@') {
            use std::os::linux::net::SocketAddrExt;
            SocketAddr::from_abstract_name(name.as_bytes()).map_err(|e| bad(e.to_string()))?
        } else if address.starts_with('/') {
            SocketAddr::from_pathname(address).map_err(|e| bad(e.to_string()))?
        } else {
            return Err(bad("neither an absolute path nor @name".into()));
        };
        let socket = UnixDatagram::unbound().map_err(NotifyError::Socket)?;
        Ok(Self { socket, addr })
    }

    /// Send `state` (newline-separated `KEY=VALUE` assignments) in one datagram.
    pub fn notify(&self, state: &str) -> Result<(), NotifyError> {
        self.socket
            .send_to_addr(state.as_bytes(), &self.addr)
            .map(|_| ())
            .map_err(|source| NotifyError::Send {
                state: state.to_string(),
                source,
            })
    }
}

/// The watchdog interval asked for by the service manager: `WATCHDOG_USEC` µs, when
/// `WATCHDOG_PID` is unset or names this process (`sd_watchdog_enabled(3)`).
pub fn watchdog_timeout() -> Option<Duration> {
    let usec: u64 = std::env::var("WATCHDOG_USEC").ok()?.parse().ok()?;
    if let Ok(pid) = std::env::var("WATCHDOG_PID")
        && pid.parse::<u32>().ok() != Some(std::process::id())
    {
        return None;
    }
    (usec > 0).then(|| Duration::from_micros(usec))
}

/// What the daemon tells the service manager, driven from its main loop ([`Service::tick`]).
#[derive(Debug)]
pub struct Service {
    notifier: Option<Notifier>,
    /// Half the watchdog timeout, when the watchdog is on.
    ping_every: Option<Duration>,
    last_ping: Instant,
    ready: bool,
    last_mode: Option<u32>,
    failed: bool,
}

impl Service {
    /// From the environment the service manager set (`NOTIFY_SOCKET`, `WATCHDOG_USEC`,
    /// `WATCHDOG_PID`); inert when there is none. A bad `NOTIFY_SOCKET` is logged, not fatal.
    pub fn from_env() -> Self {
        let notifier = Notifier::from_env().unwrap_or_else(|e| {
            tracing::error!("{e}; not notifying the service manager");
            None
        });
        let ping_every = notifier
            .as_ref()
            .and_then(|_| watchdog_timeout())
            .map(|t| t / 2);
        if let Some(p) = ping_every {
            tracing::info!("service watchdog: pinging every {p:?}");
        }
        Self {
            notifier,
            ping_every,
            last_ping: Instant::now(),
            ready: false,
            last_mode: None,
            failed: false,
        }
    }

    /// True when a service manager listens.
    pub fn is_active(&self) -> bool {
        self.notifier.is_some()
    }

    fn send(&mut self, state: &str) {
        if let Some(n) = &self.notifier
            && let Err(e) = n.notify(state)
            && !self.failed
        {
            self.failed = true;
            tracing::warn!("{e} (further failures not logged)");
        }
    }

    /// Called from the main loop at every wake-up: `READY=1` the first time, `STATUS=` when the
    /// mode changed, `WATCHDOG=1` when half the watchdog timeout has passed since the last.
    pub fn tick(&mut self, mode: u32, solutions: u64, records_dropped: u64) {
        if self.notifier.is_none() {
            return;
        }
        let mode_changed = self.last_mode != Some(mode);
        if !self.ready || mode_changed {
            self.last_mode = Some(mode);
            let name = crate::NavMode::from_u32(mode).map_or("unknown mode", |m| m.name());
            let mut state =
                format!("STATUS={name}, {solutions} solutions, {records_dropped} records dropped");
            if !self.ready {
                self.ready = true;
                state.insert_str(0, "READY=1\n");
            }
            self.send(&state);
        }
        self.ping();
    }

    /// For a process without a navigation mode (a driver), called at every wake-up:
    /// `READY=1` the first time, then `WATCHDOG=1` when half the watchdog timeout has passed.
    pub fn ping(&mut self) {
        if self.notifier.is_none() {
            return;
        }
        if !self.ready {
            self.ready = true;
            self.send("READY=1");
        }
        if let Some(every) = self.ping_every
            && self.last_ping.elapsed() >= every
        {
            self.last_ping = Instant::now();
            self.send("WATCHDOG=1");
        }
    }

    /// `STATUS=text` (and `READY=1` the first time): for a process whose state is not a
    /// navigation mode (the bridge's link). `text` is one line.
    pub fn status(&mut self, text: &str) {
        if self.notifier.is_none() {
            return;
        }
        let mut state = format!("STATUS={text}");
        if !self.ready {
            self.ready = true;
            state.insert_str(0, "READY=1\n");
        }
        self.send(&state);
    }

    /// `STOPPING=1`: the daemon is shutting down.
    pub fn stopping(&mut self) {
        if self.notifier.is_some() {
            self.send("STOPPING=1\nSTATUS=stopping");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn datagrams_reach_a_path_socket_and_an_abstract_one() {
        let dir = std::env::temp_dir().join(format!("sextant-sdnotify-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("notify.sock");
        let _ = std::fs::remove_file(&path);
        let server = UnixDatagram::bind(&path).unwrap();
        Notifier::new(path.to_str().unwrap())
            .unwrap()
            .notify("READY=1\nSTATUS=x")
            .unwrap();
        let mut buf = [0u8; 64];
        let n = server.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"READY=1\nSTATUS=x");

        use std::os::linux::net::SocketAddrExt;
        let name = format!("sextant-sdnotify-{}", std::process::id());
        let addr = SocketAddr::from_abstract_name(name.as_bytes()).unwrap();
        let server = UnixDatagram::bind_addr(&addr).unwrap();
        Notifier::new(&format!("@{name}"))
            .unwrap()
            .notify("WATCHDOG=1")
            .unwrap();
        let n = server.recv(&mut buf).unwrap();
        assert_eq!(&buf[..n], b"WATCHDOG=1");
    }

    #[test]
    fn a_relative_address_is_an_error_naming_it() {
        let e = Notifier::new("relative/sock").unwrap_err().to_string();
        assert!(e.contains("relative/sock"), "{e}");
    }
}
