//! Device links: the seam between the real-time loop and the devices' protocols, on both
//! sides of the wire.
//!
//! The loop ([`crate::runtime`]) talks to one [`SensorLink`] (a force/torque sensor) and one
//! [`RobotLink`] (a robot controller's external-motion interface) and names neither device:
//! every protocol detail (ports, codecs, units, counts per unit, pose mapping, the feedback
//! period) lives in the link's implementation. The robot link also chooses the loop's
//! [`Pacing`]: the PC's monotonic clock at the scenario's period ([`Pacing::Clock`], ABB EGM),
//! or one tick per robot packet ([`Pacing::Robot`], e.g. KUKA RSI, whose 4 ms packet must be
//! answered).
//!
//! The emulated facility ([`crate::emulator`]) is the devices' side of the same protocols: a
//! [`SensorEndpoint`] serves the sensor's protocol given the physical wrench, a
//! [`RobotEndpoint`] takes the commands and sends the robot's feedback; it names no device
//! either.
//!
//! Implementations, one file per protocol with both sides: `rdt.rs` ([`rdt::RdtSensor`] and the
//! emulated [`rdt::RdtEndpoint`], ATI Net F/T, RDT over UDP), `egm.rs` ([`egm::EgmRobot`]
//! and the emulated [`egm::EgmEndpoint`], ABB EGM, protobuf over UDP), `rsi.rs`
//! ([`rsi::RsiRobot`] and the emulated [`rsi::RsiEndpoint`], KUKA RSI, XML over UDP, robot
//! paced) and `sri.rs` ([`sri::SriSensor`] and the emulated [`sri::SriEndpoint`], SRI M812x,
//! AT commands and binary frames over TCP). A new protocol is one
//! file implementing the link and the endpoint, one variant in [`SensorOptions`] /
//! [`RobotOptions`] and in [`EmulatedSensorOptions`] / [`EmulatedRobotOptions`], one arm in
//! [`open_sensor`] / [`open_robot`] and [`open_sensor_endpoint`] / [`open_robot_endpoint`], and
//! its kind in [`SENSOR_KINDS`] / [`ROBOT_KINDS`].
//!
//! Every datagram a link or an endpoint receives is counted in its [`LinkStats`], and so is
//! every socket error, on receive and on send ([`LinkStats::io_errors`]): nothing is dropped
//! uncounted. Polling, serving, sending and holding never allocate.

pub mod egm;
pub mod rdt;
pub mod rsi;
pub mod sri;

use std::io::ErrorKind;
use std::net::{IpAddr, SocketAddr, ToSocketAddrs, UdpSocket};

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use hilcontact_core::world::RelativeMotion;

use crate::clock::now_ns;
use crate::error::{Result, RtError};
use crate::feedback::FeedbackEstimator;
use crate::rdt::{SequenceTracker, SequenceVerdict};

/// Sensor protocols, as `[sensor] kind` / `--sensor-protocol` accept them, in the runtime's
/// options and the emulator's alike (the one list; a test checks both option types take
/// exactly these kinds).
pub const SENSOR_KINDS: &[&str] = &["rdt", "sri"];
/// Robot protocols, as `[robot] kind` / `--robot-protocol` accept them, in the runtime's
/// options and the emulator's alike (the one list).
pub const ROBOT_KINDS: &[&str] = &["egm", "rsi"];

/// The default options of every protocol, keyed by kind, for the runtime's links and the
/// emulator's devices: `{"runtime": {"sensor": {"rdt": {...}, "sri": {...}}, "robot": {...}},
/// "facility": {...}, "robot_paced": [KIND, ...]}` (each kind's options as `{"kind": KIND}` deserializes them: the one
/// place the defaults live).
pub fn protocol_defaults() -> serde_json::Value {
    fn each<T: Serialize + serde::de::DeserializeOwned>(
        kinds: &[&str],
    ) -> serde_json::Map<String, serde_json::Value> {
        kinds
            .iter()
            .filter_map(|kind| {
                let options: T =
                    serde_json::from_value(serde_json::json!({ "kind": kind })).ok()?;
                Some((kind.to_string(), serde_json::to_value(options).ok()?))
            })
            .collect()
    }
    let paced: Vec<&str> = ROBOT_KINDS
        .iter()
        .copied()
        .filter(|kind| {
            serde_json::from_value::<RobotOptions>(serde_json::json!({ "kind": kind }))
                .is_ok_and(|o| o.pacing() == Pacing::Robot)
        })
        .collect();
    serde_json::json!({
        "robot_paced": paced,
        "runtime": {
            "sensor": each::<SensorOptions>(SENSOR_KINDS),
            "robot": each::<RobotOptions>(ROBOT_KINDS),
        },
        "facility": {
            "sensor": each::<EmulatedSensorOptions>(SENSOR_KINDS),
            "robot": each::<EmulatedRobotOptions>(ROBOT_KINDS),
        },
    })
}

/// Packet counters of one link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct LinkStats {
    /// Datagrams (messages) received.
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
    /// Sensor: ticks without a new record. Robot: feedback more than 1.5 feedback periods
    /// after the previous.
    pub late: u64,
    /// Datagrams (requests, commands) sent.
    pub sent: u64,
    /// Sends that failed (also counted in `io_errors`).
    pub send_errors: u64,
    /// Socket errors on receive or send (e.g. ICMP port unreachable surfaced on the socket).
    pub io_errors: u64,
}

impl LinkStats {
    /// Datagrams received and dropped: malformed, invalid, foreign or stale.
    pub fn dropped(&self) -> u64 {
        self.malformed + self.invalid + self.foreign + self.stale
    }

    /// Counts the result of one send.
    pub fn count_send<T, E>(&mut self, result: std::result::Result<T, E>) {
        match result {
            Ok(_) => self.sent += 1,
            Err(_) => {
                self.send_errors += 1;
                self.io_errors += 1;
            }
        }
    }
}

/// A wrench measured by the sensor, in the sensor's frame.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wrench {
    /// Force, N.
    pub force: Vector3<f64>,
    /// Moment about the sensor's origin, N·m.
    pub moment: Vector3<f64>,
}

/// What clocks the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pacing {
    /// The PC's monotonic clock, one tick per scenario period (absolute sleeps).
    Clock,
    /// The robot's packets: the loop waits (up to the watchdog) for the robot's next packet
    /// and runs one tick per packet; the scenario's period must equal the robot's.
    Robot,
}

/// A force/torque sensor as the loop sees it.
pub trait SensorLink: Send {
    /// Short protocol name for messages, e.g. `"RDT"`.
    fn name(&self) -> &'static str;

    /// The peer for messages, e.g. `"the sensor at 127.0.0.1:49152"` (allocates: not in a tick).
    fn describe(&self) -> String;

    /// Asks the sensor to stream (called again every 200 ms while nothing arrives at start);
    /// a bias configured in the link's options is sent before the first request.
    fn start_streaming(&mut self);

    /// Asks the sensor to stop streaming.
    fn stop_streaming(&mut self);

    /// Asks the sensor to bias its output (zero it at the current load; the rod must be free).
    fn bias(&mut self);

    /// Reads everything that arrived (non-blocking, never allocates) and returns the newest
    /// valid wrench, if a new one arrived; `now_ns` is the monotonic time of the call.
    fn poll(&mut self, now_ns: u64) -> Option<Wrench>;

    /// The link's counters.
    fn stats(&self) -> &LinkStats;

    /// The link's counters, for the loop's own (`late`).
    fn stats_mut(&mut self) -> &mut LinkStats;

    /// Device-specific facts for `metrics.json`'s `realtime` section (e.g. counts per unit),
    /// merged into it at the end of a run.
    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }
}

/// A robot controller's external-motion interface as the loop sees it: feedback in, command
/// poses out, in the target frame `t` (m, SI) on the loop's side of the link.
pub trait RobotLink: Send {
    /// Short protocol name for messages, e.g. `"EGM"`.
    fn name(&self) -> &'static str;

    /// The peer for messages, e.g. `"the robot on UDP port 6510"` (allocates: not in a tick).
    fn describe(&self) -> String;

    /// What clocks the loop with this link.
    fn pacing(&self) -> Pacing;

    /// The robot's feedback period, s (EGM: 0.004).
    fn feedback_period(&self) -> f64;

    /// Reads everything that arrived (non-blocking, never allocates), pushes each valid
    /// feedback pose with the robot's time into `estimator`; returns how many were accepted.
    fn poll(&mut self, now_ns: u64, estimator: &mut FeedbackEstimator) -> usize;

    /// Waits until at least one valid feedback arrived or the monotonic time passes
    /// `deadline_ns`; returns how many were accepted (0 = timed out). The default polls every
    /// 100 µs; a robot-paced link should block on its socket ([`wait_readable`]).
    fn wait(&mut self, deadline_ns: u64, estimator: &mut FeedbackEstimator) -> usize {
        loop {
            let n = self.poll(now_ns(), estimator);
            if n > 0 || now_ns() >= deadline_ns {
                return n;
            }
            std::thread::sleep(std::time::Duration::from_micros(100));
        }
    }

    /// Sends a command (pose and velocity in `t`); `clock_ns` is the loop's time since its
    /// start, ns. Does nothing before the robot is known (no feedback yet). Errors are counted.
    fn send(&mut self, command: &RelativeMotion, clock_ns: u64);

    /// Commands the robot to hold `pose` (at rest: zero velocity). By default a [`send`] with
    /// the velocity zeroed.
    ///
    /// [`send`]: RobotLink::send
    fn hold(&mut self, pose: &RelativeMotion, clock_ns: u64) {
        let at_rest = RelativeMotion {
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
            ..*pose
        };
        self.send(&at_rest, clock_ns);
    }

    /// The robot's address, once known.
    fn peer(&self) -> Option<SocketAddr>;

    /// The link's counters.
    fn stats(&self) -> &LinkStats;

    /// The link's counters, for the loop's own (`late`).
    fn stats_mut(&mut self) -> &mut LinkStats;

    /// Device-specific facts for `metrics.json`'s `realtime` section (e.g. RSI's answer
    /// latency), merged into it at the end of a run.
    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }
}

/// Options of the sensor link, one variant per protocol (`kind`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum SensorOptions {
    /// ATI Net F/T over RDT.
    Rdt(rdt::RdtOptions),
    /// SRI M812x interface box over TCP.
    Sri(sri::SriOptions),
}

impl Default for SensorOptions {
    fn default() -> Self {
        SensorOptions::Rdt(rdt::RdtOptions::default())
    }
}

/// Options of the robot link, one variant per protocol (`kind`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum RobotOptions {
    /// ABB Externally Guided Motion.
    Egm(egm::EgmOptions),
    /// KUKA RobotSensorInterface over Ethernet.
    Rsi(rsi::RsiOptions),
}

impl Default for RobotOptions {
    fn default() -> Self {
        RobotOptions::Egm(egm::EgmOptions::default())
    }
}

impl RobotOptions {
    /// What clocks the loop with this robot, known before it is opened (the opened link's
    /// [`RobotLink::pacing`] says the same; with [`Pacing::Robot`] the scenario's period
    /// must equal the robot's cycle).
    pub fn pacing(&self) -> Pacing {
        match self {
            RobotOptions::Egm(_) => Pacing::Clock,
            RobotOptions::Rsi(_) => Pacing::Robot,
        }
    }
}

/// What a link needs to know of the run when it is opened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkContext {
    /// The scenario's control period, s.
    pub period: f64,
    /// Longest wait for the peers at start, s (also bounds the HTTP read of the counts).
    pub connect_timeout: f64,
    /// Where the robot must be at start: a robot link that is not told its robot's address
    /// locks onto the first sender whose feedback lies in it (None: the first sender).
    pub start: Option<StartRegion>,
}

/// The scenario's start as a robot link sees it: a sender whose fed-back rod tip is within
/// `tolerance` of the initial rod tip is the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartRegion {
    /// The scenario's initial relative pose (m, rad, `t` frame).
    pub pose: RelativeMotion,
    /// The rod tip in the servicer's body frame, m.
    pub rod: Vector3<f64>,
    /// Largest distance of the fed-back rod tip from the initial one, m (the runtime's
    /// `start_tolerance`).
    pub tolerance: f64,
}

impl StartRegion {
    /// Distance of `pose`'s rod tip from the initial rod tip, m.
    pub fn distance(&self, pose: &RelativeMotion) -> f64 {
        (pose.point(&self.rod) - self.pose.point(&self.rod)).norm()
    }
}

/// Which sender is the robot, for a robot link: the host `robot_host` names, else the first
/// sender whose valid feedback puts the rod tip in the start region ([`LinkContext::start`]);
/// identified, not raced for: a foreign sender that started earlier, elsewhere, is counted
/// `foreign` and never locked onto. Once locked, only that address is the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotIdentity {
    robot_ip: Option<IpAddr>,
    robot_addr: Option<SocketAddr>,
    start: Option<StartRegion>,
    /// The nearest sender whose feedback was outside the start region, and its distance, m.
    nearest_outside: Option<(SocketAddr, f64)>,
}

impl RobotIdentity {
    /// The robot `robot_host` names (resolved; an error names the option), or the one at
    /// `start`.
    pub fn new(robot_host: Option<&str>, start: Option<StartRegion>) -> Result<Self> {
        let robot_ip = match robot_host {
            Some(h) => Some(resolve("robot_host", h, 0)?.ip()),
            None => None,
        };
        Ok(RobotIdentity {
            robot_ip,
            robot_addr: None,
            start,
            nearest_outside: None,
        })
    }

    /// Whether a datagram from `from` may be the robot's (checked before decoding); else it is
    /// counted `foreign`.
    pub fn admits(&self, from: SocketAddr, stats: &mut LinkStats) -> bool {
        let ok = match (self.robot_ip, self.robot_addr) {
            (_, Some(addr)) => from == addr,
            (Some(ip), None) => from.ip() == ip,
            (None, None) => true,
        };
        if !ok {
            stats.foreign += 1;
        }
        ok
    }

    /// After decoding a valid pose (`t` frame, m): whether its sender can be the robot. Before
    /// the lock and without `robot_host`, a sender whose rod tip is outside the start region is
    /// counted `foreign` (and remembered for [`RobotIdentity::describe`]).
    pub fn at_start(
        &mut self,
        from: SocketAddr,
        position: Vector3<f64>,
        orientation: UnitQuaternion<f64>,
        stats: &mut LinkStats,
    ) -> bool {
        let (None, None, Some(start)) = (self.robot_ip, self.robot_addr, self.start) else {
            return true;
        };
        let distance = start.distance(&RelativeMotion {
            position,
            orientation,
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        });
        let at_start = distance <= start.tolerance; // false for NaN
        if !at_start {
            stats.foreign += 1;
            if self.nearest_outside.is_none_or(|(_, d)| distance < d) {
                self.nearest_outside = Some((from, distance));
            }
        }
        at_start
    }

    /// Locks onto `from` (the first accepted feedback's sender), if not locked yet.
    pub fn lock(&mut self, from: SocketAddr) {
        self.robot_addr.get_or_insert(from);
    }

    /// The robot's address, once locked.
    pub fn address(&self) -> Option<SocketAddr> {
        self.robot_addr
    }

    /// For a connect error: `what` (e.g. "EGM feedback") came only from senders away from the
    /// start — the nearest one and how far, and what to do; empty otherwise.
    pub fn describe(&self, what: &str) -> String {
        match (self.nearest_outside, self.start) {
            (Some((addr, distance)), Some(start)) => format!(
                " ({what} came from {addr}, but {:.1} mm from the scenario's start, beyond start_tolerance {:.1} mm: move the robot there, or name it with --robot)",
                distance * 1e3,
                start.tolerance * 1e3
            ),
            _ => String::new(),
        }
    }
}

/// The sensor link's options once parsed ([`SensorOptions::parse`]), one variant per protocol:
/// what [`open_sensor`] opens, checked once.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorConfig {
    /// ATI Net F/T over RDT.
    Rdt(rdt::RdtConfig),
    /// SRI M812x interface box over TCP.
    Sri(sri::SriConfig),
}

impl SensorOptions {
    /// Checks the options that need no socket (the host's form, the protocol's own values) and
    /// types them, once, so that bad input is refused before any file or socket is created.
    pub fn parse(&self) -> Result<SensorConfig> {
        Ok(match self {
            SensorOptions::Rdt(o) => SensorConfig::Rdt(o.parse()?),
            SensorOptions::Sri(o) => SensorConfig::Sri(o.parse()?),
        })
    }
}

impl SensorConfig {
    /// The checks across the options and the scenario's control period `period` (s), e.g. a
    /// sample rate taken from it; done once, before anything is opened.
    pub fn check_period(&self, period: f64) -> Result<()> {
        match self {
            SensorConfig::Rdt(_) => Ok(()),
            SensorConfig::Sri(c) => c.sample_rate(period).map(|_| ()),
        }
    }
}

/// The robot link's options once parsed ([`RobotOptions::parse`]), one variant per protocol:
/// what [`open_robot`] opens, checked once.
#[derive(Debug, Clone, PartialEq)]
pub enum RobotConfig {
    /// ABB Externally Guided Motion.
    Egm(egm::EgmConfig),
    /// KUKA RobotSensorInterface over Ethernet.
    Rsi(rsi::RsiConfig),
}

impl RobotOptions {
    /// Checks the options that need no socket (hosts, pose mapping, the protocol's own
    /// values) and types them, once, so that bad input is refused before any file or socket is
    /// created.
    pub fn parse(&self) -> Result<RobotConfig> {
        Ok(match self {
            RobotOptions::Egm(o) => RobotConfig::Egm(o.parse()?),
            RobotOptions::Rsi(o) => RobotConfig::Rsi(o.parse()?),
        })
    }
}

/// The form of a host option, checked without a lookup: an IP address or a host name (at most
/// 253 characters without spaces or control characters; one of digits and dots only must be
/// an IPv4 address, so `999.1.1.1` is refused). `key` names the option for the message.
pub(crate) fn check_host(key: &str, host: &str) -> Result<()> {
    let numeric = host.chars().all(|c| c.is_ascii_digit() || c == '.');
    let bad = host.is_empty()
        || host.len() > 253
        || host.chars().any(|c| c.is_whitespace() || c.is_control())
        || (numeric && host.parse::<std::net::Ipv4Addr>().is_err());
    if bad {
        return Err(RtError::option(
            key,
            format!("{host:?} is not an IP address (IPv4: four numbers 0-255) or a host name"),
        ));
    }
    Ok(())
}

/// Opens the sensor link of `config` (binds, reads what it needs before the loop starts).
pub fn open_sensor(config: &SensorConfig, context: &LinkContext) -> Result<Box<dyn SensorLink>> {
    Ok(match config {
        SensorConfig::Rdt(c) => Box::new(rdt::RdtSensor::open_parsed(c, context)?),
        SensorConfig::Sri(c) => Box::new(sri::SriSensor::open_parsed(c, context)?),
    })
}

/// Opens the robot link of `config` (binds its endpoint).
pub fn open_robot(config: &RobotConfig, context: &LinkContext) -> Result<Box<dyn RobotLink>> {
    Ok(match config {
        RobotConfig::Egm(c) => Box::new(egm::EgmRobot::open_parsed(c, context)?),
        RobotConfig::Rsi(c) => Box::new(rsi::RsiRobot::open_parsed(c, context)?),
    })
}

/// An emulated force/torque sensor: the device's side of a sensor protocol. The emulator
/// calls [`serve`](SensorEndpoint::serve) then [`sample`](SensorEndpoint::sample) once per
/// control period, on its real-time thread.
pub trait SensorEndpoint: Send {
    /// Short protocol name for messages and the status, e.g. `"RDT"`.
    fn name(&self) -> &'static str;

    /// The local address the sensor serves its protocol on.
    fn address(&self) -> SocketAddr;

    /// The address of the sensor's HTTP configuration server, if it has one (Net F/T:
    /// `/netftapi2.xml`).
    fn http_address(&self) -> Option<SocketAddr> {
        None
    }

    /// Reads and answers the requests that arrived (non-blocking, never allocates); every
    /// datagram and socket error is counted in [`stats`](SensorEndpoint::stats).
    fn serve(&mut self);

    /// Takes one sample of the physical wrench (sensor frame: force N, moment N·m about the
    /// sensor's origin) and sends it to the streaming client, if any; `send = false` takes the
    /// sample without sending it (fault injection: a silent sensor). Never allocates.
    fn sample(&mut self, wrench: &Wrench, send: bool);

    /// The endpoint's counters (`sent`: samples sent; `accepted`: valid requests).
    fn stats(&self) -> &LinkStats;
}

/// An emulated robot controller: the device's side of a robot protocol. The emulator calls
/// [`receive`](RobotEndpoint::receive) before and [`feedback`](RobotEndpoint::feedback) after
/// each control period's physics step, on its real-time thread.
pub trait RobotEndpoint: Send {
    /// Short protocol name for messages and the status, e.g. `"EGM"`.
    fn name(&self) -> &'static str;

    /// The robot's own local address.
    fn address(&self) -> SocketAddr;

    /// Where the robot's feedback goes (the PC running the loop).
    fn peer(&self) -> SocketAddr;

    /// Reads the commands that arrived (non-blocking, never allocates) and returns the newest
    /// valid one as the pose and velocity to follow, in the target frame `t` (m, m/s, rad/s),
    /// or None if none arrived; every datagram and socket error is counted.
    fn receive(&mut self) -> Option<RelativeMotion>;

    /// Called after control period `k` (time `k·T` since the start): sends the robot's
    /// feedback of its `actual` motion (`t` frame, m) when the protocol's own period is due;
    /// `send = false` sends nothing (fault injection: a silent robot). Never allocates.
    fn feedback(&mut self, k: u64, actual: &RelativeMotion, send: bool);

    /// The endpoint's counters (`sent`: feedback messages; `accepted`: commands taken).
    fn stats(&self) -> &LinkStats;
}

/// Options of the emulated sensor, one variant per protocol (`kind`, the same kinds as
/// [`SensorOptions`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum EmulatedSensorOptions {
    /// ATI Net F/T over RDT, with `/netftapi2.xml` over HTTP.
    Rdt(rdt::RdtEndpointOptions),
    /// SRI M812x interface box over TCP.
    Sri(sri::SriEndpointOptions),
}

impl Default for EmulatedSensorOptions {
    fn default() -> Self {
        EmulatedSensorOptions::Rdt(rdt::RdtEndpointOptions::default())
    }
}

/// Options of the emulated robot, one variant per protocol (`kind`, the same kinds as
/// [`RobotOptions`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum EmulatedRobotOptions {
    /// ABB Externally Guided Motion.
    Egm(egm::EgmEndpointOptions),
    /// KUKA RobotSensorInterface over Ethernet.
    Rsi(rsi::RsiEndpointOptions),
}

impl Default for EmulatedRobotOptions {
    fn default() -> Self {
        EmulatedRobotOptions::Egm(egm::EgmEndpointOptions::default())
    }
}

/// What an emulated device needs to know of the run when it is opened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EndpointContext {
    /// The emulator's control period (the scenario's), s.
    pub period: f64,
    /// The robot's initial pose (at rest), target frame `t` (m): the first command the robot
    /// holds and reports as planned.
    pub initial: RelativeMotion,
}

/// The emulated sensor's options once parsed ([`EmulatedSensorOptions::parse`]), one variant
/// per protocol: what [`open_sensor_endpoint`] opens, checked once.
#[derive(Debug, Clone, PartialEq)]
pub enum EmulatedSensorConfig {
    /// ATI Net F/T over RDT, with `/netftapi2.xml` over HTTP.
    Rdt(rdt::RdtEndpointConfig),
    /// SRI M812x interface box over TCP.
    Sri(sri::SriEndpointOptions),
}

impl EmulatedSensorOptions {
    /// Checks and types the options (counts, units), once, before anything is opened.
    pub fn parse(&self) -> Result<EmulatedSensorConfig> {
        Ok(match self {
            EmulatedSensorOptions::Rdt(o) => EmulatedSensorConfig::Rdt(o.parse()?),
            EmulatedSensorOptions::Sri(o) => EmulatedSensorConfig::Sri(o.clone()),
        })
    }
}

/// The emulated robot's options once parsed ([`EmulatedRobotOptions::parse`]), one variant
/// per protocol: what [`open_robot_endpoint`] opens, checked once.
#[derive(Debug, Clone, PartialEq)]
pub enum EmulatedRobotConfig {
    /// ABB Externally Guided Motion.
    Egm(egm::EgmEndpointConfig),
    /// KUKA RobotSensorInterface over Ethernet.
    Rsi(rsi::RsiEndpointConfig),
}

impl EmulatedRobotOptions {
    /// Checks and types the options (period, names, pose mapping), once, before anything is
    /// opened.
    pub fn parse(&self) -> Result<EmulatedRobotConfig> {
        Ok(match self {
            EmulatedRobotOptions::Egm(o) => EmulatedRobotConfig::Egm(o.parse()?),
            EmulatedRobotOptions::Rsi(o) => EmulatedRobotConfig::Rsi(o.parse()?),
        })
    }
}

/// Opens the emulated sensor of `config` (binds its sockets and servers).
pub fn open_sensor_endpoint(
    config: &EmulatedSensorConfig,
    context: &EndpointContext,
) -> Result<Box<dyn SensorEndpoint>> {
    Ok(match config {
        EmulatedSensorConfig::Rdt(c) => Box::new(rdt::RdtEndpoint::open_parsed(c, context)?),
        EmulatedSensorConfig::Sri(o) => Box::new(sri::SriEndpoint::open(o, context)?),
    })
}

/// Opens the emulated robot of `config` (binds its socket, resolves where feedback goes).
pub fn open_robot_endpoint(
    config: &EmulatedRobotConfig,
    context: &EndpointContext,
) -> Result<Box<dyn RobotEndpoint>> {
    Ok(match config {
        EmulatedRobotConfig::Egm(c) => Box::new(egm::EgmEndpoint::open_parsed(c, context)?),
        EmulatedRobotConfig::Rsi(c) => Box::new(rsi::RsiEndpoint::open_parsed(c, context)?),
    })
}

/// Resolves `host:port` to one socket address; `key` names the option for the message.
pub(crate) fn resolve(key: &str, host: &str, port: u16) -> Result<SocketAddr> {
    (host, port)
        .to_socket_addrs()
        .map_err(|e| RtError::option(key, format!("cannot resolve {host:?}: {e}")))?
        .next()
        .ok_or_else(|| RtError::option(key, format!("{host:?} has no address")))
}

/// Binds a non-blocking UDP socket; `what` names it for the message (an error keeps its
/// kind and errno, e.g. `EADDRINUSE`).
pub(crate) fn bind_udp(what: &str, addr: SocketAddr) -> Result<UdpSocket> {
    let socket = UdpSocket::bind(addr)
        .map_err(|e| RtError::io(format!("{what}: cannot bind UDP {addr}"), &e))?;
    socket
        .set_nonblocking(true)
        .map_err(|e| RtError::io(what, &e))?;
    Ok(socket)
}

/// The local address of a bound socket; `what` names it for the message.
pub(crate) fn local_addr(what: &str, socket: &UdpSocket) -> Result<SocketAddr> {
    socket.local_addr().map_err(|e| RtError::io(what, &e))
}

/// Checks a packet's sequence number against `tracker`: a stale packet (a duplicate or
/// reordered one) is counted and to be dropped (false); a gap counts the packets it says
/// were lost. The one sequence rule of every link and endpoint.
pub fn sequence_counted(tracker: &mut SequenceTracker, seq: u32, stats: &mut LinkStats) -> bool {
    match tracker.check(seq) {
        SequenceVerdict::Stale => {
            stats.stale += 1;
            false
        }
        SequenceVerdict::Gap(n) => {
            stats.lost += n as u64;
            true
        }
        SequenceVerdict::First | SequenceVerdict::Next => true,
    }
}

/// Receives one datagram from a non-blocking socket: `Some((len, from))`, or None when
/// nothing is waiting. A socket error is counted in `stats.io_errors` and the read goes on
/// (at most 64 errors per call, so a persistently failing socket cannot spin the tick).
pub fn recv_counted(
    socket: &UdpSocket,
    buf: &mut [u8],
    stats: &mut LinkStats,
) -> Option<(usize, SocketAddr)> {
    for _ in 0..64 {
        match socket.recv_from(buf) {
            Ok(x) => return Some(x),
            Err(e) if e.kind() == ErrorKind::WouldBlock => return None,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(_) => stats.io_errors += 1, // e.g. ICMP port unreachable surfaced on the socket
        }
    }
    None
}

/// Blocks until `socket` is readable or the monotonic time passes `deadline_ns` (`poll(2)`,
/// no allocation); returns whether it is readable. For robot-paced links.
pub fn wait_readable(socket: &UdpSocket, deadline_ns: u64) -> bool {
    #[cfg(unix)]
    {
        use std::os::fd::AsRawFd;
        loop {
            let now = now_ns();
            if now >= deadline_ns {
                return false;
            }
            let timeout_ms = (deadline_ns - now).div_ceil(1_000_000).min(i32::MAX as u64) as i32;
            let mut fd = libc::pollfd {
                fd: socket.as_raw_fd(),
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: one valid pollfd for the duration of the call.
            let r = unsafe { libc::poll(&mut fd, 1, timeout_ms) };
            if r > 0 {
                return true;
            }
            if r < 0 && std::io::Error::last_os_error().kind() != ErrorKind::Interrupted {
                return false;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = socket;
        while now_ns() < deadline_ns {
            std::thread::sleep(std::time::Duration::from_micros(100));
        }
        true
    }
}
