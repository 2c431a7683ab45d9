//! Live test: start real driver processes, subscribe over iceoryx2, check what arrives.

use msgs::ipc::Bus;
use msgs::{GnssSample, ImuSample, TruthSample};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

fn scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/scenarios/static_site.toml")
}

fn spawn(bin: &str, prefix: &str, start: u64, speed: f64, duration: f64) -> Child {
    match Command::new(bin)
        .arg("--scenario")
        .arg(scenario())
        .args(["--prefix", prefix])
        .args(["--start-mono-ns", &start.to_string()])
        .args(["--speed", &speed.to_string()])
        .args(["--duration", &duration.to_string()])
        .spawn()
    {
        Ok(c) => c,
        Err(e) => panic!("spawn {bin}: {e}"),
    }
}

fn wait_exit(child: &mut Child, limit: Duration) -> Option<i32> {
    let t0 = Instant::now();
    while t0.elapsed() < limit {
        if let Ok(Some(status)) = child.try_wait() {
            return status.code();
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let _ = child.kill();
    None
}

/// IMU, GNSS and truth drivers at 10× speed for 3 s of scenario time: every sample arrives,
/// in order, on the GPS time grid, and the processes exit 0.
#[test]
fn drivers_publish_paced_samples_and_exit_cleanly() {
    let prefix = format!("simtest{}", std::process::id());
    let bus = Bus::new(&prefix, "simtest-sub").expect("bus");
    let imu_sub = bus.subscriber::<ImuSample>().expect("imu sub");
    let gnss_sub = bus.subscriber::<GnssSample>().expect("gnss sub");
    let truth_sub = bus.subscriber::<TruthSample>().expect("truth sub");
    let start = msgs::monotonic_ns() + 1_500_000_000;
    let mut children = [
        spawn(
            env!("CARGO_BIN_EXE_sextant-sim-imu"),
            &prefix,
            start,
            10.0,
            3.0,
        ),
        spawn(
            env!("CARGO_BIN_EXE_sextant-sim-gnss"),
            &prefix,
            start,
            10.0,
            3.0,
        ),
        spawn(
            env!("CARGO_BIN_EXE_sextant-sim-truth"),
            &prefix,
            start,
            10.0,
            3.0,
        ),
    ];
    let (mut imu, mut gnss, mut truth) = (Vec::new(), Vec::new(), Vec::new());
    let mut late_ns: u64 = 0;
    let t0 = Instant::now();
    let mut codes = [None; 3];
    while t0.elapsed() < Duration::from_secs(60) {
        while let Ok(Some(s)) = imu_sub.receive() {
            late_ns = late_ns.max(msgs::monotonic_ns().saturating_sub(s.header.send_mono_ns));
            imu.push(s);
        }
        while let Ok(Some(s)) = gnss_sub.receive() {
            gnss.push(s);
        }
        while let Ok(Some(s)) = truth_sub.receive() {
            truth.push(s);
        }
        for (i, c) in children.iter_mut().enumerate() {
            if codes[i].is_none()
                && let Ok(Some(st)) = c.try_wait()
            {
                codes[i] = Some(st.code());
            }
        }
        if codes.iter().all(Option::is_some) {
            // Drain what is left.
            while let Ok(Some(s)) = imu_sub.receive() {
                imu.push(s);
            }
            while let Ok(Some(s)) = gnss_sub.receive() {
                gnss.push(s);
            }
            while let Ok(Some(s)) = truth_sub.receive() {
                truth.push(s);
            }
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    for (i, c) in children.iter_mut().enumerate() {
        if codes[i].is_none() {
            let _ = c.kill();
        }
    }
    assert_eq!(codes, [Some(Some(0)); 3]);
    assert_eq!(imu.len(), 600, "IMU samples");
    assert_eq!(gnss.len(), 4, "GNSS samples (t = 0, 1, 2, 3 s)");
    assert_eq!(truth.len(), 151, "truth samples at 50 Hz incl. t = 0");
    let epoch = truth[0].header.time_ns;
    for (k, s) in imu.iter().enumerate() {
        assert_eq!(s.header.seq, k as u64 + 1);
        assert_eq!(s.header.time_ns, epoch + (k as i64 + 1) * 5_000_000);
        // Not sent before its (scaled) time of validity.
        let due = start + ((k as u64 + 1) * 5_000_000) / 10;
        assert!(s.header.send_mono_ns >= due);
    }
    assert!(gnss.iter().all(|g| g.fix_valid == 1 && g.n_satellites >= 4));
    let h = truth[0].height_m;
    // The site's height, with the IMU mount's vibration (the parked car's engine runs:
    // displacements of micrometres).
    assert!((h - 200.0).abs() < 1e-4, "{h}");
    eprintln!(
        "max IMU send→receive delay seen by a 2 ms poller: {} µs",
        late_ns / 1000
    );
}

/// SIGTERM stops a long run promptly with exit code 0.
#[test]
fn sigterm_stops_cleanly() {
    let prefix = format!("simtestsig{}", std::process::id());
    let start = msgs::monotonic_ns();
    let mut child = spawn(
        env!("CARGO_BIN_EXE_sextant-sim-baro"),
        &prefix,
        start,
        1.0,
        600.0,
    );
    std::thread::sleep(Duration::from_millis(1500));
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).expect("kill");
    let t0 = Instant::now();
    let code = wait_exit(&mut child, Duration::from_secs(5));
    assert_eq!(code, Some(0));
    assert!(
        t0.elapsed() < Duration::from_millis(1000),
        "{:?}",
        t0.elapsed()
    );
}
