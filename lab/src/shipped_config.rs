//! Where the experiments find the shipped configuration (`scenarios/`, `sensors/`): the
//! directory given to `sextant experiment --config DIR`, else the copy of the repository's
//! `config/` embedded in the binary (`sextant_daemons::config::embedded_config_files`), written
//! once under the system's temporary directory in a directory named for its content — so that
//! an installed `sextant` needs no source tree, and a changed configuration never reuses a stale
//! copy.

use crate::config::{ConfigError, embedded_config_files};
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The directory chosen for this process (set once, on first use or by [`use_dir`]).
static CHOSEN: OnceLock<Result<PathBuf, String>> = OnceLock::new();

/// Use `dir` (a directory laid out like `config/`) instead of the embedded configuration.
/// Returns false when the configuration was already chosen (call it before any experiment).
pub fn use_dir(dir: PathBuf) -> bool {
    CHOSEN.set(Ok(dir)).is_ok()
}

/// The configuration directory of this process: the one given to [`use_dir`], else the
/// embedded copy (see [`materialize_under`] with the temporary directory); the error says why
/// the embedded copy could not be written.
pub fn dir() -> Result<&'static Path, &'static str> {
    match CHOSEN.get_or_init(|| {
        materialize_under(&std::env::temp_dir()).map_err(|e| format!("embedded configuration: {e}"))
    }) {
        Ok(p) => Ok(p),
        Err(e) => Err(e),
    }
}

/// Path of the shipped scenario `scenarios/NAME` (e.g. `vehicle.toml`). When the embedded
/// configuration could not be written, the reason is logged and the path returned is where it
/// would have been, so that loading it fails with an error naming the file.
pub fn scenario(name: &str) -> PathBuf {
    match dir() {
        Ok(d) => d.join("scenarios").join(name),
        Err(e) => {
            tracing::error!("{e}");
            std::env::temp_dir()
                .join("sextant-config")
                .join("scenarios")
                .join(name)
        }
    }
}

/// Write the embedded configuration into `base/sextant-config-HASH` (HASH of the package
/// version and every embedded file) unless it is already there, and return that directory.
/// The copy is first written to a directory of its own and then renamed into place, so that
/// concurrent processes never see a partial copy.
pub fn materialize_under(base: &Path) -> Result<PathBuf, ConfigError> {
    let files = embedded_config_files();
    let mut h = std::hash::DefaultHasher::new();
    env!("CARGO_PKG_VERSION").hash(&mut h);
    files.hash(&mut h);
    let dir = base.join(format!("sextant-config-{:016x}", h.finish()));
    if dir.join("sextant.toml").is_file() {
        return Ok(dir);
    }
    let tmp = base.join(format!(
        "sextant-config-{:016x}.{}.partial",
        h.finish(),
        std::process::id()
    ));
    crate::config::materialize_embedded(&tmp)?;
    if std::fs::rename(&tmp, &dir).is_err() {
        // Another process renamed its identical copy into place first.
        let _ = std::fs::remove_dir_all(&tmp);
        if !dir.join("sextant.toml").is_file() {
            return Err(ConfigError::Read {
                file: dir,
                source: std::io::Error::other("could not move the embedded configuration here"),
            });
        }
    }
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_copy_holds_every_file_and_is_reused() {
        let base = std::env::temp_dir().join(format!("sextant-shipped-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        std::fs::create_dir_all(&base).unwrap();
        let a = materialize_under(&base).unwrap();
        for (rel, text) in embedded_config_files() {
            assert_eq!(
                std::fs::read_to_string(a.join(rel)).unwrap(),
                *text,
                "{rel}"
            );
        }
        let b = materialize_under(&base).unwrap();
        assert_eq!(a, b);
        // Nothing partial is left behind.
        assert_eq!(std::fs::read_dir(&base).unwrap().count(), 1);
        // Every scenario of the copy loads with its sensor grades and its shared world file
        // (found relative to it), to the same world as the repository's; those following a
        // recorded trajectory read its points from the source tree, not from the copy.
        let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config");
        let mut names = 0;
        for e in std::fs::read_dir(a.join("scenarios")).unwrap().flatten() {
            let rel = Path::new("scenarios").join(e.file_name());
            let text = std::fs::read_to_string(e.path()).unwrap();
            if text.contains("kind = \"reference\"") {
                continue;
            }
            let copy = drivers_sim::scenario::Scenario::load(&a.join(&rel))
                .unwrap_or_else(|e| panic!("{e}"));
            let shipped = drivers_sim::scenario::Scenario::load(&repo.join(&rel)).unwrap();
            assert_eq!(
                format!("{:?}", copy.spec.world),
                format!("{:?}", shipped.spec.world),
                "{}",
                rel.display()
            );
            names += 1;
        }
        assert!(names >= 2, "{names} scenarios");
        assert!(a.join("worlds/car.toml").is_file());
        std::fs::remove_dir_all(&base).unwrap();
    }

    #[test]
    fn scenarios_resolve_to_the_chosen_configuration() {
        let s = scenario("astro_stand.toml");
        assert!(s.is_file(), "{}", s.display());
        assert!(s.starts_with(dir().unwrap()));
    }
}
