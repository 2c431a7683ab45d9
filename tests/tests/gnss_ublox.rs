//! The receiver driver end to end, through a real tty: a pseudo-terminal pair stands in for the
//! serial cable. The test plays a u-blox receiver on the master side — UBX epochs (RXM-RAWX,
//! NAV-SAT, NAV-PVT) and NMEA epochs (RMC, GGA, GSA, GST) of a static site, on the simulated
//! clock, with garbage bytes, frames with bad checksums and truncated frames among them — while
//! a real `sextant-gnss-ublox` reads the slave side and a real `sextant-fusion` (with the
//! simulated IMU of the same scenario) fuses what the driver publishes.
//!
//! Checked: the driver skips exactly the injected bytes and counts each injected fault; every
//! sample it published reached the fusion daemon, which took it for a GNSS receiver like the
//! simulator (schema-valid records of both origins, GNSS fused after alignment, none rejected)
//! and navigates on it (GNSS-inertial, metre-level error and sigma at the site).

use drivers_ublox::framing::{nmea_sentence, ubx_frame};
use drivers_ublox::nmea::{TimeOfDay, format_angle, format_time};
use drivers_ublox::sample::STATUS_FROM_NMEA;
use drivers_ublox::ubx::{NavPvt, NavSat, NavSatSv, Rawx, RawxMeas};
use fusion::earth::{Geodetic, WGS84, geodetic_to_ecef};
use msgs::SensorId;
use nix::fcntl::{FcntlArg, FdFlag, fcntl};
use nix::sys::signal::{Signal, kill};
use nix::sys::termios;
use nix::unistd::Pid;
use sextant_tests::*;
use std::io::Write;
use std::os::fd::{AsFd, AsRawFd};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The site of config/scenarios/static_site.toml.
const LAT_DEG: f64 = 55.655;
const LON_DEG: f64 = 37.534;
const HEIGHT_M: f64 = 200.0;
/// The parked car's heading there, deg.
const HEADING_DEG: f64 = 30.0;

/// The receiver's antenna on the parked car: the site (the IMU) plus the antenna's lever arm
/// of the car's filter (`config/filter.toml` [gnss]) turned by the car's heading. The receiver
/// reports where its antenna is. Computed once (every epoch's message uses it).
fn antenna() -> Geodetic {
    static ANTENNA: std::sync::OnceLock<Geodetic> = std::sync::OnceLock::new();
    *ANTENNA.get_or_init(antenna_from_the_filter)
}

fn antenna_from_the_filter() -> Geodetic {
    let text = std::fs::read_to_string(repo_root().join("config/filter.toml")).unwrap();
    let car: fusion::navigator::NavigatorConfig = toml::from_str(&text).unwrap();
    let [x, y, z] = car.gnss.lever_arm_b_m;
    let (s, c) = HEADING_DEG.to_radians().sin_cos();
    let (north, east, down) = (c * x - s * y, s * x + c * y, z);
    let lat = LAT_DEG.to_radians();
    let (r_n, r_e) = fusion::earth::radii_of_curvature(&WGS84, lat);
    Geodetic {
        lat_rad: lat + north / (r_n + HEIGHT_M),
        lon_rad: LON_DEG.to_radians() + east / ((r_e + HEIGHT_M) * lat.cos()),
        height_m: HEIGHT_M - down,
    }
}

/// Its start, 2025-03-20T21:00:00 UTC: a Thursday, so GPS time of week = 4 days + 21 h + 18 s.
const TOW0_MS: u32 = (4 * 86_400 + 21 * 3600 + 18) * 1000;
const TOD0_MS: u32 = 21 * 3600 * 1000;
/// Simulated seconds: 100 s of alignment (config/filter.toml), then GNSS-inertial.
const EPOCHS: u32 = 130;
/// Ten times real time: the delayed-fusion window (1 s simulated) is then 100 ms of wall time,
/// enough for the pty, the driver and the IPC hop on a loaded 2-core machine (at 20× its 50 ms
/// were once exceeded under load and fixes arrived too late to fuse).
const SPEED: f64 = 10.0;

fn ubx_epoch(k: u32) -> Vec<u8> {
    let tow = TOW0_MS + 1000 * k;
    let a = antenna();
    let pvt = NavPvt {
        itow_ms: tow,
        utc: (2025, 3, 20, 21, (k / 60) as u8, (k % 60) as u8),
        valid: 0x07,
        fix_type: 3,
        flags: 1,
        num_sv: 8,
        lat_rad: a.lat_rad,
        lon_rad: a.lon_rad,
        height_m: a.height_m,
        h_acc_m: 2.0,
        v_acc_m: 3.0,
        s_acc_m_s: 0.1,
        pdop: 1.6,
        ..NavPvt::default()
    };
    let sat = NavSat {
        itow_ms: tow,
        svs: (1..=8)
            .map(|prn| NavSatSv {
                gnss_id: 0,
                sv_id: prn,
                cn0_dbhz: 40.0,
                flags: 8,
                ..NavSatSv::default()
            })
            .collect(),
    };
    let rawx = Rawx {
        rcv_tow_s: f64::from(tow) * 1e-3,
        week: 2358,
        leap_s: 18,
        rec_stat: 1,
        meas: (1..=8)
            .map(|prn| RawxMeas {
                pr_m: 2.0e7 + f64::from(prn) * 1.0e5,
                doppler_hz: 100.0 * f64::from(prn),
                gnss_id: 0,
                sv_id: prn,
                cn0_dbhz: 40.0,
                pr_stdev_m: 0.64,
                doppler_stdev_hz: 0.064,
                trk_stat: 1,
                ..RawxMeas::default()
            })
            .collect(),
    };
    [
        ubx_frame(0x02, 0x15, &rawx.encode()),
        ubx_frame(0x01, 0x35, &sat.encode()),
        ubx_frame(0x01, 0x07, &pvt.encode()),
    ]
    .concat()
}

fn gga(k: u32) -> String {
    let t = format_time(TimeOfDay(TOD0_MS + 1000 * k));
    let a = antenna();
    let lat = format_angle(a.lat_rad, true);
    let lon = format_angle(a.lon_rad, false);
    // MSL altitude + geoid separation = the ellipsoidal height of the antenna.
    let msl = a.height_m - 15.0;
    format!("GNGGA,{t},{lat},{lon},1,08,1.00,{msl:.3},M,15.0,M,,")
}

fn nmea_epoch(k: u32) -> Vec<u8> {
    let t = format_time(TimeOfDay(TOD0_MS + 1000 * k));
    let a = antenna();
    let lat = format_angle(a.lat_rad, true);
    let lon = format_angle(a.lon_rad, false);
    [
        nmea_sentence(&format!("GNRMC,{t},A,{lat},{lon},0.000,,200325,,,A,V")),
        nmea_sentence(&gga(k)),
        nmea_sentence("GNGSA,A,3,01,02,03,04,05,06,07,08,,,,,1.80,1.00,1.50,1"),
        nmea_sentence(&format!("GNGST,{t},3.0,,,,2.0,2.0,3.0")),
    ]
    .concat()
    .into_bytes()
}

/// The system configuration with the car's filter told that this receiver's samples carry
/// its measurement epoch (the u-blox driver stamps each with the receiver's own time of week,
/// where the car's simulated receiver stamps its fix 50 ms late), written into `dir`.
fn config_for_the_ublox_driver(dir: &std::path::Path) -> std::path::PathBuf {
    let root = repo_root();
    let filter = std::fs::read_to_string(root.join("config/filter.toml")).unwrap();
    let at_epoch = filter.replacen("gnss_s = 0.05", "gnss_s = 0.0", 1);
    assert_ne!(
        at_epoch, filter,
        "config/filter.toml changed its [latency] layout"
    );
    std::fs::write(dir.join("filter.toml"), at_epoch).unwrap();
    let system = std::fs::read_to_string(root.join("config/sextant.toml")).unwrap();
    let scenario = root.join("config/scenarios/static_site.toml");
    let edited = system
        .replace(
            "filter = \"filter.toml\"",
            &format!(
                "filter = {:?}",
                dir.join("filter.toml").display().to_string()
            ),
        )
        .replace(
            "scenario = \"scenarios/vehicle.toml\"",
            &format!("scenario = {:?}", scenario.display().to_string()),
        );
    assert!(
        edited.contains(&*dir.to_string_lossy()),
        "config/sextant.toml changed its layout"
    );
    let path = dir.join("sextant.toml");
    std::fs::write(&path, edited).unwrap();
    path
}

/// Faults put in front of some epochs, and what the driver must count for them.
#[derive(Debug, Default)]
struct Injected {
    bytes: u64,
    ubx_checksum: u64,
    nmea_checksum: u64,
    truncated: u64,
}

/// The bytes of epoch `k`, faults included.
fn epoch_bytes(k: u32, inj: &mut Injected) -> Vec<u8> {
    let mut junk: Vec<u8> = Vec::new();
    match k % 10 {
        // Line noise (an 0xB5 not followed by the second sync byte among it).
        3 => junk.extend_from_slice(&[0x00, 0xFF, 0x13, 0xB5, 0x07, b'x', 0x80, b'\r', b'\n']),
        // A NAV-PVT whose payload was damaged on the line.
        5 => {
            let mut f = ubx_frame(
                0x01,
                0x07,
                &NavPvt {
                    itow_ms: 1,
                    ..NavPvt::default()
                }
                .encode(),
            );
            f[30] ^= 0x40;
            junk.extend_from_slice(&f);
            inj.ubx_checksum += 1;
        }
        // A GGA with a changed digit.
        7 => {
            let mut s = nmea_sentence(&gga(k)).into_bytes();
            s[10] = if s[10] == b'9' { b'8' } else { b'9' };
            junk.extend_from_slice(&s);
            inj.nmea_checksum += 1;
        }
        // A sentence cut short (the receiver was plugged in mid-sentence).
        9 => {
            junk.extend_from_slice(&nmea_sentence(&gga(k)).into_bytes()[..25]);
            inj.truncated += 1;
        }
        // A UBX frame cut short: it swallows the start of what follows, fails its checksum,
        // and the scan resumes right after its sync byte.
        1 => {
            junk.extend_from_slice(
                &ubx_frame(
                    0x01,
                    0x07,
                    &NavPvt {
                        itow_ms: 1,
                        ..NavPvt::default()
                    }
                    .encode(),
                )[..30],
            );
            inj.ubx_checksum += 1;
        }
        _ => {}
    }
    // Exact counts need junk that holds no other frame start than its own first byte.
    let starts = |b: u8| b == b'$' || (b == 0xB5 && k % 10 != 3);
    assert!(
        !junk.iter().skip(1).any(|&b| starts(b)),
        "junk of epoch {k} holds a frame start"
    );
    inj.bytes += junk.len() as u64;
    let epoch = if k.is_multiple_of(2) {
        ubx_epoch(k)
    } else {
        nmea_epoch(k)
    };
    [junk, epoch].concat()
}

fn stop(child: &mut Child, name: &str) -> std::process::ExitStatus {
    let _ = kill(Pid::from_raw(child.id() as i32), Signal::SIGTERM);
    wait_exit(child, &format!("{name} stopping"), Duration::from_secs(20))
}

/// Bytes written to the master that the slave side has not read yet.
fn unread(slave: &std::os::fd::OwnedFd) -> i32 {
    let mut n: nix::libc::c_int = 0;
    // SAFETY: FIONREAD writes one int through the pointer, which points to a live c_int.
    let r = unsafe { nix::libc::ioctl(slave.as_raw_fd(), nix::libc::FIONREAD, &mut n) };
    assert_eq!(r, 0, "FIONREAD");
    n
}

#[test]
fn ublox_and_nmea_bytes_through_a_pty_are_fused_and_the_faults_counted() {
    let _g = MACHINE.shared();
    let dir = tempdir("gnss-ublox");
    let prefix = format!("sextant_ublox_{}", std::process::id());
    let root = repo_root();
    let rec_path = dir.join("recording.mcap");

    let pty = nix::pty::openpty(None, None).unwrap();
    // Not inherited by the processes started below: the hang-up at the end must reach the
    // driver when this test closes the master.
    for fd in [&pty.master, &pty.slave] {
        fcntl(fd, FcntlArg::F_SETFD(FdFlag::FD_CLOEXEC)).unwrap();
    }
    // Raw from the start, so that nothing written before the driver configures the line is
    // echoed or translated.
    let mut t = termios::tcgetattr(pty.slave.as_fd()).unwrap();
    termios::cfmakeraw(&mut t);
    termios::tcsetattr(pty.slave.as_fd(), termios::SetArg::TCSANOW, &t).unwrap();
    let slave_path =
        std::fs::read_link(format!("/proc/self/fd/{}", pty.slave.as_raw_fd())).unwrap();

    let start_mono = msgs::monotonic_ns() + 2_000_000_000;
    let config = config_for_the_ublox_driver(&dir);
    let mut fusion = Command::new(bin("sextant-fusion").unwrap())
        .current_dir(&root)
        .arg("--config")
        .arg(&config)
        .args(["--prefix", &prefix])
        .args(["--speed", &SPEED.to_string(), "--out"])
        .arg(&rec_path)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("fusion.log")).unwrap())
        .spawn()
        .unwrap();
    let mut imu = Command::new(bin("sextant-sim-imu").unwrap())
        .current_dir(&root)
        .args([
            "--scenario",
            "config/scenarios/static_site.toml",
            "--prefix",
            &prefix,
        ])
        .args([
            "--speed",
            &SPEED.to_string(),
            "--start-mono-ns",
            &start_mono.to_string(),
        ])
        .args(["--duration", &(EPOCHS + 1).to_string()])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("imu.log")).unwrap())
        .spawn()
        .unwrap();
    let driver = Command::new(bin("sextant-gnss-ublox").unwrap())
        .arg("--device")
        .arg(&slave_path)
        .args(["--baud", "115200", "--prefix", &prefix])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(dir.join("driver.log")).unwrap())
        .spawn()
        .unwrap();

    // Play the receiver on the simulated clock: epoch k at start + k s / speed.
    let mut master = std::fs::File::from(pty.master);
    let mut inj = Injected::default();
    for k in 0..EPOCHS {
        let bytes = epoch_bytes(k, &mut inj);
        let due = start_mono + (f64::from(k) * 1e9 / SPEED) as u64;
        while msgs::monotonic_ns() < due {
            std::thread::sleep(Duration::from_millis(2));
        }
        master.write_all(&bytes).unwrap();
    }
    // Hang up once the driver has read everything: it ends its input like a closed port.
    // The kernel moves bytes from the master to the slave's input queue asynchronously, so an
    // empty queue right after a write proves nothing: it must stay empty for half a second.
    termios::tcdrain(master.as_fd()).unwrap();
    let t0 = Instant::now();
    let mut empty_since = Instant::now();
    while empty_since.elapsed() < Duration::from_millis(500) {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "the driver does not read"
        );
        if unread(&pty.slave) > 0 {
            empty_since = Instant::now();
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    drop(master);
    drop(pty.slave);
    let out = driver.wait_with_output().unwrap();
    let driver_log = std::fs::read_to_string(dir.join("driver.log")).unwrap_or_default();
    assert!(out.status.success(), "driver: {}\n{driver_log}", out.status);
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Two status periods, so that the last status holds every GNSS sample.
    std::thread::sleep(Duration::from_millis(2200));
    let imu_st = stop(&mut imu, "sextant-sim-imu");
    assert!(imu_st.success(), "sim IMU: {imu_st}");
    let st = stop(&mut fusion, "sextant-fusion");
    let fusion_log = std::fs::read_to_string(dir.join("fusion.log")).unwrap_or_default();
    assert!(st.success(), "fusion: {st}\n{fusion_log}");

    // The driver skipped exactly the injected bytes and counted each fault.
    let f = |k: &str| report["framing"][k].as_u64().unwrap();
    let e = |k: &str| report["epochs"][k].as_u64().unwrap();
    eprintln!("driver report: {report}");
    assert_eq!(f("skipped_bytes"), inj.bytes, "{report}");
    assert_eq!(f("ubx_checksum_errors"), inj.ubx_checksum, "{report}");
    assert_eq!(f("nmea_checksum_errors"), inj.nmea_checksum, "{report}");
    assert_eq!(f("truncated_frames"), inj.truncated, "{report}");
    assert_eq!(f("nmea_malformed"), 0);
    assert_eq!(f("ubx_frames"), 3 * u64::from(EPOCHS / 2));
    assert_eq!(f("nmea_sentences"), 4 * u64::from(EPOCHS / 2));
    // Every epoch is published but the first NMEA one: the driver learns each protocol's
    // epoch from its first one, closed only when the next begins, so NMEA epoch 1 is closed
    // at epoch 3, after UBX epoch 2 went out, and is stale.
    assert_eq!(e("samples_published"), u64::from(EPOCHS) - 1, "{report}");
    assert_eq!(e("fixes_published"), u64::from(EPOCHS) - 1);
    assert_eq!(e("epochs_stale"), 1);

    // The fusion daemon received every sample and fused them like the simulator's.
    let rec = read_recording(&rec_path).unwrap();
    assert!(rec.invalid.is_empty(), "{:?}", rec.invalid.first());
    let gnss: Vec<&Record> = rec.topic("gnss").collect();
    assert_eq!(gnss.len() as u64, e("samples_published"));
    let from_nmea = gnss
        .iter()
        .filter(|r| int(&r.json, "/header/status").unwrap() as u32 & STATUS_FROM_NMEA != 0)
        .count();
    assert!(
        from_nmea > 0 && from_nmea < gnss.len(),
        "{from_nmea} of {} from NMEA",
        gnss.len()
    );
    let status = rec.topic("status").last().expect("a status").json.clone();
    let h = |field: &str| {
        int(
            &status,
            &format!("/sensors/{}/{field}", SensorId::Gnss as usize),
        )
        .unwrap() as u64
    };
    assert_eq!(h("received"), e("samples_published"), "{status}");
    assert_eq!(h("rejected_invalid") + h("rejected_gate"), 0, "{status}");
    // Fused after the 100 s alignment: one per simulated second up to 129 s, less those a
    // loaded machine delivers after the delayed-fusion window.
    let fused = h("fused");
    eprintln!(
        "GNSS received {}, fused {fused}, dropped late {}",
        h("received"),
        h("dropped_late")
    );
    assert!(fused >= 15, "GNSS fused {fused}\n{status}");
    let nav = rec.topic("nav").last().expect("a solution").json.clone();
    assert_eq!(
        int(&nav, "/mode").unwrap() as u32,
        msgs::NavMode::GnssInertial as u32,
        "{nav}"
    );
    let site = geodetic_to_ecef(
        &WGS84,
        &Geodetic {
            lat_rad: LAT_DEG.to_radians(),
            lon_rad: LON_DEG.to_radians(),
            height_m: HEIGHT_M,
        },
    );
    let p = f64s(&nav["pos_ecef_m"]);
    let err = ((p[0] - site.x).powi(2) + (p[1] - site.y).powi(2) + (p[2] - site.z).powi(2)).sqrt();
    let sigma = f64s(&nav["pos_sigma_ned_m"]);
    eprintln!("position error {err:.2} m, sigma NED {sigma:?} m");
    // The fixes sit on the site with 2 m (UBX) and 2 m (GST) horizontal sigmas.
    assert!(err < 3.0, "position error {err} m");
    assert!(sigma.iter().all(|s| *s > 0.0 && *s < 3.0), "{sigma:?}");
}
