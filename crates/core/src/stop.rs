//! How a run stops: the one vocabulary of simulated and real-time runs ([`StopKind`], the
//! [`Stop`] with its value and limit, and the run's [`Status`]).
//!
//! The HIL step ([`crate::hil::HilStep`]) stops a run that diverged, stopped being finite or
//! ran to its end, in a simulation and in the real-time loop alike; the real-time runtime
//! (`hilcontact-rt`, its `safety` module) adds the safety stops (force and moment limits,
//! watchdogs, workspace, tracking) and the user's. `metrics.json` states the stop, and the
//! status follows from it ([`crate::metrics::Metrics::verdict`]).

use serde::Serialize;

/// Outcome of a run, as `metrics.json` states it (one vocabulary for simulated and
/// real-time runs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Ran to the end, faithful to the reference within the tolerances.
    Ok,
    /// Ran to the end, but broke a tolerance (see `violations`).
    Unfaithful,
    /// Stopped by the user (Ctrl-C).
    Interrupted,
    /// Stopped when the energy passed its bound or a value stopped being finite.
    Diverged,
    /// Stopped by a safety function of the real-time runtime.
    Stopped,
}

/// Why a run stopped: the one list for simulations and the real-time runtime.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopKind {
    /// Ran for the whole duration.
    Completed,
    /// Stopped by the user (Ctrl-C).
    User,
    /// Measured force magnitude above the limit.
    ForceLimit,
    /// Measured moment magnitude above the limit.
    MomentLimit,
    /// No valid sensor record for longer than the watchdog.
    SensorWatchdog,
    /// No valid robot feedback for longer than the watchdog.
    RobotWatchdog,
    /// Commanded rod tip outside the workspace.
    Workspace,
    /// The robot's fed-back rod tip far from every command of the tracking window (frozen or
    /// wrong feedback, a robot that does not follow).
    Tracking,
    /// A state, force or command stopped being finite.
    NonFinite,
    /// The virtual energy passed the scenario's divergence bound.
    Diverged,
    /// The force the hardware would feel at the new command (the scenario's contact law at
    /// the commanded rod tip) above the force limit: stopped before it is sent.
    PredictedForceLimit,
    /// The moment the hardware would feel at the new command above the moment limit.
    PredictedMomentLimit,
    /// The robot's cycle, measured from its own time stamps (RSI IPOC, EGM time), is not the
    /// configured one.
    RobotCycle,
    /// Too many consecutive answers to a robot that paces the loop left after its deadline.
    LateAnswers,
    /// The measured force at the first contact disagrees with the scenario's stiffness at
    /// the robot's penetration: the sensor's units or scale are wrong.
    Units,
    /// The sensor's connection was reset or closed by the sensor.
    SensorConnection,
    /// Too many sensor frames with a wrong checksum.
    SensorChecksum,
    /// The robot's sequence (RSI IPOC) went backwards: the controller restarted or another
    /// sender took over.
    RobotSequence,
    /// Stopped by an operator from the live view (its `/hilcontact/stop` service): the same
    /// path as a force limit (retreat, hold).
    Operator,
}

impl StopKind {
    /// Every kind, in the order of [`StopKind::code`].
    pub const ALL: [StopKind; 19] = [
        StopKind::Completed,
        StopKind::User,
        StopKind::ForceLimit,
        StopKind::MomentLimit,
        StopKind::SensorWatchdog,
        StopKind::RobotWatchdog,
        StopKind::Workspace,
        StopKind::Tracking,
        StopKind::NonFinite,
        StopKind::Diverged,
        StopKind::PredictedForceLimit,
        StopKind::PredictedMomentLimit,
        StopKind::RobotCycle,
        StopKind::LateAnswers,
        StopKind::Units,
        StopKind::SensorConnection,
        StopKind::SensorChecksum,
        StopKind::RobotSequence,
        StopKind::Operator,
    ];

    /// The run's status for this stop.
    pub fn status(self) -> Status {
        match self {
            StopKind::Completed => Status::Ok,
            StopKind::User => Status::Interrupted,
            StopKind::Diverged | StopKind::NonFinite => Status::Diverged,
            _ => Status::Stopped,
        }
    }

    /// Whether a safety function stopped the run.
    pub fn is_safety_stop(self) -> bool {
        !matches!(self, StopKind::Completed | StopKind::User)
    }

    /// Exit code of the command that ran it: 0 completed (or a simulation that ran its
    /// course), 130 user stop (Ctrl-C), 3 any safety stop.
    pub fn exit_code(self) -> i32 {
        match self {
            StopKind::Completed => 0,
            StopKind::User => 130,
            _ => 3,
        }
    }

    /// Small integer for atomics (0 = still running).
    pub fn code(self) -> u8 {
        self as u8 + 1
    }

    /// The kind of a [`StopKind::code`].
    pub fn from_code(code: u8) -> Option<Self> {
        StopKind::ALL.get((code as usize).checked_sub(1)?).copied()
    }
}

/// How a run stopped: kind, tick time (s), and the value that tripped against its limit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stop {
    /// Why.
    pub kind: StopKind,
    /// Time of the tick, s.
    pub time: f64,
    /// The offending value (N, N·m, ms, m or J), NaN when there is none.
    #[serde(serialize_with = "finite_or_null")]
    pub value: f64,
    /// The limit it passed, same unit, NaN when there is none.
    #[serde(serialize_with = "finite_or_null")]
    pub limit: f64,
}

/// The sensor unit a ratio measured/expected force points to (", the sensor seems to report
/// kgf", ...), empty when it is near none of them (within 25 %).
pub fn likely_unit(ratio: f64) -> &'static str {
    const UNITS: [(f64, &str); 4] = [
        (
            1.0 / 9.80665,
            ": the sensor seems to report kgf (ratio near 1/9.81)",
        ),
        (
            1.0 / 4.448222,
            ": the sensor seems to report lbf (ratio near 1/4.448)",
        ),
        (1000.0, ": the sensor seems to report mN (ratio near 1000)"),
        (
            1.0 / 1000.0,
            ": the sensor seems to report kN (ratio near 1/1000)",
        ),
    ];
    UNITS
        .iter()
        .find(|(r, _)| ratio > 0.0 && (ratio / r).ln().abs() < 1.25f64.ln())
        .map_or("", |(_, text)| text)
}

fn finite_or_null<S: serde::Serializer>(v: &f64, s: S) -> std::result::Result<S::Ok, S::Error> {
    if v.is_finite() {
        s.serialize_f64(*v)
    } else {
        s.serialize_none()
    }
}

impl Stop {
    /// A stop without a value.
    pub fn plain(kind: StopKind, time: f64) -> Self {
        Stop {
            kind,
            time,
            value: f64::NAN,
            limit: f64::NAN,
        }
    }

    /// One line for humans, `None` for a completed run (formats: call it outside a loop).
    pub fn reason(&self) -> Option<String> {
        self.reason_naming("sensor", "robot")
    }

    /// [`Stop::reason`] naming the devices' protocols, e.g. `reason_naming("RDT", "EGM")`:
    /// "no valid RDT record", "no valid EGM feedback".
    pub fn reason_naming(&self, sensor: &str, robot: &str) -> Option<String> {
        let (v, l, t) = (self.value, self.limit, self.time);
        Some(match self.kind {
            StopKind::Completed => return None,
            StopKind::User => format!("stopped by the user at {t:.3} s"),
            StopKind::ForceLimit => format!("force limit: |F| = {v:.1} N > {l:.1} N (force_limit) at {t:.3} s"),
            StopKind::MomentLimit => format!("moment limit: |M| = {v:.2} N·m > {l:.2} N·m (moment_limit) at {t:.3} s"),
            StopKind::SensorWatchdog => format!("sensor watchdog: no valid {sensor} record for {v:.1} ms > {l:.1} ms (watchdog_ms) at {t:.3} s"),
            StopKind::RobotWatchdog => format!("robot watchdog: no valid {robot} feedback for {v:.1} ms > {l:.1} ms (watchdog_ms) at {t:.3} s"),
            StopKind::Workspace => format!("workspace limit: commanded rod tip {:.1} mm from its start > {:.1} mm (workspace) at {t:.3} s", v * 1e3, l * 1e3),
            StopKind::Tracking => format!("tracking limit: the fed-back rod tip is {:.1} mm from every command of the tracking window > {:.1} mm (tracking_limit) at {t:.3} s: frozen or wrong feedback, or a robot that does not follow", v * 1e3, l * 1e3),
            StopKind::NonFinite => format!("a state, force or command stopped being finite at {t:.3} s"),
            StopKind::Diverged => format!("diverged: energy {v:.4} J passed the divergence bound {l:.4} J at {t:.3} s"),
            StopKind::PredictedForceLimit => format!("predicted force limit: the next command would press the rod with |F| = {v:.1} N > {l:.1} N (force_limit, the scenario's contact law at the commanded rod tip) at {t:.3} s"),
            StopKind::PredictedMomentLimit => format!("predicted moment limit: the next command would load the sensor with |M| = {v:.2} N·m > {l:.2} N·m (moment_limit, the scenario's contact law at the commanded rod tip) at {t:.3} s"),
            StopKind::RobotCycle => format!("robot cycle: the {robot} robot's cycle measured from its time stamps is {:.1} ms, configured {:.1} ms (the robot's period option) at {t:.3} s", v * 1e3, l * 1e3),
            StopKind::LateAnswers => format!("late answers: {v:.0} consecutive answers to the {robot} robot left after their deadline (max_late_answers {l:.0}), stopped before the controller would at {t:.3} s"),
            StopKind::Units => format!("units check: at the first contact the measured force is {v:.3} times the scenario's contact law at the robot's penetration (allowed 1/{l:.1} to {l:.1}: units_check_factor){} at {t:.3} s", likely_unit(v)),
            StopKind::SensorConnection => format!("sensor connection: the {sensor} sensor {} its connection at {t:.3} s", if v == 1.0 { "reset (TCP RST)" } else if v == 0.0 { "closed" } else { "failed on" }),
            StopKind::SensorChecksum => format!("sensor checksum errors: {v:.0} {sensor} frames with a wrong checksum or length (max_checksum_errors {l:.0}) at {t:.3} s"),
            StopKind::RobotSequence => format!("robot sequence went backwards: the {robot} robot's sequence (IPOC) fell by {v:.0} at {t:.3} s (a restarted controller or another sender)"),
            StopKind::Operator => format!("operator: stopped from the live view at {t:.3} s"),
        })
    }
}
