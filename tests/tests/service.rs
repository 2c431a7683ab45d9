//! The fusion daemon as a `Type=notify` service: this test plays the service manager. It binds
//! a datagram socket of its own, starts the real `sextant-fusion` with `NOTIFY_SOCKET`,
//! `WATCHDOG_USEC` and `WATCHDOG_PID` pointing at it (as systemd does), and checks the
//! `sd_notify` protocol: `READY=1` with a `STATUS=` naming the mode, `WATCHDOG=1` often enough
//! for the watchdog never to fire, `STOPPING=1` on SIGTERM, then a clean exit. Also checks the
//! unit file shipped in `dist/systemd/` asks for what the daemon provides.

use sextant_tests::*;
use std::os::unix::net::UnixDatagram;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn out_dir(name: &str) -> PathBuf {
    tempdir(&format!("service-{name}"))
}

/// Watchdog timeout given to the daemon. It pings every half of it from its main loop, which
/// wakes at least every 100 ms (its stop-check interval), so consecutive pings are at most
/// 0.5·T + 0.1 s apart (0.6 s here) on an idle machine; the watchdog fires only past T = 1 s.
const WATCHDOG: Duration = Duration::from_secs(1);

#[test]
fn fusion_notifies_ready_status_watchdog_and_stopping() {
    let _g = MACHINE.shared();
    let dir = out_dir("notify");
    let sock_path = dir.join("notify.sock");
    let manager = UnixDatagram::bind(&sock_path).unwrap();
    manager
        .set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let prefix = format!("sextant_service_{}", std::process::id());
    // WATCHDOG_PID names the service's main process, as systemd sets it: the shell's own pid,
    // which `exec` hands on to the daemon.
    let mut cmd = Command::new("/bin/sh");
    cmd.current_dir(repo_root())
        .arg("-c")
        .arg(r#"export WATCHDOG_PID=$$; exec "$0" "$@""#)
        .arg(bin("sextant-fusion").unwrap())
        .args([
            "--config",
            "config/sextant.toml",
            "--prefix",
            &prefix,
            "--out",
        ])
        .arg(dir.join("recording.mcap"))
        .env("NOTIFY_SOCKET", &sock_path)
        .env("WATCHDOG_USEC", WATCHDOG.as_micros().to_string())
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    let t0 = Instant::now();
    let mut child = cmd.spawn().unwrap();

    // Collect datagrams for 3 s of running.
    let mut got: Vec<(Duration, String)> = Vec::new();
    let mut buf = [0u8; 4096];
    while t0.elapsed() < Duration::from_secs(3) {
        if let Ok(n) = manager.recv(&mut buf) {
            got.push((
                t0.elapsed(),
                String::from_utf8_lossy(&buf[..n]).into_owned(),
            ));
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "daemon exited: {got:?}"
        );
    }
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let stop_t = Instant::now();
    let status = loop {
        if let Ok(n) = manager.recv(&mut buf) {
            got.push((
                t0.elapsed(),
                String::from_utf8_lossy(&buf[..n]).into_owned(),
            ));
        }
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            stop_t.elapsed() < Duration::from_secs(10),
            "no exit after SIGTERM"
        );
    };
    while let Ok(n) = manager.recv(&mut buf) {
        got.push((
            t0.elapsed(),
            String::from_utf8_lossy(&buf[..n]).into_owned(),
        ));
    }
    assert!(status.success(), "exit status {status}: {got:?}");

    // READY=1 first, with the mode in STATUS= (no sensor runs: initializing).
    let (t_ready, first) = &got[0];
    assert!(
        first.lines().any(|l| l == "READY=1")
            && first.lines().any(|l| l.starts_with("STATUS=initializing")),
        "{got:?}"
    );
    // Watchdog pings from READY until SIGTERM, never further apart than the timeout allows.
    let pings: Vec<Duration> = got
        .iter()
        .filter(|(_, m)| m.lines().any(|l| l == "WATCHDOG=1"))
        .map(|(t, _)| *t)
        .collect();
    let before_stop = t0.elapsed() - stop_t.elapsed();
    assert!(
        pings.len() >= 4,
        "{} pings in {:?}: {got:?}",
        pings.len(),
        before_stop - *t_ready
    );
    let mut gaps: Vec<Duration> = pings.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.push(pings[0] - *t_ready);
    let worst = gaps.iter().max().unwrap();
    assert!(*worst < WATCHDOG, "longest gap between pings {worst:?}");
    // STOPPING=1 at the end.
    assert!(
        got.iter()
            .any(|(_, m)| m.lines().any(|l| l == "STOPPING=1")),
        "{got:?}"
    );
    eprintln!(
        "READY after {t_ready:?}, {} watchdog pings, longest gap {worst:?}",
        pings.len()
    );
}

#[test]
fn unit_file_asks_for_what_the_daemon_provides() {
    let unit = std::fs::read_to_string(repo_root().join("dist/systemd/sextant-fusion.service"))
        .expect("unit file");
    let has = |line: &str| unit.lines().any(|l| l.trim() == line);
    for line in [
        "Type=notify",
        "NotifyAccess=main",
        "Restart=on-failure",
        "User=sextant",
        "ConfigurationDirectory=sextant",
        "StandardError=journal",
    ] {
        assert!(has(line), "unit file lacks {line}");
    }
    let watchdog = unit
        .lines()
        .find_map(|l| l.trim().strip_prefix("WatchdogSec="))
        .expect("WatchdogSec");
    assert!(watchdog.ends_with('s'), "{watchdog}");
    // The configuration it starts with lives under /etc/sextant.
    assert!(unit.contains("--config /etc/sextant/sextant.toml"));
}
