//! The generic side of the devices: what the loop and the emulator see of a device (the
//! [`SensorLink`] and [`RobotLink`] traits of the PC's side, the [`SensorEndpoint`] and
//! [`RobotEndpoint`] traits of the emulated device's side, their [`LinkStats`], the
//! [`Wrench`], the loop's [`Pacing`]), what they are opened with ([`LinkContext`],
//! [`EndpointContext`]), which sender is the robot ([`RobotIdentity`]), and what a protocol
//! implements to be registered ([`SensorDevice`], [`RobotDevice`], [`EmulatedSensor`],
//! [`EmulatedRobot`]). Nothing here names a
//! device.

use std::net::{IpAddr, SocketAddr};

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use hilcontact_core::world::RelativeMotion;

use super::transport::{resolve, sequence_counted, SequenceNumber, SequenceTracker};
use crate::clock::now_ns;
use crate::error::Result;
use crate::feedback::FeedbackEstimator;

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

/// How a link or an endpoint reaches the other side: the loop and the emulator name no
/// transport, a link chooses it (and whether it connects or listens) in its `open`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Transport {
    /// UDP datagrams (RDT, EGM, RSI): the device sends first, or answers the PC's requests.
    Udp,
    /// A TCP connection the PC opens to the device (the SRI box; e.g. Universal Robots RTDE,
    /// port 30004).
    TcpClient,
    /// A TCP server on this side, the other side connects (the emulated SRI box).
    TcpServer,
}

/// [`SensorLink::stats`] and [`SensorLink::stats_mut`] (or [`RobotLink`]'s) of a link whose
/// counters are its `stats` field: `stats_accessors!();` in the trait's `impl`.
macro_rules! stats_accessors {
    () => {
        fn stats(&self) -> &LinkStats {
            &self.stats
        }

        fn stats_mut(&mut self) -> &mut LinkStats {
            &mut self.stats
        }
    };
}
pub(crate) use stats_accessors;

/// A force/torque sensor as the loop sees it.
pub trait SensorLink: Send {
    /// Short protocol name for messages, e.g. `"RDT"`.
    fn name(&self) -> &'static str;

    /// The peer for messages, e.g. `"the sensor at 127.0.0.1:49152"` (allocates: not in a tick).
    fn describe(&self) -> String;

    /// How the link reaches the sensor (UDP by default).
    fn transport(&self) -> Transport {
        Transport::Udp
    }

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

    /// A fault the link saw and named, which stops the run (e.g. the sensor reset its TCP
    /// connection, too many checksum errors); None while there is none. Never allocates.
    fn fault(&self) -> Option<LinkFault> {
        None
    }
}

/// A robot controller's external-motion interface as the loop sees it: feedback in, command
/// poses out, in the target frame `t` (m, SI) on the loop's side of the link.
pub trait RobotLink: Send {
    /// Short protocol name for messages, e.g. `"EGM"`.
    fn name(&self) -> &'static str;

    /// The peer for messages, e.g. `"the robot on UDP port 6510"` (allocates: not in a tick).
    fn describe(&self) -> String;

    /// How the link reaches the robot (UDP by default): a link that connects out (TCP, the PC
    /// as client, e.g. Universal Robots RTDE) connects in its `open` and says
    /// [`Transport::TcpClient`]; the loop does not change.
    fn transport(&self) -> Transport {
        Transport::Udp
    }

    /// What clocks the loop with this link.
    fn pacing(&self) -> Pacing;

    /// The robot's feedback period, s (EGM: 0.004).
    fn feedback_period(&self) -> f64;

    /// Reads everything that arrived (non-blocking, never allocates), pushes each valid
    /// feedback pose with the robot's time into `estimator`; returns how many were accepted.
    fn poll(&mut self, now_ns: u64, estimator: &mut FeedbackEstimator) -> usize;

    /// Waits until at least one valid feedback arrived or the monotonic time passes
    /// `deadline_ns`; returns how many were accepted (0 = timed out). The default polls every
    /// 100 µs; a robot-paced link should block on its socket ([`wait_readable`](super::wait_readable)).
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

    /// The robot's address, once known: the sender locked onto (a robot that sends first, over
    /// UDP), or the address connected to (a link that connects out in its `open`, known from
    /// the start). None before that.
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

    /// A fault the link saw and named, which stops the run (e.g. too many late answers, the
    /// robot's sequence going backwards); None while there is none. Never allocates.
    fn fault(&self) -> Option<LinkFault> {
        None
    }

    /// Ends the robot's session after the run's last hold, holding `pose` (`t`), the way the
    /// robot's program expects (KUKA RSI: answers with the end signal until the controller
    /// stops sending); returns whether the session ended cleanly (None: the protocol has no
    /// end of session). Not real-time.
    fn end_session(&mut self, _pose: &RelativeMotion) -> Option<bool> {
        None
    }
}

/// A fault a link saw, named by the stop it causes: its kind, the offending value and its
/// limit (units as in [`hilcontact_core::stop::Stop`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkFault {
    /// The stop it causes (e.g. `LateAnswers`, `SensorConnection`).
    pub kind: hilcontact_core::stop::StopKind,
    /// The offending value (a count, a drop of the sequence), NaN when there is none.
    pub value: f64,
    /// Its limit, NaN when there is none.
    pub limit: f64,
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

/// One decoded robot feedback as [`RobotIdentity::accept`] takes it: the sender, the
/// protocol's sequence number, the robot's time and the fed-back pose in `t`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedbackPose<T> {
    /// The datagram's sender.
    pub from: SocketAddr,
    /// The protocol's sequence number (EGM `seqno`, RSI IPOC).
    pub seq: T,
    /// The robot's time of the pose, s.
    pub robot_time: f64,
    /// Fed-back position in `t`, m.
    pub position: Vector3<f64>,
    /// Fed-back orientation in `t`.
    pub orientation: UnitQuaternion<f64>,
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

    /// Whether a datagram from `from` may be the robot's (checked before decoding); else the
    /// receive loop counts it `foreign`.
    pub fn admits(&self, from: SocketAddr) -> bool {
        match (self.robot_ip, self.robot_addr) {
            (_, Some(addr)) => from == addr,
            (Some(ip), None) => from.ip() == ip,
            (None, None) => true,
        }
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

    /// The one acceptance rule of a decoded robot feedback `f`: before the lock its sender at
    /// the scenario's start ([`RobotIdentity::at_start`]), newer than the last accepted one
    /// (`sequence`: stale and lost counted), then its sender locked onto, and a motion the
    /// robot can make (`estimator`, which takes it; else `invalid`). Counts `accepted`;
    /// returns whether it was. Never allocates.
    pub fn accept<T: SequenceNumber>(
        &mut self,
        f: &FeedbackPose<T>,
        sequence: &mut SequenceTracker<T>,
        now_ns: u64,
        estimator: &mut FeedbackEstimator,
        stats: &mut LinkStats,
    ) -> bool {
        if !self.at_start(f.from, f.position, f.orientation, stats) {
            return false; // not locked yet: the robot is the sender at the scenario's start
        }
        if !sequence_counted(sequence, f.seq, stats) {
            return false;
        }
        self.lock(f.from);
        if !estimator.push(f.robot_time, now_ns, f.position, f.orientation) {
            stats.invalid += 1; // a jump no robot makes in one cycle
            return false;
        }
        stats.accepted += 1;
        true
    }

    /// Locks onto `from` (the first accepted feedback's sender), if not locked yet.
    pub fn lock(&mut self, from: SocketAddr) {
        self.robot_addr.get_or_insert(from);
    }

    /// The robot's address, once locked.
    pub fn address(&self) -> Option<SocketAddr> {
        self.robot_addr
    }

    /// [`RobotLink::describe`] of a robot that sends `what` (e.g. "EGM feedback") to UDP
    /// `port`: `"the robot on UDP port 6510"`, then [`RobotIdentity::describe`].
    pub fn describe_udp(&self, port: u16, what: &str) -> String {
        format!("the robot on UDP port {port}{}", self.describe(what))
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

/// An emulated force/torque sensor: the device's side of a sensor protocol. The emulator
/// calls [`serve`](SensorEndpoint::serve) then [`sample`](SensorEndpoint::sample) once per
/// control period, on its real-time thread.
pub trait SensorEndpoint: Send {
    /// Short protocol name for messages and the status, e.g. `"RDT"`.
    fn name(&self) -> &'static str;

    /// The local address the sensor serves its protocol on.
    fn address(&self) -> SocketAddr;

    /// How the emulated sensor serves (UDP by default).
    fn transport(&self) -> Transport {
        Transport::Udp
    }

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

    /// Where the robot's feedback goes (the PC running the loop): the configured address
    /// (UDP), or the connected client's (a TCP server; None until one connects).
    fn peer(&self) -> Option<SocketAddr>;

    /// How the emulated robot reaches the PC (UDP by default).
    fn transport(&self) -> Transport {
        Transport::Udp
    }

    /// Reads the commands that arrived (non-blocking, never allocates) and returns the newest
    /// valid one as the pose and velocity to follow, in the target frame `t` (m, m/s, rad/s),
    /// or None if none arrived; every datagram and socket error is counted.
    fn receive(&mut self) -> Option<RelativeMotion>;

    /// Called after control period `k` (time `k·T` since the start): sends the robot's
    /// feedback of its `actual` motion (`t` frame, m) when the protocol's own period is due;
    /// `send = false` sends nothing (fault injection: a silent robot). Never allocates.
    fn feedback(&mut self, k: u64, actual: &RelativeMotion, send: bool);

    /// How the robot's session ended, as the controller sees it: Some(true) once the PC
    /// ended it with the protocol's end signal (KUKA RSI: `<Stop>1</Stop>`), Some(false) once
    /// the controller stopped it with an error (too many late answers), None while it runs or
    /// when the protocol has no session.
    fn session_ended_cleanly(&self) -> Option<bool> {
        None
    }

    /// The endpoint's counters (`sent`: feedback messages; `accepted`: commands taken).
    fn stats(&self) -> &LinkStats;
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

/// A sensor link that the registry ([`crate::devices`]) opens: its options (`[sensor]` of
/// the runtime's options, without `kind`), parsed once into what opens it.
pub trait SensorDevice: SensorLink + Sized + 'static {
    /// How the link reaches the sensor, known before it is opened (the opened link's
    /// [`SensorLink::transport`] says the same); UDP by default.
    const TRANSPORT: Transport = Transport::Udp;
    /// The link's options.
    type Options;
    /// The link's options once parsed: what opens the link.
    type Config;

    /// Checks and types the options, once, before anything is opened.
    fn parse(options: &Self::Options) -> Result<Self::Config>;

    /// The checks across the options and the scenario's control period `period` (s), done once
    /// before anything is opened; none by default.
    fn check_period(_config: &Self::Config, _period: f64) -> Result<()> {
        Ok(())
    }

    /// Opens the link (binds or connects, reads what it needs before the loop starts); checks
    /// nothing again.
    fn open_parsed(config: &Self::Config, context: &LinkContext) -> Result<Self>;
}

/// A robot link that the registry ([`crate::devices`]) opens: its options (`[robot]` of the
/// runtime's options, without `kind`), parsed once into what opens it, and what clocks the
/// loop with it.
pub trait RobotDevice: RobotLink + Sized + 'static {
    /// What clocks the loop with this robot, known before it is opened (the opened link's
    /// [`RobotLink::pacing`] says the same).
    const PACING: Pacing;
    /// How the link reaches the robot, known before it is opened (the opened link's
    /// [`RobotLink::transport`] says the same); UDP by default.
    const TRANSPORT: Transport = Transport::Udp;
    /// The link's options.
    type Options;
    /// The link's options once parsed: what opens the link.
    type Config;

    /// Checks and types the options, once, before anything is opened.
    fn parse(options: &Self::Options) -> Result<Self::Config>;

    /// Opens the link (binds its socket, or connects to the robot); checks nothing again.
    fn open_parsed(config: &Self::Config, context: &LinkContext) -> Result<Self>;
}

/// An emulated sensor that the registry ([`crate::devices`]) opens: its options (`[sensor]`
/// of the emulator's options, without `kind`), parsed once into what opens it.
pub trait EmulatedSensor: SensorEndpoint + Sized + 'static {
    /// The emulated sensor's options.
    type Options;
    /// The options once parsed: what opens the endpoint.
    type Config;

    /// Checks and types the options, once, before anything is opened.
    fn parse(options: &Self::Options) -> Result<Self::Config>;

    /// Opens the emulated sensor (binds its sockets and servers).
    fn open_parsed(config: &Self::Config, context: &EndpointContext) -> Result<Self>;
}

/// An emulated robot that the registry ([`crate::devices`]) opens: its options (`[robot]` of
/// the emulator's options, without `kind`), parsed once into what opens it.
pub trait EmulatedRobot: RobotEndpoint + Sized + 'static {
    /// The emulated robot's options.
    type Options;
    /// The options once parsed: what opens the endpoint.
    type Config;

    /// Checks and types the options, once, before anything is opened.
    fn parse(options: &Self::Options) -> Result<Self::Config>;

    /// Opens the emulated robot (binds its socket, resolves where feedback goes, or listens).
    fn open_parsed(config: &Self::Config, context: &EndpointContext) -> Result<Self>;
}
