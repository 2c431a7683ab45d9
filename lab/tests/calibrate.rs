//! `sextant calibrate boresight` over a real MCAP: a static stand recorded by the daemons'
//! recorder from the simulator's own driver sources (`config/scenarios/astro_stand.toml`,
//! 1 200 s, IMU 100 Hz, star tracker 1 Hz, κ = (0.30°, 0.45°, −0.35°)).

use drivers_sim::scenario::Scenario;
use drivers_sim::sources::{ImuSource, SampleSource, StarTrackerSource};
use sextant_lab::calibrate::{self, BoresightOptions, SiteArg};
use sextant_lab::recorder::{Record, Recorder, RecorderOptions};
use std::path::{Path, PathBuf};
use std::process::Command;

const DURATION_S: i64 = 1200;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("sextant-calibrate-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("tmp dir");
    d
}

/// Record `DURATION_S` of the stand into `path`, messages in time order (star tracker before
/// the IMU sample of the same instant, as the offline stream orders them).
fn record_stand(path: &Path) -> Scenario {
    let scn = Scenario::load(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/scenarios/astro_stand.toml"),
    )
    .expect("scenario");
    let epoch = scn.epoch_gps().ns;
    let mut imu = ImuSource::new(&scn, epoch);
    let mut st = StarTrackerSource::new(&scn, epoch);
    let rec = Recorder::start(path, &RecorderOptions::default()).expect("recorder");
    let imu_p = imu.period_ns();
    let st_p = st.period_ns();
    let (mut ki, mut ks) = (imu.first_index(), st.first_index());
    let end = DURATION_S * 1_000_000_000;
    loop {
        let (ti, ts) = (ki * imu_p, ks * st_p);
        if ti > end && ts > end {
            break;
        }
        if ts <= ti {
            assert!(rec.record_blocking(Record::StarTracker(st.sample(ts)), 0));
            ks += 1;
        } else {
            assert!(rec.record_blocking(Record::Imu(imu.sample(ti)), 0));
            ki += 1;
        }
    }
    rec.finish().expect("finish");
    scn
}

/// Calibrated vs uncalibrated, and κ against the truth. Physics of the bounds:
/// - uncalibrated, the fix is off by the mounting tilt: R·|(κ2, κ3)| ≈ 6.37e6·0.57° ≈ 63 km;
/// - calibrated, κ's tilt absorbs the IMU vertical error of the window (the accelerometer
///   bias over g: 250 µg 1-σ per axis ⇒ ≤ 0.05° at 3σ each), so |κ̂ − κ| in κ2, κ3 is below
///   0.05°, and the fixes after the window are off only by the vertical's drift and noise: a
///   few hundred metres, ≥ 10× below the uncalibrated error;
/// - κ1 (about the vertical) comes from gyrocompassing in stage 1: navigation-grade gyro bias
///   0.01°/h ⇒ 0.01/(15·cos 55.7°) rad ≈ 0.07° 1-σ; bound 0.3°. The least-squares methods
///   hardly observe it on a static stand (a rotation about the vertical moves no astro fix;
///   they report a σ of ≈ 0.9°): their κ1 is checked against 3 of their own σ.
#[test]
fn calibrates_a_recorded_static_stand() {
    let t0 = std::time::Instant::now();
    let dir = tmp("stand");
    let mcap = dir.join("stand.mcap");
    let scn = record_stand(&mcap);
    let kd = scn.spec.star_tracker.mounting_kappa_deg;
    let out = dir.join("out");
    let s = calibrate::boresight(&BoresightOptions {
        recording: mcap.clone(),
        site: SiteArg {
            lat_deg: scn.spec.site.lat_deg,
            lon_deg: scn.spec.site.lon_deg,
            height_m: scn.spec.site.height_m,
        },
        out: out.clone(),
        window_s: 600.0,
    })
    .expect("calibration");
    eprintln!("{}", calibrate::table(&s));
    assert_eq!(s["samples"].as_u64(), Some(DURATION_S as u64));
    let m = &s["methods"];
    let uncal = m["uncalibrated"]["mean_fix_error_m"].as_f64().expect("u");
    assert!(
        (55_000.0..75_000.0).contains(&uncal),
        "uncalibrated {uncal} m"
    );
    for name in [
        "three_stage",
        "least_squares_window",
        "least_squares_all_samples",
    ] {
        let e = m[name]["mean_fix_error_m"].as_f64().expect("e");
        assert!(e * 10.0 < uncal, "{name}: {e} m vs uncalibrated {uncal} m");
        let k = |j: usize| m[name]["kappa_deg"][j].as_f64().expect("κ");
        assert!(
            (k(1) - kd[1]).abs() < 0.05 && (k(2) - kd[2]).abs() < 0.05,
            "{name}: κ {} {} vs {kd:?}",
            k(1),
            k(2)
        );
        let k1_bound = if name == "three_stage" {
            0.3
        } else {
            3.0 * s[name]["kappa_sigma_deg"][0].as_f64().expect("σκ1")
        };
        assert!(
            (k(0) - kd[0]).abs() < k1_bound,
            "{name}: κ1 {} vs {} (bound {k1_bound})",
            k(0),
            kd[0]
        );
    }
    assert!(out.join("summary.json").exists());
    assert!(out.join("calibrate_boresight_error_vs_time.png").exists());

    // The command line on the same file.
    let cli = Command::new(env!("CARGO_BIN_EXE_sextant"))
        .args(["calibrate", "boresight"])
        .arg(&mcap)
        .args(["--site", "55.655,37.534,200", "--out"])
        .arg(dir.join("cli"))
        .output()
        .expect("run sextant");
    let stdout = String::from_utf8_lossy(&cli.stdout);
    assert!(
        cli.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&cli.stderr)
    );
    assert!(
        stdout.contains("three stage") && stdout.contains("least squares"),
        "{stdout}"
    );
    assert!(dir.join("cli/summary.json").exists());

    // A truncated copy still calibrates from what is readable, and says so.
    let bytes = std::fs::read(&mcap).expect("read");
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).expect("write");
    let s = calibrate::boresight(&BoresightOptions {
        recording: cut,
        site: SiteArg {
            lat_deg: 55.655,
            lon_deg: 37.534,
            height_m: 200.0,
        },
        out: dir.join("cut"),
        window_s: 600.0,
    })
    .expect("truncated calibration");
    assert!(
        s["read_error"]
            .as_str()
            .is_some_and(|e| e.contains("truncated")),
        "{}",
        s["read_error"]
    );
    eprintln!("{:.1} s", t0.elapsed().as_secs_f64());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_inputs_get_clear_errors() {
    let dir = tmp("bad");
    let not_mcap = dir.join("x.mcap");
    std::fs::write(&not_mcap, b"hello").expect("write");
    let out = Command::new(env!("CARGO_BIN_EXE_sextant"))
        .args(["calibrate", "boresight"])
        .arg(&not_mcap)
        .args(["--site", "55.6,37.5,0"])
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("x.mcap") && err.contains("not an MCAP"),
        "{err}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_sextant"))
        .args(["calibrate", "boresight"])
        .arg(&not_mcap)
        .args(["--site", "55.6;37.5"])
        .output()
        .expect("run");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("LAT,LON,H"), "{err}");
    assert!("91,0,0".parse::<SiteArg>().is_err());
    assert!("-33.9,151.2,10".parse::<SiteArg>().is_ok());
    let _ = std::fs::remove_dir_all(&dir);
}
