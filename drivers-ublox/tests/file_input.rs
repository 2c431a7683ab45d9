//! The driver binary on a file (`--file`): garbage before a valid NMEA sentence is skipped and
//! counted byte for byte, the sentence is read (a GGA alone has no date, so no sample), and the process ends at the end of the file with
//! its counters as JSON on stdout. (Also what makes `cargo test` build the binary that the
//! pseudo-terminal end-to-end test in `tests/tests/gnss_ublox.rs` starts.)

use std::process::Command;

#[test]
fn garbage_is_counted_and_a_valid_sentence_is_read_from_a_file() {
    let dir = std::env::temp_dir().join(format!("sextant-ublox-file-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let garbage = b"no receiver here!";
    let mut bytes = garbage.to_vec();
    // The NMEA 0183 standard's GGA example, with its checksum.
    bytes.extend_from_slice(
        b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n",
    );
    let file = dir.join("input.nmea");
    std::fs::write(&file, &bytes).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sextant-gnss-ublox"))
        .arg("--file")
        .arg(&file)
        .args([
            "--prefix",
            &format!("sextant_ublox_file_{}", std::process::id()),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&out.stdout)));
    assert_eq!(
        report["framing"]["skipped_bytes"].as_u64(),
        Some(garbage.len() as u64),
        "{report}"
    );
    assert_eq!(
        report["framing"]["nmea_sentences"].as_u64(),
        Some(1),
        "{report}"
    );
    // GGA has a time of day but no date: no sample can be dated, and that is counted.
    assert_eq!(
        report["epochs"]["epochs_undated"].as_u64(),
        Some(1),
        "{report}"
    );
    assert_eq!(
        report["epochs"]["samples_published"].as_u64(),
        Some(0),
        "{report}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
