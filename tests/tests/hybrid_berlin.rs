//! `sextant experiment hybrid-berlin --data DIR`: the real process reads the smartLoc files from
//! a directory given on the command line (here the shipped slice under the dataset's own file
//! names) and gives the same figures as the run on the slice embedded in the binary; a
//! directory that does not exist is refused with a message naming it.

use sextant_tests::*;
use std::process::Command;

#[test]
fn data_from_a_directory_equals_the_embedded_slice() {
    let _g = MACHINE.shared();
    let root = repo_root();
    let dir = std::env::temp_dir().join(format!("sextant-berlin-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let data = dir.join("smartloc");
    std::fs::create_dir_all(&data).unwrap();
    let slice = root.join("tests/data/smartloc-berlin");
    for (from, to) in [
        (
            "Berlin_Potsdamer_Platz_Input_150-210s.txt.gz",
            "Berlin_Potsdamer_Platz_Input.txt.gz",
        ),
        (
            "Berlin_Potsdamer_Platz_GT_150-210s.txt.gz",
            "Berlin_Potsdamer_Platz_GT.txt.gz",
        ),
    ] {
        std::fs::copy(slice.join(from), data.join(to)).unwrap();
    }
    let sextant = bin("sextant").unwrap();
    let run = |extra: &[&std::ffi::OsStr], out: &std::path::Path| {
        Command::new(&sextant)
            .args(["experiment", "hybrid-berlin", "--out"])
            .arg(out)
            .args(extra)
            .output()
            .unwrap()
    };
    let (a, b) = (dir.join("from-dir"), dir.join("embedded"));
    let o = run(&["--data".as_ref(), data.as_os_str()], &a);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = run(&[], &b);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let read = |d: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap()).unwrap()
    };
    let (mut sa, mut sb) = (read(&a), read(&b));
    let source = sa["source"].as_str().unwrap().to_string();
    assert!(source.contains("smartloc"), "{source}");
    assert_eq!(sa["epochs"], 298);
    // Everything but the source is the same measurement of the same data.
    sa["source"] = serde_json::Value::Null;
    sb["source"] = serde_json::Value::Null;
    assert_eq!(sa, sb);
    assert!(a.join("horizontal_error.png").is_file());

    let o = run(
        &["--data".as_ref(), dir.join("missing").as_os_str()],
        &dir.join("x"),
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("missing") && err.contains("not a directory"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
