//! The `sextant` command's surface, run as a real process. (Having integration tests in this
//! package also makes `cargo test --workspace` build the `sextant` binary, which the end-to-end
//! tests in `tests/` start.)

use std::process::Command;

#[test]
fn help_lists_the_subcommands() {
    let out = Command::new(env!("CARGO_BIN_EXE_sextant"))
        .arg("--help")
        .output()
        .expect("run sextant --help");
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for sub in ["run", "experiment"] {
        assert!(text.contains(sub), "--help lacks {sub}: {text}");
    }
}

#[test]
fn unknown_experiment_is_a_clear_error_naming_the_known_ones() {
    let dir = std::env::temp_dir().join(format!("sextant-cli-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_sextant"))
        .args(["experiment", "no-such-experiment", "--out"])
        .arg(&dir)
        .output()
        .expect("run sextant experiment");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no-such-experiment") && err.contains("schuler"),
        "{err}"
    );
}
