//! Test-only publisher of bad input: `sextant-test-publisher --prefix P`.
//!
//! Waits until a fusion daemon on prefix P publishes its status (so that its subscribers
//! exist), then sends over iceoryx2, on the real services, a fixed script of good and bad
//! samples (see [`script`]), and prints what it sent as one JSON line on stdout:
//! `{"imu_sent": N, "imu_bad": B, "gnss_bad": .., "star_tracker_bad": .., "odometer_bad": ..,
//! "baro_bad": .., "imu_seq_skipped": S, "flood": F}`.
//! The end-to-end test (tests/tests/bad_input.rs) compares it with the daemon's status.

use msgs::ipc::Bus;
use msgs::{BaroSample, GnssSample, ImuSample, OdometerSample, StarTrackerSample, Status};
use std::time::{Duration, Instant};

/// GPS time of the first sample: 2024-05-01, ns.
const T0: i64 = 1_398_556_800_000_000_000;
/// IMU period, ns (200 Hz).
const DT_NS: i64 = 5_000_000;
/// Static IMU increments over 5 ms near 55.7° N: specific force −g along z (NED body level),
/// Earth rate; magnitudes only need to be plausible for validation.
fn good_imu(seq: u64, t: i64) -> ImuSample {
    let mut s = ImuSample::default();
    s.header.seq = seq;
    s.header.time_ns = t;
    s.header.send_mono_ns = msgs::monotonic_ns();
    s.dt_s = DT_NS as f64 * 1e-9;
    s.delta_angle_rad = [4.1e-5 * s.dt_s, 0.0, -6.0e-5 * s.dt_s];
    s.delta_velocity_m_s = [0.0, 0.0, -9.815 * s.dt_s];
    s
}

/// The next good sample: sequence number and time advanced by one.
fn next(seq: &mut u64, t: &mut i64) -> ImuSample {
    *seq += 1;
    *t += DT_NS;
    good_imu(*seq, *t)
}

struct Args {
    prefix: String,
    flood: u64,
}

fn args() -> Result<Args, String> {
    let mut prefix = None;
    let mut flood = 20_000;
    let mut it = std::env::args().skip(1);
    while let Some(a) = it.next() {
        match a.as_str() {
            "--prefix" => prefix = it.next(),
            "--flood" => {
                flood = it
                    .next()
                    .and_then(|v| v.parse().ok())
                    .ok_or("--flood needs a count")?
            }
            other => return Err(format!("unknown argument {other}")),
        }
    }
    Ok(Args {
        prefix: prefix.ok_or("--prefix P is required")?,
        flood,
    })
}

fn main() {
    if let Err(e) = script() {
        eprintln!("sextant-test-publisher: {e}");
        std::process::exit(1);
    }
}

/// The script: good IMU, each kind of bad IMU sample, a skipped sequence number, a flood,
/// then one bad sample of every aiding sensor between good ones.
fn script() -> Result<(), String> {
    let a = args()?;
    let bus = Bus::new(&a.prefix, "sextant-test-publisher").map_err(|e| e.to_string())?;
    let status = bus.subscriber::<Status>().map_err(|e| e.to_string())?;
    let mut imu = bus.publisher::<ImuSample>().map_err(|e| e.to_string())?;
    let mut gnss = bus.publisher::<GnssSample>().map_err(|e| e.to_string())?;
    let mut star = bus
        .publisher::<StarTrackerSample>()
        .map_err(|e| e.to_string())?;
    let mut odo = bus
        .publisher::<OdometerSample>()
        .map_err(|e| e.to_string())?;
    let mut baro = bus.publisher::<BaroSample>().map_err(|e| e.to_string())?;
    let t_wait = Instant::now();
    loop {
        if let Ok(Some(_)) = status.receive() {
            break;
        }
        if t_wait.elapsed() > Duration::from_secs(20) {
            return Err("no status from a fusion daemon within 20 s".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let pace = || std::thread::sleep(Duration::from_micros(500));
    let mut seq = 0u64;
    let mut t = T0;
    let mut sent = 0u64;
    let mut send = |s: ImuSample, sent: &mut u64| -> Result<(), String> {
        imu.send_raw(s).map_err(|e| e.to_string())?;
        *sent += 1;
        Ok(())
    };
    for _ in 0..100 {
        let s = next(&mut seq, &mut t);
        send(s, &mut sent)?;
        pace();
    }
    // Bad IMU samples, each with a fresh sequence number and time unless the defect is one
    // of those.
    let mut bad = Vec::new();
    let mut s = next(&mut seq, &mut t);
    s.delta_angle_rad[1] = f64::NAN;
    bad.push(s);
    let mut s = next(&mut seq, &mut t);
    s.delta_velocity_m_s[0] = f64::INFINITY;
    bad.push(s);
    let mut s = next(&mut seq, &mut t);
    s.dt_s = -0.005;
    bad.push(s);
    let mut s = next(&mut seq, &mut t);
    s.delta_angle_rad[2] = 10.0; // 2000 rad/s over 5 ms
    bad.push(s);
    let mut s = next(&mut seq, &mut t);
    s.delta_velocity_m_s[2] = -50.0; // 10 000 m/s² over 5 ms
    bad.push(s);
    let mut s = next(&mut seq, &mut t);
    s.n_channels = 1000;
    bad.push(s);
    // Nothing above was accepted, so the last accepted sample is the 100th good one.
    let last_good_t = T0 + 100 * DT_NS;
    let mut s = next(&mut seq, &mut t);
    s.header.time_ns = last_good_t - DT_NS; // time going backwards
    bad.push(s);
    let mut s = next(&mut seq, &mut t);
    s.header.time_ns = last_good_t; // the same time again
    bad.push(s);
    let mut s = next(&mut seq, &mut t);
    s.header.seq = 100; // duplicate of the last accepted sequence number
    bad.push(s);
    let imu_bad = bad.len() as u64;
    for s in bad {
        send(s, &mut sent)?;
        pace();
    }
    // A skipped sequence number: accepted, a gap of 9.
    seq += 9;
    let s = next(&mut seq, &mut t);
    send(s, &mut sent)?;
    for _ in 0..100 {
        let s = next(&mut seq, &mut t);
        send(s, &mut sent)?;
        pace();
    }
    // The flood: samples back to back, as fast as the transport takes them.
    for _ in 0..a.flood {
        let s = next(&mut seq, &mut t);
        send(s, &mut sent)?;
    }
    std::thread::sleep(Duration::from_millis(200));

    // Aiding sensors: a good sample, a bad one, a good one, at IMU times already passed.
    let ta = t;
    let mut g = GnssSample::default();
    g.header.time_ns = ta + DT_NS;
    g.header.seq = 1;
    g.fix_valid = 1;
    g.pos_ecef_m = [f64::NAN, 0.0, 0.0];
    gnss.send_raw(g).map_err(|e| e.to_string())?;
    g.header.seq = 2;
    g.header.time_ns += DT_NS;
    g.pos_ecef_m = [0.0, 0.0, 0.0]; // the Earth's centre
    gnss.send_raw(g).map_err(|e| e.to_string())?;
    let mut st = StarTrackerSample::default();
    st.header.time_ns = ta + DT_NS;
    st.header.seq = 1;
    st.valid = 1;
    st.q_sensor_icrf = [0.5, 0.5, 0.5, 0.6]; // not a unit quaternion
    st.sigma_cross_rad = 2.4e-5;
    st.sigma_roll_rad = 2.0e-4;
    star.send_raw(st).map_err(|e| e.to_string())?;
    let mut o = OdometerSample::default();
    o.header.time_ns = ta + DT_NS;
    o.header.seq = 1;
    o.dt_s = 0.05;
    o.speed_m_s = 1.0e6;
    o.distance_m = 5.0e4;
    odo.send_raw(o).map_err(|e| e.to_string())?;
    let mut b = BaroSample::default();
    b.header.time_ns = ta + DT_NS;
    b.header.seq = 1;
    b.pressure_pa = -101_325.0;
    b.temperature_c = 15.0;
    baro.send_raw(b).map_err(|e| e.to_string())?;
    // The IMU keeps going for a few more samples.
    for _ in 0..20 {
        let s = next(&mut seq, &mut t);
        send(s, &mut sent)?;
        pace();
    }
    println!(
        "{{\"imu_sent\": {sent}, \"imu_bad\": {imu_bad}, \"gnss_bad\": 2, \"star_tracker_bad\": 1, \
         \"odometer_bad\": 1, \"baro_bad\": 1, \"imu_seq_skipped\": 9, \"flood\": {}}}",
        a.flood
    );
    Ok(())
}
