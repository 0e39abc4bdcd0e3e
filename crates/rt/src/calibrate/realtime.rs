//! `hilcontact calibrate SCENARIO --out cal.toml` over the device links: the calibration
//! [`Procedure`] as the real-time loop's driver ([`crate::runtime`]), with the links, options
//! and safety functions of `hil` unchanged (workspace, force and moment limits including the
//! predicted one, tracking, watchdogs, start checks, retreat and hold on every stop); the
//! procedure's own bounds (probe depth, press force, its abort force) apply as well.
//!
//! [`CalibrationHandle::start`] starts it; [`CalibrationHandle::progress`] gives the progress
//! lines, surface by surface, as they come; [`CalibrationHandle::finish`] waits for the end
//! and builds the calibration file when every wall was measured.
//!
//! The loop's tick allocates nothing, as `hil`'s (`tests/no_alloc_calibrate.rs`): the
//! procedure's logs are preallocated and bounded ([`Procedure`]); the robot's response and
//! each wall's fit run on a thread of their own (`calibration fit`), off the loop's, with the
//! probes' logs handed there and back (the procedure holds at rest, out of contact, and each
//! tick polls for the result); progress goes out as fixed-size messages ([`Progress`]) to a
//! thread of its own (`calibration progress`) that formats the lines. Only a stop of the
//! procedure formats its reason in the tick. Each tick's time is measured and reported like
//! `hil`'s (overruns).

use std::sync::mpsc::{channel, sync_channel, Receiver, Sender, SyncSender, TrySendError};
use std::sync::Mutex;
use std::thread::JoinHandle;
use std::time::Duration;

use nalgebra::{UnitQuaternion, Vector3};
use serde_json::Value;

use hilcontact_core::compensator::Rendering;
use hilcontact_core::contact::ContactModel;
use hilcontact_core::facility::Measurement;
use hilcontact_core::hil::HilRecord;
use hilcontact_core::world::{RelativeMotion, TwoBodySystem};
use hilcontact_core::{Plan, Scenario};

use super::procedure::{FitDone, FitJob};
use super::{
    calibration_file, describe, CalibrateOptions, CalibrationOutcome, Procedure, Progress, Step,
    MAX_SECONDS_PER_WALL,
};
use crate::error::{Result, RtError};
use crate::options::RuntimeOptions;
use crate::report::loop_report;
use std::any::Any;

use crate::runtime::driver::Driver;
use crate::runtime::{LoopEnd, LoopHandle, StatusSnapshot};
use crate::safety::{StopEvent, StopKind};

/// The procedure as the loop's driver: each tick's measurement in, the next command out; its
/// progress lines sent to the handle.
pub struct RealtimeProcedure {
    procedure: Procedure,
    /// The scenario's contact law (the units check's expectation).
    law: ContactModel,
    rod: Vector3<f64>,
    /// Sensor to `t`.
    sensor_to_t: UnitQuaternion<f64>,
    /// Control period, s.
    period: f64,
    /// The loop's bound, ticks: past it the procedure has not finished in time.
    ticks: u64,
    initial: RelativeMotion,
    /// The command the procedure gave last (sent after this tick's checks).
    command: RelativeMotion,
    /// Whether the procedure reached its end (finished or stopped by itself).
    done: bool,
    /// Progress events to the formatting thread (room for every event of a calibration: the
    /// robot's and one per wall, so a send never finds it full); None once finished.
    progress: Option<SyncSender<Progress>>,
    /// The formatting thread: every progress line in order and the time spent on each wall
    /// measured (s), once `progress` is dropped.
    formatter: Option<JoinHandle<(Vec<String>, Vec<f64>)>>,
    /// A fit to the fitting thread (one at a time: the procedure holds until its result),
    /// and its result back.
    jobs: SyncSender<FitJob>,
    results: Receiver<FitDone>,
}

impl RealtimeProcedure {
    /// The procedure of `plan` as a driver, with the loop's bound in ticks; refuses (before
    /// anything is opened) what [`Procedure::new`] refuses.
    fn new(
        plan: &Plan,
        options: &CalibrateOptions,
        force_limit: f64,
        progress: Sender<String>,
    ) -> Result<(Self, u64)> {
        let procedure = Procedure::new(plan, options, force_limit)
            .map_err(|message| RtError::option("calibrate", message))?;
        let initial = plan.nominal.relative_motion(&plan.initial);
        let initial = RelativeMotion {
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
            ..initial
        };
        let seconds = options.excitation_duration
            + 10.0
            + MAX_SECONDS_PER_WALL * plan.nominal.contact.walls.len() as f64;
        let ticks = (seconds / plan.period).ceil() as u64;
        // the walls' fits run on their own thread, off the loop's: the loop holds at rest and
        // polls for the result (a fit takes up to ~0.1 s; in a tick it stalled the loop)
        let (jobs, job_queue) = sync_channel::<FitJob>(1);
        let (result_sender, results) = sync_channel::<FitDone>(1);
        std::thread::Builder::new()
            .name("calibration fit".into())
            .spawn(move || {
                for job in job_queue {
                    if result_sender.send(job.run()).is_err() {
                        break;
                    }
                }
            })
            .map_err(|e| RtError::io_other("calibration fit thread", e.to_string()))?;
        // the progress lines are formatted off the loop's thread, sent to the handle as they
        // come and kept
        let names = procedure.wall_names();
        let (events, event_queue) = sync_channel::<Progress>(names.len() + 2);
        let formatter = std::thread::Builder::new()
            .name("calibration progress".into())
            .spawn(move || {
                let (mut lines, mut wall_seconds) = (Vec::new(), Vec::new());
                for event in event_queue {
                    if let Progress::Wall { spent, .. } = event {
                        wall_seconds.push(spent);
                    }
                    let line = describe(&event, &names);
                    // the handle may be gone (dropped): the lines are kept here as well
                    let _ = progress.send(line.clone());
                    lines.push(line);
                }
                (lines, wall_seconds)
            })
            .map_err(|e| RtError::io_other("calibration progress thread", e.to_string()))?;
        Ok((
            RealtimeProcedure {
                procedure,
                law: plan.nominal.contact.law,
                rod: plan.nominal.rod_tip,
                sensor_to_t: plan.sensor.orientation,
                period: plan.period,
                ticks,
                initial,
                command: initial,
                done: false,
                progress: Some(events),
                formatter: Some(formatter),
                jobs,
                results,
            },
            ticks,
        ))
    }

    /// The force the loop's units check expects at the fed-back pose, N: the scenario's
    /// (static) law at the penetration past the contact the current probe detected, 0 while
    /// no probe is in contact. The pose is the newest one the robot reported
    /// ([`Procedure::fed_back_tip`]), not the loop's estimate `actual` extrapolated between
    /// its messages (whose amplified reporting noise made the expected force spike).
    pub(crate) fn units_expected(&self, actual: &RelativeMotion) -> f64 {
        let Some((point, normal)) = self.procedure.contact_reference() else {
            return 0.0;
        };
        let tip = self
            .procedure
            .fed_back_tip()
            .unwrap_or_else(|| actual.point(&self.rod));
        let depth = (point - tip).dot(&normal).max(0.0);
        match self.law {
            ContactModel::Linear(l) => l.stiffness * depth,
            ContactModel::HuntCrossley(h) => h.stiffness * depth.powf(h.exponent),
        }
    }

    /// The command the run starts from: the scenario's initial pose at rest.
    pub(crate) fn initial(&self) -> RelativeMotion {
        self.initial
    }

    /// Tick `k`'s first half: the procedure's step on `m`; the tick's record (desired: the
    /// command being followed; measured: `m`) and the stop it calls for: `completed` when the
    /// procedure is over (finished, or stopped by itself and backed out of contact) or at the
    /// loop's bound, `non-finite` for a record that is not finite.
    pub(crate) fn observe(&mut self, k: u64, m: &Measurement) -> (HilRecord, Option<StopEvent>) {
        let time = k as f64 * self.period;
        let desired = self.command;
        let step = self.procedure.step(m);
        if let Some(job) = self.procedure.take_fit_job() {
            // one job at a time: a full queue or a thread gone cannot happen while the
            // procedure waits; if either did, the fit runs here rather than never
            if let Err(TrySendError::Full(job) | TrySendError::Disconnected(job)) =
                self.jobs.try_send(job)
            {
                self.procedure.deliver_fit(job.run());
            }
        }
        if let Ok(result) = self.results.try_recv() {
            self.procedure.deliver_fit(result);
        }
        if let Some(progress) = &self.progress {
            // room for every event of the calibration: never full, never allocating
            self.procedure.drain_events(|event| {
                let _ = progress.try_send(event);
            });
        }
        let mut stop = None;
        match step {
            Step::Command(c) => self.command = c,
            Step::Done => {
                self.done = true;
                stop = Some(StopEvent::plain(StopKind::Completed, time));
            }
        }
        if k >= self.ticks {
            stop = Some(StopEvent::plain(StopKind::Completed, time));
        }
        let rod_force = -(self.sensor_to_t * m.force);
        let record = HilRecord {
            time,
            tip_position: desired.point(&self.rod),
            tip_velocity: desired.point_velocity(&self.rod),
            angular_velocity: desired.angular_velocity,
            orientation: desired.orientation,
            actual_tip_position: m.actual.point(&self.rod),
            actual_tip_velocity: m.actual.point_velocity(&self.rod),
            actual_orientation: m.actual.orientation,
            actual_angular_velocity: m.actual.angular_velocity,
            contact_force: rod_force,
            friction_force: Vector3::zeros(),
            contact_moment: self.sensor_to_t * m.moment,
            measured_force: m.force,
            measured_moment: m.moment,
            applied_force: Vector3::zeros(),
            applied_moment: Vector3::zeros(),
            energy: 0.0,
            stiffness_estimate: f64::NAN,
            damping_estimate: f64::NAN,
            law_factor: f64::NAN,
            observed_energy: f64::NAN,
            rendering: Rendering::Unreported,
        };
        if !record.is_finite() {
            stop = Some(StopEvent::plain(StopKind::NonFinite, time));
        }
        (record, stop)
    }

    /// Tick `k`'s second half: the procedure's command for the next tick, or a `non-finite`
    /// stop (never sent).
    pub(crate) fn advance(&mut self, k: u64) -> std::result::Result<RelativeMotion, StopEvent> {
        let c = &self.command;
        let finite = c.position.iter().all(|x| x.is_finite())
            && c.velocity.iter().all(|x| x.is_finite())
            && c.angular_velocity.iter().all(|x| x.is_finite())
            && c.orientation.coords.iter().all(|x| x.is_finite());
        if finite {
            Ok(self.command)
        } else {
            Err(StopEvent::plain(
                StopKind::NonFinite,
                k as f64 * self.period,
            ))
        }
    }
}

/// The loop's driver: the procedure's tick halves; a late tick's periods skipped, not caught
/// up (caught up, the moves after a long tick would be sent in a burst); the units check against the contact the probe detected, since the hardware is
/// not where the scenario says; no virtual energy.
impl Driver for RealtimeProcedure {
    fn set_robot_fresh(&mut self, fresh: bool) {
        self.procedure.set_robot_fresh(fresh)
    }

    fn set_sensor_fresh(&mut self, fresh: bool) {
        self.procedure.set_sensor_fresh(fresh)
    }

    fn observe(&mut self, k: u64, m: &Measurement) -> (HilRecord, Option<StopEvent>) {
        RealtimeProcedure::observe(self, k, m)
    }

    fn advance(&mut self, k: u64) -> std::result::Result<RelativeMotion, StopEvent> {
        RealtimeProcedure::advance(self, k)
    }

    fn command(&self) -> RelativeMotion {
        self.initial()
    }

    fn catches_up(&self) -> bool {
        false
    }

    fn units_expected(&self, _system: &TwoBodySystem, actual: &RelativeMotion) -> f64 {
        RealtimeProcedure::units_expected(self, actual)
    }

    fn energy(&self) -> f64 {
        0.0
    }

    fn into_any(self: Box<Self>) -> Box<dyn Any + Send> {
        self
    }
}

/// A real-time calibration's end: the calibration (or why there is none) and the loop's stop.
#[derive(Debug, Clone)]
pub struct RealtimeCalibration {
    /// The file (when every wall was measured and the loop ran to the procedure's end), the
    /// progress lines, the time taken (s, the loop's wall-clock time), the time per wall (s),
    /// the peak and the last measured force (N).
    pub outcome: CalibrationOutcome,
    /// Why the loop stopped: `completed` at the procedure's end, else a safety stop of `hil`
    /// (the robot retreated from the contact where `hil` does, then held) or `user`.
    pub stop: StopEvent,
    /// The stop's reason in words (None when completed).
    pub stop_reason: Option<String>,
    /// 0 calibrated, 1 the procedure stopped itself (a wall not found, its force bound, a
    /// failed fit, its time bound: the tip backed out of contact, the robot holds), 3 a
    /// safety stop of the loop (as `hil`), 130 stopped by the user.
    pub exit_code: i32,
    /// The loop's report: stop, timing, the links' counters, the safety functions' peaks.
    pub realtime: Value,
}

/// A running real-time calibration.
pub struct CalibrationHandle {
    running: LoopHandle,
    plan: Plan,
    options: CalibrateOptions,
    /// The runtime options it started with (in its loop report).
    runtime: RuntimeOptions,
    force_limit: f64,
    measured_at: String,
    progress: Mutex<Receiver<String>>,
}

impl CalibrationHandle {
    /// Validates the scenario, the runtime options (as `hil`'s) and the procedure's options
    /// against the runtime's force limit (`limits.force_limit`: the probes press to a fifth of
    /// it), then opens the outputs and links of `runtime` and starts the loop with the
    /// procedure as its driver. `measured_at`: the time stamp written into the file.
    pub fn start(
        scenario: &Scenario,
        runtime: &RuntimeOptions,
        options: &CalibrateOptions,
        measured_at: &str,
    ) -> Result<Self> {
        let force_limit = runtime.limits.force_limit;
        let (sender, progress) = channel();
        let (plan, running) = LoopHandle::start(
            scenario,
            runtime,
            |plan| {
                let (driver, ticks) = RealtimeProcedure::new(plan, options, force_limit, sender)?;
                Ok((Box::new(driver) as Box<dyn Driver>, ticks))
            },
            false,
        )?;
        Ok(CalibrationHandle {
            running,
            plan,
            options: options.clone(),
            runtime: runtime.clone(),
            force_limit,
            measured_at: measured_at.to_string(),
            progress: Mutex::new(progress),
        })
    }

    /// A snapshot for a live display (lock-free reads).
    pub fn status(&self) -> StatusSnapshot {
        self.running.status(self.plan.period)
    }

    /// The progress lines since the last call, surface by surface.
    pub fn progress(&self) -> Vec<String> {
        match self.progress.lock() {
            Ok(receiver) => receiver.try_iter().collect(),
            Err(_) => Vec::new(),
        }
    }

    /// Asks the loop to stop (the robot backs out of contact and holds); returns at once.
    pub fn stop(&self) {
        self.running.stop();
    }

    /// Whether the loop has ended.
    pub fn is_finished(&self) -> bool {
        self.running.is_finished()
    }

    /// Waits up to `timeout` for the loop to end; returns whether it has.
    pub fn wait(&self, timeout: Duration) -> bool {
        self.running.wait(timeout)
    }

    /// Waits for the loop's end and builds the calibration: the file when the procedure
    /// measured every wall and the loop ran to its end; else why not. Errors only when the
    /// loop never started (a peer not heard, the start pose refused) or a thread panicked.
    pub fn finish(self) -> Result<RealtimeCalibration> {
        let last_force = self.status().force;
        let LoopEnd {
            outcome,
            driver,
            outputs,
            ..
        } = self.running.join()?;
        let outcome = match outcome {
            Ok(outcome) => outcome,
            Err(e) => {
                outputs.discard();
                return Err(e);
            }
        };
        let _ = outputs.finish();
        let Some(mut driver) =
            driver.and_then(|d| d.into_any().downcast::<RealtimeProcedure>().ok())
        else {
            return Err(RtError::io_other("loop thread", "panicked"));
        };
        // the progress thread ends with its queue, with every line
        driver.progress = None;
        let (lines, wall_seconds) = match driver.formatter.take().map(JoinHandle::join) {
            Some(Ok(formatted)) => formatted,
            _ => return Err(RtError::io_other("calibration progress thread", "panicked")),
        };
        let stop = outcome.stop;
        let stop_reason = stop.reason_naming(outcome.sensor_name, outcome.robot_name);
        let procedure = &driver.procedure;
        let error = if let Some(reason) = &stop_reason {
            Some(format!("the loop stopped: {reason}"))
        } else if let Some(e) = procedure.error() {
            Some(e)
        } else if !driver.done {
            Some(format!(
                "the calibration did not finish in its time bound ({})",
                procedure.whereabouts()
            ))
        } else {
            None
        };
        let facility = format!(
            "real time: {} sensor, {} robot{}",
            outcome.sensor_name,
            outcome.robot_name,
            outcome
                .robot_address
                .map_or(String::new(), |a| format!(" at {a}"))
        );
        let file = match &error {
            Some(_) => None,
            None => Some(
                calibration_file(
                    &self.plan,
                    procedure,
                    &self.options,
                    self.force_limit,
                    &facility,
                    &self.measured_at,
                    outcome.wall_time,
                )
                .map_err(|e| RtError::io_other("calibration", e))?,
            ),
        };
        let exit_code = if stop.kind != StopKind::Completed {
            stop.kind.exit_code()
        } else if error.is_some() {
            1
        } else {
            0
        };
        let mut realtime = loop_report(
            &outcome,
            self.plan.period,
            0,
            stop_reason.clone(),
            exit_code,
            &self.runtime,
        );
        // how the law's samples were paired: those with a new robot pose, and those of them
        // left out because the force was a held sensor record (one period older)
        let (held, with_pose) = procedure.held_forces();
        if let Some(map) = realtime.as_object_mut() {
            map.insert(
                "pairing".into(),
                serde_json::json!({
                    "samples_with_new_pose": with_pose,
                    "held_forces_left_out": held,
                }),
            );
        }
        Ok(RealtimeCalibration {
            outcome: CalibrationOutcome {
                file,
                error,
                progress: lines,
                duration: outcome.wall_time,
                wall_seconds,
                peak_force: outcome.safety.measured_peak_force,
                final_force: last_force,
            },
            stop,
            stop_reason,
            exit_code,
            realtime,
        })
    }
}
