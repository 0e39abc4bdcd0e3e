//! The emulated facility: the core's facility engine of the scenario's `[facility] kind` (the
//! facility model: robot with the scenario's response lag, contact law, F/T sensor with the
//! scenario's delay and noise) running in real time behind the real devices' protocols, in
//! the core's [`FacilityLoop`], the tick loop the simulation runs too.
//!
//! The emulator names no protocol: it holds a [`SensorEndpoint`] and a [`RobotEndpoint`]
//! ([`crate::devices`]), opened from the options' `sensor` and `robot` groups by their `kind`
//! (RDT: [`crate::devices::rdt::RdtEndpoint`], EGM: [`crate::devices::egm::EgmEndpoint`], KUKA RSI:
//! [`crate::devices::rsi::RsiEndpoint`]).
//!
//! One control period k (`simulation.period`, on the monotonic clock; a late wake-up is caught
//! up by running the missed periods at once, as time goes on for hardware):
//! 1. the sensor endpoint serves the requests that arrived; the robot endpoint reads the
//!    commands, and the newest becomes the command the robot follows (held until the next),
//!    with the scenario's `facility.robot_delay` (and servo lag, if any);
//! 2. one [`FacilityLoop::tick`] with that command: the facility advances one period (not at
//!    k = 0; the model with `simulation.plant_substeps` sub-steps), then it is measured;
//! 3. the sensor endpoint samples the measured wrench (and streams it), the robot endpoint
//!    sends feedback of the actual motion when its own period is due.
//!
//! Every datagram and socket error of both endpoints is counted in their [`LinkStats`]
//! ([`FacilityStatus::sensor`], [`FacilityStatus::robot`]); nothing is dropped uncounted. Each
//! control period never allocates after start-up, with the live view on too
//! (`tests/no_alloc.rs`, `tests/no_alloc_facility_live.rs`).
//!
//! **Live view** ([`EmulatorOptions::live`], `hilcontact facility --live`): the facility's
//! physical truth, as a [`Sample`] per period (the commanded pose it received as the record's
//! commanded pose and velocity, the actual ones, the physical contact force, its friction part
//! and moment, the sensor's wrench as measured, the wake-up latency as `wake_latency` and the
//! newest command's age as `robot_age`; no virtual dynamics: applied wrench zero, energy and
//! estimates NaN), goes through the same output seam as a run's ([`Outputs`], the `live`
//! sink). The real-time thread only pushes it into a preallocated ring (full: the sample is
//! dropped and counted, [`FacilityStatus::live_samples_dropped`]); a thread of normal priority
//! drains the ring into the sink every 5 ms, and watches for the operator's stop: the facility
//! then stops serving ([`FacilityStatus::operator_stop`]).

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use nalgebra::Vector3;
use serde::Serialize;
use serde_json::Value;

use hilcontact_core::compensator::Rendering;
use hilcontact_core::facility::{FacilityLoop, Measurement};
use hilcontact_core::frames::FrameWrench;
use hilcontact_core::hil::HilRecord;
use hilcontact_core::world::RelativeMotion;
use hilcontact_core::{Plan, Scenario};

use crate::clock::{
    now_ns, request_realtime, sleep_until_ns, tighten_timer_slack, SchedulingReport,
};
use crate::devices::{
    open_robot_endpoint, open_sensor_endpoint, EndpointContext, LinkStats, RobotEndpoint,
    SensorEndpoint, Wrench,
};
use crate::error::{Result, RtError};
use crate::output::live::FACILITY_RUN;
use crate::output::{EventLevel, Outputs, RunInfo};
use crate::report::Sample;

use crate::counters::SharedLinkStats;
pub use crate::options::EmulatorOptions;

/// Counters of the emulator (read them with [`FacilityHandle::status`]).
#[derive(Debug, Default)]
struct Shared {
    stop: AtomicBool,
    finished: AtomicBool,
    tick: AtomicU64,
    contact_force_bits: AtomicU64,
    peak_contact_force_bits: AtomicU64,
    sensor: SharedLinkStats,
    robot: SharedLinkStats,
    overruns: AtomicU64,
    max_latency_ns: AtomicU64,
    /// The robot's session end: 0 running (or none), 1 ended cleanly, 2 ended with an error.
    session: std::sync::atomic::AtomicU8,
    /// The live view's operator asked for the stop.
    operator_stop: AtomicBool,
    /// Samples the live view's ring had no room for.
    live_dropped: AtomicU64,
    /// The live view's report once it has finished (`realtime.live`'s fields).
    live_report: Mutex<Option<Value>>,
}

/// A snapshot of the emulator's counters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FacilityStatus {
    /// Whether the emulator thread has ended.
    pub finished: bool,
    /// Control periods run.
    pub tick: u64,
    /// Time since start, s (tick × period).
    pub time: f64,
    /// Magnitude of the physical contact force, N.
    pub contact_force: f64,
    /// Largest magnitude of the physical contact force so far (what the hardware felt), N.
    pub peak_contact_force: f64,
    /// The sensor's protocol, e.g. `"RDT"`.
    pub sensor_protocol: &'static str,
    /// The robot's protocol, e.g. `"EGM"`.
    pub robot_protocol: &'static str,
    /// The emulated sensor's counters: `received` requests, `accepted` valid ones,
    /// `malformed`, `sent` samples, `send_errors`, `io_errors` (socket errors on receive or
    /// send).
    pub sensor: LinkStats,
    /// The emulated robot's counters: `received` commands, `accepted`, dropped ones as
    /// `malformed`/`invalid`/`foreign`/`stale`, `lost` (sequence gaps), `sent` feedback
    /// messages, `send_errors`, `io_errors`.
    pub robot: LinkStats,
    /// Socket errors of both endpoints (receive or send), never dropped uncounted.
    pub io_errors: u64,
    /// Valid sensor requests received (`sensor.accepted`; the name of earlier versions).
    pub rdt_requests: u64,
    /// Invalid sensor requests (size, header, command) dropped (`sensor.dropped()`).
    pub rdt_bad_requests: u64,
    /// Robot commands (EGM corrections) accepted (`robot.accepted`).
    pub corrections: u64,
    /// Robot commands dropped: malformed, invalid, foreign, stale (`robot.dropped()`).
    pub corrections_dropped: u64,
    /// Periods that started more than one period late.
    pub overruns: u64,
    /// Largest wake-up latency, µs.
    pub max_latency_us: f64,
    /// How the robot's session ended (KUKA RSI): true with the PC's end signal, false with
    /// the controller's error (too many late answers), None while it runs or without
    /// sessions.
    pub session_ended_cleanly: Option<bool>,
    /// Whether the live view's operator stopped the facility (`/hilcontact/stop` with
    /// `--live-control`): it stopped serving (the CLI exits 3, reason `operator`).
    pub operator_stop: bool,
    /// The live view's port as asked for (0: any free one, the server prints the one bound on
    /// stderr); None: no live view.
    pub live_port: Option<u16>,
    /// Periods whose sample the live view's ring had no room for (its thread fell behind).
    pub live_samples_dropped: u64,
}

/// Where the emulator listens and sends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FacilityAddresses {
    /// The sensor's socket.
    pub sensor: SocketAddr,
    /// The sensor's HTTP server, if any.
    pub http: Option<SocketAddr>,
    /// The robot's socket.
    pub robot: SocketAddr,
    /// Where the robot's feedback goes (the PC; None: a TCP server no client connected to yet).
    pub robot_peer: Option<SocketAddr>,
}

/// A running emulated facility.
pub struct FacilityHandle {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    /// The live view's thread (drains the ring into the sink).
    live_thread: Option<JoinHandle<()>>,
    live_port: Option<u16>,
    addresses: FacilityAddresses,
    protocols: (&'static str, &'static str),
    period: f64,
    scheduling: SchedulingReport,
}

impl FacilityHandle {
    /// What the OS granted the facility's thread of [`EmulatorOptions::scheduling`].
    pub fn scheduling(&self) -> &SchedulingReport {
        &self.scheduling
    }

    /// Starts the emulated facility of a scenario: opens the endpoints of `options` (binds the
    /// sockets; errors here, e.g. a port in use, keep their errno) and starts the real-time
    /// thread.
    pub fn start(scenario: &Scenario, options: &EmulatorOptions) -> Result<Self> {
        let plan = scenario.resolve()?;
        let o = options;
        let parsed = o.parse()?;
        let period = plan.period;
        let initial = plan.system.relative_motion(&plan.initial);
        let initial = RelativeMotion {
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
            ..initial
        };
        let context = EndpointContext { period, initial };
        let sensor = open_sensor_endpoint(&parsed.sensor, &context)?;
        let robot = open_robot_endpoint(&parsed.robot, &context)?;
        let addresses = FacilityAddresses {
            sensor: sensor.address(),
            http: sensor.http_address(),
            robot: robot.address(),
            robot_peer: robot.peer(),
        };
        let protocols = (sensor.name(), robot.name());

        let shared = Arc::new(Shared::default());
        // the live view first: its port refused before the facility's thread starts
        let (live, live_thread, live_port) = match &o.live {
            Some(live) => {
                let (producer, consumer) = rtrb::RingBuffer::new(LIVE_RING);
                let (thread, port) = spawn_live(&plan, live, consumer, shared.clone())?;
                (Some(producer), Some(thread), port)
            }
            None => (None, None, None),
        };
        let facility = FacilityLoop::new(&plan);
        let silence = |after: Option<f64>| after.map(|s| (s / period).round() as u64);
        let mut state = Emulator {
            facility,
            sensor,
            robot,
            shared: shared.clone(),
            period_ns: (period * 1e9).round() as u64,
            sensor_silent_after: silence(o.silence_sensor_after),
            robot_silent_after: silence(o.silence_robot_after),
            first_command: None,
            offset: Wrench {
                force: Vector3::new(o.sensor_offset[0], o.sensor_offset[1], o.sensor_offset[2]),
                moment: Vector3::new(o.sensor_offset[3], o.sensor_offset[4], o.sensor_offset[5]),
            },
            command: initial,
            unit: o.sensor_unit.newtons(),
            live,
            truth: Truth::new(&plan),
            last_command: 0,
        };
        let scheduling = o.scheduling;
        let (told, granted) = std::sync::mpsc::sync_channel(1);
        let thread = std::thread::Builder::new()
            .name("hil-facility".into())
            .spawn(move || {
                tighten_timer_slack();
                // the start waits for this before it returns
                let report = match &scheduling {
                    Some(asked) => request_realtime(asked),
                    None => SchedulingReport::normal(),
                };
                let _ = told.send(report);
                state.run();
                state.publish();
                state.live = None; // the ring abandoned: the live view drains it and ends
                state.shared.finished.store(true, Ordering::Release);
            })
            .map_err(|e| RtError::io("emulator thread", &e))?;
        // the thread sends before its loop; a thread that died before it sent is a closed
        // channel, reported as normal scheduling
        let scheduling = granted
            .recv()
            .unwrap_or_else(|_| SchedulingReport::normal());
        Ok(FacilityHandle {
            scheduling,
            shared,
            thread: Some(thread),
            live_thread,
            live_port,
            addresses,
            protocols,
            period,
        })
    }

    /// The addresses in use.
    pub fn addresses(&self) -> FacilityAddresses {
        self.addresses
    }

    /// A snapshot of the counters.
    pub fn status(&self) -> FacilityStatus {
        let s = &self.shared;
        let tick = s.tick.load(Ordering::Relaxed);
        let (sensor, robot) = (s.sensor.load(), s.robot.load());
        FacilityStatus {
            finished: s.finished.load(Ordering::Acquire),
            tick,
            time: tick as f64 * self.period,
            contact_force: f64::from_bits(s.contact_force_bits.load(Ordering::Relaxed)),
            peak_contact_force: f64::from_bits(s.peak_contact_force_bits.load(Ordering::Relaxed)),
            sensor_protocol: self.protocols.0,
            robot_protocol: self.protocols.1,
            sensor,
            robot,
            io_errors: sensor.io_errors + robot.io_errors,
            rdt_requests: sensor.accepted,
            rdt_bad_requests: sensor.dropped(),
            corrections: robot.accepted,
            corrections_dropped: robot.dropped(),
            overruns: s.overruns.load(Ordering::Relaxed),
            max_latency_us: s.max_latency_ns.load(Ordering::Relaxed) as f64 / 1e3,
            session_ended_cleanly: match s.session.load(Ordering::Relaxed) {
                1 => Some(true),
                2 => Some(false),
                _ => None,
            },
            operator_stop: s.operator_stop.load(Ordering::Acquire),
            live_port: self.live_port,
            live_samples_dropped: s.live_dropped.load(Ordering::Relaxed),
        }
    }

    /// The live view's report once the facility has been joined ([`FacilityHandle::join`]):
    /// `metrics.json` `realtime.live`'s fields; None without a live view or before.
    pub fn live_report(&self) -> Option<Value> {
        self.shared.live_report.lock().ok().and_then(|r| r.clone())
    }

    /// Asks the emulator to stop (returns at once).
    pub fn stop(&self) {
        self.shared.stop.store(true, Ordering::Release);
    }

    /// Whether the emulator thread has ended.
    pub fn is_finished(&self) -> bool {
        self.shared.finished.load(Ordering::Acquire)
    }

    /// Stops the emulator and waits for its thread (and the live view's); returns the final
    /// counters.
    pub fn join(mut self) -> FacilityStatus {
        self.end();
        self.status()
    }

    /// [`FacilityHandle::join`] that also returns the live view's report
    /// ([`FacilityHandle::live_report`]).
    pub fn join_with_live(mut self) -> (FacilityStatus, Option<Value>) {
        self.end();
        (self.status(), self.live_report())
    }

    fn end(&mut self) {
        self.stop();
        for t in [self.thread.take(), self.live_thread.take()]
            .into_iter()
            .flatten()
        {
            let _ = t.join(); // a panic has already been reported by the thread; the counters stand
        }
    }
}

impl Drop for FacilityHandle {
    fn drop(&mut self) {
        self.end();
    }
}

/// Periods the live view's ring holds (8 s at 1 kHz, as the loop's): its thread drains it every
/// [`LIVE_DRAIN`].
const LIVE_RING: usize = 8192;

/// How often the live view's thread drains the ring.
const LIVE_DRAIN: Duration = Duration::from_millis(5);

/// Opens the live view (binds its server: a port in use refuses the start) and starts its
/// thread: it drains `ring` into the sink, hands the operator's stop to the facility, and
/// once the ring is abandoned (the facility ended) finishes the sink into
/// [`Shared::live_report`].
fn spawn_live(
    plan: &Plan,
    live: &crate::output::live::LiveOptions,
    mut ring: rtrb::Consumer<Sample>,
    shared: Arc<Shared>,
) -> Result<(JoinHandle<()>, Option<u16>)> {
    let info = RunInfo {
        kind: FACILITY_RUN,
        estimates_contact: false,
        ..RunInfo::new(plan, true)
    };
    let options = serde_json::json!({ "live": live });
    let mut outputs = Outputs::open(plan, &info, &options)?;
    let control = outputs.control();
    let thread = std::thread::Builder::new()
        .name("facility-live".into())
        .spawn(move || {
            let mut stop_told = false;
            loop {
                let abandoned = ring.is_abandoned();
                while let Ok(s) = ring.pop() {
                    outputs.sample(&s);
                }
                if control.operator_stop_requested() && !stop_told {
                    stop_told = true;
                    shared.operator_stop.store(true, Ordering::Release);
                    shared.stop.store(true, Ordering::Release);
                }
                if abandoned {
                    break;
                }
                std::thread::sleep(LIVE_DRAIN);
            }
            let text = if stop_told {
                "facility stopped by the operator (live view): no longer serving".to_string()
            } else {
                "facility stopped".to_string()
            };
            let level = if stop_told {
                EventLevel::Error
            } else {
                EventLevel::Info
            };
            outputs.event(outputs.last_time(), level, &text);
            let report = outputs.finish().into_iter().find(|(k, _)| *k == "live");
            if let (Ok(mut slot), Some((_, value))) = (shared.live_report.lock(), report) {
                *slot = Some(value);
            }
        })
        .map_err(|e| RtError::io("live view thread", &e))?;
    Ok((thread, Some(live.port)))
}

/// What the live view's sample is built from: the plan's rod and sensor origin.
struct Truth {
    rod_tip: Vector3<f64>,
    sensor_origin: Vector3<f64>,
    period: f64,
}

impl Truth {
    fn new(plan: &Plan) -> Self {
        Truth {
            rod_tip: plan.system.rod_tip,
            sensor_origin: plan.system.sensor_origin,
            period: plan.period,
        }
    }

    /// Period `k`'s sample: the command held, the measurement `m` (sensor's wrench in N), the
    /// physical contact, the wake-up latency (s) and the command's age (s). Never allocates.
    fn sample(
        &self,
        k: u64,
        command: &RelativeMotion,
        m: &Measurement,
        facility: &FacilityLoop,
        latency: f64,
        command_age: f64,
    ) -> Sample {
        let rod = &self.rod_tip;
        let p = facility.physical_contact();
        let tip = m.actual.point(rod);
        let moment = p.moment.unwrap_or_else(|| {
            FrameWrench::from_rod_force(&p.force, &tip, &self.sensor_origin).moment
        });
        Sample {
            record: HilRecord {
                time: k as f64 * self.period,
                tip_position: command.point(rod),
                tip_velocity: command.point_velocity(rod),
                angular_velocity: command.angular_velocity,
                orientation: command.orientation,
                actual_tip_position: tip,
                actual_tip_velocity: m.actual.point_velocity(rod),
                actual_orientation: m.actual.orientation,
                actual_angular_velocity: m.actual.angular_velocity,
                contact_force: p.force,
                friction_force: p.friction_force,
                contact_moment: moment,
                measured_force: m.force,
                measured_moment: m.moment,
                applied_force: Vector3::zeros(),
                applied_moment: Vector3::zeros(),
                energy: f64::NAN,
                stiffness_estimate: f64::NAN,
                damping_estimate: f64::NAN,
                law_factor: p.law_factor.unwrap_or(f64::NAN),
                observed_energy: f64::NAN,
                rendering: Rendering::Unreported,
            },
            wake_latency: latency,
            sensor_age: 0.0,
            robot_age: command_age,
        }
    }
}

struct Emulator {
    /// The facility's side of each tick (advance with `command`, measure).
    facility: FacilityLoop,
    sensor: Box<dyn SensorEndpoint>,
    robot: Box<dyn RobotEndpoint>,
    shared: Arc<Shared>,
    period_ns: u64,
    /// Fault injection: ticks after the first command when the sensor / the robot go silent.
    sensor_silent_after: Option<u64>,
    robot_silent_after: Option<u64>,
    /// The tick the first command arrived (the run's start, as the facility sees it).
    first_command: Option<u64>,
    /// Added to every measured wrench (fault injection), N and N·m.
    offset: Wrench,
    /// The command the robot follows (newest command, held), `t` frame.
    command: RelativeMotion,
    /// Newtons per unit the sensor reports in (fault injection: 9.80665 for kgf).
    unit: f64,
    /// The live view's ring (None: no live view).
    live: Option<rtrb::Producer<Sample>>,
    /// What the live view's samples are built from.
    truth: Truth,
    /// The tick the newest command arrived.
    last_command: u64,
}

impl Emulator {
    fn run(&mut self) {
        let t0 = now_ns() + self.period_ns;
        let mut k: u64 = 0;
        while !self.shared.stop.load(Ordering::Acquire) {
            let deadline = t0 + k * self.period_ns;
            sleep_until_ns(deadline);
            let latency = now_ns().saturating_sub(deadline);
            self.shared
                .max_latency_ns
                .fetch_max(latency, Ordering::Relaxed);
            if latency > self.period_ns {
                self.shared.overruns.fetch_add(1, Ordering::Relaxed);
            }
            self.step(k, latency as f64 * 1e-9);
            k += 1;
            self.publish();
            self.shared.tick.store(k, Ordering::Relaxed);
        }
    }

    /// The endpoints' counters into the shared atomics.
    fn publish(&self) {
        self.shared.sensor.store(self.sensor.stats());
        self.shared.robot.store(self.robot.stats());
        let session = match self.robot.session_ended_cleanly() {
            Some(true) => 1,
            Some(false) => 2,
            None => 0,
        };
        self.shared.session.store(session, Ordering::Relaxed);
    }

    fn step(&mut self, k: u64, latency: f64) {
        self.sensor.serve();
        if let Some(command) = self.robot.receive() {
            self.command = command;
            self.first_command.get_or_insert(k);
            self.last_command = k;
        }
        let m = self.facility.tick(&self.command);
        let contact_force = self.facility.contact_force().norm();
        self.shared
            .contact_force_bits
            .store(contact_force.to_bits(), Ordering::Relaxed);
        // non-negative floats order as their bits
        self.shared
            .peak_contact_force_bits
            .fetch_max(contact_force.to_bits(), Ordering::Relaxed);
        let wrench = Wrench {
            force: (m.force + self.offset.force) / self.unit,
            moment: (m.moment + self.offset.moment) / self.unit,
        };
        let speaks = |after: Option<u64>| match (after, self.first_command) {
            (Some(after), Some(first)) => k < first.saturating_add(after),
            _ => true,
        };
        let (sensor_speaks, robot_speaks) = (
            speaks(self.sensor_silent_after),
            speaks(self.robot_silent_after),
        );
        self.sensor.sample(&wrench, sensor_speaks);
        self.robot.feedback(k, &m.actual, robot_speaks);
        if let Some(ring) = &mut self.live {
            let measured = Measurement {
                force: m.force + self.offset.force,
                moment: m.moment + self.offset.moment,
                ..m
            };
            let age = (k - self.last_command) as f64 * self.truth.period;
            let sample =
                self.truth
                    .sample(k, &self.command, &measured, &self.facility, latency, age);
            if ring.push(sample).is_err() {
                self.shared.live_dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}
