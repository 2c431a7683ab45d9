//! `sextant-foxglove`'s command line, run as the real binary: its help carries an example, and
//! an invalid prefix is refused by name before anything joins the bus.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_sextant-foxglove");

#[test]
fn help_shows_an_example() {
    let o = Command::new(BIN).arg("--help").output().unwrap();
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("--listen"), "{text}");
    assert!(text.contains("sextant-foxglove --prefix"), "{text}");
}

#[test]
fn an_invalid_prefix_is_refused_by_name() {
    let o = Command::new(BIN)
        .args([
            "--prefix",
            "bad prefix/with spaces",
            "--listen",
            "127.0.0.1:0",
        ])
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--prefix"), "{err}");
}
