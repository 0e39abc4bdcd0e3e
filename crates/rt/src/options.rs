//! The real-time options at the edge: [`RuntimeOptions`] (the HIL loop's) and
//! [`EmulatorOptions`] (the emulated facility's), their parsing into typed configs
//! ([`RuntimeOptions::parse`], [`EmulatorOptions::parse`]: every option checked once, before
//! any file or socket is created; what is opened is built from the result) and their JSON
//! Schema ([`schema`]): the one place where the real-time options' names, defaults, units (in
//! the descriptions), allowed values and ranges are written. The bindings export [`schema`] as `_core.realtime_schema()`, from which the CLI
//! builds its real-time flags.
//!
//! Ranges are the schema's `minimum`, `exclusiveMinimum`, `maximum` and `exclusiveMaximum`,
//! written on the fields as the core writes the scenario's (`#[schemars(range(min = ...))]`,
//! `#[schemars(extend("exclusiveMinimum" = ...))]`). The per-protocol options of `sensor` and
//! `robot` are the `oneOf` variants of those properties, tagged by `kind`.

use schemars::JsonSchema;

use hilcontact_core::error::Issues;
use hilcontact_core::schema::check_ranges_of;
use hilcontact_core::CoreError;
use serde::{Deserialize, Serialize};

use crate::clock::SchedulingOptions;
use crate::devices::{
    EmulatedRobotConfig, EmulatedRobotOptions, EmulatedSensorConfig, EmulatedSensorOptions,
    RobotConfig, RobotOptions, SensorConfig, SensorOptions,
};
use crate::error::{Result, RtError};
use crate::feedback::Extrapolation;
use crate::offset::OffsetOptions;
use crate::output::live::LiveOptions;
use crate::output::mcap::McapOptions;
use crate::safety::SafetyLimits;

/// Longest wait a real-time option or command accepts, s (an hour): `connect_timeout` and
/// `hilcontact check --duration` (the one place this limit is written; the CLI reads it from
/// the schema, `connect_timeout`'s `maximum`).
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
    /// the file and its chunk interval ([`crate::output::mcap`]). The file is created before
    /// anything is opened or started; `metrics.json` reports it in `realtime.mcap`.
    pub mcap: Option<McapOptions>,
    /// A Foxglove live view of the run (`--live [HOST:]PORT`): None, or the server's address,
    /// whether the operator's stop and mark are accepted, the per-client backlog
    /// ([`crate::output::live`]). Bound before anything else is opened; `metrics.json`
    /// reports it in `realtime.live`.
    pub live: Option<LiveOptions>,
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
            live: None,
        }
    }
}

/// The runtime's options once parsed ([`RuntimeOptions::parse`]): the links' typed configs,
/// every other option checked.
#[derive(Debug, Clone, PartialEq)]
pub struct ParsedRuntime {
    /// What the sensor link opens.
    pub sensor: SensorConfig,
    /// What the robot link opens.
    pub robot: RobotConfig,
}

impl RuntimeOptions {
    /// Checks every option alone (bad input, refused as an option error naming the key) and
    /// types the links' options, once, before any file or socket is created.
    pub fn parse(&self) -> Result<ParsedRuntime> {
        let o = self;
        o.limits.validate()?;
        o.offset.validate()?;
        o.scheduling.validate()?;
        if let Some(mcap) = &o.mcap {
            mcap.validate()?;
        }
        if let Some(live) = &o.live {
            live.validate()?;
        }
        let sensor = o.sensor.parse()?;
        let robot = o.robot.parse()?;
        for (key, v, max) in [
            ("connect_timeout", o.connect_timeout, MAX_CONNECT_TIMEOUT),
            ("start_tolerance", o.start_tolerance, f64::MAX),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= max) {
                let allowed = if max < f64::MAX {
                    format!("a number > 0 and <= {max}")
                } else {
                    "a positive number".to_string()
                };
                return Err(RtError::option(key, format!("must be {allowed}, got {v}")));
            }
        }
        if !(o.hold_time.is_finite() && o.hold_time >= 0.0) {
            return Err(RtError::option(
                "hold_time",
                format!("must be a number >= 0, got {}", o.hold_time),
            ));
        }
        check_schema_ranges(o, schemars::schema_for!(RuntimeOptions))?;
        Ok(ParsedRuntime { sensor, robot })
    }
}

/// Options of the emulated facility (defaults: RDT sensor and EGM robot with their defaults, no
/// fault injection), grouped per device like
/// [`RuntimeOptions`].
///
/// As TOML: `[sensor] kind = "rdt"`, `port = 49152`, ...; `[robot] kind = "egm"`, `port =
/// 6510`, ...; the fault injection at the top level.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct EmulatorOptions {
    /// The emulated sensor: its protocol (`kind`) and that protocol's options.
    pub sensor: EmulatedSensorOptions,
    /// The emulated robot: its protocol (`kind`) and that protocol's options.
    pub robot: EmulatedRobotOptions,
    /// Fault injection: the sensor stops sending this many seconds after the first command
    /// the robot received (the run's start, whenever the loop is started; None = never).
    #[schemars(range(min = 0.0))]
    pub silence_sensor_after: Option<f64>,
    /// Fault injection: the robot stops sending this many seconds after the first command it
    /// received (None = never).
    #[schemars(range(min = 0.0))]
    pub silence_robot_after: Option<f64>,
    /// Fault injection: an offset added to every measured wrench (an unbiased sensor),
    /// `[Fx, Fy, Fz]` N then `[Mx, My, Mz]` N·m, sensor frame.
    pub sensor_offset: [f64; 6],
    /// Fault injection: the unit the sensor reports its wrench in while the loop takes N and
    /// N·m (a box configured in kgf or lbf; moments scaled by the same factor).
    pub sensor_unit: ReportedUnit,
    /// A Foxglove live view of the facility's physical truth and scene (`--live
    /// [HOST:]PORT`, [`crate::output::live`]): None, or the server's options; its operator
    /// stop ends the facility (it stops serving).
    pub live: Option<LiveOptions>,
    /// Real-time scheduling of the facility's thread (`[scheduling]`, keys as the loop's):
    /// None (the default) = normal scheduling. A test whose verdict depends on the hardware's
    /// timing asks for `SCHED_FIFO`: the emulator then stands in for hardware, which a busy
    /// PC never starves (a starved facility thread stops moving the robot while the loop, at
    /// `SCHED_FIFO`, goes on). What the OS refuses is kept in
    /// [`crate::FacilityHandle::scheduling`] and the facility goes on.
    pub scheduling: Option<SchedulingOptions>,
}

/// The unit an emulated sensor reports in ([`EmulatorOptions::sensor_unit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
pub enum ReportedUnit {
    /// Newtons (and N·m): right.
    #[default]
    N,
    /// Kilogram-force: the wrench divided by 9.80665.
    #[serde(rename = "kgf")]
    Kgf,
    /// Pound-force: the wrench divided by 4.448222.
    #[serde(rename = "lbf")]
    Lbf,
}

impl ReportedUnit {
    /// Newtons per reported unit.
    pub fn newtons(self) -> f64 {
        match self {
            ReportedUnit::N => 1.0,
            ReportedUnit::Kgf => 9.80665,
            ReportedUnit::Lbf => 4.448222,
        }
    }
}

/// The emulator's options once parsed ([`EmulatorOptions::parse`]): the devices' typed
/// configs, the fault injection checked.
#[derive(Debug, Clone, PartialEq)]
pub struct ParsedFacility {
    /// What the emulated sensor opens.
    pub sensor: EmulatedSensorConfig,
    /// What the emulated robot opens.
    pub robot: EmulatedRobotConfig,
}

impl EmulatorOptions {
    /// Checks every option (an option error naming the key) and types the devices' options,
    /// once, before any socket is created.
    pub fn parse(&self) -> Result<ParsedFacility> {
        let o = self;
        for (key, v) in [
            ("silence_sensor_after", o.silence_sensor_after),
            ("silence_robot_after", o.silence_robot_after),
        ] {
            if v.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
                return Err(RtError::option(
                    key,
                    format!("must be a number of seconds >= 0, got {v:?}"),
                ));
            }
        }
        if !o.sensor_offset.iter().all(|v| v.is_finite()) {
            return Err(RtError::option(
                "sensor_offset",
                format!("must be 6 finite numbers, got {:?}", o.sensor_offset),
            ));
        }
        if let Some(live) = &o.live {
            live.validate()?;
        }
        if let Some(scheduling) = &o.scheduling {
            scheduling.validate()?;
        }
        let parsed = ParsedFacility {
            sensor: o.sensor.parse()?,
            robot: o.robot.parse()?,
        };
        check_schema_ranges(o, schemars::schema_for!(EmulatorOptions))?;
        Ok(parsed)
    }
}

/// Every number of `options` against the range its field's `#[schemars(...)]` gives in the
/// options' JSON Schema (the core's `check_ranges_of`, as for a scenario): the one check an
/// option needs beyond its type. Run after the hand-written checks above, whose messages
/// (named for the flags of earlier versions) come first; a new option's range is checked here
/// without a line of its own. The first problem is the error, its key dotted
/// (`limits.force_limit`).
fn check_schema_ranges(options: &impl Serialize, schema: schemars::Schema) -> Result<()> {
    let mut issues = Issues::default();
    check_ranges_of(options, &schema, "options", &mut issues);
    match issues.finish() {
        Ok(()) => Ok(()),
        Err(CoreError::InvalidScenario { key, message, .. }) => Err(RtError::option(key, message)),
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
        for kind in crate::devices::SENSOR_KINDS
            .iter()
            .chain(crate::devices::ROBOT_KINDS)
        {
            assert!(text.contains(&format!("\"const\":\"{kind}\"")), "{kind}");
        }
        let runtime = &s["runtime"]["properties"];
        assert_eq!(runtime["connect_timeout"]["maximum"], MAX_CONNECT_TIMEOUT);
        assert_eq!(runtime["connect_timeout"]["exclusiveMinimum"], 0.0);
        assert_eq!(runtime["connect_timeout"]["default"], 5.0);
        assert!(s["facility"]["properties"]["robot"].is_object());
    }

    /// A bad sensor count, sample rate, host or pose mapping fails when the options are
    /// parsed, naming the key: before any file or socket exists.
    #[test]
    fn bad_link_options_fail_when_parsed() {
        use crate::devices::{egm::EgmOptions, rdt::RdtOptions, sri::SriOptions};
        let rdt = |o: RdtOptions| RuntimeOptions {
            sensor: SensorOptions::Rdt(o),
            ..Default::default()
        };
        let cases = [
            (
                rdt(RdtOptions {
                    counts_per_force: Some(-1.0),
                    counts_per_torque: Some(1.0),
                    ..Default::default()
                }),
                "counts_per_force",
            ),
            (
                rdt(RdtOptions {
                    counts_per_force: Some(1.0),
                    ..Default::default()
                }),
                "counts_per_force",
            ),
            (
                RuntimeOptions {
                    sensor: SensorOptions::Sri(SriOptions {
                        sample_rate: Some(1e9),
                        ..Default::default()
                    }),
                    ..Default::default()
                },
                "sample_rate",
            ),
            (
                RuntimeOptions {
                    robot: RobotOptions::Egm(EgmOptions {
                        offset_mm: [f64::NAN, 0.0, 0.0],
                        ..Default::default()
                    }),
                    ..Default::default()
                },
                "egm_offset_mm",
            ),
        ];
        for (options, key) in cases {
            match options.parse() {
                Err(RtError::Option { key: k, .. }) => assert_eq!(k, key),
                other => panic!("{key}: {other:?}"),
            }
        }
        let emulator = EmulatorOptions {
            silence_robot_after: Some(-1.0),
            ..Default::default()
        };
        assert!(emulator.parse().is_err());
        assert!(RuntimeOptions::default().parse().is_ok());
        assert!(EmulatorOptions::default().parse().is_ok());
    }

    /// A field with nothing but its `#[schemars]` range (a new option, as the recipe adds it)
    /// is checked: out of range, not finite, nested in a group, each refused naming its key.
    #[test]
    fn a_range_in_the_schema_alone_is_checked() {
        #[derive(Serialize, JsonSchema)]
        struct Group {
            /// s.
            #[schemars(range(min = 0.0, max = 2.0))]
            new_time: f64,
        }
        #[derive(Serialize, JsonSchema)]
        struct Options {
            /// N.
            #[schemars(extend("exclusiveMinimum" = 0.0))]
            new_force: f64,
            group: Group,
        }
        let check = |new_force, new_time| {
            check_schema_ranges(
                &Options {
                    new_force,
                    group: Group { new_time },
                },
                schemars::schema_for!(Options),
            )
        };
        assert!(check(1.0, 2.0).is_ok());
        for (force, time, key, text) in [
            (0.0, 1.0, "new_force", "must be > 0, got 0"),
            (f64::NAN, 1.0, "new_force", "must be a finite number"),
            (
                1.0,
                2.5,
                "group.new_time",
                "must be between 0 and 2, got 2.5",
            ),
        ] {
            let message = check(force, time).unwrap_err().to_string();
            assert!(
                message.contains(key) && message.contains(text),
                "{force} {time}: {message}"
            );
        }
    }
}
