//! Helpers shared by the integration tests: presets and scenario tweaks.
#![allow(dead_code)]

use hilcontact_core::{Scenario, SimulationOutput};

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

/// `oblique-6dof` with the geometry of a random 6-DOF case: the target's and the servicer's
/// spins (`spins`, rad/s, body frames), the target's drift (m/s), the front wall's normal
/// tilted from −x by `tilt[0]` about z and `tilt[1]` about y (rad), and the rod tip off the
/// axis by `offset` (y, z, m) with the wall's point beside it.
pub fn oblique_6dof(
    spins: ([f64; 3], [f64; 3]),
    drift: [f64; 3],
    tilt: [f64; 2],
    offset: [f64; 2],
) -> Scenario {
    let mut s = preset("oblique-6dof");
    s.target.angular_velocity = spins.0;
    s.servicer.angular_velocity = spins.1;
    s.target.velocity = drift;
    s.walls[0].normal = [
        -tilt[0].cos() * tilt[1].cos(),
        -tilt[0].sin(),
        tilt[1].sin(),
    ];
    s.rod.tip = [1.0, offset[0], offset[1]];
    s.walls[0].point = [0.010, offset[0] - 0.05, offset[1]];
    s
}

proptest::prop_compose! {
    /// Random [`oblique_6dof`] cases: spins within ±`spin` rad/s, drift within ±`drift` m/s
    /// (> 0), tilts within ±`max_tilt` rad, offsets within ±`max_offset` m.
    pub fn oblique_6dof_cases(spin: f64, drift: f64, max_tilt: f64, max_offset: f64)(
        target_spin in proptest::array::uniform3(-spin..spin),
        servicer_spin in proptest::array::uniform3(-spin..spin),
        target_drift in proptest::array::uniform3(-drift..drift),
        tilt in proptest::array::uniform2(-max_tilt..max_tilt),
        offset in proptest::array::uniform2(-max_offset..max_offset),
    ) -> Scenario {
        oblique_6dof((target_spin, servicer_spin), target_drift, tilt, offset)
    }
}

/// A column of a run's time series.
pub fn col<'a>(out: &'a SimulationOutput, name: &str) -> &'a [f64] {
    out.timeseries
        .column(name)
        .unwrap_or_else(|| panic!("no column {name}"))
}

/// The CoV of each of a run's collisions that has one.
pub fn covs(out: &SimulationOutput) -> Vec<f64> {
    out.metrics
        .collisions
        .iter()
        .filter_map(|c| c.cov)
        .collect()
}

/// The CoF of each of a run's collisions that has one.
pub fn cofs(out: &SimulationOutput) -> Vec<f64> {
    out.metrics
        .collisions
        .iter()
        .filter_map(|c| c.cof)
        .collect()
}

/// Reads `probe-drogue`'s drogue mesh (`probe-drogue-cone.obj`, beside the preset) into its
/// target shape, as the Python loader does (a Rust [`preset`] has the file's name only).
pub fn load_drogue_mesh(s: &mut Scenario) {
    let path = format!(
        "{}/../../python/hilcontact/scenarios/probe-drogue-cone.obj",
        env!("CARGO_MANIFEST_DIR")
    );
    read_obj(&path, &mut s.target.shapes[0]);
}

/// Reads the vertices and triangles of the OBJ file at `path` into a mesh shape (as the Python
/// loader does; the core reads no files).
pub fn read_obj(path: &str, shape: &mut hilcontact_core::config::ShapeConfig) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let v: Vec<f64> = words.map(|w| w.parse().expect("a number")).collect();
                shape.vertices.push([v[0], v[1], v[2]]);
            }
            Some("f") => {
                let f: Vec<u32> = words
                    .map(|w| w.parse::<u32>().expect("an index") - 1)
                    .collect();
                shape.triangles.push([f[0], f[1], f[2]]);
            }
            _ => {}
        }
    }
}
