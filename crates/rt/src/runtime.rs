//! The real-time HIL loop: RDT sensor client, EGM endpoint, compensator and virtual dynamics
//! in one thread at the scenario's period on the monotonic clock.
//!
//! One tick k (deadline `t0 + k·T`, absolute sleep):
//! 1. drain the RDT socket (non-blocking): keep the newest valid record from the sensor's
//!    address; drain the EGM socket: keep the newest valid feedback from the robot;
//! 2. the measurement: the record's wrench (sensor frame) and the actual motion estimated from
//!    the feedback ([`crate::feedback`]);
//! 3. [`VirtualDynamics::compensate`], the sample into the lock-free ring buffer, the safety
//!    checks ([`crate::safety`]);
//! 4. [`VirtualDynamics::integrate`], the new command checked against the workspace and the
//!    energy bound, and sent as an `EgmSensor` correction to the robot.
//!
//! The tick never allocates, locks or logs: sockets are non-blocking, codecs and buffers are
//! preallocated, samples go to an `rtrb` ring buffer that a writer thread drains, counters and
//! the live status are atomics. Lateness is counted, never hidden: every wake-up latency and
//! period goes into a histogram, a tick that ends after the next deadline is an overrun, and
//! missed periods are caught up (the virtual time stays `k·T`).
//!
//! Bad input is counted and dropped, never reaches the dynamics: datagrams of the wrong size,
//! header or type, undecodable, non-finite or out-of-range values, stale sequence numbers
//! (duplicates, reordering), and datagrams from any address but the configured peers.
//!
//! Every stop (end of run, `stop()`, a safety limit) ends the same way: the robot is commanded
//! to hold its last fed-back pose for `hold_time`, the sensor's streaming is stopped, and the
//! writer thread drains the ring buffer completely before the results are built.

use std::io::ErrorKind;
use std::net::{IpAddr, SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use hilcontact_core::facility::Measurement;
use hilcontact_core::hil::{HilRecord, HilStep};
use hilcontact_core::world::RelativeMotion;
use hilcontact_core::{metrics, sim, Plan, Scenario};

use crate::clock::{now_ns, sleep_until_ns, tighten_timer_slack, Histogram, TimingSummary};
use crate::egm::{CorrectionEncoder, EgmError, RobotDecoder, EGM_PERIOD, EGM_PORT};
use crate::emulator::{bind_udp, resolve};
use crate::error::{Result, RtError};
use crate::feedback::{Extrapolation, FeedbackEstimator};
use crate::mapping::{EgmTarget, PoseMapping};
use crate::netftapi::fetch_counts;
use crate::rdt::{
    CountsPerUnit, RdtCommand, RdtRecord, RdtRequest, SequenceTracker, SequenceVerdict, RDT_PORT,
};
use crate::report::{build_output, HilOutput};
use crate::safety::{check_workspace, check_wrench, SafetyLimits, StopEvent, StopKind};

/// Options of the real-time runtime (defaults in [`Default`]; the CLI documents each).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RuntimeOptions {
    /// Host of the F/T sensor (Net F/T).
    pub sensor_host: String,
    /// RDT port of the sensor (49152).
    pub sensor_port: u16,
    /// HTTP port of the sensor's `/netftapi2.xml` (80).
    pub http_port: u16,
    /// Counts per N; with `counts_per_torque`, skips reading `/netftapi2.xml`.
    pub counts_per_force: Option<f64>,
    /// Counts per N·m.
    pub counts_per_torque: Option<f64>,
    /// Local UDP port of the RDT client (0 = any free port).
    pub rdt_local_port: u16,
    /// Send the sensor a bias command (0x0042) before streaming: the rod must be free.
    pub bias: bool,
    /// Address the EGM endpoint binds to.
    pub egm_bind_host: String,
    /// UDP port the robot controller sends its EGM feedback to (6510).
    pub egm_port: u16,
    /// Accept EGM feedback only from this host; None = from the first robot that sends.
    pub robot_host: Option<String>,
    /// Origin of the target frame `t` in the EGM frame, mm.
    pub egm_offset_mm: [f64; 3],
    /// Rotation from `t` to the EGM frame, quaternion `[w, x, y, z]`.
    pub egm_rotation: [f64; 4],
    /// How the actual motion is estimated between feedback messages.
    pub extrapolation: Extrapolation,
    /// Safety limits.
    pub limits: SafetyLimits,
    /// Longest wait for the first sensor record and robot feedback, s.
    pub connect_timeout: f64,
    /// Largest distance between the robot's fed-back pose and the scenario's initial pose at
    /// start, m.
    pub start_tolerance: f64,
    /// How long the hold command is streamed after a stop, s.
    pub hold_time: f64,
}

impl Default for RuntimeOptions {
    fn default() -> Self {
        RuntimeOptions {
            sensor_host: "127.0.0.1".into(),
            sensor_port: RDT_PORT,
            http_port: 80,
            counts_per_force: None,
            counts_per_torque: None,
            rdt_local_port: 0,
            bias: false,
            egm_bind_host: "0.0.0.0".into(),
            egm_port: EGM_PORT,
            robot_host: None,
            egm_offset_mm: [0.0; 3],
            egm_rotation: [1.0, 0.0, 0.0, 0.0],
            extrapolation: Extrapolation::default(),
            limits: SafetyLimits::default(),
            connect_timeout: 5.0,
            start_tolerance: 0.005,
            hold_time: 0.1,
        }
    }
}

/// One tick of the loop, as logged (fixed size, `Copy`): the simulation's record of a tick
/// plus the loop's timing.
///
/// In the record, `time` is the virtual time (tick × period), `actual_*` the rod tip estimated
/// from EGM feedback and `contact_force` the force on the rod that the sensor reports (the
/// opposite of the measured force, in `t`): the true contact force is not observable.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// The tick, as the simulation records it.
    pub record: HilRecord,
    /// Wake-up latency of the tick, s.
    pub wake_latency: f64,
    /// Age of the sensor record used (since its arrival), s.
    pub sensor_age: f64,
    /// Age of the newest robot feedback (since its arrival), s.
    pub robot_age: f64,
}

/// Packet counters of one link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct LinkStats {
    /// Datagrams received.
    pub received: u64,
    /// Datagrams accepted.
    pub accepted: u64,
    /// Wrong size, header or type, or undecodable.
    pub malformed: u64,
    /// Non-finite or out-of-range values, or an error status.
    pub invalid: u64,
    /// From an address that is not the peer.
    pub foreign: u64,
    /// Duplicates or older than the newest accepted.
    pub stale: u64,
    /// Missing sequence numbers (gaps).
    pub lost: u64,
    /// Sensor: ticks without a new record. Robot: feedback more than 1.5 EGM periods after the previous.
    pub late: u64,
}

impl LinkStats {
    fn dropped(&self) -> u64 {
        self.malformed + self.invalid + self.foreign + self.stale
    }
}

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
    /// Why it stopped, once it has.
    pub stop: Option<StopKind>,
}

/// What the loop thread hands back.
#[derive(Debug, Clone)]
pub struct RunOutcome {
    /// Why it stopped.
    pub stop: StopEvent,
    /// Ticks run.
    pub ticks: u64,
    /// Wall time of the loop, s.
    pub wall_time: f64,
    /// Wake-up latency (wake − deadline), µs.
    pub wake_latency: TimingSummary,
    /// |actual period − T|, µs.
    pub period_error: TimingSummary,
    /// Time from wake-up to the command sent, µs.
    pub compute: TimingSummary,
    /// Ticks that ended after the next deadline.
    pub overruns: u64,
    /// Sensor link.
    pub sensor: LinkStats,
    /// Robot link.
    pub robot: LinkStats,
    /// Corrections sent.
    pub commands_sent: u64,
    /// Corrections that could not be sent.
    pub send_errors: u64,
    /// Samples lost because the ring buffer was full.
    pub samples_dropped: u64,
    /// Counts per unit in use.
    pub counts: CountsPerUnit,
    /// The robot's address.
    pub robot_address: Option<SocketAddr>,
}

/// A running HIL loop.
pub struct HilHandle {
    shared: Arc<SharedStatus>,
    thread: Option<JoinHandle<Result<RunOutcome>>>,
    writer: Option<JoinHandle<Vec<Sample>>>,
    plan: Plan,
    options: RuntimeOptions,
    period: f64,
}

/// Capacity of the sample ring buffer (8 s at 1 kHz; the writer drains it every 5 ms).
const RING_CAPACITY: usize = 8192;

impl HilHandle {
    /// Validates, binds the sockets, reads the sensor's counts per unit (HTTP, unless given),
    /// computes the ideal reference's energy bound, and starts the writer and loop threads.
    pub fn start(scenario: &Scenario, options: &RuntimeOptions) -> Result<Self> {
        let plan = scenario.resolve()?;
        let o = options;
        o.limits.validate()?;
        for (key, v) in [
            ("connect_timeout", o.connect_timeout),
            ("start_tolerance", o.start_tolerance),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RtError::option(
                    key,
                    format!("must be a positive number, got {v}"),
                ));
            }
        }
        if !(o.hold_time.is_finite() && o.hold_time >= 0.0) {
            return Err(RtError::option(
                "hold_time",
                format!("must be a number >= 0, got {}", o.hold_time),
            ));
        }
        let counts = match (o.counts_per_force, o.counts_per_torque) {
            (Some(force), Some(torque)) => {
                if !(force.is_finite() && force > 0.0 && torque.is_finite() && torque > 0.0) {
                    return Err(RtError::option("counts_per_force", "counts per unit must be positive numbers"));
                }
                CountsPerUnit { force, torque }
            }
            (None, None) => fetch_counts(&o.sensor_host, o.http_port, Duration::from_secs_f64(o.connect_timeout.min(5.0)))
                .map_err(|e| RtError::Connect(format!("cannot read the sensor's counts per unit: {e} (or give counts_per_force and counts_per_torque)")))?,
            _ => return Err(RtError::option("counts_per_force", "give both counts_per_force and counts_per_torque, or neither")),
        };
        let mapping = PoseMapping::new(o.egm_offset_mm, o.egm_rotation)?;
        let sensor_addr = resolve("sensor_host", &o.sensor_host, o.sensor_port)?;
        let rdt_bind: SocketAddr = if sensor_addr.ip().is_loopback() {
            ([127, 0, 0, 1], o.rdt_local_port).into()
        } else {
            ([0, 0, 0, 0], o.rdt_local_port).into()
        };
        let rdt = bind_udp("RDT client", rdt_bind)?;
        let egm = bind_udp(
            "EGM endpoint",
            resolve("egm_bind_host", &o.egm_bind_host, o.egm_port)?,
        )?;
        let robot_ip = match &o.robot_host {
            Some(h) => Some(resolve("robot_host", h, 0)?.ip()),
            None => None,
        };

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
        let writer = std::thread::Builder::new()
            .name("hil-writer".into())
            .spawn(move || {
                let mut samples = Vec::with_capacity(ticks as usize + 1);
                loop {
                    let abandoned = consumer.is_abandoned();
                    while let Ok(s) = consumer.pop() {
                        samples.push(s);
                    }
                    if abandoned {
                        break; // drained after the producer was dropped: complete
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
                samples
            })
            .map_err(|e| RtError::Io(format!("writer thread: {e}")))?;

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
            mapping,
            counts,
            options: o.clone(),
            rdt,
            sensor_addr,
            rdt_seq: SequenceTracker::new(),
            sensor: LinkStats::default(),
            last_rdt_ns: 0,
            new_record: false,
            force: Vector3::zeros(),
            moment: Vector3::zeros(),
            egm,
            robot_ip,
            robot_addr: None,
            egm_seq: SequenceTracker::new(),
            robot: LinkStats::default(),
            last_egm_ns: 0,
            decoder: RobotDecoder::new(),
            encoder: CorrectionEncoder::new(),
            estimator: FeedbackEstimator::new(o.extrapolation),
            send_seq: 0,
            commands_sent: 0,
            send_errors: 0,
            buf: [0u8; 2048],
            producer,
            samples_dropped: 0,
            shared: shared.clone(),
            wake: Histogram::new(20_000),
            period_hist: Histogram::new(20_000),
            compute: Histogram::new(20_000),
            overruns: 0,
            t0_ns: 0,
        };
        let flag = shared.clone();
        let thread = std::thread::Builder::new()
            .name("hil-rt".into())
            .spawn(move || {
                tighten_timer_slack();
                let outcome = state.run();
                flag.phase.store(3, Ordering::Release);
                flag.finished.store(true, Ordering::Release);
                outcome
            })
            .map_err(|e| RtError::Io(format!("loop thread: {e}")))?;
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

    /// Waits for the loop and the writer, and builds the time series, reference and metrics.
    pub fn finish(mut self) -> Result<HilOutput> {
        let outcome = match self.thread.take().map(|t| t.join()) {
            Some(Ok(outcome)) => outcome,
            _ => Err(RtError::Io("the loop thread panicked".into())),
        };
        let samples = match self.writer.take().map(|t| t.join()) {
            Some(Ok(samples)) => samples,
            _ => return Err(RtError::Io("the writer thread panicked".into())),
        };
        build_output(
            &self.plan,
            &self.options,
            &samples,
            &outcome?,
        )
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
    mapping: PoseMapping,
    counts: CountsPerUnit,
    options: RuntimeOptions,
    // sensor link
    rdt: UdpSocket,
    sensor_addr: SocketAddr,
    rdt_seq: SequenceTracker,
    sensor: LinkStats,
    last_rdt_ns: u64,
    new_record: bool,
    force: Vector3<f64>,
    moment: Vector3<f64>,
    // robot link
    egm: UdpSocket,
    robot_ip: Option<IpAddr>,
    robot_addr: Option<SocketAddr>,
    egm_seq: SequenceTracker,
    robot: LinkStats,
    last_egm_ns: u64,
    decoder: RobotDecoder,
    encoder: CorrectionEncoder,
    estimator: FeedbackEstimator,
    send_seq: u32,
    commands_sent: u64,
    send_errors: u64,
    buf: [u8; 2048],
    // log and timing
    producer: rtrb::Producer<Sample>,
    samples_dropped: u64,
    shared: Arc<SharedStatus>,
    wake: Histogram,
    period_hist: Histogram,
    compute: Histogram,
    overruns: u64,
    t0_ns: u64,
}

impl Loop {
    fn run(&mut self) -> Result<RunOutcome> {
        let connected = self.connect();
        if let Err(e) = connected {
            self.stop_streaming();
            return Err(e);
        }
        self.shared.phase.store(1, Ordering::Release);
        self.t0_ns = now_ns() + self.period_ns;
        let mut stop = StopEvent::plain(StopKind::Completed, self.ticks as f64 * self.period);
        let mut last_wake: Option<u64> = None;
        let mut k = 0u64;
        while k <= self.ticks {
            let deadline = self.t0_ns + k * self.period_ns;
            sleep_until_ns(deadline);
            let wake = now_ns();
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
        self.hold();
        self.stop_streaming();
        Ok(RunOutcome {
            stop,
            ticks: k.min(self.ticks) + 1,
            wall_time,
            wake_latency: self.wake.summary(),
            period_error: self.period_hist.summary(),
            compute: self.compute.summary(),
            overruns: self.overruns,
            sensor: self.sensor,
            robot: self.robot,
            commands_sent: self.commands_sent,
            send_errors: self.send_errors,
            samples_dropped: self.samples_dropped,
            counts: self.counts,
            robot_address: self.robot_addr,
        })
    }

    /// Start-up (not real-time): requests streaming, waits for the first record and feedback,
    /// keeps the robot at the initial pose meanwhile, checks the start pose.
    fn connect(&mut self) -> Result<()> {
        if self.options.bias {
            self.request(RdtCommand::SetBias);
        }
        self.request(RdtCommand::StartRealtime);
        let start = now_ns();
        let timeout_ns = (self.options.connect_timeout * 1e9) as u64;
        let mut last_request = start;
        let hold = self.mapping.to_egm(&self.initial);
        loop {
            if self.shared.stop_requested.load(Ordering::Acquire) {
                return Err(RtError::Connect(
                    "stopped by the user while connecting".into(),
                ));
            }
            let now = now_ns();
            self.poll_sensor(now);
            self.poll_robot(now);
            if self.robot_addr.is_some() {
                self.send(&hold);
            }
            if self.sensor.accepted > 0 && self.estimator.has_feedback() {
                break;
            }
            if now - start > timeout_ns {
                let mut missing = Vec::new();
                if self.sensor.accepted == 0 {
                    missing.push(format!(
                        "no RDT record from the sensor at {}",
                        self.sensor_addr
                    ));
                }
                if !self.estimator.has_feedback() {
                    missing.push(format!(
                        "no EGM feedback from the robot on UDP port {}",
                        self.options.egm_port
                    ));
                }
                return Err(RtError::Connect(format!(
                    "{} within {} s (connect_timeout)",
                    missing.join(" and "),
                    self.options.connect_timeout
                )));
            }
            if self.sensor.accepted == 0 && now - last_request > 200_000_000 {
                self.request(RdtCommand::StartRealtime);
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
        if distance > self.options.start_tolerance {
            self.hold();
            return Err(RtError::Connect(format!(
                "the robot's rod tip is {:.1} mm from the scenario's initial position (start_tolerance {:.1} mm): move it there first",
                distance * 1e3,
                self.options.start_tolerance * 1e3
            )));
        }
        // forget the start-up's sequence bookkeeping for the lateness counters
        self.sensor.late = 0;
        self.robot.late = 0;
        Ok(())
    }

    fn request(&mut self, command: RdtCommand) {
        let bytes = RdtRequest {
            command,
            sample_count: 0,
        }
        .encode();
        let _ = self.rdt.send_to(&bytes, self.sensor_addr);
    }

    fn stop_streaming(&mut self) {
        for _ in 0..2 {
            self.request(RdtCommand::Stop);
        }
    }

    /// Streams the hold command (the last fed-back pose, at rest) for `hold_time`.
    fn hold(&mut self) {
        let Some(pose) = self.estimator.last_pose() else {
            return;
        };
        let target = self.mapping.to_egm(&pose);
        let periods = (self.options.hold_time / self.period).ceil() as u64;
        let start = now_ns();
        for i in 0..periods.max(1) {
            sleep_until_ns(start + i * self.period_ns);
            self.poll_sensor(now_ns());
            self.poll_robot(now_ns());
            self.send(&target);
        }
    }

    fn send(&mut self, target: &EgmTarget) {
        let Some(addr) = self.robot_addr else { return };
        self.send_seq = self.send_seq.wrapping_add(1);
        let tm = ((now_ns().saturating_sub(self.t0_ns)) / 1_000_000) as u32;
        let bytes = self.encoder.encode(self.send_seq, tm, target);
        match self.egm.send_to(bytes, addr) {
            Ok(_) => self.commands_sent += 1,
            Err(_) => self.send_errors += 1,
        }
    }

    fn poll_sensor(&mut self, now: u64) {
        loop {
            let (n, from) = match self.rdt.recv_from(&mut self.buf) {
                Ok(x) => x,
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(_) => break, // e.g. ICMP port unreachable surfaced on the socket
            };
            self.sensor.received += 1;
            if from != self.sensor_addr {
                self.sensor.foreign += 1;
                continue;
            }
            let record = match RdtRecord::decode(&self.buf[..n]) {
                Ok(r) => r,
                Err(_) => {
                    self.sensor.malformed += 1;
                    continue;
                }
            };
            match self.rdt_seq.check(record.rdt_sequence) {
                SequenceVerdict::Stale => {
                    self.sensor.stale += 1;
                    continue;
                }
                SequenceVerdict::Gap(n) => self.sensor.lost += n as u64,
                SequenceVerdict::First | SequenceVerdict::Next => {}
            }
            // a record with an error status arrived (not lost) but its values are not used
            if record.status != 0 {
                self.sensor.invalid += 1;
                continue;
            }
            let (f, m) = self.counts.to_wrench(&record.counts);
            self.force = Vector3::from(f);
            self.moment = Vector3::from(m);
            self.sensor.accepted += 1;
            self.last_rdt_ns = now;
            self.new_record = true;
        }
    }

    fn poll_robot(&mut self, now: u64) {
        loop {
            let (n, from) = match self.egm.recv_from(&mut self.buf) {
                Ok(x) => x,
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(_) => break,
            };
            self.robot.received += 1;
            let peer_ok = match (self.robot_ip, self.robot_addr) {
                (_, Some(addr)) => from == addr,
                (Some(ip), None) => from.ip() == ip,
                (None, None) => true,
            };
            if !peer_ok {
                self.robot.foreign += 1;
                continue;
            }
            let feedback = match self.decoder.decode(&self.buf[..n]) {
                Ok(f) => f,
                Err(
                    EgmError::WrongSize(_)
                    | EgmError::Decode
                    | EgmError::MissingHeader
                    | EgmError::WrongType(_),
                ) => {
                    self.robot.malformed += 1;
                    continue;
                }
                Err(_) => {
                    self.robot.invalid += 1;
                    continue;
                }
            };
            match self.egm_seq.check(feedback.seqno) {
                SequenceVerdict::Stale => {
                    self.robot.stale += 1;
                    continue;
                }
                SequenceVerdict::Gap(n) => self.robot.lost += n as u64,
                SequenceVerdict::First | SequenceVerdict::Next => {}
            }
            if self.robot_addr.is_none() {
                self.robot_addr = Some(from);
            }
            if self.last_egm_ns > 0 && (now - self.last_egm_ns) as f64 > 1.5 * EGM_PERIOD * 1e9 {
                self.robot.late += 1;
            }
            let (position, orientation) = self.mapping.from_egm(&feedback.actual);
            self.estimator
                .push(feedback.robot_time(), now, position, orientation);
            self.robot.accepted += 1;
            self.last_egm_ns = now;
        }
    }

    /// One control tick; returns a stop, if any. Never allocates.
    fn tick(&mut self, k: u64, wake: u64, latency: u64) -> Option<StopEvent> {
        let time = k as f64 * self.period;
        self.new_record = false;
        self.poll_sensor(wake);
        self.poll_robot(wake);
        if !self.new_record {
            self.sensor.late += 1;
        }
        let actual = self.estimator.estimate(wake).unwrap_or(self.initial);
        let m = Measurement {
            force: self.force,
            moment: self.moment,
            actual,
        };
        let (record, verdict) = self.step.observe(k as usize, &m, None);
        let sample = Sample {
            record,
            wake_latency: latency as f64 * 1e-9,
            sensor_age: wake.saturating_sub(self.last_rdt_ns) as f64 * 1e-9,
            robot_age: wake.saturating_sub(self.last_egm_ns) as f64 * 1e-9,
        };
        if self.producer.push(sample).is_err() {
            self.samples_dropped += 1;
        }

        if self.shared.stop_requested.load(Ordering::Acquire) {
            return Some(StopEvent::plain(StopKind::User, time));
        }
        let watchdog = self.limits.watchdog_ns();
        let sensor_silence = wake.saturating_sub(self.last_rdt_ns);
        if sensor_silence > watchdog {
            return Some(StopEvent {
                kind: StopKind::SensorWatchdog,
                time,
                value: sensor_silence as f64 * 1e-6,
                limit: self.limits.watchdog_ms,
            });
        }
        let robot_silence = wake.saturating_sub(self.last_egm_ns);
        if robot_silence > watchdog {
            return Some(StopEvent {
                kind: StopKind::RobotWatchdog,
                time,
                value: robot_silence as f64 * 1e-6,
                limit: self.limits.watchdog_ms,
            });
        }
        if let Some(stop) = check_wrench(&self.limits, &self.force, &self.moment, time) {
            return Some(stop);
        }
        // divergence, a non-finite record, or the end of the run
        if let Some(stop) = verdict {
            return Some(stop);
        }
        let command = match self.step.advance(k as usize) {
            Ok(command) => command,
            Err(stop) => return Some(stop),
        };
        if let Some(stop) = check_workspace(
            &self.limits,
            &command.point(&self.rod),
            &self.start_tip,
            time,
        ) {
            return Some(stop);
        }
        let target = self.mapping.to_egm(&command);
        self.send(&target);
        None
    }

    fn publish(&self, tick: u64, latency: u64) {
        let s = &self.shared;
        s.tick.store(tick, Ordering::Relaxed);
        s.force_bits
            .store(self.force.norm().to_bits(), Ordering::Relaxed);
        s.energy_bits
            .store(self.step.dynamics().energy().to_bits(), Ordering::Relaxed);
        s.max_latency_ns.fetch_max(latency, Ordering::Relaxed);
        s.overruns.store(self.overruns, Ordering::Relaxed);
        s.sensor_lost.store(self.sensor.lost, Ordering::Relaxed);
        s.sensor_late.store(self.sensor.late, Ordering::Relaxed);
        s.robot_lost.store(self.robot.lost, Ordering::Relaxed);
        s.robot_late.store(self.robot.late, Ordering::Relaxed);
        s.dropped.store(
            self.sensor.dropped() + self.robot.dropped(),
            Ordering::Relaxed,
        );
    }
}
