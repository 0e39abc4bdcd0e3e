//! The outputs of a run: the seam between a run (a real-time loop's writer thread, or a
//! finished simulation) and what it is written to.
//!
//! This module owns the [`Sink`] trait, the list of outputs ([`OUTPUTS`], one line each), the
//! start information every sink gets ([`RunInfo`], and the [`Plan`] through [`SinkContext`]),
//! the run's events ([`Event`]: their texts in [`events`]) and [`Outputs`], the set of sinks a
//! run opened. The sinks:
//!
//! - [`mcap`]: an MCAP recording (ROS 2 messages) for robotics viewers, option `mcap`;
//! - [`live`]: a Foxglove WebSocket server streaming the same channels live, with the
//!   operator's stop and mark services, option `live` (cargo feature `live`).
//!
//! Both draw the facility in 3-D from [`scene`] (walls, rods, contact, force arrow, frames).
//!
//! Beside them, not a sink: [`run_folder`], the samples of a real-time run, from which its
//! time series, reference and metrics are built (the run folder); every real-time run has it,
//! and its metrics are what the sinks' end events and reports go into.
//!
//! **Threads and timing.** A real-time run's sinks live in the writer thread
//! (`crate::runtime`), never the loop thread: they get every tick's [`Sample`] in tick order,
//! in bursts (the writer drains the loop's ring buffer every 5 ms), and the events as the
//! writer sees them (the start before the first sample, faults, the stop, the end and the
//! loop's summary). A sink may allocate, block briefly and fail: a failure is counted in its
//! own report, never stops the run (the loop does not wait for the writer).
//!
//! **Adding an output** (a live view, say):
//! 1. write `output/<name>.rs`: its options (serde, with a `JsonSchema`), a type implementing
//!    [`Sink`], and an `open` function ([`OpenSink`]) that parses its options from the JSON
//!    value it is given and creates the sink (binds its socket, creates its file);
//! 2. add its line to the `outputs!` list here (`<name>;`): it declares the module and
//!    registers it in [`OUTPUTS`] under the key `<name>`.
//!
//! Nothing else changes for a simulation (`hilcontact._core.simulate(scenario, outputs)` and
//! `hilcontact.simulate(..., outputs={"<name>": {...}})` take any registered key). A real-time
//! run's options are typed and refuse unknown keys, so it also needs its options as a field
//! `<name>: Option<...>` of `RuntimeOptions` (`crate::options`: one field, from which the
//! schema and the CLI's flags follow). The loop, the writer thread, the bindings and run.py
//! are not edited. Its report is `metrics.json` `realtime.<key>` (a real-time run) or the
//! simulation's result under `<key>`.

pub mod events;
pub mod run_folder;
pub mod scene;

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use nalgebra::{UnitQuaternion, Vector3};
use serde_json::Value;

use hilcontact_core::hil::{HilRecord, VirtualDynamics};
use hilcontact_core::metrics::Metrics;
use hilcontact_core::Plan;

use crate::error::{Result, RtError};
use crate::report::Sample;

pub use events::start_text;

/// Opens a sink for a run whose options have its key (given as `options`, the key's value):
/// fails (naming the option or the file) before the run starts, when nothing else is opened
/// yet.
pub type OpenSink = fn(context: &SinkContext<'_>, options: &Value) -> Result<Box<dyn Sink>>;

/// An output a run can have: the key of its options (a key of the run's options, and of its
/// report) and how it is opened.
#[derive(Debug, Clone, Copy)]
pub struct Output {
    /// The options key (`mcap`): the run's options have it when the output is wanted; its
    /// report is `metrics.json` `realtime.<key>`.
    pub key: &'static str,
    /// Opens the sink.
    pub open: OpenSink,
}

/// Declares each output's module and lists it in [`OUTPUTS`], its key the module's name.
macro_rules! outputs {
    ($( $module:ident; )+) => {
        $( pub mod $module; )+

        /// Every output a run can have besides its run folder, in the order they are fed and
        /// finished: the one list.
        pub const OUTPUTS: &[Output] = &[
            $( Output { key: stringify!($module), open: $module::open }, )+
        ];
    };
}

outputs! {
    // an MCAP recording (ROS 2 messages, crash-safe chunks) for robotics viewers
    mcap;
    // a Foxglove live view (WebSocket server, the same channels, stop and mark services)
    live;
}

/// A run time in ns (negative or non-finite: 0).
pub fn time_ns(t: f64) -> u64 {
    if t.is_finite() && t > 0.0 {
        (t * 1e9).round() as u64
    } else {
        0
    }
}

/// A destination of a run's samples and events. Fed by one thread (a real-time run's writer
/// thread), in time order; every method is infallible (a sink counts its own failures and
/// reports them when finished).
pub trait Sink: Send {
    /// One tick: its record (run time `record.time`, s) and the loop's timing (zero in a
    /// simulation). Called at tick rate on average, in bursts.
    fn sample(&mut self, s: &Sample);

    /// An event of the run (start, a fault, the stop, the end, the loop's summary).
    fn event(&mut self, e: &Event<'_>);

    /// The run has ended and every sample and event was given: completes the output and
    /// returns what was written (the report under the output's key).
    fn finish(self: Box<Self>) -> Value;

    /// The run never started (a link could not be opened, a peer did not answer): gives the
    /// output up and removes what it created.
    fn discard(self: Box<Self>);

    /// Whether this sink replays a simulation at wall-clock speed (the live view): the user's
    /// stop ([`Outputs::record_simulation_until`]) skips its remaining samples, where a file
    /// gets every record of the run.
    fn paced(&self) -> bool {
        false
    }
}

/// Severity of an event (`rcl_interfaces/msg/Log` levels).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventLevel {
    /// Something the run did (start, normal end): 20.
    Info = 20,
    /// Something to look at (lost packets, overruns, a user stop): 30.
    Warn = 30,
    /// A fault or a safety stop: 40.
    Error = 40,
}

/// An event of a run, as the sinks get it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Event<'a> {
    /// Run time, s (never before the newest sample's).
    pub time: f64,
    /// Severity.
    pub level: EventLevel,
    /// What happened, one line.
    pub text: &'a str,
}

/// What a sink knows of its run from the start, from the plan.
#[derive(Debug, Clone)]
pub struct RunInfo {
    /// `simulation` or `realtime`.
    pub kind: &'static str,
    /// The scenario's name.
    pub scenario: String,
    /// The compensator's kind.
    pub compensator: &'static str,
    /// The control period, s.
    pub period: f64,
    /// The run's duration, s.
    pub duration: f64,
    /// The sensor origin in `t`, m.
    pub sensor_position: Vector3<f64>,
    /// The sensor's attitude in `t` (sensor to `t`).
    pub sensor_orientation: UnitQuaternion<f64>,
    /// Whether the compensator identifies the contact (stiffness and damping estimates).
    pub estimates_contact: bool,
    /// The resolved scenario as JSON.
    pub scenario_json: String,
    /// What the sinks share with the running loop (an operator's stop).
    pub control: Arc<RunControl>,
}

/// What a run's sinks share with its loop, lock-free: a stop asked by an operator (the live
/// view's `/hilcontact/stop`; the loop reads it each tick and stops as after a force limit).
#[derive(Debug, Default)]
pub struct RunControl {
    operator_stop: AtomicBool,
    /// Events from a sink's threads (an operator's mark, a refused call), for every sink.
    events: Mutex<VecDeque<(EventLevel, String)>>,
    has_events: AtomicBool,
    /// Events refused because [`MAX_PENDING_EVENTS`] were waiting already.
    events_dropped: AtomicU64,
}

/// Most events [`RunControl`] holds until the writer takes them (more are dropped and counted,
/// [`RunControl::events_dropped`]: a client calling in a loop cannot grow the memory).
pub const MAX_PENDING_EVENTS: usize = 64;

impl RunControl {
    /// Asks the loop to stop (reason `operator`).
    pub fn request_operator_stop(&self) {
        self.operator_stop.store(true, Ordering::Release);
    }

    /// An event for every sink of the run (given at the newest sample's time); dropped when
    /// [`MAX_PENDING_EVENTS`] wait already (counted: [`RunControl::events_dropped`]).
    pub fn push_event(&self, level: EventLevel, text: String) {
        let kept = match self.events.lock() {
            Ok(mut events) if events.len() < MAX_PENDING_EVENTS => {
                events.push_back((level, text));
                self.has_events.store(true, Ordering::Release);
                true
            }
            _ => false,
        };
        if !kept {
            self.events_dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Events [`RunControl::push_event`] dropped so far (the queue was full, or its lock
    /// poisoned).
    pub fn events_dropped(&self) -> u64 {
        self.events_dropped.load(Ordering::Relaxed)
    }

    /// The events pushed since the last call (none: nothing is locked).
    pub fn take_events(&self) -> Vec<(EventLevel, String)> {
        if !self.has_events.swap(false, Ordering::AcqRel) {
            return Vec::new();
        }
        self.events
            .lock()
            .map(|mut e| e.drain(..).collect())
            .unwrap_or_default()
    }

    /// Whether an operator asked for a stop.
    pub fn operator_stop_requested(&self) -> bool {
        self.operator_stop.load(Ordering::Acquire)
    }
}

impl RunInfo {
    /// The run of `plan`: a real-time one (with the loop's timing) if `realtime`.
    pub fn new(plan: &Plan, realtime: bool) -> Self {
        RunInfo {
            kind: if realtime { "realtime" } else { "simulation" },
            scenario: plan.scenario.name.clone(),
            compensator: plan.compensator.kind(),
            period: plan.period,
            duration: plan.ticks as f64 * plan.period,
            sensor_position: plan.system.sensor_origin,
            sensor_orientation: plan.sensor.orientation,
            estimates_contact: VirtualDynamics::new(plan).estimates_contact(),
            scenario_json: serde_json::to_string(&plan.scenario).unwrap_or_default(),
            control: Arc::default(),
        }
    }

    /// Whether it is a real-time run (its samples carry the loop's timing).
    pub fn realtime(&self) -> bool {
        self.kind == "realtime"
    }
}

/// What a sink is opened with: the run's plan (the scenario resolved: geometry, walls,
/// period) and its [`RunInfo`].
#[derive(Debug, Clone, Copy)]
pub struct SinkContext<'a> {
    /// The run's plan.
    pub plan: &'a Plan,
    /// The run, as the sinks describe it.
    pub info: &'a RunInfo,
}

/// The sinks a run opened (those of [`OUTPUTS`] its options ask for), fed together: the start
/// event before the first sample, then samples and events in time order.
pub struct Outputs {
    sinks: Vec<(&'static str, Box<dyn Sink>)>,
    control: Arc<RunControl>,
    start_text: String,
    started: bool,
    /// Run time of the newest sample or event, s.
    last_time: f64,
}

impl Outputs {
    /// Opens the outputs that `options` (a JSON object: the run's options, e.g. a real-time
    /// run's `RuntimeOptions`) asks for, each under its key; keys of no output are ignored.
    /// An output that fails to open refuses the start: the ones opened before it are
    /// discarded.
    pub fn open(plan: &Plan, info: &RunInfo, options: &Value) -> Result<Self> {
        let context = SinkContext { plan, info };
        let mut outputs = Outputs {
            sinks: Vec::new(),
            control: info.control.clone(),
            start_text: start_text(info),
            started: false,
            last_time: 0.0,
        };
        for output in OUTPUTS {
            let Some(value) = options.get(output.key).filter(|v| !v.is_null()) else {
                continue;
            };
            match (output.open)(&context, value) {
                Ok(sink) => outputs.sinks.push((output.key, sink)),
                Err(e) => {
                    outputs.discard();
                    return Err(e);
                }
            }
        }
        Ok(outputs)
    }

    /// As [`Outputs::open`], refusing keys of no output first (`options`: the outputs' options
    /// only, as a simulation is given them).
    pub fn open_only(plan: &Plan, info: &RunInfo, options: &Value) -> Result<Self> {
        let known: Vec<&str> = OUTPUTS.iter().map(|o| o.key).collect();
        let Some(map) = options.as_object() else {
            return Err(RtError::option(
                "outputs",
                format!("must be an object of outputs by key ({})", known.join(", ")),
            ));
        };
        if let Some(key) = map.keys().find(|k| !known.contains(&k.as_str())) {
            return Err(RtError::option(
                key,
                format!("is not an output (outputs: {})", known.join(", ")),
            ));
        }
        Self::open(plan, info, options)
    }

    /// What the sinks share with the loop (the loop reads the operator's stop from it).
    pub fn control(&self) -> Arc<RunControl> {
        self.control.clone()
    }

    /// Whether no output was asked for (then nothing is fed, and no event is even made).
    pub fn is_empty(&self) -> bool {
        self.sinks.is_empty()
    }

    /// One tick to every sink (the start event first, once).
    pub fn sample(&mut self, s: &Sample) {
        if self.sinks.is_empty() {
            return;
        }
        if !self.started {
            self.started = true;
            let text = std::mem::take(&mut self.start_text);
            self.event(0.0, EventLevel::Info, &text);
        }
        for (_, sink) in &mut self.sinks {
            sink.sample(s);
        }
        self.last_time = self.last_time.max(s.record.time);
        for (level, text) in self.control.take_events() {
            self.event(self.last_time, level, &text);
        }
    }

    /// An event to every sink, at run time `time` (s; not before the newest sample or event).
    pub fn event(&mut self, time: f64, level: EventLevel, text: &str) {
        let time = time.max(self.last_time);
        for (_, sink) in &mut self.sinks {
            sink.event(&Event { time, level, text });
        }
        self.last_time = time;
    }

    /// Whether the start event was given (the first sample arrived).
    pub fn started(&self) -> bool {
        self.started
    }

    /// Run time of the newest sample or event, s.
    pub fn last_time(&self) -> f64 {
        self.last_time
    }

    /// Finishes every sink; returns their reports, each under its key.
    pub fn finish(self) -> Vec<(&'static str, Value)> {
        self.sinks
            .into_iter()
            .map(|(key, sink)| (key, sink.finish()))
            .collect()
    }

    /// Gives every sink up (the run never started).
    pub fn discard(self) {
        for (_, sink) in self.sinks {
            sink.discard();
        }
    }

    /// A simulation's whole run to every sink ([`feed_simulation`]), then finishes them.
    pub fn record_simulation(
        self,
        info: &RunInfo,
        records: &[HilRecord],
        metrics: &Metrics,
    ) -> Vec<(&'static str, Value)> {
        self.record_simulation_until(info, records, metrics, &AtomicBool::new(false))
    }

    /// [`Outputs::record_simulation`] that the user can stop (Ctrl-C): once `stop` is set, a
    /// sink that replays at wall-clock speed ([`Sink::paced`], the live view) gets no more
    /// samples, only the end event; the others get every record.
    pub fn record_simulation_until(
        mut self,
        info: &RunInfo,
        records: &[HilRecord],
        metrics: &Metrics,
        stop: &AtomicBool,
    ) -> Vec<(&'static str, Value)> {
        for (_, sink) in &mut self.sinks {
            let stop = sink.paced().then_some(stop);
            feed_simulation_until(sink.as_mut(), info, records, metrics, stop);
        }
        self.finish()
    }
}

/// A simulation's whole run to `sink`, from its records and metrics: the start event, one
/// sample per record, the end event (status and reason) at the last record's time.
pub fn feed_simulation(
    sink: &mut dyn Sink,
    info: &RunInfo,
    records: &[HilRecord],
    metrics: &Metrics,
) {
    feed_simulation_until(sink, info, records, metrics, None);
}

/// [`feed_simulation`], skipping the samples left once `stop` (if any) is set.
fn feed_simulation_until(
    sink: &mut dyn Sink,
    info: &RunInfo,
    records: &[HilRecord],
    metrics: &Metrics,
    stop: Option<&AtomicBool>,
) {
    sink.event(&Event {
        time: 0.0,
        level: EventLevel::Info,
        text: &start_text(info),
    });
    for record in records {
        if stop.is_some_and(|stop| stop.load(Ordering::Relaxed)) {
            break;
        }
        sink.sample(&Sample {
            record: *record,
            ..Sample::default()
        });
    }
    let end = records.last().map_or(0.0, |r| r.time);
    let (level, text) = events::simulation_end(end, metrics);
    sink.event(&Event {
        time: end,
        level,
        text: &text,
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    /// A sink that logs what it is given: `s <time>` per sample, `e <time> <text>` per event.
    struct Log(Arc<Mutex<Vec<String>>>);

    impl Sink for Log {
        fn sample(&mut self, s: &Sample) {
            self.0.lock().unwrap().push(format!("s {}", s.record.time));
        }
        fn event(&mut self, e: &Event<'_>) {
            self.0
                .lock()
                .unwrap()
                .push(format!("e {} {}", e.time, e.text));
        }
        fn finish(self: Box<Self>) -> Value {
            Value::from("done")
        }
        fn discard(self: Box<Self>) {}
    }

    fn outputs(log: &Arc<Mutex<Vec<String>>>) -> Outputs {
        Outputs {
            sinks: vec![("log", Box::new(Log(log.clone())))],
            control: Arc::default(),
            start_text: "start".into(),
            started: false,
            last_time: 0.0,
        }
    }

    #[test]
    fn the_start_event_comes_first_and_events_are_never_before_the_newest_sample() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut o = outputs(&log);
        assert!(!o.is_empty() && !o.started());
        for k in 0..3 {
            let mut s = Sample::default();
            s.record.time = k as f64 * 0.5;
            o.sample(&s);
        }
        o.event(0.2, EventLevel::Warn, "late");
        assert_eq!(o.finish(), vec![("log", Value::from("done"))]);
        assert_eq!(
            *log.lock().unwrap(),
            ["e 0 start", "s 0", "s 0.5", "s 1", "e 1 late"]
        );
    }

    #[test]
    fn events_beyond_the_pending_ones_are_dropped_and_counted() {
        let control = RunControl::default();
        let extra = 37;
        for i in 0..MAX_PENDING_EVENTS + extra {
            control.push_event(EventLevel::Info, format!("mark {i}"));
        }
        assert_eq!(control.events_dropped(), extra as u64);
        let taken = control.take_events();
        assert_eq!(taken.len(), MAX_PENDING_EVENTS);
        assert_eq!(
            taken[0].1, "mark 0",
            "the oldest are kept, the newest dropped"
        );
        // the queue has room again: nothing more is dropped
        control.push_event(EventLevel::Warn, "again".into());
        assert_eq!(control.events_dropped(), extra as u64);
        assert_eq!(control.take_events().len(), 1);
        assert!(control.take_events().is_empty());
    }

    #[test]
    fn a_simulation_refuses_keys_of_no_output() {
        let path = format!(
            "{}/../../python/hilcontact/scenarios/paper-table1.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let scenario: hilcontact_core::Scenario =
            toml::from_str(&std::fs::read_to_string(path).expect("preset")).expect("toml");
        let plan = scenario.resolve().expect("plan");
        let info = RunInfo::new(&plan, false);
        let err = Outputs::open_only(&plan, &info, &serde_json::json!({"mcapp": {}}))
            .err()
            .expect("refused");
        assert!(err.to_string().contains("mcapp"), "{err}");
        assert!(Outputs::open_only(&plan, &info, &serde_json::json!([])).is_err());
        let none = Outputs::open_only(&plan, &info, &serde_json::json!({})).expect("none");
        assert!(none.is_empty());
    }
}
