//! Helpers shared by the integration tests: presets and scenario tweaks.
#![allow(dead_code)]

use hilcontact_core::Scenario;

/// A preset scenario from `python/hilcontact/scenarios/<name>.toml`.
pub fn preset(name: &str) -> Scenario {
    let path = format!(
        "{}/../../python/hilcontact/scenarios/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    toml::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// `paper-table1` with the given robot and sensor delays (s) and no noise.
pub fn table1(robot_delay: f64, sensor_delay: f64) -> Scenario {
    let mut s = preset("paper-table1");
    s.facility.robot_delay = robot_delay;
    s.facility.sensor_delay = sensor_delay;
    s
}
