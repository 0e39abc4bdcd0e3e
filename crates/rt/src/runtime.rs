//! The real-time HIL loop: a sensor link, a robot link, compensator and virtual dynamics in
//! one thread, paced by the PC's monotonic clock at the scenario's period or by the robot's
//! packets ([`Pacing`], the robot link's choice).
//!
//! One tick k (clock pacing: deadline `t0 + k·T`, absolute sleep; robot pacing: the robot's
//! next packet, waited for up to the watchdog):
//! 1. poll the sensor link (non-blocking): the newest valid wrench; poll the robot link: every
//!    valid feedback pose into the [`FeedbackEstimator`];
//! 2. the measurement: the wrench (sensor frame) and the actual motion estimated from the
//!    feedback ([`crate::feedback`]);
//! 3. [`Loop::virtual_step`]: the core's [`HilStep`] (compensate, the record, divergence and
//!    end of run, integrate: the same code as a simulation), the sample into the lock-free
//!    ring buffer, the loop's safety checks ([`crate::safety`]), the new command checked
//!    against the workspace;
//! 4. the command sent through the robot link.
//!
//! The loop names no device: the links ([`crate::links`]) own the protocols, their counters
//! ([`LinkStats`], socket errors included) and their units. The tick never allocates, locks or
//! logs: sockets are non-blocking, codecs and buffers are preallocated, samples go to an
//! `rtrb` ring buffer that a writer thread drains, counters and the live status are atomics.
//! Lateness is counted, never hidden: every wake-up latency and period goes into a histogram,
//! a tick that ends after the next deadline is an overrun, and missed periods are caught up
//! (the virtual time stays `k·T`).
//!
//! Every stop (end of run, `stop()`, a safety limit) ends the same way: the robot is commanded
//! to hold its last fed-back pose for `hold_time`, the sensor's streaming is stopped, and the
//! writer thread drains the ring buffer completely before the results are built.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use nalgebra::Vector3;
use serde::Serialize;

use hilcontact_core::facility::Measurement;
use hilcontact_core::hil::{HilStep, VirtualDynamics};
use hilcontact_core::world::RelativeMotion;
use hilcontact_core::{metrics, sim, Plan, Scenario};

use crate::clock::{
    now_ns, request_realtime, sleep_until_ns, tighten_timer_slack, Histogram, SchedulingReport,
};
use crate::error::{Result, RtError};
use crate::feedback::FeedbackEstimator;
pub use crate::links::LinkStats;
use crate::links::{
    open_robot, open_sensor, LinkContext, Pacing, RobotLink, SensorLink, StartRegion, Wrench,
};
use crate::offset::{OffsetMode, OffsetOptions, WrenchStats};
use crate::options::ParsedRuntime;
pub use crate::options::RuntimeOptions;
use crate::recording::{start_text, EventLevel, McapRecorder, RunInfo};
use crate::report::{build_output, HilOutput};
pub use crate::report::{RunOutcome, Sample};
use crate::safety::{
    check_workspace, check_wrench, hold_target, SafetyLimits, StopEvent, StopKind, Tracking,
};

#[derive(Debug, Default)]
struct SharedStatus {
    stop_requested: AtomicBool,
    finished: AtomicBool,
    /// 0 connecting, 1 running, 2 holding, 3 finished.
    phase: AtomicU8,
    stop_code: AtomicU8,
    tick: AtomicU64,
    force_bits: AtomicU64,
    energy_bits: AtomicU64,
    max_latency_ns: AtomicU64,
    overruns: AtomicU64,
    sensor_lost: AtomicU64,
    sensor_late: AtomicU64,
    robot_lost: AtomicU64,
    robot_late: AtomicU64,
    dropped: AtomicU64,
    io_errors: AtomicU64,
}

/// A snapshot of the loop's state for a live display.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StatusSnapshot {
    /// `connecting`, `running`, `holding` or `finished`.
    pub phase: &'static str,
    /// Ticks run.
    pub tick: u64,
    /// Virtual time, s.
    pub time: f64,
    /// Measured force magnitude, N.
    pub force: f64,
    /// Virtual kinetic energy, J.
    pub energy: f64,
    /// Largest wake-up latency so far, µs.
    pub max_latency_us: f64,
    /// Ticks that ended after the next deadline.
    pub overruns: u64,
    /// Sensor records lost (sequence gaps).
    pub sensor_lost: u64,
    /// Ticks without a new sensor record.
    pub sensor_late: u64,
    /// Robot feedback messages lost.
    pub robot_lost: u64,
    /// Late robot feedback messages.
    pub robot_late: u64,
    /// Datagrams dropped (malformed, invalid, foreign, stale) on both links.
    pub dropped: u64,
    /// Socket errors (receive or send) on both links.
    pub io_errors: u64,
    /// Why it stopped, once it has.
    pub stop: Option<StopKind>,
}

/// A running HIL loop.
pub struct HilHandle {
    shared: Arc<SharedStatus>,
    thread: Option<JoinHandle<Result<RunOutcome>>>,
    writer: Option<JoinHandle<(Vec<Sample>, Option<McapRecorder>)>>,
    plan: Plan,
    options: RuntimeOptions,
    period: f64,
}

/// Capacity of the sample ring buffer (8 s at 1 kHz; the writer drains it every 5 ms).
const RING_CAPACITY: usize = 8192;

pub use crate::options::MAX_CONNECT_TIMEOUT;

impl HilHandle {
    /// Validates, creates the MCAP file if asked for, opens the links of `options` (binds the
    /// sockets, reads the sensor's counts per unit over HTTP unless given), computes the ideal
    /// reference's energy bound, and starts the writer and loop threads. A start that fails
    /// after the MCAP file was created removes it.
    pub fn start(scenario: &Scenario, options: &RuntimeOptions) -> Result<Self> {
        let (plan, parsed) = Self::validate(scenario, options)?;
        let recorder = open_recorder(&plan, options)?;
        let context = link_context(&plan, options);
        let links = open_sensor(&parsed.sensor, &context)
            .and_then(|sensor| Ok((sensor, open_robot(&parsed.robot, &context)?)));
        match links {
            Ok((sensor, robot)) => Self::start_inner(plan, options, sensor, robot, recorder),
            Err(e) => {
                if let Some(r) = recorder {
                    r.discard();
                }
                Err(e)
            }
        }
    }

    /// As [`HilHandle::start`], with links opened by the caller (a protocol outside the
    /// registry, or a test double); `options.sensor` and `options.robot` are not used but
    /// are reported in `metrics.json`.
    pub fn start_with_links(
        scenario: &Scenario,
        options: &RuntimeOptions,
        sensor: Box<dyn SensorLink>,
        robot: Box<dyn RobotLink>,
    ) -> Result<Self> {
        let (plan, _) = Self::validate(scenario, options)?;
        let recorder = open_recorder(&plan, options)?;
        Self::start_inner(plan, options, sensor, robot, recorder)
    }

    /// The scenario's plan, once the options are checked too, and that the scenario can start
    /// with them ([`OffsetOptions::check_start`]).
    pub(crate) fn validate(
        scenario: &Scenario,
        options: &RuntimeOptions,
    ) -> Result<(Plan, ParsedRuntime)> {
        let (plan, parsed) = Self::validate_options(scenario, options)?;
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

    fn start_inner(
        plan: Plan,
        options: &RuntimeOptions,
        sensor: Box<dyn SensorLink>,
        robot: Box<dyn RobotLink>,
        mut recorder: Option<McapRecorder>,
    ) -> Result<Self> {
        let o = options;
        if let Err(e) = check_pacing(robot.as_ref(), plan.period) {
            if let Some(r) = recorder {
                r.discard();
            }
            return Err(e);
        }
        let pacing = robot.pacing();
        let feedback_period = robot.feedback_period();

        let reference_energy = sim::run_reference(&plan, false).0.energy;
        let energy_bound = metrics::divergence_bound(
            plan.divergence_energy_ratio,
            plan.system.energy(&plan.initial),
            &reference_energy,
        );
        let step = HilStep::new(&plan, energy_bound);
        let period = plan.period;
        let ticks = plan.ticks as u64;

        let shared = Arc::new(SharedStatus::default());
        let (producer, mut consumer) = rtrb::RingBuffer::<Sample>::new(RING_CAPACITY);
        let mut events = EventWatch::new(shared.clone(), start_text(&RunInfo::new(&plan, true)));
        // the writer thread: drains the ring into the run's samples and, with --mcap, feeds
        // the recording (messages, the loop's events, chunks written out as run time passes)
        let writer = std::thread::Builder::new()
            .name("hil-writer".into())
            .spawn(move || {
                // room for the whole run, up to 2^20 ticks (17 min at 1 kHz): a longer run
                // grows the log as it goes rather than reserving it all at the start
                let mut samples = Vec::with_capacity((ticks as usize).min(1 << 20) + 1);
                loop {
                    let abandoned = consumer.is_abandoned();
                    // read before draining: every sample up to the stop is in the ring then
                    let stop_code = events.shared.stop_code.load(Ordering::Acquire);
                    let new = samples.len();
                    while let Ok(s) = consumer.pop() {
                        samples.push(s);
                    }
                    if let Some(recorder) = recorder.as_mut() {
                        for s in &samples[new..] {
                            events.before_sample(recorder);
                            recorder.sample(s);
                        }
                        events.after_drain(recorder, stop_code);
                    }
                    if abandoned {
                        break; // drained after the producer was dropped: complete
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
                (samples, recorder)
            })
            .map_err(|e| RtError::io("writer thread", &e))?;

        let rod = plan.system.rod_tip;
        let initial = step.command();
        let start_tip = initial.point(&rod);
        let mut state = Loop {
            rod,
            step,
            period,
            period_ns: (period * 1e9).round() as u64,
            ticks,
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
            estimator: FeedbackEstimator::new(o.extrapolation),
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
                outcome
            })
            .map_err(|e| RtError::io("loop thread", &e))?;
        Ok(HilHandle {
            shared,
            thread: Some(thread),
            writer: Some(writer),
            plan,
            options: o.clone(),
            period,
        })
    }

    /// A snapshot for a live display (lock-free reads).
    pub fn status(&self) -> StatusSnapshot {
        let s = &self.shared;
        let tick = s.tick.load(Ordering::Relaxed);
        StatusSnapshot {
            phase: ["connecting", "running", "holding", "finished"]
                [s.phase.load(Ordering::Acquire).min(3) as usize],
            tick,
            time: tick.saturating_sub(1) as f64 * self.period,
            force: f64::from_bits(s.force_bits.load(Ordering::Relaxed)),
            energy: f64::from_bits(s.energy_bits.load(Ordering::Relaxed)),
            max_latency_us: s.max_latency_ns.load(Ordering::Relaxed) as f64 / 1e3,
            overruns: s.overruns.load(Ordering::Relaxed),
            sensor_lost: s.sensor_lost.load(Ordering::Relaxed),
            sensor_late: s.sensor_late.load(Ordering::Relaxed),
            robot_lost: s.robot_lost.load(Ordering::Relaxed),
            robot_late: s.robot_late.load(Ordering::Relaxed),
            dropped: s.dropped.load(Ordering::Relaxed),
            io_errors: s.io_errors.load(Ordering::Relaxed),
            stop: StopKind::from_code(s.stop_code.load(Ordering::Acquire)),
        }
    }

    /// Asks the loop to stop (it holds the robot, stops streaming, flushes); returns at once.
    pub fn stop(&self) {
        self.shared.stop_requested.store(true, Ordering::Release);
    }

    /// Whether the loop thread has ended.
    pub fn is_finished(&self) -> bool {
        self.shared.finished.load(Ordering::Acquire)
    }

    /// Waits up to `timeout` for the loop to end; returns whether it has.
    pub fn wait(&self, timeout: Duration) -> bool {
        let end = std::time::Instant::now() + timeout;
        while !self.is_finished() {
            if std::time::Instant::now() >= end {
                return false;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        true
    }

    /// Waits for the loop and the writer, and builds the time series, reference and metrics;
    /// with a recording, writes its end events, summary and footer (`realtime.mcap` in the
    /// metrics). A run that never started (a peer did not answer) removes its recording.
    pub fn finish(mut self) -> Result<HilOutput> {
        let outcome = match self.thread.take().map(|t| t.join()) {
            Some(Ok(outcome)) => outcome,
            _ => Err(RtError::io_other("loop thread", "panicked")),
        };
        let (samples, recorder) = match self.writer.take().map(|t| t.join()) {
            Some(Ok(drained)) => drained,
            _ => return Err(RtError::io_other("writer thread", "panicked")),
        };
        let outcome = match outcome {
            Ok(outcome) => outcome,
            Err(e) => {
                if let Some(r) = recorder {
                    r.discard();
                }
                return Err(e);
            }
        };
        let mut output = build_output(&self.plan, &self.options, &samples, &outcome)?;
        if let Some(recorder) = recorder {
            let stats = end_recording(recorder, &outcome, &output.metrics);
            if let Some(realtime) = output
                .metrics
                .get_mut("realtime")
                .and_then(|v| v.as_object_mut())
            {
                realtime.insert(
                    "mcap".into(),
                    serde_json::to_value(&stats).unwrap_or_default(),
                );
            }
        }
        Ok(output)
    }
}

impl Drop for HilHandle {
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

/// The run's MCAP recorder, if `options.mcap` asks for one: the file created (or the start
/// refused, naming it) before anything else is opened.
fn open_recorder(plan: &Plan, options: &RuntimeOptions) -> Result<Option<McapRecorder>> {
    options
        .mcap
        .as_ref()
        .map(|mcap| McapRecorder::create(mcap, &RunInfo::new(plan, true)))
        .transpose()
}

/// Run time between two fault events on `/hil/events`, ns: faults that keep coming are
/// summed up, not reported once per tick.
const FAULT_EVENT_INTERVAL_NS: u64 = 500_000_000;

/// The loop's live events for the recording, read by the writer thread from the shared
/// status: the start (before the first sample), faults (the loop's counters that grew: lost
/// packets, dropped datagrams, socket errors, overruns) and the stop as it happens.
struct EventWatch {
    shared: Arc<SharedStatus>,
    start_text: String,
    started: bool,
    /// The fault counters last reported: overruns, sensor lost, robot lost, dropped, io errors.
    reported: [u64; 5],
    /// Run time of the last fault event, ns.
    last_fault_ns: Option<u64>,
    stop_reported: bool,
}

impl EventWatch {
    fn new(shared: Arc<SharedStatus>, start_text: String) -> Self {
        EventWatch {
            shared,
            start_text,
            started: false,
            reported: [0; 5],
            last_fault_ns: None,
            stop_reported: false,
        }
    }

    fn counters(&self) -> [u64; 5] {
        let s = &self.shared;
        [
            s.overruns.load(Ordering::Relaxed),
            s.sensor_lost.load(Ordering::Relaxed),
            s.robot_lost.load(Ordering::Relaxed),
            s.dropped.load(Ordering::Relaxed),
            s.io_errors.load(Ordering::Relaxed),
        ]
    }

    /// The start event, before the first sample.
    fn before_sample(&mut self, recorder: &mut McapRecorder) {
        if !self.started {
            self.started = true;
            recorder.event(0.0, EventLevel::Info, &self.start_text);
        }
    }

    /// After a drain: a fault event if counters grew (at most one per
    /// [`FAULT_EVENT_INTERVAL_NS`] of run time), and the stop once `stop_code` is set.
    fn after_drain(&mut self, recorder: &mut McapRecorder, stop_code: u8) {
        let now_ns = crate::recording::time_ns(recorder.last_time());
        let due = self
            .last_fault_ns
            .is_none_or(|t| now_ns >= t + FAULT_EVENT_INTERVAL_NS);
        let counters = self.counters();
        if self.started && due && counters != self.reported {
            const NAMES: [&str; 5] = [
                "overruns",
                "sensor records lost",
                "robot feedback lost",
                "datagrams dropped",
                "socket errors",
            ];
            let parts: Vec<String> = NAMES
                .iter()
                .zip(counters.iter().zip(self.reported))
                .filter(|(_, (now, before))| **now > *before)
                .map(|(name, (now, before))| format!("{name} +{} ({now} in all)", now - before))
                .collect();
            recorder.event(recorder.last_time(), EventLevel::Warn, &parts.join(", "));
            self.reported = counters;
            self.last_fault_ns = Some(now_ns);
        }
        if let (false, Some(kind)) = (self.stop_reported, StopKind::from_code(stop_code)) {
            self.stop_reported = true;
            let level = match kind {
                StopKind::Completed => EventLevel::Info,
                StopKind::User => EventLevel::Warn,
                _ => EventLevel::Error,
            };
            let name = serde_json::to_value(kind)
                .ok()
                .and_then(|v| v.as_str().map(str::to_string))
                .unwrap_or_default();
            let what = if kind.is_safety_stop() {
                "safety stop"
            } else {
                "stop"
            };
            recorder.event(
                recorder.last_time(),
                level,
                &format!(
                    "{what}: {name} at {:.3} s; the robot is commanded to hold",
                    recorder.last_time()
                ),
            );
        }
    }
}

/// The recording's end: the run's status and reason and the loop's counters as events at the
/// stop's time, then the summary and footer; returns what was written.
fn end_recording(
    mut recorder: McapRecorder,
    outcome: &RunOutcome,
    metrics: &serde_json::Value,
) -> crate::recording::RecordingStats {
    let stop = &outcome.stop;
    let status = metrics["status"].as_str().unwrap_or("?");
    let reason = metrics["reason"]
        .as_str()
        .unwrap_or("ran its whole duration");
    let level = match stop.kind {
        StopKind::Completed if status == "ok" => EventLevel::Info,
        StopKind::Completed | StopKind::User => EventLevel::Warn,
        _ => EventLevel::Error,
    };
    recorder.event(
        stop.time,
        level,
        &format!(
            "run ended at {:.3} s: status {status}; {reason}; exit code {}",
            stop.time,
            stop.kind.exit_code()
        ),
    );
    let (sensor, robot) = (&outcome.sensor, &outcome.robot);
    recorder.event(
        stop.time,
        EventLevel::Info,
        &format!(
            "loop: {} ticks, wake latency p50/p99/max {:.0}/{:.0}/{:.0} µs, overruns {}, samples dropped {}; \
             {} sensor: accepted {}, lost {}, late {}, dropped {}, socket errors {}; \
             {} robot: accepted {}, lost {}, late {}, dropped {}, socket errors {}",
            outcome.ticks,
            outcome.wake_latency.p50,
            outcome.wake_latency.p99,
            outcome.wake_latency.max,
            outcome.overruns,
            outcome.samples_dropped,
            outcome.sensor_name,
            sensor.accepted,
            sensor.lost,
            sensor.late,
            sensor.dropped(),
            sensor.io_errors,
            outcome.robot_name,
            robot.accepted,
            robot.lost,
            robot.late,
            robot.dropped(),
            robot.io_errors,
        ),
    );
    recorder.finish()
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
/// loop ([`Pacing::Robot`]) at another period than the scenario's (`period`, s).
pub(crate) fn check_pacing(robot: &dyn RobotLink, period: f64) -> Result<()> {
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
    if robot.pacing() == Pacing::Robot && (feedback_period - period).abs() > 1e-6 * feedback_period
    {
        return Err(RtError::option(
            "simulation.period",
            format!(
                "the {} robot paces the loop every {} s: set simulation.period = {}",
                robot.name(),
                feedback_period,
                feedback_period
            ),
        ));
    }
    Ok(())
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

/// Below this measured force magnitude the rod is taken as free of contact (the retreat
/// target of a force stop), N.
pub const CONTACT_FREE_FORCE: f64 = 5.0;

/// The loop thread's state: the virtual side, the two links and the timing statistics.
struct Loop {
    /// The virtual side of a tick: the core's one HIL step.
    step: HilStep,
    rod: Vector3<f64>,
    period: f64,
    period_ns: u64,
    ticks: u64,
    limits: SafetyLimits,
    start_tip: Vector3<f64>,
    initial: RelativeMotion,
    connect_timeout: f64,
    start_tolerance: f64,
    hold_time: f64,
    offset: OffsetOptions,
    /// The sensor's offset measured at start (subtracted from every record), N and N·m.
    sensor_offset: Wrench,
    // the links
    pacing: Pacing,
    /// Robot feedback later than this after the previous one is `late`, ns.
    late_ns: u64,
    sensor: Box<dyn SensorLink>,
    last_sensor_ns: u64,
    force: Vector3<f64>,
    moment: Vector3<f64>,
    robot: Box<dyn RobotLink>,
    last_robot_ns: u64,
    estimator: FeedbackEstimator,
    /// The last command sent (it passed every check), m and rad in `t`.
    last_command: Option<RelativeMotion>,
    /// The robot's fed-back pose at the last tick whose measured force was below
    /// [`CONTACT_FREE_FORCE`] (the retreat target of a force stop).
    last_free: Option<RelativeMotion>,
    /// The commands of the tracking window, against which the feedback is checked.
    tracking: Tracking,
    // log and timing
    producer: rtrb::Producer<Sample>,
    samples_dropped: u64,
    shared: Arc<SharedStatus>,
    wake: Histogram,
    period_hist: Histogram,
    compute: Histogram,
    overruns: u64,
    t0_ns: u64,
    /// What the OS granted this thread (asked for at its start).
    scheduling: SchedulingReport,
}

impl Loop {
    fn run(&mut self) -> Result<RunOutcome> {
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
        while k <= self.ticks {
            let (wake, deadline) = match self.pacing {
                Pacing::Clock => {
                    let deadline = self.t0_ns + k * self.period_ns;
                    sleep_until_ns(deadline);
                    (now_ns(), deadline)
                }
                Pacing::Robot => self.wait_for_robot(last_wake),
            };
            let latency = wake.saturating_sub(deadline);
            self.wake.record(latency);
            if let Some(prev) = last_wake {
                self.period_hist
                    .record((wake - prev).abs_diff(self.period_ns));
            }
            last_wake = Some(wake);
            let outcome = self.tick(k, wake, latency);
            let end = now_ns();
            self.compute.record(end - wake);
            if end > deadline + self.period_ns {
                self.overruns += 1;
            }
            self.publish(k + 1, latency);
            if let Some(event) = outcome {
                stop = event;
                break;
            }
            k += 1;
        }
        let wall_time = (now_ns() - self.t0_ns) as f64 * 1e-9;
        self.shared
            .stop_code
            .store(stop.kind.code(), Ordering::Release);
        self.shared.phase.store(2, Ordering::Release);
        // a force or moment stop first backs away from the contact, then holds there
        let retreated = matches!(stop.kind, StopKind::ForceLimit | StopKind::MomentLimit)
            .then(|| self.retreat())
            .flatten();
        self.hold(retreated);
        self.sensor.stop_streaming();
        let robot = *self.robot.stats();
        Ok(RunOutcome {
            stop,
            ticks: k.min(self.ticks) + 1,
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
        })
    }

    /// Robot pacing: waits for the robot's next packet, at most the watchdog (then the tick
    /// runs and the watchdog stops the run). Returns the wake-up time and the tick's nominal
    /// deadline (one period after the previous wake-up; the first tick has none), ns.
    fn wait_for_robot(&mut self, last_wake: Option<u64>) -> (u64, u64) {
        let start = now_ns();
        let n = self
            .robot
            .wait(start + self.limits.watchdog_ns(), &mut self.estimator);
        let wake = now_ns();
        self.robot_arrived(n, wake);
        let deadline = last_wake.map_or(wake, |w| w + self.period_ns);
        (wake, deadline)
    }

    /// Start-up (not real-time): requests streaming, waits for the first record and feedback,
    /// checks the start pose. Nothing that could move the robot is sent before the check has
    /// passed: before the first feedback nothing at all, then only holds at the robot's own
    /// fed-back pose (at rest), which keep a controller's session alive without moving it.
    fn connect(&mut self) -> Result<()> {
        self.sensor.start_streaming();
        let start = now_ns();
        let timeout_ns = (self.connect_timeout * 1e9) as u64;
        let mut last_request = start;
        loop {
            if self.shared.stop_requested.load(Ordering::Acquire) {
                return Err(RtError::Connect(
                    "stopped by the user while connecting".into(),
                ));
            }
            let now = now_ns();
            self.poll_links(now);
            if let Some(pose) = self.estimator.last_pose() {
                self.robot.hold(&pose, now_ns().saturating_sub(self.t0_ns));
            }
            if self.sensor.stats().accepted > 0 && self.estimator.has_feedback() {
                break;
            }
            if now - start > timeout_ns {
                let missing = missing_peers(
                    self.sensor.as_ref(),
                    self.robot.as_ref(),
                    self.estimator.has_feedback(),
                );
                return Err(RtError::Connect(format!(
                    "{} within {} s (connect_timeout)",
                    missing.join(" and "),
                    self.connect_timeout
                )));
            }
            if self.sensor.stats().accepted == 0 && now - last_request > 200_000_000 {
                self.sensor.start_streaming();
                last_request = now;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        // the robot must be where the scenario starts
        let actual = self
            .estimator
            .last_pose()
            .map_or(self.initial.position, |p| p.point(&self.rod));
        let distance = (actual - self.initial.point(&self.rod)).norm();
        if let Err(e) = check_start_distance(distance, self.start_tolerance) {
            self.hold(None);
            return Err(e);
        }
        if self.offset.mode == OffsetMode::Measure {
            if let Err(e) = self.measure_offset() {
                self.hold(None);
                return Err(e);
            }
        }
        // forget the start-up's sequence bookkeeping for the lateness counters
        self.sensor.stats_mut().late = 0;
        self.robot.stats_mut().late = 0;
        Ok(())
    }

    /// Averages the sensor's records over `offset.time` with the robot held at its own pose (rod
    /// free: the start pose was checked) and keeps the mean as the offset, or refuses
    /// ([`OffsetOptions::offset`]).
    fn measure_offset(&mut self) -> Result<()> {
        let mut stats = WrenchStats::default();
        let start = now_ns();
        let end = start + (self.offset.time * 1e9) as u64;
        while now_ns() < end {
            if self.poll_links(now_ns()) {
                stats.push(&Wrench {
                    force: self.force,
                    moment: self.moment,
                });
            }
            if let Some(pose) = self.checked_pose() {
                self.robot.hold(&pose, now_ns().saturating_sub(self.t0_ns));
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        self.sensor_offset = self.offset.offset(&stats)?;
        Ok(())
    }

    /// Waits for the next period of a stop's stream: the clock's period `i` after `start`, or
    /// the robot's next packet (at most two periods); then polls the links.
    fn next_stop_period(&mut self, start: u64, i: u64) {
        match self.pacing {
            Pacing::Clock => sleep_until_ns(start + i * self.period_ns),
            Pacing::Robot => {
                let n = self
                    .robot
                    .wait(now_ns() + 2 * self.period_ns, &mut self.estimator);
                self.robot_arrived(n, now_ns());
            }
        }
        self.poll_links(now_ns());
    }

    /// The robot's pose as far as it can be trusted: its last fed-back pose if plausible, else
    /// the last command ([`hold_target`]).
    fn checked_pose(&self) -> Option<RelativeMotion> {
        hold_target(
            &self.limits,
            self.estimator.last_pose(),
            self.last_command,
            &self.tracking,
            &self.rod,
            &self.start_tip,
        )
    }

    /// Streams the hold command for `hold_time` (one per period on the clock, or one per robot
    /// packet): `at` (the end of a retreat) if given, else the last fed-back pose at rest if it
    /// is plausible, else the last command ([`hold_target`]).
    fn hold(&mut self, at: Option<RelativeMotion>) {
        let Some(pose) = at.or_else(|| self.checked_pose()) else {
            return;
        };
        let periods = (self.hold_time / self.period).ceil() as u64;
        let start = now_ns();
        for i in 0..periods.max(1) {
            self.next_stop_period(start, i);
            self.robot.hold(&pose, now_ns().saturating_sub(self.t0_ns));
        }
    }

    /// After a force or moment stop: backs the robot away, at `limits.retreat_speed`, from its
    /// (checked) pose to the last pose where the measured force was below
    /// [`CONTACT_FREE_FORCE`], at most `limits.retreat_distance` away, so that the stop releases
    /// the contact instead of holding the rod pressed; returns where it ended (the hold that
    /// follows holds there, not at the delayed feedback). Nothing is sent, and None returned,
    /// when either pose is unknown or not plausible.
    fn retreat(&mut self) -> Option<RelativeMotion> {
        let (Some(from), Some(free)) = (self.checked_pose(), self.last_free) else {
            return None;
        };
        let (a, b) = (from.point(&self.rod), free.point(&self.rod));
        let inside = (b - self.start_tip).norm() <= self.limits.workspace;
        let distance = (b - a).norm();
        if !inside || distance <= 1e-6 {
            return None;
        }
        // never farther than retreat_distance: along the same line
        let reach = (self.limits.retreat_distance / distance).min(1.0);
        let speed = self.limits.retreat_speed;
        let periods = (distance * reach / (speed * self.period)).ceil() as u64;
        let velocity = (free.position - from.position) * (reach / (periods as f64 * self.period));
        let start = now_ns();
        let mut command = from;
        for i in 1..=periods {
            self.next_stop_period(start, i - 1);
            let s = reach * i as f64 / periods as f64;
            command = RelativeMotion {
                position: from.position.lerp(&free.position, s),
                orientation: from.orientation.slerp(&free.orientation, s),
                velocity,
                angular_velocity: Vector3::zeros(),
            };
            self.robot
                .send(&command, now_ns().saturating_sub(self.t0_ns));
        }
        let end = RelativeMotion {
            velocity: Vector3::zeros(),
            ..command
        };
        self.last_command = Some(end);
        Some(end)
    }

    /// Polls both links; returns whether a new sensor record arrived.
    fn poll_links(&mut self, now: u64) -> bool {
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
    fn robot_arrived(&mut self, n: usize, now: u64) {
        if n == 0 {
            return;
        }
        if self.last_robot_ns > 0 && now - self.last_robot_ns > self.late_ns {
            self.robot.stats_mut().late += 1;
        }
        self.last_robot_ns = now;
    }

    /// One control tick; returns a stop, if any. Never allocates.
    fn tick(&mut self, k: u64, wake: u64, latency: u64) -> Option<StopEvent> {
        if !self.poll_links(wake) {
            self.sensor.stats_mut().late += 1;
        }
        let actual = self.estimator.estimate(wake).unwrap_or(self.initial);
        if self.force.norm() < CONTACT_FREE_FORCE {
            self.last_free = self.estimator.last_pose();
        }
        let m = Measurement {
            force: self.force,
            moment: self.moment,
            actual,
        };
        match self.virtual_step(k, &m, wake, latency) {
            Ok(command) => {
                self.robot
                    .send(&command, now_ns().saturating_sub(self.t0_ns));
                self.last_command = Some(command);
                None
            }
            Err(stop) => Some(stop),
        }
    }

    /// Stops that are the loop's, not the dynamics': `stop()` and the links' watchdogs.
    fn loop_checks(&self, time: f64, wake: u64) -> Option<StopEvent> {
        if self.shared.stop_requested.load(Ordering::Acquire) {
            return Some(StopEvent::plain(StopKind::User, time));
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
    fn virtual_step(
        &mut self,
        k: u64,
        m: &Measurement,
        wake: u64,
        latency: u64,
    ) -> std::result::Result<RelativeMotion, StopEvent> {
        let time = k as f64 * self.period;
        let (record, verdict) = self.step.observe(k as usize, m, None);
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
        if let Some(stop) = check_wrench(&self.limits, &m.force, &m.moment, time) {
            return Err(stop);
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
        let command = self.step.advance(k as usize)?;
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

    fn publish(&self, tick: u64, latency: u64) {
        let s = &self.shared;
        let (sensor, robot) = (self.sensor.stats(), self.robot.stats());
        s.tick.store(tick, Ordering::Relaxed);
        s.force_bits
            .store(self.force.norm().to_bits(), Ordering::Relaxed);
        s.energy_bits
            .store(self.step.dynamics().energy().to_bits(), Ordering::Relaxed);
        s.max_latency_ns.fetch_max(latency, Ordering::Relaxed);
        s.overruns.store(self.overruns, Ordering::Relaxed);
        s.sensor_lost.store(sensor.lost, Ordering::Relaxed);
        s.sensor_late.store(sensor.late, Ordering::Relaxed);
        s.robot_lost.store(robot.lost, Ordering::Relaxed);
        s.robot_late.store(robot.late, Ordering::Relaxed);
        s.dropped
            .store(sensor.dropped() + robot.dropped(), Ordering::Relaxed);
        s.io_errors
            .store(sensor.io_errors + robot.io_errors, Ordering::Relaxed);
    }
}
