//! Replay: a compensator run offline on a recording's measurements and poses, giving what it
//! would have applied at each tick (to compare compensators and tune their parameters).
//!
//! The compensator is the one the live loop builds ([`CompensatorConfig::build`] with
//! [`crate::hil::compensator_context`]), fed the same [`CompensatorInput`] as
//! [`crate::hil::VirtualDynamics::input`] builds: the measured wrench turned from the sensor
//! frame into `t`, the actual and desired rod tip. Replaying a run's own time series with its
//! own scenario therefore gives its recorded applied wrench, bit for bit. The replay is
//! open-loop: the desired tip comes from the recording, not from dynamics driven by the new
//! output. The output columns are allocated once; the loop over ticks does not allocate.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::compensator::{CompensatorConfig, CompensatorContext, CompensatorInput};
use crate::error::RecordingError;
use crate::frames::FrameWrench;
use crate::hil::compensator_context;
use crate::plan::Plan;
use crate::sim::Table;

/// Fewest samples a recording may have.
pub const MIN_SAMPLES: usize = 3;

/// Three columns `<name>_x`, `<name>_y`, `<name>_z` of a recording.
pub type Columns3<'a> = [&'a [f64]; 3];

/// A recorded run, as columns of equal length, one sample per control tick (period T).
/// Column names are those of a run's `timeseries.parquet`.
#[derive(Debug, Clone, Copy)]
pub struct Recording<'a> {
    /// `time`, s, strictly increasing.
    pub time: &'a [f64],
    /// `measured_force_*`: force on the frame, sensor frame, N.
    pub measured_force: Columns3<'a>,
    /// `measured_moment_*`: moment about the sensor origin, sensor frame, N·m.
    pub measured_moment: Columns3<'a>,
    /// `actual_tip_position_*`: robot's rod tip, eq. (3), `t`, m.
    pub actual_tip_position: Columns3<'a>,
    /// `actual_tip_velocity_*`: robot's rod-tip velocity, eq. (4), `t`, m/s.
    pub actual_tip_velocity: Columns3<'a>,
    /// `tip_position_*`: desired (virtual) rod tip, eq. (25), `t`, m (replay only).
    pub tip_position: Option<Columns3<'a>>,
    /// `tip_velocity_*`: desired rod-tip velocity, eq. (26), `t`, m/s (replay only).
    pub tip_velocity: Option<Columns3<'a>>,
}

fn three<'a>(table: &'a Table, name: &str, missing: &mut Vec<String>) -> Option<Columns3<'a>> {
    let mut out: [&[f64]; 3] = [&[], &[], &[]];
    let mut ok = true;
    for (i, axis) in ["x", "y", "z"].iter().enumerate() {
        let column = format!("{name}_{axis}");
        match table.column(&column) {
            Some(values) => out[i] = values,
            None => {
                missing.push(column);
                ok = false;
            }
        }
    }
    ok.then_some(out)
}

impl<'a> Recording<'a> {
    /// The recording in `table`'s columns (names as in a run's `timeseries.parquet`); the
    /// desired tip (`tip_position_*`, `tip_velocity_*`) is required if `desired`. Checks it
    /// ([`Recording::check`]); names every missing column.
    pub fn from_table(table: &'a Table, desired: bool) -> Result<Self, RecordingError> {
        let mut missing = Vec::new();
        let time = table.column("time");
        if time.is_none() {
            missing.push("time".to_string());
        }
        let measured_force = three(table, "measured_force", &mut missing);
        let measured_moment = three(table, "measured_moment", &mut missing);
        let actual_tip_position = three(table, "actual_tip_position", &mut missing);
        let actual_tip_velocity = three(table, "actual_tip_velocity", &mut missing);
        let (tip_position, tip_velocity) = if desired {
            (
                three(table, "tip_position", &mut missing),
                three(table, "tip_velocity", &mut missing),
            )
        } else {
            (None, None)
        };
        if !missing.is_empty() {
            return Err(RecordingError::MissingColumns(missing));
        }
        let unwrap = |c: Option<Columns3<'a>>| c.unwrap_or([&[], &[], &[]]);
        let recording = Recording {
            time: time.unwrap_or(&[]),
            measured_force: unwrap(measured_force),
            measured_moment: unwrap(measured_moment),
            actual_tip_position: unwrap(actual_tip_position),
            actual_tip_velocity: unwrap(actual_tip_velocity),
            tip_position,
            tip_velocity,
        };
        recording.check()?;
        Ok(recording)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time.len()
    }

    /// Whether there is no sample.
    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    fn named_columns(&self) -> Vec<(String, &'a [f64])> {
        let mut out = vec![("time".to_string(), self.time)];
        let mut add = |name: &str, c: &Columns3<'a>| {
            for (axis, values) in ["x", "y", "z"].iter().zip(c.iter()) {
                out.push((format!("{name}_{axis}"), *values));
            }
        };
        add("measured_force", &self.measured_force);
        add("measured_moment", &self.measured_moment);
        add("actual_tip_position", &self.actual_tip_position);
        add("actual_tip_velocity", &self.actual_tip_velocity);
        if let Some(c) = &self.tip_position {
            add("tip_position", c);
        }
        if let Some(c) = &self.tip_velocity {
            add("tip_velocity", c);
        }
        out
    }

    /// Equal lengths, at least [`MIN_SAMPLES`], strictly increasing time, finite samples.
    pub fn check(&self) -> Result<(), RecordingError> {
        let n = self.time.len();
        for (name, values) in self.named_columns() {
            if values.len() != n {
                return Err(RecordingError::Length {
                    name,
                    len: values.len(),
                    expected: n,
                });
            }
        }
        if n < MIN_SAMPLES {
            return Err(RecordingError::TooShort {
                len: n,
                min: MIN_SAMPLES,
            });
        }
        for (name, values) in self.named_columns() {
            if let Some(index) = values.iter().position(|v| !v.is_finite()) {
                return Err(RecordingError::NonFinite {
                    name,
                    index,
                    value: values[index],
                });
            }
        }
        if let Some(i) = self.time.windows(2).position(|w| w[1] <= w[0]) {
            return Err(RecordingError::NonMonotonic {
                index: i + 1,
                before: self.time[i],
                after: self.time[i + 1],
            });
        }
        Ok(())
    }

    fn at(c: &Columns3<'_>, k: usize) -> Vector3<f64> {
        Vector3::new(c[0][k], c[1][k], c[2][k])
    }

    /// What a compensator sees at tick `k`, as [`crate::hil::VirtualDynamics::input`] builds it:
    /// the measured wrench turned into `t` by `sensor_to_t` (the sensor's attitude in `t`), the
    /// actual tip and the desired one (the actual one when the recording has none). The tip's
    /// mobility is left zero (a recording has no virtual state; [`replay`] puts in `1/μ`).
    pub fn input(&self, k: usize, sensor_to_t: &UnitQuaternion<f64>) -> CompensatorInput {
        let actual_position = Self::at(&self.actual_tip_position, k);
        let actual_velocity = Self::at(&self.actual_tip_velocity, k);
        CompensatorInput {
            measured: FrameWrench {
                force: sensor_to_t * Self::at(&self.measured_force, k),
                moment: sensor_to_t * Self::at(&self.measured_moment, k),
            },
            tip_position_actual: actual_position,
            tip_velocity_actual: actual_velocity,
            // a recording has no attitude column
            orientation_actual: None,
            tip_position_desired: self
                .tip_position
                .map_or(actual_position, |c| Self::at(&c, k)),
            tip_velocity_desired: self
                .tip_velocity
                .map_or(actual_velocity, |c| Self::at(&c, k)),
            // a recording has no attitude column: no virtual pose
            motion_desired: None,
            // a recording has no virtual state: `replay` puts in the translational mobility
            tip_mobility: Matrix3::zeros(),
            // every row a new record (a recording's held records: `identify` skips them)
            fresh: true,
        }
    }
}

/// Names of the replay's output columns, in order: `time` (s), `applied_force_*` (N) and
/// `applied_moment_*` (N·m) in the sensor frame and convention (as a run records them),
/// `velocity_correction_*` (`t`, m/s), `stiffness_estimate` (N/m), `damping_estimate`
/// (N·s/m), `observed_energy` (J); the last three NaN where the compensator has none.
pub const REPLAY_COLUMNS: [&str; 13] = [
    "time",
    "applied_force_x",
    "applied_force_y",
    "applied_force_z",
    "applied_moment_x",
    "applied_moment_y",
    "applied_moment_z",
    "velocity_correction_x",
    "velocity_correction_y",
    "velocity_correction_z",
    "stiffness_estimate",
    "damping_estimate",
    "observed_energy",
];

/// Runs `config`'s compensator, built with `context`, over `recording` (with the desired tip),
/// the sensor's attitude in `t` being `sensor_to_t`. Returns the columns of
/// [`REPLAY_COLUMNS`], one row per sample.
pub fn replay(
    config: &CompensatorConfig,
    context: &CompensatorContext,
    sensor_to_t: &UnitQuaternion<f64>,
    recording: &Recording<'_>,
) -> Result<Table, RecordingError> {
    recording.check()?;
    if recording.tip_position.is_none() || recording.tip_velocity.is_none() {
        return Err(RecordingError::MissingColumns(
            ["tip_position_*", "tip_velocity_*"]
                .iter()
                .map(|s| s.to_string())
                .collect(),
        ));
    }
    let n = recording.len();
    let mut columns: Vec<Vec<f64>> = vec![vec![0.0; n]; REPLAY_COLUMNS.len()];
    let mut compensator = config.build(context);
    // the tip's mobility as if it moved with the centres of mass (no rotation): exact for a
    // contact on their line, an approximation otherwise (only admittance-type compensators use it)
    let mobility = Matrix3::identity() / context.reduced_mass;
    for k in 0..n {
        let mut input = recording.input(k, sensor_to_t);
        input.tip_mobility = mobility;
        let out = compensator.step(&input);
        // as HilStep::observe records it: back into the sensor frame
        let force = sensor_to_t.inverse_transform_vector(&out.applied.force);
        let moment = sensor_to_t.inverse_transform_vector(&out.applied.moment);
        let row = [
            recording.time[k],
            force.x,
            force.y,
            force.z,
            moment.x,
            moment.y,
            moment.z,
            out.velocity_correction.x,
            out.velocity_correction.y,
            out.velocity_correction.z,
            out.estimate.map_or(f64::NAN, |e| e.stiffness),
            out.estimate.map_or(f64::NAN, |e| e.damping),
            out.observed_energy,
        ];
        for (column, value) in columns.iter_mut().zip(row) {
            column[k] = value;
        }
    }
    Ok(Table {
        columns: REPLAY_COLUMNS
            .iter()
            .map(|s| s.to_string())
            .zip(columns)
            .collect(),
    })
}

/// [`replay`] with a plan's compensator, context and sensor attitude.
pub fn replay_plan(plan: &Plan, recording: &Recording<'_>) -> Result<Table, RecordingError> {
    replay(
        &plan.compensator,
        &compensator_context(plan),
        &plan.sensor.orientation,
        recording,
    )
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::sim::simulate_plan;

    /// A preset with the compensator `kind` and the robot delay (s).
    pub(crate) fn preset_plan(name: &str, kind: &str, robot_delay: f64) -> Plan {
        let path = format!(
            "{}/../../python/hilcontact/scenarios/{name}.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let text = std::fs::read_to_string(&path).expect("preset");
        let mut scenario: crate::Scenario = toml::from_str(&text).expect("toml");
        scenario.compensator = CompensatorConfig::from_kind(kind).expect("kind");
        scenario.facility.robot_delay = robot_delay;
        scenario.resolve().expect("plan")
    }

    fn plan(kind: &str, robot_delay: f64) -> Plan {
        preset_plan("oblique-6dof", kind, robot_delay)
    }

    #[test]
    fn replaying_a_run_gives_its_applied_wrench() {
        for kind in ["pida", "pic", "dac", "tdpa-impedance", "none"] {
            let plan = plan(kind, 0.02);
            let out = simulate_plan(&plan);
            let table = &out.timeseries;
            let recording = Recording::from_table(table, true).expect("recording");
            let replayed = replay_plan(&plan, &recording).expect("replay");
            for name in ["applied_force_x", "applied_force_z", "applied_moment_y"] {
                let a = table.column(name).unwrap();
                let b = replayed.column(name).unwrap();
                assert_eq!(a, b, "{kind} {name}");
            }
            if kind == "pida" {
                assert_eq!(
                    table.column("stiffness_estimate").unwrap(),
                    replayed.column("stiffness_estimate").unwrap()
                );
            }
        }
    }

    #[test]
    fn bad_recordings_are_named() {
        let plan = plan("pida", 0.0);
        let mut table = simulate_plan(&plan).timeseries;
        table.columns.retain(|(n, _)| n != "measured_force_y");
        let err = Recording::from_table(&table, true).unwrap_err();
        assert_eq!(err.to_string(), "missing columns: measured_force_y");
        let mut table = simulate_plan(&plan).timeseries;
        for (name, values) in table.columns.iter_mut() {
            if name == "time" {
                values[5] = values[3];
            }
            if name == "actual_tip_velocity_z" {
                values[9] = f64::NAN;
            }
        }
        let err = Recording::from_table(&table, true).unwrap_err();
        assert!(
            err.to_string().contains("actual_tip_velocity_z: sample 9"),
            "{err}"
        );
    }
}
