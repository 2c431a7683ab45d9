//! The `sextant-fusion` command line, run as a real process. (Having integration tests in this
//! package also makes `cargo test --workspace` build the `sextant-fusion` binary, which the
//! end-to-end tests in `tests/` start.)

use std::process::Command;

#[test]
fn fusion_daemon_rejects_a_malformed_config_naming_the_file() {
    let dir = std::env::temp_dir().join(format!("sextant-badcfg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cfg = dir.join("sextant.toml");
    std::fs::write(&cfg, "[system]\nprefix = 3\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_sextant-fusion"))
        .arg("--config")
        .arg(&cfg)
        .args(["--out"])
        .arg(dir.join("r.mcap"))
        .output()
        .expect("run sextant-fusion");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("sextant.toml"),
        "error does not name the file: {err}"
    );
}
