//! The real-time options at the edge: [`RuntimeOptions`] (the HIL loop's, `hilcontact run-rt`)
//! and their JSON Schema with the emulator's ([`schema`]): the one place where the real-time
//! options' names, defaults, units (in the descriptions), allowed values and ranges are
//! written. The bindings export [`schema`] as `_core.realtime_schema()`, from which the CLI
//! builds its real-time flags.
//!
//! Ranges are the schema's `minimum`, `exclusiveMinimum`, `maximum` and `exclusiveMaximum`,
//! written on the fields as the core writes the scenario's (`#[schemars(range(min = ...))]`,
//! `#[schemars(extend("exclusiveMinimum" = ...))]`). The per-protocol options of `sensor` and
//! `robot` are the `oneOf` variants of those properties, tagged by `kind`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::clock::SchedulingOptions;
use crate::emulator::EmulatorOptions;
use crate::feedback::Extrapolation;
use crate::links::{RobotOptions, SensorOptions};
use crate::offset::OffsetOptions;
use crate::recording::McapOptions;
use crate::safety::SafetyLimits;

/// Longest wait a real-time option or command accepts, s (an hour): `connect_timeout` and
/// `hilcontact check --duration`.
pub const MAX_CONNECT_TIMEOUT: f64 = 3600.0;

/// Options of the real-time runtime (defaults in [`Default`]; the CLI documents each).
///
/// As TOML: `[sensor] kind = "rdt"`, `port = 49152`, ...; `[robot] kind = "egm"`, ...; the
/// other keys at the top level.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RuntimeOptions {
    /// The sensor link: its protocol (`kind`) and that protocol's options.
    pub sensor: SensorOptions,
    /// The robot link: its protocol (`kind`) and that protocol's options.
    pub robot: RobotOptions,
    /// How the actual motion is estimated between feedback messages.
    pub extrapolation: Extrapolation,
    /// Safety limits.
    pub limits: SafetyLimits,
    /// Longest wait for the first sensor record and robot feedback, s (> 0, <= an hour).
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = MAX_CONNECT_TIMEOUT))]
    pub connect_timeout: f64,
    /// Largest distance between the robot's fed-back pose and the scenario's initial pose at
    /// start, m (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub start_tolerance: f64,
    /// How long the hold command is streamed after a stop, s (>= 0).
    #[schemars(range(min = 0.0))]
    pub hold_time: f64,
    /// The sensor's offset at start: measured with the rod free and subtracted, or not.
    pub offset: OffsetOptions,
    /// Real-time scheduling of the loop thread (`SCHED_FIFO` priority, locked memory, CPU); a
    /// refusal by the OS is reported in `metrics.json` (`realtime.scheduling`), not an error.
    pub scheduling: SchedulingOptions,
    /// An MCAP recording of the run (`--mcap FILE`), written by the writer thread: None, or
    /// the file and its chunk interval ([`crate::recording`]). The file is created before
    /// anything is opened or started; `metrics.json` reports it in `realtime.mcap`.
    pub mcap: Option<McapOptions>,
}

impl Default for RuntimeOptions {
    fn default() -> Self {
        RuntimeOptions {
            sensor: SensorOptions::default(),
            robot: RobotOptions::default(),
            extrapolation: Extrapolation::default(),
            limits: SafetyLimits::default(),
            connect_timeout: 5.0,
            start_tolerance: 0.005,
            hold_time: 0.1,
            offset: OffsetOptions::default(),
            scheduling: SchedulingOptions::default(),
            mcap: None,
        }
    }
}

/// The JSON Schema (draft 2020-12) of the real-time options: `{"runtime": <RuntimeOptions>,
/// "facility": <EmulatorOptions>}`, each with every default, description (units included),
/// allowed value and range.
pub fn schema() -> serde_json::Value {
    serde_json::json!({
        "runtime": schemars::schema_for!(RuntimeOptions),
        "facility": schemars::schema_for!(EmulatorOptions),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The protocols' options are the `oneOf` variants of `sensor` and `robot`, tagged by
    /// `kind`, and the hand-written checks' ranges are in the schema.
    #[test]
    fn the_schema_has_every_protocol_and_the_ranges() {
        let s = schema();
        let text = s.to_string();
        for kind in crate::links::SENSOR_KINDS
            .iter()
            .chain(crate::links::ROBOT_KINDS)
        {
            assert!(text.contains(&format!("\"const\":\"{kind}\"")), "{kind}");
        }
        let runtime = &s["runtime"]["properties"];
        assert_eq!(runtime["connect_timeout"]["maximum"], MAX_CONNECT_TIMEOUT);
        assert_eq!(runtime["connect_timeout"]["exclusiveMinimum"], 0.0);
        assert_eq!(runtime["connect_timeout"]["default"], 5.0);
        assert!(s["facility"]["properties"]["robot"].is_object());
    }
}
