//! The loop thread ([`Loop`]): the run's ticks from the first to the stop, and one tick
//! ([`Loop::tick`]: poll the links, the measurement, [`Loop::virtual_step`], the command sent).
//! Its start-up is in [`super::connect`], its stop's hold and retreat in [`super::hold`].
//! Never allocates, locks or logs once the first tick has started.

use std::sync::atomic::Ordering;
use std::sync::Arc;

use nalgebra::Vector3;

use hilcontact_core::facility::Measurement;
use hilcontact_core::world::RelativeMotion;

use super::driver::Driver;
use super::status::SharedStatus;
use crate::clock::{now_ns, sleep_until_ns, Histogram, SchedulingReport};
use crate::devices::{Pacing, RobotLink, SensorLink, Wrench};
use crate::error::Result;
use crate::feedback::FeedbackEstimator;
use crate::offset::{OffsetMode, OffsetOptions};
use crate::report::{RunOutcome, Sample};
use crate::safety::{
    check_predicted, check_workspace, check_wrench, predicted_wrench, SafetyLimits, SafetyReport,
    StopEvent, StopKind, Tracking, UnitsCheck,
};
use hilcontact_core::world::TwoBodySystem;

/// Below this measured force magnitude the rod is taken as free of contact (the retreat
/// target of a force stop), N.
pub const CONTACT_FREE_FORCE: f64 = 5.0;

/// The loop thread's state: the virtual side, the two links and the timing statistics.
pub(super) struct Loop {
    /// The virtual side of a tick: the core's one HIL step, or the calibration procedure.
    pub(super) step: Box<dyn Driver>,
    pub(super) rod: Vector3<f64>,
    pub(super) period: f64,
    pub(super) period_ns: u64,
    pub(super) ticks: u64,
    /// The scenario's two bodies and contact (the predicted wrench of a command, the
    /// expected force at the robot's pose).
    pub(super) system: TwoBodySystem,
    /// Virtual steps per robot message (robot pacing: the robot's cycle / `period`; 1 on
    /// the clock).
    pub(super) steps: u64,
    /// The last virtual step run.
    pub(super) last_step: u64,
    /// The units check of the first contact.
    pub(super) units: UnitsCheck,
    /// What the safety functions saw (peaks, the line that tripped, the cycle).
    pub(super) safety: SafetyReport,
    pub(super) limits: SafetyLimits,
    pub(super) start_tip: Vector3<f64>,
    pub(super) initial: RelativeMotion,
    pub(super) connect_timeout: f64,
    pub(super) start_tolerance: f64,
    pub(super) hold_time: f64,
    pub(super) offset: OffsetOptions,
    /// The sensor's offset measured at start (subtracted from every record), N and N·m.
    pub(super) sensor_offset: Wrench,
    // the links
    pub(super) pacing: Pacing,
    /// Robot feedback later than this after the previous one is `late`, ns.
    pub(super) late_ns: u64,
    pub(super) sensor: Box<dyn SensorLink>,
    pub(super) last_sensor_ns: u64,
    pub(super) force: Vector3<f64>,
    pub(super) moment: Vector3<f64>,
    pub(super) robot: Box<dyn RobotLink>,
    pub(super) last_robot_ns: u64,
    /// `last_robot_ns` at the previous tick (a new robot message since: a fresh pose).
    pub(super) previous_robot_ns: u64,
    pub(super) estimator: FeedbackEstimator,
    /// The last command sent (it passed every check), m and rad in `t`.
    pub(super) last_command: Option<RelativeMotion>,
    /// The robot's fed-back pose at the last tick whose measured force was below
    /// [`CONTACT_FREE_FORCE`] (the retreat target of a force stop).
    pub(super) last_free: Option<RelativeMotion>,
    /// The commands of the tracking window, against which the feedback is checked.
    pub(super) tracking: Tracking,
    // log and timing
    pub(super) producer: rtrb::Producer<Sample>,
    pub(super) samples_dropped: u64,
    pub(super) shared: Arc<SharedStatus>,
    pub(super) wake: Histogram,
    pub(super) period_hist: Histogram,
    pub(super) compute: Histogram,
    pub(super) overruns: u64,
    pub(super) t0_ns: u64,
    /// What the OS granted this thread (asked for at its start).
    pub(super) scheduling: SchedulingReport,
}

/// Whether a stop of `kind` backs the robot away from the contact before it holds: the
/// stops that may find the rod pressed into a wall and a robot that still follows.
pub(super) fn retreats(kind: StopKind) -> bool {
    matches!(
        kind,
        StopKind::ForceLimit
            | StopKind::MomentLimit
            | StopKind::PredictedForceLimit
            | StopKind::PredictedMomentLimit
            | StopKind::Units
            | StopKind::RobotCycle
            | StopKind::LateAnswers
            | StopKind::SensorConnection
            | StopKind::SensorChecksum
            | StopKind::Operator
    )
}

impl Loop {
    pub(super) fn run(&mut self) -> Result<RunOutcome> {
        let connected = self.connect();
        if let Err(e) = connected {
            self.sensor.stop_streaming();
            return Err(e);
        }
        self.shared.phase.store(1, Ordering::Release);
        self.t0_ns = now_ns() + self.period_ns;
        let mut stop = StopEvent::plain(StopKind::Completed, self.ticks as f64 * self.period);
        let mut last_wake: Option<u64> = None;
        let mut k = 0u64;
        let cycle_ns = self.cycle_ns();
        // the clock's deadlines moved later by the periods a driver that does not catch up
        // skipped, ns
        let mut skipped_ns = 0u64;
        while k <= self.ticks {
            let (wake, deadline) = match self.pacing {
                Pacing::Clock => {
                    let deadline = self.t0_ns + k * self.period_ns + skipped_ns;
                    sleep_until_ns(deadline);
                    (now_ns(), deadline)
                }
                Pacing::Robot => self.wait_for_robot(last_wake),
            };
            let latency = wake.saturating_sub(deadline);
            self.wake.record(latency);
            if let Some(prev) = last_wake {
                self.period_hist.record((wake - prev).abs_diff(cycle_ns));
            }
            last_wake = Some(wake);
            let outcome = self.tick(k, wake, latency);
            let end = now_ns();
            self.compute.record(end - wake);
            if end > deadline + cycle_ns {
                self.overruns += 1;
                if !self.step.catches_up() {
                    // the next deadline one period from now: the missed periods are skipped,
                    // not caught up in a burst of commands
                    skipped_ns += (end - deadline) / self.period_ns * self.period_ns;
                }
            }
            self.publish(self.last_step + 1, latency);
            if let Some(event) = outcome {
                stop = event;
                break;
            }
            k += self.steps;
        }
        let wall_time = (now_ns() - self.t0_ns) as f64 * 1e-9;
        self.shared
            .stop_code
            .store(stop.kind.code(), Ordering::Release);
        self.shared.phase.store(2, Ordering::Release);
        // a stop that may find the rod in contact first backs away from it, then holds there
        let retreated = retreats(stop.kind).then(|| self.retreat()).flatten();
        self.safety.robot_cycle = self.estimator.cycle.measured;
        self.safety.units_ratio = self.units.ratio;
        (
            self.safety.units_expected_peak,
            self.safety.units_measured_peak,
        ) = self.units.peaks();
        self.hold(retreated);
        if let Some(pose) = retreated.or_else(|| self.checked_pose()) {
            self.safety.session_ended_cleanly = self.robot.end_session(&pose);
        }
        self.sensor.stop_streaming();
        let robot = *self.robot.stats();
        Ok(RunOutcome {
            stop,
            ticks: self.last_step.min(self.ticks) + 1,
            wall_time,
            wake_latency: self.wake.summary(),
            period_error: self.period_hist.summary(),
            compute: self.compute.summary(),
            overruns: self.overruns,
            sensor: *self.sensor.stats(),
            robot,
            commands_sent: robot.sent,
            send_errors: robot.send_errors,
            samples_dropped: self.samples_dropped,
            sensor_name: self.sensor.name(),
            robot_name: self.robot.name(),
            pacing: self.pacing,
            sensor_report: self.sensor.report(),
            robot_report: self.robot.report(),
            robot_address: self.robot.peer(),
            sensor_offset: (self.offset.mode == OffsetMode::Measure).then(|| {
                let (f, m) = (self.sensor_offset.force, self.sensor_offset.moment);
                [f.x, f.y, f.z, m.x, m.y, m.z]
            }),
            scheduling: self.scheduling.clone(),
            safety: self.safety,
        })
    }

    /// The time between two of the loop's wake-ups, ns: the robot's cycle on robot pacing,
    /// the period on the clock.
    pub(super) fn cycle_ns(&self) -> u64 {
        self.steps * self.period_ns
    }

    /// Robot pacing: waits for the robot's next packet, at most the watchdog (then the tick
    /// runs and the watchdog stops the run). Returns the wake-up time and the tick's nominal
    /// deadline (one period after the previous wake-up; the first tick has none), ns.
    pub(super) fn wait_for_robot(&mut self, last_wake: Option<u64>) -> (u64, u64) {
        let start = now_ns();
        let n = self
            .robot
            .wait(start + self.limits.watchdog_ns(), &mut self.estimator);
        let wake = now_ns();
        self.robot_arrived(n, wake);
        let deadline = last_wake.map_or(wake, |w| w + self.cycle_ns());
        (wake, deadline)
    }

    /// Polls both links; returns whether a new sensor record arrived.
    pub(super) fn poll_links(&mut self, now: u64) -> bool {
        let new_record = match self.sensor.poll(now) {
            Some(Wrench { force, moment }) => {
                self.force = force - self.sensor_offset.force;
                self.moment = moment - self.sensor_offset.moment;
                self.last_sensor_ns = now;
                true
            }
            None => false,
        };
        let n = self.robot.poll(now, &mut self.estimator);
        self.robot_arrived(n, now);
        new_record
    }

    /// Bookkeeping of `n` feedback messages accepted at `now`: lateness and the watchdog.
    pub(super) fn robot_arrived(&mut self, n: usize, now: u64) {
        if n == 0 {
            return;
        }
        if self.last_robot_ns > 0 && now - self.last_robot_ns > self.late_ns {
            self.robot.stats_mut().late += 1;
        }
        self.last_robot_ns = now;
    }

    /// One control tick: the links polled once, then `steps` virtual steps from `k` (one on
    /// the clock; as many as fit in the robot's cycle on robot pacing, the robot's motion
    /// estimated at each step's time), the last command sent; returns a stop, if any. Never
    /// allocates.
    pub(super) fn tick(&mut self, k: u64, wake: u64, latency: u64) -> Option<StopEvent> {
        let new_record = self.poll_links(wake);
        if !new_record {
            self.sensor.stats_mut().late += 1;
        }
        let new_pose = self.last_robot_ns != self.previous_robot_ns;
        self.previous_robot_ns = self.last_robot_ns;
        if let Some(pose) = self.estimator.last_pose() {
            let expected = predicted_wrench(&self.system, &pose).0;
            if self.force.norm() < CONTACT_FREE_FORCE && expected < CONTACT_FREE_FORCE {
                self.last_free = Some(pose);
            }
        }
        let mut command = None;
        for j in 0..self.steps {
            let kk = k + j;
            if kk > self.ticks {
                break;
            }
            let at = wake + j * self.period_ns;
            let actual = self.estimator.estimate(at).unwrap_or(self.initial);
            let m = Measurement {
                force: self.force,
                moment: self.moment,
                actual,
            };
            self.last_step = kk;
            // a record is new at the first step after it came; held otherwise (the
            // compensators' identification learns only from new ones)
            self.step.set_sensor_fresh(new_record && j == 0);
            self.step.set_robot_fresh(new_pose && j == 0);
            match self.virtual_step(kk, &m, wake, latency) {
                Ok(c) => command = Some(c),
                Err(stop) => return Some(stop),
            }
        }
        let command = command?;
        self.robot
            .send(&command, now_ns().saturating_sub(self.t0_ns));
        self.last_command = Some(command);
        None
    }

    /// Stops that are the loop's, not the dynamics': `stop()` and the links' watchdogs.
    pub(super) fn loop_checks(&self, time: f64, wake: u64) -> Option<StopEvent> {
        if self.shared.stop_requested.load(Ordering::Acquire) {
            return Some(StopEvent::plain(StopKind::User, time));
        }
        if self.shared.control.operator_stop_requested() {
            return Some(StopEvent::plain(StopKind::Operator, time));
        }
        let watchdog = self.limits.watchdog_ns();
        let sensor_silence = wake.saturating_sub(self.last_sensor_ns);
        if sensor_silence > watchdog {
            return Some(StopEvent {
                kind: StopKind::SensorWatchdog,
                time,
                value: sensor_silence as f64 * 1e-6,
                limit: self.limits.watchdog_ms,
            });
        }
        // The sensor's fault first, then the robot's.
        if let Some(fault) = self.sensor.fault().or_else(|| self.robot.fault()) {
            return Some(StopEvent {
                kind: fault.kind,
                time,
                value: fault.value,
                limit: fault.limit,
            });
        }
        if let Some(measured) = self.estimator.cycle.mismatch {
            return Some(StopEvent {
                kind: StopKind::RobotCycle,
                time,
                value: measured,
                limit: self.estimator.cycle.configured,
            });
        }
        let robot_silence = wake.saturating_sub(self.last_robot_ns);
        if robot_silence > watchdog {
            return Some(StopEvent {
                kind: StopKind::RobotWatchdog,
                time,
                value: robot_silence as f64 * 1e-6,
                limit: self.limits.watchdog_ms,
            });
        }
        None
    }

    /// The virtual side of tick `k` (virtual time `k·T`): compensate the measurement, log the
    /// sample, the checks, integrate, check the new command (workspace, energy bound); returns
    /// the command (relative motion in `t`) to send, or the stop. Never allocates.
    pub(super) fn virtual_step(
        &mut self,
        k: u64,
        m: &Measurement,
        wake: u64,
        latency: u64,
    ) -> std::result::Result<RelativeMotion, StopEvent> {
        let time = k as f64 * self.period;
        let (record, verdict) = self.step.observe(k, m);
        let sample = Sample {
            record,
            wake_latency: latency as f64 * 1e-9,
            sensor_age: wake.saturating_sub(self.last_sensor_ns) as f64 * 1e-9,
            robot_age: wake.saturating_sub(self.last_robot_ns) as f64 * 1e-9,
        };
        if self.producer.push(sample).is_err() {
            self.samples_dropped += 1;
        }

        if let Some(stop) = self.loop_checks(time, wake) {
            return Err(stop);
        }
        let measured = m.force.norm();
        self.safety.measured_peak_force = self.safety.measured_peak_force.max(measured);
        // the law at the newest reported pose (with the estimate's velocity, for the damping):
        // an extrapolated pose overshoots when a report comes late, and its spike would be the
        // expected peak (the calibration's own check read 0.43-0.97 from it over EGM)
        let reported = self
            .estimator
            .last_pose()
            .map(|pose| RelativeMotion {
                velocity: m.actual.velocity,
                angular_velocity: m.actual.angular_velocity,
                ..pose
            })
            .unwrap_or(m.actual);
        let expected = self.step.units_expected(&self.system, &reported);
        if let Some(stop) = self.units.push(expected, measured, time) {
            return Err(stop);
        }
        if let Some(stop) = check_wrench(&self.limits, &m.force, &m.moment, time) {
            self.safety.limit_line = Some("measured");
            return Err(self.units.decide(time).unwrap_or(stop));
        }
        if let Some(fed_back) = self.estimator.last_pose() {
            if let Some(stop) = self.tracking.check(&fed_back.point(&self.rod), time) {
                return Err(stop);
            }
        }
        // divergence, a non-finite record, or the end of the run
        if let Some(stop) = verdict {
            return Err(stop);
        }
        let command = self.step.advance(k)?;
        let (force, moment) = predicted_wrench(&self.system, &command);
        if let Some(stop) = check_predicted(&self.limits, force, moment, time) {
            self.safety.limit_line = Some("predicted");
            return Err(self.units.decide(time).unwrap_or(stop));
        }
        self.safety.predicted_peak_force = self.safety.predicted_peak_force.max(force);
        self.safety.predicted_peak_moment = self.safety.predicted_peak_moment.max(moment);
        if let Some(stop) = check_workspace(
            &self.limits,
            &command.point(&self.rod),
            &self.start_tip,
            time,
        ) {
            return Err(stop);
        }
        self.tracking.push(command.point(&self.rod));
        Ok(command)
    }

    pub(super) fn publish(&self, tick: u64, latency: u64) {
        let s = &self.shared;
        let (sensor, robot) = (self.sensor.stats(), self.robot.stats());
        s.tick.store(tick, Ordering::Relaxed);
        s.force_bits
            .store(self.force.norm().to_bits(), Ordering::Relaxed);
        s.energy_bits
            .store(self.step.energy().to_bits(), Ordering::Relaxed);
        s.max_latency_ns.fetch_max(latency, Ordering::Relaxed);
        s.overruns.store(self.overruns, Ordering::Relaxed);
        s.sensor.store(sensor);
        s.robot.store(robot);
    }
}
