//! ABB Externally Guided Motion (EGM), both sides: [`EgmRobot`] is the [`RobotLink`] of the
//! loop (`EgmRobot` feedback in, `EgmSensor` corrections out, protobuf over UDP, codec in
//! [`self::codec`]), [`EgmEndpoint`] the emulated controller's [`RobotEndpoint`] (feedback out,
//! corrections in).
//!
//! The controller sends feedback every 4 ms ([`EGM_PERIOD`]) to the PC's EGM port; the loop
//! runs on the PC's clock ([`Pacing::Clock`]) and answers each tick with a correction to the
//! address the feedback came from. Poses cross the link through [`PoseMapping`] (m and the
//! `t` frame on the loop's side, mm and quaternions in the EGM frame on the robot's).
//!
//! A feedback message is accepted when it comes from the robot, decodes, has finite in-range
//! values and a unit quaternion, and a sequence number newer than the last accepted one. The
//! robot is `robot_host` if given; else it is identified, not raced for: the first sender
//! whose valid feedback puts the rod tip within the start region ([`LinkContext::start`]:
//! `start_tolerance` of the scenario's start), so that a foreign EGM sender that started
//! earlier (another robot, a simulator) is counted `foreign` and never locked onto. Every
//! other sender is counted `foreign`.

pub mod codec;
pub mod proto;

use std::net::SocketAddr;

use serde::{Deserialize, Serialize};

use hilcontact_core::world::RelativeMotion;

use self::codec::{
    CorrectionDecoder, CorrectionEncoder, EgmError, FeedbackEncoder, RobotDecoder, EGM_PERIOD,
    EGM_PORT,
};
use super::transport::{bind_address_for, decode_counted, DecodeError, SequenceTracker, UdpInbox};
use super::{
    check_host, local_addr, resolve, sequence_counted, EmulatedRobot, EndpointContext,
    FeedbackPose, LinkContext, LinkStats, Pacing, RobotDevice, RobotEndpoint, RobotIdentity,
    RobotLink,
};
use crate::devices::pose::{PoseMapping, PoseMm};
use crate::error::{Result, RtError};
use crate::feedback::FeedbackEstimator;

/// Options of an EGM robot link (`[robot] kind = "egm"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct EgmOptions {
    /// Address the EGM endpoint binds to (CLI `--egm-bind`).
    pub bind_host: String,
    /// UDP port the robot controller sends its EGM feedback to (6510) (CLI `--egm-port`).
    pub port: u16,
    /// Accept EGM feedback only from this host; None = from the first sender whose feedback
    /// is at the scenario's start (CLI `--robot`).
    pub robot_host: Option<String>,
    /// Origin of the target frame `t` in the EGM frame, mm (CLI `--egm-offset`).
    pub offset_mm: [f64; 3],
    /// Rotation from `t` to the EGM frame, quaternion `[w, x, y, z]` (CLI `--egm-rotation`).
    pub rotation: [f64; 4],
}

impl Default for EgmOptions {
    fn default() -> Self {
        EgmOptions {
            bind_host: "0.0.0.0".into(),
            port: EGM_PORT,
            robot_host: None,
            offset_mm: [0.0; 3],
            rotation: [1.0, 0.0, 0.0, 0.0],
        }
    }
}

/// The PC side of ABB EGM.
pub struct EgmRobot {
    inbox: UdpInbox<2048>,
    port: u16,
    /// Which sender is the robot.
    identity: RobotIdentity,
    mapping: PoseMapping,
    sequence: SequenceTracker,
    decoder: RobotDecoder,
    encoder: CorrectionEncoder,
    send_seq: u32,
    stats: LinkStats,
}

/// An EGM link's options once parsed ([`RobotDevice::parse`] of [`EgmRobot`]): the hosts' form checked, the
/// pose mapping built.
#[derive(Debug, Clone, PartialEq)]
pub struct EgmConfig {
    options: EgmOptions,
    mapping: PoseMapping,
}

impl EgmRobot {
    /// Parses the options ([`RobotDevice::parse`] of [`EgmRobot`]) and binds the EGM endpoint
    /// ([`EgmRobot::open_parsed`]).
    pub fn open(o: &EgmOptions, context: &LinkContext) -> Result<Self> {
        Self::open_parsed(&Self::parse(o)?, context)
    }
}

impl RobotDevice for EgmRobot {
    const PACING: Pacing = Pacing::Clock;
    type Options = EgmOptions;
    type Config = EgmConfig;

    /// Checks the hosts' form and builds the pose mapping, once, without opening anything.
    fn parse(options: &EgmOptions) -> Result<EgmConfig> {
        check_host("egm_bind_host", &options.bind_host)?;
        if let Some(host) = &options.robot_host {
            check_host("robot_host", host)?;
        }
        Ok(EgmConfig {
            options: options.clone(),
            mapping: PoseMapping::new(options.offset_mm, options.rotation)?,
        })
    }

    /// Binds the EGM endpoint.
    fn open_parsed(c: &EgmConfig, context: &LinkContext) -> Result<Self> {
        let (o, mapping) = (&c.options, c.mapping);
        let inbox = UdpInbox::bind(
            "EGM endpoint",
            resolve("egm_bind_host", &o.bind_host, o.port)?,
        )?;
        let identity = RobotIdentity::new(o.robot_host.as_deref(), context.start)?;
        Ok(EgmRobot {
            port: o.port,
            inbox,
            identity,
            mapping,
            sequence: SequenceTracker::new(),
            decoder: RobotDecoder::new(),
            encoder: CorrectionEncoder::new(),
            send_seq: 0,
            stats: LinkStats::default(),
        })
    }
}

impl RobotLink for EgmRobot {
    fn name(&self) -> &'static str {
        "EGM"
    }

    fn describe(&self) -> String {
        self.identity.describe_udp(self.port, "EGM feedback")
    }

    fn pacing(&self) -> Pacing {
        <Self as RobotDevice>::PACING
    }

    fn feedback_period(&self) -> f64 {
        EGM_PERIOD
    }

    fn poll(&mut self, now_ns: u64, estimator: &mut FeedbackEstimator) -> usize {
        let mut accepted = 0;
        while let Some((bytes, from)) = self
            .inbox
            .next(&mut self.stats, |from| self.identity.admits(from))
        {
            let Some(feedback) = decode_counted(self.decoder.decode(bytes), &mut self.stats) else {
                continue;
            };
            let (position, orientation) = self.mapping.from_device(&feedback.actual);
            let pose = FeedbackPose {
                from,
                seq: feedback.seqno,
                robot_time: feedback.robot_time(),
                position,
                orientation,
            };
            let (sequence, stats) = (&mut self.sequence, &mut self.stats);
            if self
                .identity
                .accept(&pose, sequence, now_ns, estimator, stats)
            {
                accepted += 1;
            }
        }
        accepted
    }

    fn send(&mut self, command: &RelativeMotion, clock_ns: u64) {
        let Some(addr) = self.identity.address() else {
            return;
        };
        self.send_seq = self.send_seq.wrapping_add(1);
        let tm = (clock_ns / 1_000_000) as u32;
        let target = self.mapping.to_device(command);
        let bytes = self.encoder.encode(self.send_seq, tm, &target);
        let sent = self.inbox.socket().send_to(bytes, addr);
        self.stats.count_send(sent);
    }

    fn peer(&self) -> Option<SocketAddr> {
        self.identity.address()
    }

    super::link::stats_accessors!();
}

/// EGM decoding errors as the counters see them: a wrong size, bytes that are not protobuf, a
/// missing header or a wrong type are malformed, the rest invalid.
impl DecodeError for EgmError {
    fn is_malformed(&self) -> bool {
        matches!(
            self,
            EgmError::WrongSize(_)
                | EgmError::Decode
                | EgmError::MissingHeader
                | EgmError::WrongType(_)
        )
    }
}

/// Options of the emulated EGM robot controller (`[robot] kind = "egm"` of the emulator's
/// options).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct EgmEndpointOptions {
    /// Host the robot sends its feedback to: the PC running the loop (CLI `--egm-host`).
    pub host: String,
    /// UDP port the robot sends its feedback to: the PC side's port (6510) (CLI `--egm-port`).
    pub port: u16,
    /// The robot's own UDP port (0 = any free port) (CLI `--egm-local-port`).
    pub local_port: u16,
    /// Feedback period, s (> 0; 0.004 = 250 Hz), rounded to whole control periods.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub period: f64,
    /// Origin of the target frame `t` in the EGM frame, mm (CLI `--egm-offset`; see
    /// [`crate::devices::pose`]).
    pub offset_mm: [f64; 3],
    /// Rotation from `t` to the EGM frame, quaternion `[w, x, y, z]` (CLI `--egm-rotation`).
    pub rotation: [f64; 4],
    /// RobotWare generation of the feedback's `egm.proto`, 6 or 7 (fault injection: 6 sends
    /// `measuredForce` in RobotWare 6's layout, which RobotWare 7's proto cannot decode).
    #[schemars(range(min = 6, max = 7))]
    pub robotware: u8,
}

impl Default for EgmEndpointOptions {
    fn default() -> Self {
        EgmEndpointOptions {
            host: "127.0.0.1".into(),
            port: EGM_PORT,
            local_port: 0,
            period: EGM_PERIOD,
            offset_mm: [0.0; 3],
            rotation: [1.0, 0.0, 0.0, 0.0],
            robotware: 7,
        }
    }
}

/// The emulated ABB controller's EGM side. Every feedback period an `EgmRobot` message with
/// the actual pose (feedback) and the last commanded one (planned) goes to the PC's
/// `host:port`; `EgmSensor` corrections are accepted from that address only, and the newest
/// (by sequence number; gaps are counted as `lost`, older ones as `stale`) becomes the command
/// the robot follows. With `robotware = 6` the feedback carries RobotWare 6's `measuredForce`.
pub struct EgmEndpoint {
    inbox: UdpInbox<2048>,
    address: SocketAddr,
    peer: SocketAddr,
    mapping: PoseMapping,
    /// Feedback every this many control periods (≥ 1).
    every: u64,
    /// Control period, ns.
    period_ns: u64,
    /// The newest commanded pose, mm (`planned` in the feedback).
    planned: PoseMm,
    seqno: u32,
    sequence: SequenceTracker,
    decoder: CorrectionDecoder,
    encoder: FeedbackEncoder,
    stats: LinkStats,
}

/// The emulated EGM robot's options once parsed ([`EmulatedRobot::parse`] of [`EgmEndpoint`]): a positive
/// feedback period, the RobotWare generation's encoder, the pose mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct EgmEndpointConfig {
    options: EgmEndpointOptions,
    mapping: PoseMapping,
}

impl EgmEndpoint {
    /// Parses the options ([`EmulatedRobot::parse`] of [`EgmEndpoint`]) and opens the endpoint
    /// ([`EgmEndpoint::open_parsed`]).
    pub fn open(o: &EgmEndpointOptions, context: &EndpointContext) -> Result<Self> {
        Self::open_parsed(&Self::parse(o)?, context)
    }
}

impl EmulatedRobot for EgmEndpoint {
    type Options = EgmEndpointOptions;
    type Config = EgmEndpointConfig;

    /// Checks the period and the RobotWare generation and builds the mapping, once.
    fn parse(options: &EgmEndpointOptions) -> Result<EgmEndpointConfig> {
        if !(options.period.is_finite() && options.period > 0.0) {
            return Err(RtError::option(
                "egm_period",
                format!("must be a positive number, got {}", options.period),
            ));
        }
        if !matches!(options.robotware, 6 | 7) {
            return Err(RtError::option(
                "robotware",
                format!("must be 6 or 7, got {}", options.robotware),
            ));
        }
        Ok(EgmEndpointConfig {
            options: options.clone(),
            mapping: PoseMapping::new(options.offset_mm, options.rotation)?,
        })
    }

    /// Resolves the PC's address and binds the robot's socket (on loopback when the PC is).
    fn open_parsed(c: &EgmEndpointConfig, context: &EndpointContext) -> Result<Self> {
        let (o, mapping) = (&c.options, c.mapping);
        let encoder = if o.robotware == 6 {
            FeedbackEncoder::robotware6()
        } else {
            FeedbackEncoder::new()
        };
        let peer = resolve("egm_host", &o.host, o.port)?;
        let inbox = UdpInbox::bind("robot (EGM)", bind_address_for(peer, o.local_port))?;
        let address = local_addr("robot (EGM)", inbox.socket())?;
        Ok(EgmEndpoint {
            inbox,
            address,
            peer,
            mapping,
            every: ((o.period / context.period).round() as u64).max(1),
            period_ns: (context.period * 1e9).round() as u64,
            planned: mapping.to_device(&context.initial).pose,
            seqno: 0,
            sequence: SequenceTracker::new(),
            decoder: CorrectionDecoder::new(),
            encoder,
            stats: LinkStats::default(),
        })
    }
}

impl RobotEndpoint for EgmEndpoint {
    fn name(&self) -> &'static str {
        "EGM"
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
            let Some(correction) = decode_counted(self.decoder.decode(bytes), &mut self.stats)
            else {
                continue;
            };
            if !sequence_counted(&mut self.sequence, correction.seqno, &mut self.stats) {
                continue;
            }
            self.stats.accepted += 1;
            newest = Some(correction);
        }
        let c = newest?;
        self.planned = c.target.pose;
        Some(self.mapping.motion_from_device(&c.target))
    }

    fn feedback(&mut self, k: u64, actual: &RelativeMotion, send: bool) {
        if !send || !k.is_multiple_of(self.every) {
            return;
        }
        let actual = self.mapping.to_device(actual).pose;
        let time_us = k * self.period_ns / 1000;
        self.seqno = self.seqno.wrapping_add(1);
        let bytes = self
            .encoder
            .encode(self.seqno, time_us, &actual, &self.planned);
        let sent = self.inbox.socket().send_to(bytes, self.peer);
        self.stats.count_send(sent);
    }

    fn stats(&self) -> &LinkStats {
        &self.stats
    }
}
