//! The emulated facility: the core's facility model (robot with the scenario's response lag,
//! contact law, F/T sensor with the scenario's delay and noise) running in real time behind
//! the real devices' protocols.
//!
//! - Sensor: ATI Net F/T RDT on UDP `bind_host:sensor_port` (49152 by default). A start
//!   request (0x0002, or 0x0003 answered the same way) makes it stream one 36-byte record per
//!   control period to the requesting address, `sample_count` records or until a stop
//!   (0x0000); 0x0042 biases the output by the current reading. `rdt_sequence` counts the
//!   records sent, `ft_sequence` the samples taken (one per period, streaming or not), as the
//!   real sensor keeps them. `/netftapi2.xml` on `bind_host:http_port` gives the counts per
//!   unit.
//! - Robot: ABB EGM. Every `egm_period` (4 ms) an `EgmRobot` message with the actual pose
//!   (feedback) and the last commanded one (planned) goes to `egm_host:egm_port`; `EgmSensor`
//!   corrections are accepted from that address only, and the newest (by sequence number)
//!   becomes the command the robot follows, with the scenario's `facility.robot_delay` (and
//!   servo lag, if any). Without new corrections the robot holds the last command.
//! - Physics: one [`FacilityModel`] step per control period (`simulation.period`, with
//!   `simulation.plant_substeps` sub-steps for the servo lag), on the monotonic clock; a late
//!   wake-up is caught up by running the missed periods at once, as time goes on for hardware.
//!
//! Each control period of the loop never allocates after start-up.

use std::net::{IpAddr, SocketAddr, ToSocketAddrs, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use hilcontact_core::facility::FacilityModel;
use hilcontact_core::hil::VirtualDynamics;
use hilcontact_core::world::RelativeMotion;
use hilcontact_core::Scenario;

use crate::clock::{now_ns, sleep_until_ns, tighten_timer_slack};
use crate::egm::{CorrectionDecoder, EgmError, FeedbackEncoder, EGM_PORT};
use crate::error::{Result, RtError};
use crate::mapping::PoseMapping;
use crate::netftapi::{netftapi_xml, NetFtApiServer};
use crate::rdt::{
    CountsPerUnit, RdtCommand, RdtRecord, RdtRequest, SequenceTracker, SequenceVerdict, RDT_PORT,
};

/// Options of the emulated facility (defaults in [`Default`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmulatorOptions {
    /// Address the sensor's RDT and HTTP servers bind to.
    pub bind_host: String,
    /// RDT port (49152 on a real sensor).
    pub sensor_port: u16,
    /// HTTP port of `/netftapi2.xml` (80 on a real sensor; 0 = no HTTP server).
    pub http_port: u16,
    /// Host the robot sends EGM feedback to (the PC running the HIL loop).
    pub egm_host: String,
    /// Port the robot sends EGM feedback to (the PC side's port, 6510 by default).
    pub egm_port: u16,
    /// The robot's own UDP port (0 = any free port).
    pub egm_local_port: u16,
    /// EGM feedback period, s (0.004 = 250 Hz), rounded to whole control periods.
    pub egm_period: f64,
    /// Counts per N of the RDT records (`cfgcpf`).
    pub counts_per_force: f64,
    /// Counts per N·m of the RDT records (`cfgcpt`).
    pub counts_per_torque: f64,
    /// Origin of `t` in the EGM frame, mm (see [`crate::mapping`]).
    pub egm_offset_mm: [f64; 3],
    /// Rotation from `t` to the EGM frame, quaternion `[w, x, y, z]`.
    pub egm_rotation: [f64; 4],
    /// Fault injection: the sensor stops sending after this many seconds (None = never).
    pub silence_sensor_after: Option<f64>,
    /// Fault injection: the robot stops sending after this many seconds (None = never).
    pub silence_robot_after: Option<f64>,
}

impl Default for EmulatorOptions {
    fn default() -> Self {
        EmulatorOptions {
            bind_host: "127.0.0.1".into(),
            sensor_port: RDT_PORT,
            http_port: 80,
            egm_host: "127.0.0.1".into(),
            egm_port: EGM_PORT,
            egm_local_port: 0,
            egm_period: crate::egm::EGM_PERIOD,
            counts_per_force: CountsPerUnit::default().force,
            counts_per_torque: CountsPerUnit::default().torque,
            egm_offset_mm: [0.0; 3],
            egm_rotation: [1.0, 0.0, 0.0, 0.0],
            silence_sensor_after: None,
            silence_robot_after: None,
        }
    }
}

/// Resolves `host:port` to one socket address.
pub(crate) fn resolve(key: &str, host: &str, port: u16) -> Result<SocketAddr> {
    (host, port)
        .to_socket_addrs()
        .map_err(|e| RtError::option(key, format!("cannot resolve {host:?}: {e}")))?
        .next()
        .ok_or_else(|| RtError::option(key, format!("{host:?} has no address")))
}

/// Binds a non-blocking UDP socket.
pub(crate) fn bind_udp(what: &str, addr: SocketAddr) -> Result<UdpSocket> {
    let socket = UdpSocket::bind(addr)
        .map_err(|e| RtError::Io(format!("{what}: cannot bind UDP {addr}: {e}")))?;
    socket
        .set_nonblocking(true)
        .map_err(|e| RtError::Io(format!("{what}: {e}")))?;
    Ok(socket)
}

/// Counters of the emulator (read them with [`FacilityHandle::status`]).
#[derive(Debug, Default)]
struct Shared {
    stop: AtomicBool,
    finished: AtomicBool,
    tick: AtomicU64,
    contact_force_bits: AtomicU64,
    rdt_sent: AtomicU64,
    rdt_requests: AtomicU64,
    rdt_bad_requests: AtomicU64,
    egm_sent: AtomicU64,
    corrections: AtomicU64,
    corrections_dropped: AtomicU64,
    overruns: AtomicU64,
    max_latency_ns: AtomicU64,
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
    /// RDT records sent.
    pub rdt_sent: u64,
    /// Valid RDT requests received.
    pub rdt_requests: u64,
    /// Invalid RDT requests (size, header, command) dropped.
    pub rdt_bad_requests: u64,
    /// EGM feedback messages sent.
    pub egm_sent: u64,
    /// EGM corrections accepted.
    pub corrections: u64,
    /// EGM corrections dropped (malformed, foreign, stale, invalid).
    pub corrections_dropped: u64,
    /// Periods that started more than one period late.
    pub overruns: u64,
    /// Largest wake-up latency, µs.
    pub max_latency_us: f64,
}

/// Where the emulator listens and sends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FacilityAddresses {
    /// RDT socket.
    pub sensor: SocketAddr,
    /// HTTP server, if any.
    pub http: Option<SocketAddr>,
    /// The robot's EGM socket.
    pub robot: SocketAddr,
    /// Where EGM feedback goes.
    pub egm_peer: SocketAddr,
}

/// A running emulated facility.
pub struct FacilityHandle {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    _http: Option<NetFtApiServer>,
    addresses: FacilityAddresses,
    period: f64,
}

impl FacilityHandle {
    /// Starts the emulated facility of a scenario: binds the sockets (errors here, e.g. a
    /// port in use) and starts the real-time thread.
    pub fn start(scenario: &Scenario, options: &EmulatorOptions) -> Result<Self> {
        let plan = scenario.resolve()?;
        let o = options;
        for (key, v) in [
            ("counts_per_force", o.counts_per_force),
            ("counts_per_torque", o.counts_per_torque),
            ("egm_period", o.egm_period),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RtError::option(
                    key,
                    format!("must be a positive number, got {v}"),
                ));
            }
        }
        for (key, v) in [
            ("silence_sensor_after", o.silence_sensor_after),
            ("silence_robot_after", o.silence_robot_after),
        ] {
            if v.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
                return Err(RtError::option(
                    key,
                    format!("must be a number of seconds >= 0, got {v:?}"),
                ));
            }
        }
        let mapping = PoseMapping::new(o.egm_offset_mm, o.egm_rotation)?;
        let counts = CountsPerUnit {
            force: o.counts_per_force,
            torque: o.counts_per_torque,
        };
        let period = plan.period;

        let rdt = bind_udp(
            "sensor (RDT)",
            resolve("bind_host", &o.bind_host, o.sensor_port)?,
        )?;
        let egm_peer = resolve("egm_host", &o.egm_host, o.egm_port)?;
        let egm_bind: SocketAddr = match egm_peer.ip() {
            IpAddr::V4(ip) if ip.is_loopback() => {
                SocketAddr::from(([127, 0, 0, 1], o.egm_local_port))
            }
            IpAddr::V4(_) => SocketAddr::from(([0, 0, 0, 0], o.egm_local_port)),
            IpAddr::V6(_) => SocketAddr::from(([0u16; 8], o.egm_local_port)),
        };
        let egm = bind_udp("robot (EGM)", egm_bind)?;
        let http = if o.http_port == 0 {
            None
        } else {
            let addr = resolve("bind_host", &o.bind_host, o.http_port)?;
            Some(NetFtApiServer::start(addr, netftapi_xml(&counts, 1.0 / period)).map_err(|e| match e {
                RtError::Io(m) => RtError::Io(format!("{m} (a real sensor serves port 80; choose another with --http-port and give the runtime the same)")),
                other => other,
            })?)
        };
        let addresses = FacilityAddresses {
            sensor: rdt.local_addr().map_err(|e| RtError::Io(e.to_string()))?,
            http: http.as_ref().map(|h| h.address()),
            robot: egm.local_addr().map_err(|e| RtError::Io(e.to_string()))?,
            egm_peer,
        };

        let initial = VirtualDynamics::new(&plan).command();
        let initial = RelativeMotion {
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
            ..initial
        };
        let facility = FacilityModel::new(&plan, &initial);
        let shared = Arc::new(Shared::default());
        let period_ns = (period * 1e9).round() as u64;
        let egm_every = ((o.egm_period / period).round() as u64).max(1);
        let silence = |after: Option<f64>| after.map_or(u64::MAX, |s| (s / period).round() as u64);
        let mut state = Emulator {
            facility,
            mapping,
            counts,
            rdt,
            egm,
            egm_peer,
            shared: shared.clone(),
            period_ns,
            egm_every,
            sensor_silent_from: silence(o.silence_sensor_after),
            robot_silent_from: silence(o.silence_robot_after),
            command: initial,
            planned: mapping.to_egm(&initial).pose,
            client: None,
            remaining: None,
            rdt_sequence: 0,
            ft_sequence: 0,
            bias: ([0.0; 3], [0.0; 3]),
            last_reading: ([0.0; 3], [0.0; 3]),
            egm_seqno: 0,
            correction_seq: SequenceTracker::new(),
            decoder: CorrectionDecoder::new(),
            encoder: FeedbackEncoder::new(),
            buf: [0u8; 2048],
        };
        let thread = std::thread::Builder::new()
            .name("hil-facility".into())
            .spawn(move || {
                tighten_timer_slack();
                state.run();
                state.shared.finished.store(true, Ordering::Release);
            })
            .map_err(|e| RtError::Io(format!("emulator thread: {e}")))?;
        Ok(FacilityHandle {
            shared,
            thread: Some(thread),
            _http: http,
            addresses,
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
        FacilityStatus {
            finished: s.finished.load(Ordering::Acquire),
            tick,
            time: tick as f64 * self.period,
            contact_force: f64::from_bits(s.contact_force_bits.load(Ordering::Relaxed)),
            rdt_sent: s.rdt_sent.load(Ordering::Relaxed),
            rdt_requests: s.rdt_requests.load(Ordering::Relaxed),
            rdt_bad_requests: s.rdt_bad_requests.load(Ordering::Relaxed),
            egm_sent: s.egm_sent.load(Ordering::Relaxed),
            corrections: s.corrections.load(Ordering::Relaxed),
            corrections_dropped: s.corrections_dropped.load(Ordering::Relaxed),
            overruns: s.overruns.load(Ordering::Relaxed),
            max_latency_us: s.max_latency_ns.load(Ordering::Relaxed) as f64 / 1e3,
        }
    }

    /// Asks the emulator to stop (returns at once).
    pub fn stop(&self) {
        self.shared.stop.store(true, Ordering::Release);
    }

    /// Whether the emulator thread has ended.
    pub fn is_finished(&self) -> bool {
        self.shared.finished.load(Ordering::Acquire)
    }

    /// Stops the emulator and waits for its thread; returns the final counters.
    pub fn join(mut self) -> FacilityStatus {
        self.stop();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        self.status()
    }
}

impl Drop for FacilityHandle {
    fn drop(&mut self) {
        self.stop();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Emulator {
    facility: FacilityModel,
    mapping: PoseMapping,
    counts: CountsPerUnit,
    rdt: UdpSocket,
    egm: UdpSocket,
    egm_peer: SocketAddr,
    shared: Arc<Shared>,
    period_ns: u64,
    egm_every: u64,
    sensor_silent_from: u64,
    robot_silent_from: u64,
    /// The command the robot follows (newest correction, held).
    command: RelativeMotion,
    planned: crate::mapping::EgmPoseMm,
    /// RDT streaming destination.
    client: Option<SocketAddr>,
    /// Records left to send (None = until stopped).
    remaining: Option<u32>,
    rdt_sequence: u32,
    ft_sequence: u32,
    bias: ([f64; 3], [f64; 3]),
    last_reading: ([f64; 3], [f64; 3]),
    egm_seqno: u32,
    correction_seq: SequenceTracker,
    decoder: CorrectionDecoder,
    encoder: FeedbackEncoder,
    buf: [u8; 2048],
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
            self.step(k);
            k += 1;
            self.shared.tick.store(k, Ordering::Relaxed);
        }
    }

    fn step(&mut self, k: u64) {
        self.serve_rdt_requests();
        self.take_corrections();
        if k > 0 {
            self.facility.advance(&self.command);
        }
        let m = self.facility.measure();
        self.shared.contact_force_bits.store(
            self.facility.contact_force().norm().to_bits(),
            Ordering::Relaxed,
        );
        let reading = (m.force.into(), m.moment.into());
        self.last_reading = reading;
        self.ft_sequence = self.ft_sequence.wrapping_add(1);
        if k < self.sensor_silent_from {
            self.send_record(&reading);
        }
        if k.is_multiple_of(self.egm_every) && k < self.robot_silent_from {
            let actual = self.mapping.to_egm(&m.actual).pose;
            let time_us = k * self.period_ns / 1000;
            self.egm_seqno = self.egm_seqno.wrapping_add(1);
            let bytes = self
                .encoder
                .encode(self.egm_seqno, time_us, &actual, &self.planned);
            if self.egm.send_to(bytes, self.egm_peer).is_ok() {
                self.shared.egm_sent.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    fn send_record(&mut self, reading: &([f64; 3], [f64; 3])) {
        let Some(client) = self.client else { return };
        if self.remaining == Some(0) {
            self.client = None;
            return;
        }
        let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let (counts, saturated) = self
            .counts
            .to_counts(&sub(reading.0, self.bias.0), &sub(reading.1, self.bias.1));
        self.rdt_sequence = self.rdt_sequence.wrapping_add(1);
        let record = RdtRecord {
            rdt_sequence: self.rdt_sequence,
            ft_sequence: self.ft_sequence,
            // bit 31 (error) and bit 16 (saturation) when a gauge is out of range
            status: if saturated { 0x8001_0000 } else { 0 },
            counts,
        };
        if self.rdt.send_to(&record.encode(), client).is_ok() {
            self.shared.rdt_sent.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(n) = self.remaining.as_mut() {
            *n -= 1;
        }
    }

    fn serve_rdt_requests(&mut self) {
        while let Ok((n, from)) = self.rdt.recv_from(&mut self.buf) {
            match RdtRequest::decode(&self.buf[..n]) {
                Ok(request) => {
                    self.shared.rdt_requests.fetch_add(1, Ordering::Relaxed);
                    match request.command {
                        RdtCommand::StartRealtime | RdtCommand::StartBuffered => {
                            self.client = Some(from);
                            self.remaining =
                                (request.sample_count > 0).then_some(request.sample_count);
                        }
                        RdtCommand::Stop => {
                            self.client = None;
                            self.remaining = None;
                        }
                        RdtCommand::SetBias => {
                            let (f, m) = self.last_reading;
                            self.bias = (f, m);
                        }
                    }
                }
                Err(_) => {
                    self.shared.rdt_bad_requests.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }

    fn take_corrections(&mut self) {
        let mut newest = None;
        while let Ok((n, from)) = self.egm.recv_from(&mut self.buf) {
            if from != self.egm_peer {
                self.shared
                    .corrections_dropped
                    .fetch_add(1, Ordering::Relaxed);
                continue;
            }
            let decoded: std::result::Result<_, EgmError> = self.decoder.decode(&self.buf[..n]);
            match decoded {
                Ok(c) if self.correction_seq.check(c.seqno) != SequenceVerdict::Stale => {
                    self.shared.corrections.fetch_add(1, Ordering::Relaxed);
                    newest = Some(c);
                }
                _ => {
                    self.shared
                        .corrections_dropped
                        .fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        if let Some(c) = newest {
            self.planned = c.target.pose;
            self.command = self.mapping.motion_from_egm(&c.target);
        }
    }
}
