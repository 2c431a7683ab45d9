//! `sextant-bridge`'s command line, run as the real binary: its help carries an example, and bad
//! values are refused by name before anything joins the bus or the network.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_sextant-bridge");

fn refused(args: &[&str], named: &str) {
    let o = Command::new(BIN).args(args).output().unwrap();
    assert!(!o.status.success(), "{args:?} accepted");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(named), "{args:?}: {err}");
}

#[test]
fn help_shows_an_example() {
    let o = Command::new(BIN).arg("--help").output().unwrap();
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("--import-from"), "{text}");
    assert!(text.contains("sextant-bridge --prefix"), "{text}");
}

#[test]
fn bad_values_are_refused_by_name() {
    refused(&["--prefix", "bad prefix/x"], "--prefix");
    refused(&["--export", "nav,speed"], "speed");
    refused(&["--listen", "udp/127.0.0.1:7447"], "udp/127.0.0.1:7447");
    refused(&["--key-prefix", "car/*"], "car/*");
    refused(&["--import", "nav", "--import-from", "car2"], "nav");
    refused(&["--export", "", "--import", "gnss"], "import_from");
}
