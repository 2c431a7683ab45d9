//! The matched fixture of the filter-algebra tests (`sextant_drivers_sim::matched`): the
//! shipped car's scenario without its world and its filter without its installation.

use fusion::navigator::NavigatorConfig;
use sextant_drivers_sim::matched;
use sextant_drivers_sim::scenario::Scenario;
use std::path::{Path, PathBuf};

/// The repository root.
pub fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// `config/scenarios/vehicle.toml`.
pub fn vehicle_path() -> PathBuf {
    root().join("config/scenarios/vehicle.toml")
}

/// The shipped car's filter, `config/filter.toml`.
pub fn car_filter() -> NavigatorConfig {
    let text = std::fs::read_to_string(root().join("config/filter.toml")).expect("filter.toml");
    toml::from_str(&text).expect("filter.toml parses")
}

/// The car's tuning with the matched installation.
pub fn matched_filter() -> NavigatorConfig {
    matched::filter(car_filter())
}

/// The default vehicle scenario, its text passed through `edit` (the trajectory, duration,
/// seed or a sensor changed by text), on the matched world.
pub fn matched_vehicle_edited(edit: impl FnOnce(String) -> String) -> Scenario {
    let path = vehicle_path();
    let text = std::fs::read_to_string(&path).expect("vehicle.toml");
    let scn = Scenario::from_toml_str(&edit(text), &path).unwrap_or_else(|e| panic!("{e}"));
    matched::scenario(scn)
}

/// `text` (a shipped file's) with every `from` replaced by `to`; panics when it has no `from`,
/// so that an edit by text never silently misses (the file changed its layout, or the value
/// moved to a shared world file).
pub fn replace_present(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "the text has no `{from}`");
    text.replace(from, to)
}

/// The default vehicle scenario's text with its trajectory's `segments` and its duration
/// replaced.
pub fn with_segments(text: &str, segments: &str, duration_s: f64) -> String {
    let start = text.find("segments = [").expect("segments");
    let end = start + text[start..].find("\n]\n").expect("end of segments") + 3;
    replace_present(
        &format!(
            "{}segments = [{segments}]\n{}",
            &text[..start],
            &text[end..]
        ),
        "duration_s = 600.0",
        &format!("duration_s = {duration_s:.1}"),
    )
}

/// The default vehicle scenario on the matched world with the trajectory and duration
/// replaced.
pub fn matched_vehicle_with(segments: &str, duration_s: f64) -> Scenario {
    matched_vehicle_edited(|t| with_segments(&t, segments, duration_s))
}
