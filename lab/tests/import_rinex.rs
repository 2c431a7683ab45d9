//! `import rinex` on the shipped ESBC hour: every epoch becomes a GNSS sample whose
//! measurements reproduce its own fix through `gnss_ls`, and the recording is read by the
//! report and the offline replay.

use fusion::gnss_ls;
use nalgebra::Vector3;
use sextant_lab::import_rinex::{ImportMode, ImportOptions, import_rinex};
use sextant_lab::recorder::Record;
use sextant_lab::recording::Recording;
use std::path::Path;

#[test]
fn esbc_hour_imports_and_reads_back() {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/data/rinex-esbc");
    let dir = std::env::temp_dir().join(format!("sextant-import-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for mode in [ImportMode::L1, ImportMode::IonoFree] {
        let out = dir.join(format!("{mode:?}.mcap"));
        let s = import_rinex(&ImportOptions {
            observation: data.join("ESBC00DNK_R_20201770000_01H_30S_MO.rnx.gz"),
            navigation: data.join("ESBC00DNK_R_20201770000_01D_GN.rnx.gz"),
            out: out.clone(),
            mode,
            elevation_mask_deg: 10.0,
        })
        .unwrap();
        assert_eq!((s.epochs, s.fixed, s.failed), (120, 120, 0), "{s:?}");
        assert!(s.mean_satellites >= 7.0, "{s:?}");
        let station = Vector3::new(3582105.2910, 532589.7313, 5232754.8054);
        let mut n = 0;
        let mut last_t = i64::MIN;
        for entry in Recording::open(&out).unwrap() {
            let Some(Record::Gnss(g)) = entry.unwrap().record else {
                continue;
            };
            n += 1;
            assert_eq!(g.fix_valid, 1);
            assert!(g.header.time_ns > last_t);
            last_t = g.header.time_ns;
            // The samples carry what the solution used: solving them again gives the fix.
            let fix = gnss_ls::solve_sample(&g).unwrap();
            let written = Vector3::from(g.pos_ecef_m);
            assert!((fix.position.r_e_m - written).norm() < 1e-3);
            // A real station: within 10 m, static within 0.5 m/s.
            assert!((written - station).norm() < 10.0);
            assert!(
                Vector3::from(g.vel_ecef_m_s).norm() < 0.5,
                "{:?}",
                g.vel_ecef_m_s
            );
            // The receiver clock of a steered Septentrio is within a millisecond of GPS time:
            // the corrected epochs stay within 1 ms of the 30 s grid.
            let phase = g.header.time_ns.rem_euclid(30_000_000_000);
            assert!(!(1_000_000..29_999_000_000).contains(&phase), "{phase} ns");
        }
        assert_eq!(n, 120);
        // The report reads it to the end (no solutions: a GNSS-only recording has no IMU for the
        // filter), and so does the offline replay.
        let report =
            sextant_lab::report::report(&out, &dir.join(format!("report-{mode:?}"))).unwrap();
        assert!(report.recording_complete && report.recording_error.is_none());
        let replay = sextant_lab::replay::replay_offline(&sextant_lab::replay::OfflineOptions {
            recording: out.clone(),
            out_dir: dir.join(format!("replay-{mode:?}")),
            config: None,
            progress: false,
            segment_duration: None,
            tap: None,
            solution_rate_hz: None,
        });
        let replay = replay.unwrap();
        assert!(replay.recording_complete, "{replay:?}");
        assert_eq!(
            replay.inputs_fed + replay.inputs_rejected,
            120,
            "{replay:?}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
