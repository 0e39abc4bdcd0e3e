//! KUKA RobotSensorInterface (RSI) over Ethernet, both sides: [`RsiRobot`] is the
//! [`RobotLink`] of the loop (the controller's XML state in, the PC's XML correction out, codec
//! in [`self::codec`]), [`RsiEndpoint`] the emulated controller's [`RobotEndpoint`].
//!
//! The controller sends its state every interpolation cycle (IPO_FAST 4 ms, or 12 ms: the
//! `period` option) to the PC's port and stops, as a real one does, when too many answers are
//! late. So the robot paces the loop ([`Pacing::Robot`]): one tick per state message, and
//! each message is answered once, echoing its `IPOC`, to the address it came from. The answer
//! latency (message read → answer sent) of every cycle goes into a histogram; answers later
//! than `deadline` are counted (`answers_late`), and so are messages superseded before they
//! were answered (`unanswered`); both, with the latency's p50/p99/max, are in the link's report
//! (`metrics.json`: `realtime.rsi`).
//!
//! Poses: `RIst` (the actual pose; the state element's name is an option) is the tool's pose
//! in the frame the corrections are made in (the RSI correction's reference frame, e.g. the
//! base; call it `e`), mm and KUKA's A, B, C (degrees, ZYX). `t` maps into `e` through
//! [`PoseMapping`] (origin offset, rotation), as for EGM. Corrections are Cartesian
//! ([`CorrectionMode`]):
//! - `absolute` (default): the target relative to the reference pose, i.e. the robot's
//!   setpoint (`RSol`, else `RIst`) in the first accepted message: the pose where the RSI
//!   motion started, whose correction is zero. `RKorr X/Y/Z = p_target − p_ref` (mm) and
//!   `A/B/C = ZYX angles of R_target · R_ref⁻¹` (the rotation about `e`'s axes);
//! - `relative`: the increment since the previous answer, same formulas with the previous
//!   answer's target as the reference (the controller sums them; a lost answer loses its
//!   increment, so `absolute` is the robust choice).
//!
//! A state message is accepted when it comes from the robot, decodes, has finite in-range
//! values and an `IPOC` newer than the last accepted one (older: `stale`; IPOC gaps of more
//! than one cycle count as `lost`, with the IPOC taken as milliseconds). The robot is
//! `robot_host` if given; else it is identified, not raced for, as with EGM: the first sender
//! whose valid state puts the rod tip within the start region ([`LinkContext::start`]).

pub mod codec;

use std::net::SocketAddr;

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use hilcontact_core::world::RelativeMotion;

use self::codec::{
    abc_to_quaternion, decode_answer, decode_state, quaternion_to_abc, AnswerEncoder, KukaPose,
    RsiNames, StateEncoder, RSI_MAX_DATAGRAM, RSI_PERIOD, RSI_PERIODS, RSI_PORT,
};
use super::transport::{bind_address_for, decode_counted, Ipoc, SequenceTracker, UdpInbox};
use super::{
    check_host, local_addr, resolve, wait_readable, EmulatedRobot, EndpointContext, FeedbackPose,
    LinkContext, LinkFault, LinkStats, Pacing, RobotDevice, RobotEndpoint, RobotIdentity,
    RobotLink,
};
use crate::clock::{now_ns, Histogram};
use crate::devices::pose::{PoseMapping, PoseMm};
use crate::error::{Result, RtError};
use crate::feedback::FeedbackEstimator;
use hilcontact_core::stop::StopKind;

/// How the answer's correction (`RKorr`) relates to the target pose (the controller's RSI
/// correction object must be configured the same way).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum CorrectionMode {
    /// The target relative to the pose where the RSI motion started (the setpoint in the
    /// first message).
    #[default]
    Absolute,
    /// The increment since the previous answer.
    Relative,
}

/// Options of a KUKA RSI robot link (`[robot] kind = "rsi"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RsiOptions {
    /// Address the PC's RSI socket binds to.
    pub bind_host: String,
    /// UDP port the controller sends its state to (the `PORT` of its ETHERNET configuration
    /// file; 59152).
    pub port: u16,
    /// Accept state messages only from this host; None = from the first sender whose state is
    /// at the scenario's start (CLI `--robot`).
    pub robot_host: Option<String>,
    /// The controller's cycle, s: 0.004 (IPO_FAST) or 0.012 (IPO). The scenario's period must
    /// equal it (the robot paces the loop).
    #[schemars(extend("enum" = [0.004, 0.012]))]
    pub period: f64,
    /// An answer sent later than this after its state message was read is counted late, s
    /// (the controller's own limit is its cycle, minus its network and processing time; > 0
    /// and <= `period`).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub deadline: f64,
    /// Consecutive late answers (later than `deadline`, or a message superseded before it was
    /// answered) after which the loop stops itself (`late-answers`), before the controller
    /// would (its `Timeout`, typically 100; >= 1).
    #[schemars(range(min = 1))]
    pub max_late_answers: u64,
    /// Longest time the end of the session waits for the controller to stop sending once the
    /// end signal (`<Stop>1</Stop>`) is in the answers, s (> 0).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub end_timeout: f64,
    /// `Type` of the answer's `<Sen>` (the configuration file's `SENTYPE`).
    pub sen_type: String,
    /// The actual-pose element of the state message (`DEF_RIst`: `RIst`).
    pub state_element: String,
    /// The correction element of the answer (the `RECEIVE` tags `RKorr.X` …: `RKorr`).
    pub correction_element: String,
    /// Absolute (w.r.t. the start) or relative (incremental) corrections.
    pub correction: CorrectionMode,
    /// Origin of the target frame `t` in the correction frame `e`, mm.
    pub offset_mm: [f64; 3],
    /// Rotation from `t` to `e`, quaternion `[w, x, y, z]`.
    pub rotation: [f64; 4],
}

impl Default for RsiOptions {
    fn default() -> Self {
        let names = RsiNames::default();
        RsiOptions {
            bind_host: "0.0.0.0".into(),
            port: RSI_PORT,
            robot_host: None,
            period: RSI_PERIOD,
            deadline: 0.002,
            max_late_answers: 50,
            end_timeout: 1.0,
            sen_type: names.sen_type,
            state_element: names.state,
            correction_element: names.correction,
            correction: CorrectionMode::Absolute,
            offset_mm: [0.0; 3],
            rotation: [1.0, 0.0, 0.0, 0.0],
        }
    }
}

/// Checks an RSI cycle option (0.004 or 0.012 s).
fn check_period(key: &str, period: f64) -> Result<()> {
    if RSI_PERIODS.iter().any(|p| (p - period).abs() < 1e-9) {
        Ok(())
    } else {
        Err(RtError::option(
            key,
            format!("must be 0.004 (IPO_FAST) or 0.012 (IPO) s, got {period}"),
        ))
    }
}

/// Checks the names (XML names of at most 32 characters).
fn checked_names(names: RsiNames) -> Result<RsiNames> {
    names.validate().map_err(|(key, value)| {
        RtError::option(
            key,
            format!("must be an XML name (letters, digits, _ - .; at most 32), got {value:?}"),
        )
    })?;
    Ok(names)
}

/// A KUKA pose (mm, A/B/C degrees) as a pose in `e` (mm, quaternion `[w, x, y, z]`).
fn from_kuka(p: &KukaPose) -> PoseMm {
    let q = abc_to_quaternion(p[3], p[4], p[5]);
    PoseMm {
        position_mm: [p[0], p[1], p[2]],
        orientation: [q.w, q.i, q.j, q.k],
    }
}

fn quaternion(p: &PoseMm) -> UnitQuaternion<f64> {
    let [w, x, y, z] = p.orientation;
    UnitQuaternion::new_normalize(nalgebra::Quaternion::new(w, x, y, z))
}

/// The correction that takes `reference` to `target` (both in `e`): translation in mm, then
/// the ZYX angles (degrees) of `R_target · R_reference⁻¹`.
pub fn correction(reference: &PoseMm, target: &PoseMm) -> KukaPose {
    let d = Vector3::from(target.position_mm) - Vector3::from(reference.position_mm);
    let [a, b, c] = quaternion_to_abc(&(quaternion(target) * quaternion(reference).inverse()));
    [d.x, d.y, d.z, a, b, c]
}

/// The pose a correction takes `reference` to (the inverse of [`correction`]).
pub fn corrected(reference: &PoseMm, correction: &KukaPose) -> PoseMm {
    let p = Vector3::from(reference.position_mm)
        + Vector3::new(correction[0], correction[1], correction[2]);
    let q = abc_to_quaternion(correction[3], correction[4], correction[5]) * quaternion(reference);
    PoseMm {
        position_mm: [p.x, p.y, p.z],
        orientation: [q.w, q.i, q.j, q.k],
    }
}

/// The PC side of KUKA RSI.
pub struct RsiRobot {
    inbox: UdpInbox<{ RSI_MAX_DATAGRAM + 1 }>,
    port: u16,
    /// Which sender is the robot.
    identity: RobotIdentity,
    mapping: PoseMapping,
    mode: CorrectionMode,
    period: f64,
    deadline_ns: u64,
    state_element: String,
    /// The pose the corrections are relative to: the start (absolute) or the previous
    /// answer's target (relative), in `e`.
    reference: Option<PoseMm>,
    ipoc: SequenceTracker<Ipoc>,
    /// The newest accepted message not answered yet: its IPOC and when it was read, ns.
    pending: Option<(u64, u64)>,
    /// The controller's own count of late answers (`Delay D`), as last sent.
    controller_delay: Option<u64>,
    latency: Histogram,
    answers_late: u64,
    unanswered: u64,
    /// Late answers in a row (late or superseded), and the limit.
    consecutive_late: u64,
    max_late_answers: u64,
    end_timeout: f64,
    /// The newest IPOC accepted, ms.
    last_ipoc: Option<u64>,
    /// The first fall of the IPOC from the robot by more than [`IPOC_RESTART_CYCLES`]
    /// cycles, ms.
    ipoc_backwards: Option<u64>,
    encoder: AnswerEncoder,
    stats: LinkStats,
}

/// A fall of the robot's IPOC by more than this many cycles is the sequence going backwards
/// (a restarted controller), not a reordered datagram (counted `stale`).
pub const IPOC_RESTART_CYCLES: u64 = 3;

/// An RSI link's options once parsed ([`RobotDevice::parse`] of [`RsiRobot`]): hosts' form, cycle and deadline
/// checked, the XML names and the pose mapping built.
#[derive(Debug, Clone, PartialEq)]
pub struct RsiConfig {
    options: RsiOptions,
    names: RsiNames,
    mapping: PoseMapping,
}

impl RsiRobot {
    /// Parses the options ([`RobotDevice::parse`] of [`RsiRobot`]) and binds the PC's RSI socket
    /// ([`RsiRobot::open_parsed`]).
    pub fn open(o: &RsiOptions, context: &LinkContext) -> Result<Self> {
        Self::open_parsed(&Self::parse(o)?, context)
    }
}

impl RobotDevice for RsiRobot {
    const PACING: Pacing = Pacing::Robot;
    type Options = RsiOptions;
    type Config = RsiConfig;

    /// Checks the options without opening anything (hosts, cycle, deadline, names, mapping),
    /// once.
    fn parse(options: &RsiOptions) -> Result<RsiConfig> {
        let o = options;
        check_host("rsi bind_host", &o.bind_host)?;
        if let Some(host) = &o.robot_host {
            check_host("robot_host", host)?;
        }
        check_period("rsi.period", o.period)?;
        if o.max_late_answers == 0 {
            return Err(RtError::option(
                "rsi.max_late_answers",
                "must be at least 1",
            ));
        }
        if !(o.end_timeout.is_finite() && o.end_timeout > 0.0) {
            return Err(RtError::option(
                "rsi.end_timeout",
                format!("must be a positive time in s, got {}", o.end_timeout),
            ));
        }
        if !(o.deadline.is_finite() && o.deadline > 0.0 && o.deadline <= o.period) {
            return Err(RtError::option(
                "rsi.deadline",
                format!(
                    "must be a time in s within the cycle (0 < deadline <= {}), got {}",
                    o.period, o.deadline
                ),
            ));
        }
        let mapping = PoseMapping::new(o.offset_mm, o.rotation)?;
        let names = checked_names(RsiNames {
            sen_type: o.sen_type.clone(),
            state: o.state_element.clone(),
            correction: o.correction_element.clone(),
        })?;
        Ok(RsiConfig {
            options: options.clone(),
            names,
            mapping,
        })
    }

    /// Binds the PC's RSI socket.
    fn open_parsed(c: &RsiConfig, context: &LinkContext) -> Result<Self> {
        let (o, names, mapping) = (&c.options, c.names.clone(), c.mapping);
        let inbox = UdpInbox::bind(
            "RSI endpoint",
            resolve("rsi bind_host", &o.bind_host, o.port)?,
        )?;
        let identity = RobotIdentity::new(o.robot_host.as_deref(), context.start)?;
        Ok(RsiRobot {
            inbox,
            port: o.port,
            identity,
            mapping,
            mode: o.correction,
            period: o.period,
            deadline_ns: (o.deadline * 1e9).round() as u64,
            state_element: names.state.clone(),
            reference: None,
            ipoc: SequenceTracker::new(),
            pending: None,
            controller_delay: None,
            latency: Histogram::new(20_000),
            answers_late: 0,
            unanswered: 0,
            consecutive_late: 0,
            max_late_answers: o.max_late_answers,
            end_timeout: o.end_timeout,
            last_ipoc: None,
            ipoc_backwards: None,
            encoder: AnswerEncoder::new(names),
            stats: LinkStats::default(),
        })
    }
}

impl RobotLink for RsiRobot {
    fn name(&self) -> &'static str {
        "RSI"
    }

    fn describe(&self) -> String {
        self.identity.describe_udp(self.port, "RSI state")
    }

    fn pacing(&self) -> Pacing {
        <Self as RobotDevice>::PACING
    }

    fn feedback_period(&self) -> f64 {
        self.period
    }

    fn poll(&mut self, now_ns: u64, estimator: &mut FeedbackEstimator) -> usize {
        let mut accepted = 0;
        while let Some((bytes, from)) = self
            .inbox
            .next(&mut self.stats, |from| self.identity.admits(from))
        {
            let decoded = decode_state(bytes, &self.state_element);
            let Some(state) = decode_counted(decoded, &mut self.stats) else {
                continue;
            };
            let step_ms = (self.period * 1e3).round() as u64;
            if let Some(last) = self.last_ipoc {
                let from_robot = self.identity.address() == Some(from);
                if from_robot && state.ipoc + IPOC_RESTART_CYCLES * step_ms < last {
                    self.ipoc_backwards.get_or_insert(last - state.ipoc);
                }
            }
            let actual = from_kuka(&state.actual);
            let (position, orientation) = self.mapping.from_device(&actual);
            let pose = FeedbackPose {
                from,
                seq: Ipoc {
                    ms: state.ipoc,
                    step_ms: (self.period * 1e3).round() as u64,
                },
                robot_time: state.ipoc as f64 * 1e-3,
                position,
                orientation,
            };
            let (sequence, stats) = (&mut self.ipoc, &mut self.stats);
            if !self
                .identity
                .accept(&pose, sequence, now_ns, estimator, stats)
            {
                continue;
            }
            if self.reference.is_none() {
                self.reference = Some(state.setpoint.map_or(actual, |s| from_kuka(&s)));
            }
            self.last_ipoc = Some(state.ipoc);
            if self.pending.is_some() {
                self.unanswered += 1;
                self.consecutive_late += 1;
            }
            self.pending = Some((state.ipoc, now_ns));
            self.controller_delay = state.delay.or(self.controller_delay);
            accepted += 1;
        }
        accepted
    }

    fn wait(&mut self, deadline_ns: u64, estimator: &mut FeedbackEstimator) -> usize {
        loop {
            let n = self.poll(now_ns(), estimator);
            if n > 0 {
                return n;
            }
            if !wait_readable(self.inbox.socket(), deadline_ns) {
                return self.poll(now_ns(), estimator);
            }
        }
    }

    /// Answers the newest state message, once; does nothing when it has been answered.
    fn send(&mut self, command: &RelativeMotion, _clock_ns: u64) {
        let (Some(addr), Some((ipoc, read_ns)), Some(reference)) =
            (self.identity.address(), self.pending, self.reference)
        else {
            return;
        };
        let target = self.mapping.to_device(command).pose;
        let korr = correction(&reference, &target);
        if self.mode == CorrectionMode::Relative {
            self.reference = Some(target);
        }
        let bytes = self.encoder.encode(&korr, ipoc);
        let sent = self.inbox.socket().send_to(bytes, addr);
        self.stats.count_send(sent);
        self.pending = None;
        let latency = now_ns().saturating_sub(read_ns);
        self.latency.record(latency);
        if latency > self.deadline_ns {
            self.answers_late += 1;
            self.consecutive_late += 1;
        } else {
            self.consecutive_late = 0;
        }
    }

    fn fault(&self) -> Option<LinkFault> {
        if let Some(fall) = self.ipoc_backwards {
            return Some(LinkFault {
                kind: StopKind::RobotSequence,
                value: fall as f64,
                limit: f64::NAN,
            });
        }
        (self.consecutive_late >= self.max_late_answers).then_some(LinkFault {
            kind: StopKind::LateAnswers,
            value: self.consecutive_late as f64,
            limit: self.max_late_answers as f64,
        })
    }

    /// Answers every state message with `pose` and the end signal (`<Stop>1</Stop>`) until
    /// the controller stops sending (no message for 5 cycles: its `RSI_MOVECORR` returned),
    /// at most `end_timeout`; true when it stopped.
    fn end_session(&mut self, pose: &RelativeMotion) -> Option<bool> {
        let reference = self.reference?;
        let mut estimator = FeedbackEstimator::new(Default::default());
        let end = now_ns() + (self.end_timeout * 1e9) as u64;
        let quiet_ns = (5.0 * self.period * 1e9) as u64;
        let target = self.mapping.to_device(pose).pose;
        let mut signalled = false;
        loop {
            let now = now_ns();
            if now >= end {
                return Some(false);
            }
            let n = self.wait((now + quiet_ns).min(end), &mut estimator);
            if n == 0 {
                if signalled && now_ns() < end {
                    return Some(true);
                }
                continue;
            }
            let (Some(addr), Some((ipoc, _))) = (self.identity.address(), self.pending) else {
                continue;
            };
            let korr = match self.mode {
                CorrectionMode::Absolute => correction(&reference, &target),
                CorrectionMode::Relative => {
                    let k = correction(&reference, &target);
                    self.reference = Some(target);
                    k
                }
            };
            let bytes = self.encoder.encode_with_end(&korr, ipoc, true);
            let sent = self.inbox.socket().send_to(bytes, addr);
            self.stats.count_send(sent);
            self.pending = None;
            signalled = true;
        }
    }

    fn peer(&self) -> Option<SocketAddr> {
        self.identity.address()
    }

    super::link::stats_accessors!();

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let reference = self.reference.map(|r| {
            let [a, b, c] = quaternion_to_abc(&quaternion(&r));
            let [x, y, z] = r.position_mm;
            [x, y, z, a, b, c]
        });
        let mut map = serde_json::Map::new();
        map.insert(
            "rsi".into(),
            serde_json::json!({
                "answer_latency_us": self.latency.summary(),
                "deadline_us": self.deadline_ns as f64 / 1e3,
                "answers_late": self.answers_late,
                "max_late_answers": self.max_late_answers,
                "unanswered": self.unanswered,
                "controller_delay": self.controller_delay,
                "correction": self.mode,
                "reference_pose": if self.mode == CorrectionMode::Absolute { reference } else { None },
            }),
        );
        map
    }
}

/// Options of the emulated KUKA controller's RSI side (`[robot] kind = "rsi"` of the
/// emulator's options).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RsiEndpointOptions {
    /// Host the controller sends its state to: the PC running the loop (the configuration
    /// file's `IP_NUMBER`).
    pub host: String,
    /// UDP port the controller sends its state to (`PORT`; 59152).
    pub port: u16,
    /// The controller's own UDP port (0 = any free port).
    pub local_port: u16,
    /// The cycle, s: 0.004 (IPO_FAST) or 0.012 (IPO), rounded to whole control periods.
    #[schemars(extend("enum" = [0.004, 0.012]))]
    pub period: f64,
    /// `Type` the answers' `<Sen>` must have (`SENTYPE`).
    pub sen_type: String,
    /// The actual-pose element sent (`RIst`).
    pub state_element: String,
    /// The correction element read (`RKorr`).
    pub correction_element: String,
    /// How the corrections are applied (the RSI correction object's mode).
    pub correction: CorrectionMode,
    /// Consecutive cycles without a timely answer after which the controller stops sending
    /// (the ETHERNET object's `Timeout` parameter; 100 in KUKA's and ROS-Industrial's
    /// examples; >= 1).
    #[schemars(range(min = 1))]
    pub max_late: u64,
    /// Origin of `t` in the correction frame `e`, mm.
    pub offset_mm: [f64; 3],
    /// Rotation from `t` to `e`, quaternion `[w, x, y, z]`.
    pub rotation: [f64; 4],
    /// Fault injection: once this many answers were taken, the IPOC falls back by 1000 ms (a
    /// restarted controller; None = never; >= 1).
    #[schemars(range(min = 1))]
    pub ipoc_back_after: Option<u64>,
}

impl Default for RsiEndpointOptions {
    fn default() -> Self {
        let names = RsiNames::default();
        RsiEndpointOptions {
            host: "127.0.0.1".into(),
            port: RSI_PORT,
            local_port: 0,
            period: RSI_PERIOD,
            sen_type: names.sen_type,
            state_element: names.state,
            correction_element: names.correction,
            correction: CorrectionMode::Absolute,
            max_late: 100,
            offset_mm: [0.0; 3],
            rotation: [1.0, 0.0, 0.0, 0.0],
            ipoc_back_after: None,
        }
    }
}

/// IPOC of the emulated controller's first message (an arbitrary controller uptime, ms).
const FIRST_IPOC: u64 = 1_000_000;

/// The emulated KUKA controller's RSI side. Every cycle a state message (`RIst`: the actual
/// pose; `RSol`: the setpoint, i.e. the start corrected by the last answer; `Delay`: the late
/// answers so far; `IPOC`: milliseconds, advancing by the cycle) goes to the PC's `host:port`.
/// An answer is accepted from that address only, with the configured `Type` and the IPOC of
/// the newest message (an older one is `stale`, another `invalid`), and its correction becomes
/// the command. A cycle that begins with the previous message unanswered counts `late`; after
/// `max_late` consecutive ones the controller stops sending, as a real one does (its `RSI
/// stopped`), and the loop's watchdog ends the run. Late cycles are counted only once the PC
/// has answered once: on a real cell the operator starts the KRL program (`RSI_MOVECORR`)
/// after the PC side is listening, so here the emulator and the PC may start in either order.
pub struct RsiEndpoint {
    inbox: UdpInbox<{ RSI_MAX_DATAGRAM + 1 }>,
    address: SocketAddr,
    peer: SocketAddr,
    mapping: PoseMapping,
    names: RsiNames,
    mode: CorrectionMode,
    max_late: u64,
    /// A state message every this many control periods (≥ 1).
    every: u64,
    /// The cycle in IPOC units (ms).
    step_ms: u64,
    /// The pose corrections apply to (absolute: the start), in `e`.
    reference: PoseMm,
    /// The setpoint: the reference corrected by the newest answer (`RSol`), in `e`.
    setpoint: PoseMm,
    ipoc: u64,
    /// The IPOC of the last message sent, while it is unanswered.
    outstanding: Option<u64>,
    consecutive_late: u64,
    stopped: bool,
    /// Fault injection: the answers after which the IPOC falls back, and by how much, ms.
    ipoc_back_after: Option<u64>,
    ipoc_back: u64,
    /// Whether the session ended with the PC's end signal (true) or the controller's error
    /// (false).
    ended_cleanly: Option<bool>,
    encoder: StateEncoder,
    stats: LinkStats,
}

/// The emulated RSI controller's options once parsed ([`EmulatedRobot::parse`] of [`RsiEndpoint`]): cycle
/// and `max_late` checked, the XML names and the pose mapping built.
#[derive(Debug, Clone, PartialEq)]
pub struct RsiEndpointConfig {
    options: RsiEndpointOptions,
    names: RsiNames,
    mapping: PoseMapping,
}

impl RsiEndpoint {
    /// Parses the options ([`EmulatedRobot::parse`] of [`RsiEndpoint`]) and opens the controller
    /// ([`RsiEndpoint::open_parsed`]).
    pub fn open(o: &RsiEndpointOptions, context: &EndpointContext) -> Result<Self> {
        Self::open_parsed(&Self::parse(o)?, context)
    }
}

impl EmulatedRobot for RsiEndpoint {
    type Options = RsiEndpointOptions;
    type Config = RsiEndpointConfig;

    /// Checks the cycle, `max_late`, the names and the mapping, once.
    fn parse(options: &RsiEndpointOptions) -> Result<RsiEndpointConfig> {
        let o = options;
        check_period("rsi.period", o.period)?;
        if o.max_late == 0 {
            return Err(RtError::option("rsi.max_late", "must be at least 1"));
        }
        let names = checked_names(RsiNames {
            sen_type: o.sen_type.clone(),
            state: o.state_element.clone(),
            correction: o.correction_element.clone(),
        })?;
        Ok(RsiEndpointConfig {
            options: options.clone(),
            names,
            mapping: PoseMapping::new(o.offset_mm, o.rotation)?,
        })
    }

    /// Resolves the PC's address and binds the controller's socket (on loopback when the PC
    /// is).
    fn open_parsed(c: &RsiEndpointConfig, context: &EndpointContext) -> Result<Self> {
        let (o, names, mapping) = (&c.options, c.names.clone(), c.mapping);
        let peer = resolve("rsi host", &o.host, o.port)?;
        let inbox = UdpInbox::bind("robot (RSI)", bind_address_for(peer, o.local_port))?;
        let address = local_addr("robot (RSI)", inbox.socket())?;
        let start = mapping.to_device(&context.initial).pose;
        Ok(RsiEndpoint {
            inbox,
            address,
            peer,
            mapping,
            encoder: StateEncoder::new(&names.state),
            names,
            mode: o.correction,
            max_late: o.max_late,
            every: ((o.period / context.period).round() as u64).max(1),
            step_ms: (o.period * 1e3).round() as u64,
            reference: start,
            setpoint: start,
            ipoc: FIRST_IPOC,
            outstanding: None,
            consecutive_late: 0,
            stopped: false,
            ipoc_back_after: o.ipoc_back_after,
            ipoc_back: 0,
            ended_cleanly: None,
            stats: LinkStats::default(),
        })
    }
}

fn to_kuka(p: &PoseMm) -> KukaPose {
    let [a, b, c] = quaternion_to_abc(&quaternion(p));
    let [x, y, z] = p.position_mm;
    [x, y, z, a, b, c]
}

impl RobotEndpoint for RsiEndpoint {
    fn name(&self) -> &'static str {
        "RSI"
    }

    fn address(&self) -> SocketAddr {
        self.address
    }

    fn peer(&self) -> Option<SocketAddr> {
        Some(self.peer)
    }

    fn receive(&mut self) -> Option<RelativeMotion> {
        let mut newest = None;
        let peer = self.peer;
        while let Some((bytes, _)) = self.inbox.next(&mut self.stats, |from| from == peer) {
            let decoded = decode_answer(bytes, &self.names);
            let Some(answer) = decode_counted(decoded, &mut self.stats) else {
                continue;
            };
            if self.outstanding != Some(answer.ipoc) {
                if answer.ipoc <= self.ipoc {
                    self.stats.stale += 1; // a late answer to an earlier message
                } else {
                    self.stats.invalid += 1; // an IPOC never sent
                }
                continue;
            }
            self.outstanding = None;
            self.consecutive_late = 0;
            self.stats.accepted += 1;
            newest = Some(answer.correction);
            if answer.end && !self.stopped {
                // the KRL program's RSI_MOVECORR returns: the session ends without error
                self.stopped = true;
                self.ended_cleanly = Some(true);
            }
        }
        let korr = newest?;
        self.setpoint = corrected(&self.reference, &korr);
        if self.mode == CorrectionMode::Relative {
            self.reference = self.setpoint;
        }
        let (position, orientation) = self.mapping.from_device(&self.setpoint);
        Some(RelativeMotion {
            position,
            orientation,
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        })
    }

    fn feedback(&mut self, k: u64, actual: &RelativeMotion, send: bool) {
        if !send || self.stopped || !k.is_multiple_of(self.every) {
            return;
        }
        if self.outstanding.is_some() && self.stats.accepted > 0 {
            self.stats.late += 1;
            self.consecutive_late += 1;
            if self.consecutive_late >= self.max_late {
                self.stopped = true; // the controller's "RSI stopped"
                self.ended_cleanly = Some(false);
                return;
            }
        }
        if self
            .ipoc_back_after
            .is_some_and(|n| self.stats.accepted >= n)
        {
            self.ipoc_back_after = None;
            self.ipoc_back = 1000;
        }
        self.ipoc = FIRST_IPOC + k / self.every * self.step_ms - self.ipoc_back;
        let actual = to_kuka(&self.mapping.to_device(actual).pose);
        let setpoint = to_kuka(&self.setpoint);
        let bytes = self
            .encoder
            .encode(&actual, &setpoint, self.stats.late, self.ipoc);
        let sent = self.inbox.socket().send_to(bytes, self.peer);
        self.stats.count_send(sent);
        self.outstanding = Some(self.ipoc);
    }

    fn stats(&self) -> &LinkStats {
        &self.stats
    }

    fn session_ended_cleanly(&self) -> Option<bool> {
        self.ended_cleanly
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn correction_and_corrected_are_inverse() {
        let reference = from_kuka(&[-995.0, 10.0, 1200.0, 90.0, -5.0, 178.0]);
        let target = from_kuka(&[-990.5, 9.0, 1201.0, 92.0, -4.0, 179.5]);
        let korr = correction(&reference, &target);
        assert!((korr[0] - 4.5).abs() < 1e-9 && (korr[1] + 1.0).abs() < 1e-9);
        let back = corrected(&reference, &korr);
        for i in 0..3 {
            assert!((back.position_mm[i] - target.position_mm[i]).abs() < 1e-9);
        }
        assert!(quaternion(&back).angle_to(&quaternion(&target)) < 1e-9);
        // a pure rotation about e's z by 2°: A = 2
        let reference = from_kuka(&[0.0, 0.0, 0.0, 10.0, 0.0, 0.0]);
        let target = from_kuka(&[0.0, 0.0, 0.0, 12.0, 0.0, 0.0]);
        let korr = correction(&reference, &target);
        assert!(
            (korr[3] - 2.0).abs() < 1e-9 && korr[4].abs() < 1e-9,
            "{korr:?}"
        );
    }

    #[test]
    fn bad_options_are_refused() {
        let context = LinkContext {
            period: 0.004,
            connect_timeout: 1.0,
            start: None,
        };
        let base = RsiOptions {
            bind_host: "127.0.0.1".into(),
            port: 0,
            ..RsiOptions::default()
        };
        for (o, key) in [
            (
                RsiOptions {
                    period: 0.001,
                    ..base.clone()
                },
                "rsi.period",
            ),
            (
                RsiOptions {
                    deadline: 0.005,
                    ..base.clone()
                },
                "rsi.deadline",
            ),
            (
                RsiOptions {
                    sen_type: "Im Free".into(),
                    ..base.clone()
                },
                "sen_type",
            ),
        ] {
            let e = RsiRobot::open(&o, &context).err().unwrap().to_string();
            assert!(e.contains(key), "{e}");
        }
        assert!(RsiRobot::open(&base, &context).is_ok());
    }
}
