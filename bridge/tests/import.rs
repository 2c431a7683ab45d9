//! Remote sensors into the local bus: two real `sextant-bridge` processes on loopback, bridge A
//! exporting the `gnss` and `imu` channels of bus A, bridge B importing them into bus B. This
//! test publishes on A and subscribes on B as the fusion daemon would: every sample arrives,
//! in order, identical to the one sent (header, every double to the bit, all 32 satellite
//! slots). Then a stranger on Zenoh puts bytes that are no GNSS message on the same key: the
//! importing bridge counts them and publishes nothing; both bridges stop cleanly on SIGTERM,
//! the importer's exit log naming the undecodable messages.

use msgs::ipc::{Bus, Pub, Sub};
use msgs::{GnssSample, ImuSample, Message};
use std::net::TcpListener;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_sextant-bridge");

struct Bridge(Child);

impl Drop for Bridge {
    fn drop(&mut self) {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(self.0.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
        let _ = self.0.wait();
    }
}

fn bridge(args: &[&str], log: &std::path::Path) -> Bridge {
    Bridge(
        Command::new(BIN)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(log).unwrap())
            .spawn()
            .unwrap(),
    )
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A GNSS sample whose every field differs from the others' and from zero, with values whose
/// decimal forms are long (any rounding on the way would show).
fn gnss(k: u32) -> GnssSample {
    let x = |i: u32| f64::from(k * 1000 + i) / 7.0 + 1e-9;
    let mut g = GnssSample {
        fix_valid: 1,
        n_satellites: 32,
        pos_ecef_m: [x(1) * 1e6, -x(2) * 1e6, x(3) * 1e6],
        vel_ecef_m_s: [x(4), x(5), -x(6)],
        pdop: x(7),
        wavelength_m: 0.190_293_672_798_364_9,
        ..GnssSample::default()
    };
    g.header.time_ns = 1_420_000_000_000_000_000 + i64::from(k) * 1_000_000_000;
    g.pos_cov_ecef_m2 = std::array::from_fn(|i| x(10 + i as u32));
    for (i, s) in g.satellites.iter_mut().enumerate() {
        let i = i as u32;
        s.prn = i + 1;
        s.flags = 3;
        s.pseudorange_m = 2.0e7 + x(100 + i) * 1e3;
        s.cn0_dbhz = 30.0 + x(200 + i) / 1e3;
        s.sat_pos_ecef_m = [x(300 + i) * 1e4, -x(400 + i) * 1e4, x(500 + i) * 1e4];
        s.baseline_phase_cycles = [x(600 + i), -x(700 + i)];
    }
    g
}

/// Send `msg` (probes with time 0 first) until one arrives on `sub`, within 20 s.
fn wait_until_linked<T: Message>(publisher: &mut Pub<T>, sub: &Sub<T>) {
    let t0 = Instant::now();
    loop {
        publisher.send(T::default()).unwrap();
        std::thread::sleep(Duration::from_millis(50));
        let mut arrived = false;
        while sub.receive().unwrap().is_some() {
            arrived = true;
        }
        if arrived {
            // Drain the probes still on their way.
            std::thread::sleep(Duration::from_millis(300));
            while sub.receive().unwrap().is_some() {}
            return;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "the bridges never linked"
        );
    }
}

fn receive_n<T: Message>(sub: &Sub<T>, n: usize) -> Vec<T> {
    let mut got = Vec::with_capacity(n);
    let t0 = Instant::now();
    while got.len() < n && t0.elapsed() < Duration::from_secs(10) {
        match sub.receive().unwrap() {
            Some(m) => got.push(m),
            None => std::thread::sleep(Duration::from_millis(1)),
        }
    }
    got
}

#[test]
fn remote_sensor_samples_arrive_on_the_local_bus_unchanged() {
    let pid = std::process::id();
    let (prefix_a, prefix_b) = (format!("brimp_a_{pid}"), format!("brimp_b_{pid}"));
    let key_a = format!("rover{pid}");
    let dir = std::env::temp_dir().join(format!("sextant-bridge-import-{pid}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    let listen_b = format!("tcp/127.0.0.1:{}", free_port());
    let a_args = [
        "--prefix",
        &prefix_a,
        "--key-prefix",
        &key_a,
        "--listen",
        &listen,
    ];
    let _a = bridge(
        &[&a_args[..], &["--export", "gnss,imu", "--name", "a"]].concat(),
        &dir.join("a.log"),
    );
    let b_args = [
        "--prefix",
        &prefix_b,
        "--connect",
        &listen,
        "--listen",
        &listen_b,
    ];
    let b = bridge(
        &[
            &b_args[..],
            &[
                "--export",
                "",
                "--import",
                "gnss,imu",
                "--import-from",
                &key_a,
                "--name",
                "b",
            ],
        ]
        .concat(),
        &dir.join("b.log"),
    );
    let bus_a = Bus::new(&prefix_a, "test-a").unwrap();
    let bus_b = Bus::new(&prefix_b, "test-b").unwrap();
    let mut gnss_pub: Pub<GnssSample> = bus_a.publisher().unwrap();
    let gnss_sub: Sub<GnssSample> = bus_b.subscriber().unwrap();
    let mut imu_pub: Pub<ImuSample> = bus_a.publisher().unwrap();
    let imu_sub: Sub<ImuSample> = bus_b.subscriber().unwrap();
    wait_until_linked(&mut gnss_pub, &gnss_sub);
    wait_until_linked(&mut imu_pub, &imu_sub);

    // GNSS: 20 full samples.
    let sent: Vec<GnssSample> = (1..=20).map(|k| gnss_pub.send(gnss(k)).unwrap()).collect();
    let got = receive_n(&gnss_sub, sent.len());
    assert_eq!(got.len(), sent.len(), "GNSS samples lost");
    for (s, g) in sent.iter().zip(&got) {
        assert_eq!(s, g, "GNSS sample {} changed on the way", s.header.seq);
    }

    // IMU: a burst of 1000 (a second at 1 kHz), every one in order.
    let mut sent = Vec::new();
    for k in 1..=1000u32 {
        let mut s = ImuSample {
            dt_s: 0.001,
            ..ImuSample::default()
        };
        s.header.time_ns = i64::from(k) * 1_000_000;
        s.delta_angle_rad = [f64::from(k) * 1e-7, -1e-9, std::f64::consts::PI * 1e-6];
        s.delta_velocity_m_s = [0.0, 1e-3 / f64::from(k), -9.80665e-3];
        s.n_channels = 4;
        s.channel_axis[3] = [0.577_350_269_189_625_8; 3];
        s.channel_delta_angle_rad[3] = f64::from(k) * 3e-8;
        sent.push(imu_pub.send(s).unwrap());
    }
    let got = receive_n(&imu_sub, sent.len());
    assert_eq!(got.len(), sent.len(), "IMU samples lost");
    assert!(sent == got, "IMU samples changed or reordered on the way");

    // A stranger connected to B puts garbage on A's GNSS key: counted, never published.
    use zenoh::Wait;
    let mut c = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_string()),
        ("connect/endpoints", format!("[\"{listen_b}\"]")),
        ("listen/endpoints", "[]".into()),
        ("scouting/multicast/enabled", "false".into()),
        ("scouting/gossip/enabled", "false".into()),
    ] {
        c.insert_json5(k, &v).unwrap();
    }
    let stranger = zenoh::open(c).wait().unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let key = format!("{key_a}/v1/gnss");
    for garbage in [
        &b"\xff\xff\xff\xff"[..],
        b"not protobuf at all",
        &[0x0a, 0x80][..],
    ] {
        stranger.put(&key, garbage).wait().unwrap();
    }
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        gnss_sub.receive().unwrap().is_none(),
        "garbage reached the local bus"
    );
    stranger.close().wait().unwrap();
    drop(b);
    let log = std::fs::read_to_string(dir.join("b.log")).unwrap();
    assert!(log.contains("does not decode"), "{log}");
    assert!(log.contains("3 undecodable"), "{log}");
}
