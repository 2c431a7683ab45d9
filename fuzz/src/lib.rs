//! Fuzz targets: one function per parser of outside input, each taking arbitrary bytes. A
//! target must never panic, abort or hang; errors are the expected outcome of bad input.
//!
//! - [`system_config`]: `config/sextant.toml` (TOML → `SystemConfig`, validation) and the filter
//!   tuning (`NavigatorConfig`).
//! - [`scenario`]: a scenario file (TOML → `Scenario`, grades resolved from `config/sensors`).
//! - [`recording`]: an MCAP recording given to `daemons::recording::read_all` (replay, report).
//! - [`samples`]: the navigator's sample validation: the bytes are cut into messages of every
//!   type with arbitrary bit patterns in every field, pushed into an aligned navigator; a
//!   rejected sample must leave its state bit-identical and every accepted one finite.
//!
//! The functions have the libFuzzer signature, so with a nightly toolchain they can be wrapped in
//! `libfuzzer_sys::fuzz_target!` as they are; on stable the `sextant-fuzz` binary drives them.

pub mod fixture;

use fusion::navigator::Navigator;
use msgs::{BaroSample, GnssSample, Header, ImuSample, OdometerSample, StarTrackerSample};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The repository root (parent of `fuzz/`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map_or_else(|| PathBuf::from(".."), Path::to_path_buf)
}

/// Names of the targets.
pub const TARGETS: [&str; 4] = ["system_config", "scenario", "recording", "samples"];

/// Run target `name` on `data`; false for an unknown name.
pub fn run_target(name: &str, data: &[u8]) -> bool {
    match name {
        "system_config" => system_config(data),
        "scenario" => scenario(data),
        "recording" => recording(data),
        "samples" => samples(data),
        _ => return false,
    }
    true
}

/// The system configuration and the filter tuning from arbitrary bytes (as text).
pub fn system_config(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let f = Path::new("fuzz/sextant.toml");
    if let Ok(c) = sextant_daemons::config::SystemConfig::parse(&text, f) {
        let _ = c.validate(f);
    }
    let _ = sextant_daemons::config::parse_navigator_config(&text, Path::new("fuzz/filter.toml"));
}

/// A scenario from arbitrary bytes (as text); grades resolve from the shipped `config/sensors`.
pub fn scenario(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let path = repo_root().join("config/scenarios/fuzz.toml");
    if let Ok(s) = drivers_sim::scenario::Scenario::from_toml_str(&text, &path) {
        // A valid scenario must also give sane derived values.
        assert!(
            s.duration_ns() >= 0,
            "negative duration of a valid scenario"
        );
    }
}

/// An MCAP recording from arbitrary bytes, read to its end.
pub fn recording(data: &[u8]) {
    thread_local! {
        static PATH: PathBuf = std::env::temp_dir().join(format!(
            "sextant-fuzz-{}-{:?}.mcap",
            std::process::id(),
            std::thread::current().id()
        ));
    }
    PATH.with(|p| {
        if std::fs::write(p, data).is_ok()
            && let Ok(out) = sextant_daemons::recording::read_all(p)
            && let Some(e) = out.error
        {
            assert!(!e.to_string().is_empty());
        }
    });
}

/// Reads little-endian fields from the input, zero past its end.
struct Bytes<'a> {
    data: &'a [u8],
    at: usize,
}

impl Bytes<'_> {
    fn u64(&mut self) -> u64 {
        let mut b = [0u8; 8];
        for x in &mut b {
            *x = self.data.get(self.at).copied().unwrap_or(0);
            self.at += 1;
        }
        u64::from_le_bytes(b)
    }
    fn u32(&mut self) -> u32 {
        self.u64() as u32
    }
    fn f64(&mut self) -> f64 {
        f64::from_bits(self.u64())
    }
    fn f3(&mut self) -> [f64; 3] {
        [self.f64(), self.f64(), self.f64()]
    }
    fn header(&mut self) -> Header {
        Header {
            time_ns: self.u64() as i64,
            seq: self.u64(),
            status: self.u32(),
            reserved: 0,
            send_mono_ns: self.u64(),
        }
    }
    fn done(&self) -> bool {
        self.at >= self.data.len()
    }
}

/// A navigator of a level static site after alignment (built once, cloned per input), and the
/// last IMU sample it took.
fn aligned() -> &'static (Navigator, ImuSample) {
    static NAV: OnceLock<(Navigator, ImuSample)> = OnceLock::new();
    NAV.get_or_init(|| {
        let text = std::fs::read_to_string(repo_root().join("config/filter.toml"))
            .expect("config/filter.toml");
        fixture::aligned_static_navigator(&text).expect("navigator fixture")
    })
}

/// Messages with arbitrary bit patterns into an aligned navigator. The first byte of each
/// message picks its type; with its low bit set, the header is a plausible continuation of the
/// IMU stream (so the message reaches the value checks) instead of raw bits.
pub fn samples(data: &[u8]) {
    let (nav0, last) = aligned();
    let mut nav = nav0.clone();
    let mut b = Bytes { data, at: 0 };
    let mut t = last.header.time_ns;
    let mut seq = last.header.seq;
    while !b.done() {
        let kind = b.data[b.at];
        b.at += 1;
        let mut header = b.header();
        if kind & 1 == 1 {
            t += 5_000_000;
            seq += 1;
            header.time_ns = t;
            header.seq = seq;
        }
        let before = *nav.nav_state();
        let p = *nav.covariance();
        let h0 = nav.health();
        let (id, ok) = match (kind >> 1) % 5 {
            0 => {
                let mut s = ImuSample {
                    header,
                    dt_s: b.f64(),
                    delta_angle_rad: b.f3(),
                    delta_velocity_m_s: b.f3(),
                    n_channels: b.u32() % 16,
                    turntable_angle_rad: b.f64(),
                    ..Default::default()
                };
                for i in 0..(s.n_channels as usize).min(msgs::MAX_IMU_CHANNELS) {
                    s.channel_axis[i] = b.f3();
                    s.channel_delta_angle_rad[i] = b.f64();
                    s.channel_delta_velocity_m_s[i] = b.f64();
                    s.channel_temperature_c[i] = b.f64();
                }
                if std::env::var_os("SEXTANT_FUZZ_VERBOSE").is_some() {
                    eprintln!("{s:?}");
                }
                (0, nav.push_imu(&s).is_ok())
            }
            1 => {
                let s = StarTrackerSample {
                    header,
                    q_sensor_icrf: [b.f64(), b.f64(), b.f64(), b.f64()],
                    sigma_cross_rad: b.f64(),
                    sigma_roll_rad: b.f64(),
                    n_stars: b.u32(),
                    valid: b.u32() % 2,
                    ..Default::default()
                };
                (1, nav.push_star_tracker(&s).is_ok())
            }
            2 => {
                let mut g = GnssSample {
                    header,
                    fix_valid: b.u32() % 2,
                    n_satellites: b.u32() % 64,
                    pos_ecef_m: b.f3(),
                    vel_ecef_m_s: b.f3(),
                    pdop: b.f64(),
                    ..Default::default()
                };
                for x in g.pos_cov_ecef_m2.iter_mut() {
                    *x = b.f64();
                }
                for x in g.vel_cov_ecef_m2_s2.iter_mut() {
                    *x = b.f64();
                }
                (2, nav.push_gnss(&g).is_ok())
            }
            3 => {
                let o = OdometerSample {
                    header,
                    dt_s: b.f64(),
                    distance_m: b.f64(),
                    speed_m_s: b.f64(),
                    ..Default::default()
                };
                (3, nav.push_odometer(&o).is_ok())
            }
            _ => {
                let s = BaroSample {
                    header,
                    pressure_pa: b.f64(),
                    temperature_c: b.f64(),
                    ..Default::default()
                };
                (4, nav.push_baro(&s).is_ok())
            }
        };
        if std::env::var_os("SEXTANT_FUZZ_VERBOSE").is_some() {
            eprintln!(
                "sensor {id} accepted {ok} header {header:?} finite {} r_e {:?}",
                fixture::state_is_finite(&nav),
                nav.nav_state().r_e
            );
        }
        let h1 = nav.health();
        assert_eq!(h1[id].received, h0[id].received + 1, "received not counted");
        if !ok {
            assert_eq!(
                h1[id].rejected_invalid,
                h0[id].rejected_invalid + 1,
                "rejection not counted"
            );
            assert!(
                *nav.nav_state() == before,
                "a rejected sample changed the state"
            );
            assert!(
                *nav.covariance() == p,
                "a rejected sample changed the covariance"
            );
        }
        assert!(
            fixture::state_is_finite(&nav),
            "an accepted sample made the state non-finite"
        );
    }
}
