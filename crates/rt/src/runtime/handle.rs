//! The handle of a running HIL loop ([`HilHandle`]): starts it (the outputs opened first, then
//! the links, the writer thread and the loop thread), reads its live status, asks it to stop,
//! and waits for it to end to build its results and finish its outputs.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use nalgebra::Vector3;

use hilcontact_core::hil::HilStep;
use hilcontact_core::world::RelativeMotion;
use hilcontact_core::{metrics, sim, Plan, Scenario};

use super::driver::Driver;
use super::start::{check_pacing, link_context, validate};
use super::status::{SharedStatus, StatusSnapshot};
use super::tick::Loop;
use super::writer::{open_outputs, spawn_writer};
use crate::clock::{request_realtime, tighten_timer_slack, Histogram, SchedulingReport};
use crate::devices::{open_robot, open_sensor, RobotLink, SensorLink, Wrench};
use crate::error::{Result, RtError};
use crate::feedback::FeedbackEstimator;
use crate::options::RuntimeOptions;
use crate::output::events::realtime_end;
use crate::output::run_folder::RunFolder;
use crate::output::Outputs;
use crate::report::{HilOutput, RunOutcome, Sample};
use crate::safety::{SafetyReport, Tracking, UnitsCheck};

/// A running HIL loop.
pub struct HilHandle {
    running: LoopHandle,
    plan: Plan,
    options: RuntimeOptions,
    period: f64,
}

/// A running loop with any driver ([`Driver`]): its live status, its loop thread (which hands
/// the run's outcome and the driver back) and its writer thread. Dropping it stops the loop and
/// waits for both threads.
pub(crate) struct LoopHandle {
    shared: Arc<SharedStatus>,
    thread: Option<JoinHandle<(Result<RunOutcome>, Box<dyn Driver>)>>,
    writer: Option<JoinHandle<(RunFolder, Outputs)>>,
}

/// What a loop hands back once both of its threads have ended.
pub(crate) struct LoopEnd {
    /// The run's outcome, or why it never started.
    pub(crate) outcome: Result<RunOutcome>,
    /// The driver, as the last tick left it (None if the loop thread panicked).
    pub(crate) driver: Option<Box<dyn Driver>>,
    /// The samples kept (none for a calibration).
    pub(crate) run_folder: RunFolder,
    /// The run's outputs, not yet finished.
    pub(crate) outputs: Outputs,
}

/// Capacity of the sample ring buffer (8 s at 1 kHz; the writer drains it every 5 ms).
const RING_CAPACITY: usize = 8192;

impl HilHandle {
    /// Validates, opens the outputs asked for (creates the MCAP file, ...), opens the links of
    /// `options` (binds the sockets, reads the sensor's counts per unit over HTTP unless
    /// given), computes the ideal reference's energy bound, and starts the writer and loop
    /// threads. A start that fails after the outputs were opened discards them (the MCAP file
    /// is removed).
    pub fn start(scenario: &Scenario, options: &RuntimeOptions) -> Result<Self> {
        let (plan, parsed) = validate(scenario, options)?;
        let outputs = open_outputs(&plan, options)?;
        let context = link_context(&plan, options);
        let links = open_sensor(&parsed.sensor, &context)
            .and_then(|sensor| Ok((sensor, open_robot(&parsed.robot, &context)?)));
        match links {
            Ok((sensor, robot)) => Self::start_inner(plan, options, sensor, robot, outputs),
            Err(e) => {
                outputs.discard();
                Err(e)
            }
        }
    }

    /// As [`HilHandle::start`], with links opened by the caller (a protocol outside the
    /// registry, or a test double); `options.sensor` and `options.robot` are parsed and
    /// checked like every option (a bad one refuses the start) and reported in
    /// `metrics.json`, but open nothing.
    pub fn start_with_links(
        scenario: &Scenario,
        options: &RuntimeOptions,
        sensor: Box<dyn SensorLink>,
        robot: Box<dyn RobotLink>,
    ) -> Result<Self> {
        let (plan, _) = validate(scenario, options)?;
        let outputs = open_outputs(&plan, options)?;
        Self::start_inner(plan, options, sensor, robot, outputs)
    }

    fn start_inner(
        plan: Plan,
        options: &RuntimeOptions,
        sensor: Box<dyn SensorLink>,
        robot: Box<dyn RobotLink>,
        outputs: Outputs,
    ) -> Result<Self> {
        let reference_energy = sim::run_reference(&plan, false).0.energy;
        let energy_bound = metrics::divergence_bound(
            plan.divergence_energy_ratio,
            plan.system.energy(&plan.initial),
            &reference_energy,
        );
        let step: Box<dyn Driver> = Box::new(HilStep::new(&plan, energy_bound));
        let ticks = plan.ticks as u64;
        let running = LoopHandle::spawn(&plan, options, sensor, robot, outputs, step, ticks, true)?;
        Ok(HilHandle {
            running,
            period: plan.period,
            plan,
            options: options.clone(),
        })
    }

    /// A snapshot for a live display (lock-free reads).
    pub fn status(&self) -> StatusSnapshot {
        self.running.status(self.period)
    }

    /// Asks the loop to stop (it holds the robot, stops streaming, flushes); returns at once.
    pub fn stop(&self) {
        self.running.stop();
    }

    /// Whether the loop thread has ended.
    pub fn is_finished(&self) -> bool {
        self.running.is_finished()
    }

    /// Waits up to `timeout` for the loop to end; returns whether it has.
    pub fn wait(&self, timeout: Duration) -> bool {
        self.running.wait(timeout)
    }

    /// Waits for the loop and the writer, and builds the time series, reference and metrics;
    /// then gives the outputs (an MCAP recording, ...) the end events and finishes them, their
    /// reports in the metrics (`realtime.mcap`, ...). A run that never started (a peer did not
    /// answer) discards its outputs (an MCAP file is removed).
    pub fn finish(self) -> Result<HilOutput> {
        let LoopEnd {
            outcome,
            run_folder,
            mut outputs,
            ..
        } = self.running.join()?;
        let outcome = match outcome {
            Ok(outcome) => outcome,
            Err(e) => {
                outputs.discard();
                return Err(e);
            }
        };
        let mut output = run_folder.build(&self.plan, &self.options, &outcome)?;
        realtime_end(&mut outputs, &outcome, &output.metrics);
        let reports = outputs.finish();
        if let Some(realtime) = output
            .metrics
            .get_mut("realtime")
            .and_then(|v| v.as_object_mut())
        {
            for (key, report) in reports {
                realtime.insert(key.into(), report);
            }
        }
        Ok(output)
    }
}

impl LoopHandle {
    /// Starts a loop as `hil` does but driven by what `driver` builds from the plan (the
    /// driver and the loop's bound in ticks): validates `scenario` and `options` (the start
    /// checks of [`HilHandle::start`]), builds the driver (a refusal opens nothing), opens the
    /// outputs and the links of `options`, and starts the threads ([`LoopHandle::spawn`]).
    pub(crate) fn start(
        scenario: &Scenario,
        options: &RuntimeOptions,
        driver: impl FnOnce(&Plan) -> Result<(Box<dyn Driver>, u64)>,
        keep_samples: bool,
    ) -> Result<(Plan, Self)> {
        let (plan, parsed) = validate(scenario, options)?;
        let (step, ticks) = driver(&plan)?;
        let outputs = open_outputs(&plan, options)?;
        let context = link_context(&plan, options);
        let links = open_sensor(&parsed.sensor, &context)
            .and_then(|sensor| Ok((sensor, open_robot(&parsed.robot, &context)?)));
        match links {
            Ok((sensor, robot)) => {
                let running = Self::spawn(
                    &plan,
                    options,
                    sensor,
                    robot,
                    outputs,
                    step,
                    ticks,
                    keep_samples,
                )?;
                Ok((plan, running))
            }
            Err(e) => {
                outputs.discard();
                Err(e)
            }
        }
    }

    /// Starts a loop driven by `step` for at most `ticks` ticks with opened links and outputs:
    /// checks the robot's pacing, starts the writer thread (keeping the samples in the run
    /// folder if `keep_samples`) and the loop thread (real-time scheduling as `options` asks).
    /// A pacing refused discards the outputs.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn spawn(
        plan: &Plan,
        options: &RuntimeOptions,
        sensor: Box<dyn SensorLink>,
        robot: Box<dyn RobotLink>,
        outputs: Outputs,
        step: Box<dyn Driver>,
        ticks: u64,
        keep_samples: bool,
    ) -> Result<Self> {
        let o = options;
        let steps = match check_pacing(robot.as_ref(), plan.period) {
            Ok(steps) => steps,
            Err(e) => {
                outputs.discard();
                return Err(e);
            }
        };
        let pacing = robot.pacing();
        let feedback_period = robot.feedback_period();
        let period = plan.period;

        let shared = Arc::new(SharedStatus {
            control: outputs.control(),
            ..SharedStatus::default()
        });
        let (producer, consumer) = rtrb::RingBuffer::<Sample>::new(RING_CAPACITY);
        let run_folder = RunFolder::new(if keep_samples { ticks } else { 0 });
        let writer = spawn_writer(consumer, shared.clone(), run_folder, keep_samples, outputs)?;

        let rod = plan.system.rod_tip;
        let initial = step.command();
        let start_tip = initial.point(&rod);
        let mut state = Loop {
            rod,
            step,
            period,
            period_ns: (period * 1e9).round() as u64,
            ticks,
            system: plan.nominal.clone(),
            steps,
            last_step: 0,
            units: UnitsCheck::new(&o.limits),
            safety: SafetyReport {
                robot_cycle_configured: feedback_period,
                steps_per_cycle: steps,
                ..Default::default()
            },
            limits: o.limits,
            start_tip,
            initial: RelativeMotion {
                velocity: Vector3::zeros(),
                angular_velocity: Vector3::zeros(),
                ..initial
            },
            connect_timeout: o.connect_timeout,
            start_tolerance: o.start_tolerance,
            hold_time: o.hold_time,
            offset: o.offset,
            sensor_offset: Wrench::default(),
            pacing,
            late_ns: (1.5 * feedback_period * 1e9) as u64,
            sensor,
            last_sensor_ns: 0,
            force: Vector3::zeros(),
            moment: Vector3::zeros(),
            robot,
            last_robot_ns: 0,
            previous_robot_ns: 0,
            estimator: {
                let mut e = FeedbackEstimator::new(o.extrapolation);
                e.measure_cycle(feedback_period, o.limits.cycle_tolerance);
                e
            },
            last_command: None,
            last_free: None,
            tracking: Tracking::new(&o.limits, period),
            producer,
            samples_dropped: 0,
            shared: shared.clone(),
            wake: Histogram::new(20_000),
            period_hist: Histogram::new(20_000),
            compute: Histogram::new(20_000),
            overruns: 0,
            t0_ns: 0,
            scheduling: SchedulingReport::normal(),
        };
        let flag = shared.clone();
        let scheduling = o.scheduling;
        // the writer (started above) keeps normal scheduling: only this thread asks for more
        let thread = std::thread::Builder::new()
            .name("hil-rt".into())
            .spawn(move || {
                tighten_timer_slack();
                state.scheduling = request_realtime(&scheduling);
                let outcome = state.run();
                flag.phase.store(3, Ordering::Release);
                flag.finished.store(true, Ordering::Release);
                (outcome, state.step)
            })
            .map_err(|e| RtError::io("loop thread", &e))?;
        Ok(LoopHandle {
            shared,
            thread: Some(thread),
            writer: Some(writer),
        })
    }

    /// A snapshot for a live display (lock-free reads; `period`: the control period, s).
    pub(crate) fn status(&self, period: f64) -> StatusSnapshot {
        self.shared.snapshot(period)
    }

    /// Asks the loop to stop (it holds the robot, stops streaming, flushes); returns at once.
    pub(crate) fn stop(&self) {
        self.shared.stop_requested.store(true, Ordering::Release);
    }

    /// Whether the loop thread has ended.
    pub(crate) fn is_finished(&self) -> bool {
        self.shared.finished.load(Ordering::Acquire)
    }

    /// Waits up to `timeout` for the loop to end; returns whether it has.
    pub(crate) fn wait(&self, timeout: Duration) -> bool {
        let end = std::time::Instant::now() + timeout;
        while !self.is_finished() {
            if std::time::Instant::now() >= end {
                return false;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        true
    }

    /// Waits for the loop and the writer; their results ([`LoopEnd`]).
    pub(crate) fn join(mut self) -> Result<LoopEnd> {
        let (outcome, driver) = match self.thread.take().map(|t| t.join()) {
            Some(Ok((outcome, driver))) => (outcome, Some(driver)),
            _ => (Err(RtError::io_other("loop thread", "panicked")), None),
        };
        let (run_folder, outputs) = match self.writer.take().map(|t| t.join()) {
            Some(Ok(drained)) => drained,
            _ => return Err(RtError::io_other("writer thread", "panicked")),
        };
        Ok(LoopEnd {
            outcome,
            driver,
            run_folder,
            outputs,
        })
    }
}

impl Drop for LoopHandle {
    fn drop(&mut self) {
        self.stop();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if let Some(t) = self.writer.take() {
            let _ = t.join();
        }
    }
}
