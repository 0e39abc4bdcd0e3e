//! The start checks of a run, shared by the run ([`super::HilHandle::start`]) and the dry run
//! ([`crate::check`]): the options and the scenario, the links' context, the robot's pacing,
//! the peers heard, the robot's distance from the scenario's start.

use hilcontact_core::hil::VirtualDynamics;
use hilcontact_core::{Plan, Scenario};

use crate::devices::{LinkContext, Pacing, RobotLink, SensorLink, StartRegion};
use crate::error::{Result, RtError};
use crate::options::{ParsedRuntime, RuntimeOptions};

/// The scenario's plan and the parsed options, once the options are checked too, and that the
/// scenario can start with them ([`crate::offset::OffsetOptions::check_start`]).
pub(crate) fn validate(
    scenario: &Scenario,
    options: &RuntimeOptions,
) -> Result<(Plan, ParsedRuntime)> {
    let (plan, parsed) = validate_options(scenario, options)?;
    options.offset.check_start(&plan)?;
    Ok((plan, parsed))
}

/// The scenario's plan and the parsed options ([`RuntimeOptions::parse`]: each alone, bad
/// input), once the checks across them are done too (the sensor's rate from the period).
pub(crate) fn validate_options(
    scenario: &Scenario,
    options: &RuntimeOptions,
) -> Result<(Plan, ParsedRuntime)> {
    let plan = scenario.resolve()?;
    let parsed = options.parse()?;
    parsed.sensor.check_period(plan.period)?;
    Ok((plan, parsed))
}

/// What the links of a run of `plan` are told when they are opened: the period, the connect
/// timeout and the start region (the scenario's initial pose, the rod, `start_tolerance`).
pub(crate) fn link_context(plan: &Plan, options: &RuntimeOptions) -> LinkContext {
    LinkContext {
        period: plan.period,
        connect_timeout: options.connect_timeout,
        start: Some(StartRegion {
            pose: VirtualDynamics::new(plan).command(),
            rod: plan.system.rod_tip,
            tolerance: options.start_tolerance,
        }),
    }
}

/// Refuses a robot link whose feedback period is not a positive number, or that paces the
/// loop ([`Pacing::Robot`]) at a cycle that is not a whole multiple of the scenario's `period`
/// (s); returns the virtual steps per loop wake-up: the robot's cycle / `period` on robot
/// pacing (the virtual dynamics keep the scenario's period), 1 on the clock.
pub(crate) fn check_pacing(robot: &dyn RobotLink, period: f64) -> Result<u64> {
    let feedback_period = robot.feedback_period();
    if !(feedback_period.is_finite() && feedback_period > 0.0) {
        return Err(RtError::option(
            "robot",
            format!(
                "the {} link reports a feedback period of {feedback_period} s",
                robot.name()
            ),
        ));
    }
    if robot.pacing() == Pacing::Clock {
        return Ok(1);
    }
    let steps = (feedback_period / period).round();
    if steps < 1.0 || (steps * period - feedback_period).abs() > 1e-6 * feedback_period {
        return Err(RtError::option(
            "simulation.period",
            format!(
                "the {} robot paces the loop every {} s, which is not a whole number of simulation.period = {} s: use a period that divides {} s (e.g. {} or 0.001)",
                robot.name(),
                feedback_period,
                period,
                feedback_period,
                feedback_period
            ),
        ));
    }
    Ok(steps as u64)
}

/// What is missing at start: "no RDT record from the sensor at ..." and/or "no EGM feedback
/// from the robot on ..." (the links' own descriptions, which explain e.g. senders that were
/// not at the start); empty when both peers were heard.
pub(crate) fn missing_peers(
    sensor: &dyn SensorLink,
    robot: &dyn RobotLink,
    has_feedback: bool,
) -> Vec<String> {
    let mut missing = Vec::new();
    if sensor.stats().accepted == 0 {
        missing.push(format!(
            "no {} record from {}",
            sensor.name(),
            sensor.describe()
        ));
    }
    if !has_feedback {
        missing.push(format!(
            "no {} feedback from {}",
            robot.name(),
            robot.describe()
        ));
    }
    missing
}

/// Refuses a start whose fed-back rod tip is `distance` from the scenario's initial one, beyond
/// `tolerance` (both m).
pub(crate) fn check_start_distance(distance: f64, tolerance: f64) -> Result<()> {
    if distance > tolerance {
        return Err(RtError::Connect(format!(
            "the robot's rod tip is {:.1} mm from the scenario's initial position (start_tolerance {:.1} mm): move it there first",
            distance * 1e3,
            tolerance * 1e3
        )));
    }
    Ok(())
}
