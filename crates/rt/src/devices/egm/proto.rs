//! ABB's `egm.proto` (package `abb.egm`, proto2) as `prost` messages.
//!
//! Field numbers, types and labels follow the `egm.proto` that ships with RobotWare 7 (and with
//! the `abb-robot-client` Python package, whose compiled descriptor was used to check every
//! tag). Encoded and decoded by `prost` (no hand-written wire code).
//!
//! RobotWare 6 controllers use an older revision ("sensor interface V1.1", e.g. the one in
//! `abb_libegm` and in the `abbegm` crate). Three differences, one of which matters here:
//! - `EgmMeasuredForce` is `repeated double force = 1` in RobotWare 6, `optional bool
//!   fcActive = 1; repeated double force = 2` in RobotWare 7. The same field number carries a
//!   double (wire type 1, or 2 when packed) in one and a bool (wire type 0) in the other, so a
//!   derived message of either revision rejects the other's datagrams. [`EgmMeasuredForce`]
//!   is therefore written by hand: it tells the two apart by field 1's wire type.
//! - `EgmRobot` ends at tag 10 (`utilizationRate`) in RobotWare 6; 11 to 13 are RobotWare 7
//!   additions, simply absent from an older controller's messages.
//! - `EgmSensor` has no `RAPIDtoRobot` (tag 4) in RobotWare 6; the PC side never sends it.
//!
//! [`EgmMeasuredForceRw6`] is the RobotWare 6 message, used by the emulated robot to send
//! RobotWare 6 feedback.

#![allow(missing_docs)] // the names are ABB's; each message says what it is

use prost::bytes::{Buf, BufMut};
use prost::encoding::{self, DecodeContext, WireType};
use prost::{DecodeError, Enumeration, Message};

/// Header of every message: sequence number, time stamp (ms), message type.
#[derive(Clone, PartialEq, Message)]
pub struct EgmHeader {
    /// Sequence number (to find lost messages).
    #[prost(uint32, optional, tag = "1")]
    pub seqno: Option<u32>,
    /// Sender's time stamp, ms.
    #[prost(uint32, optional, tag = "2")]
    pub tm: Option<u32>,
    /// A [`MessageType`].
    #[prost(enumeration = "MessageType", optional, tag = "3")]
    pub mtype: Option<i32>,
}

/// `EgmHeader.MessageType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Enumeration)]
#[repr(i32)]
pub enum MessageType {
    Undefined = 0,
    /// For future use.
    Command = 1,
    /// Sent by the robot controller.
    Data = 2,
    /// Sent by the sensor (PC) for position guidance.
    Correction = 3,
    /// Sent by the sensor for path correction.
    PathCorrection = 4,
}

/// A position, mm.
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmCartesian {
    #[prost(double, required, tag = "1")]
    pub x: f64,
    #[prost(double, required, tag = "2")]
    pub y: f64,
    #[prost(double, required, tag = "3")]
    pub z: f64,
}

/// A unit quaternion `u0 + u1 i + u2 j + u3 k` (`u0` is the scalar part).
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmQuaternion {
    #[prost(double, required, tag = "1")]
    pub u0: f64,
    #[prost(double, required, tag = "2")]
    pub u1: f64,
    #[prost(double, required, tag = "3")]
    pub u2: f64,
    #[prost(double, required, tag = "4")]
    pub u3: f64,
}

/// Euler angles, degrees: `egm.proto`'s `EgmEuler` has [`EgmCartesian`]'s fields and tags,
/// so it is the same Rust type (the same bytes on the wire).
pub type EgmEuler = EgmCartesian;

/// A time: seconds and microseconds.
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmClock {
    #[prost(uint64, required, tag = "1")]
    pub sec: u64,
    #[prost(uint64, required, tag = "2")]
    pub usec: u64,
}

/// A pose: position (mm) and orientation (quaternion or Euler angles).
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmPose {
    #[prost(message, optional, tag = "1")]
    pub pos: Option<EgmCartesian>,
    #[prost(message, optional, tag = "2")]
    pub orient: Option<EgmQuaternion>,
    #[prost(message, optional, tag = "3")]
    pub euler: Option<EgmEuler>,
}

/// A Cartesian speed: `[vx, vy, vz]` mm/s, then `[wx, wy, wz]` deg/s.
#[derive(Clone, PartialEq, Message)]
pub struct EgmCartesianSpeed {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub value: Vec<f64>,
}

/// Joint values, degrees.
#[derive(Clone, PartialEq, Message)]
pub struct EgmJoints {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub joints: Vec<f64>,
}

/// Planned (commanded) position: joints or pose. Also the measured one ([`EgmFeedBack`]).
#[derive(Clone, PartialEq, Message)]
pub struct EgmPlanned {
    #[prost(message, optional, tag = "1")]
    pub joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "2")]
    pub cartesian: Option<EgmPose>,
    #[prost(message, optional, tag = "3")]
    pub external_joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "4")]
    pub time: Option<EgmClock>,
}

/// Speed reference sent with a correction.
#[derive(Clone, PartialEq, Message)]
pub struct EgmSpeedRef {
    #[prost(message, optional, tag = "1")]
    pub joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "2")]
    pub cartesians: Option<EgmCartesianSpeed>,
    #[prost(message, optional, tag = "3")]
    pub external_joints: Option<EgmJoints>,
}

/// A path correction (mm, path coordinates).
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmPathCorr {
    #[prost(message, required, tag = "1")]
    pub pos: EgmCartesian,
    #[prost(uint32, required, tag = "2")]
    pub age: u32,
}

/// Measured (actual) position of the robot: `egm.proto`'s `EgmFeedBack` has [`EgmPlanned`]'s
/// fields and tags, so it is the same Rust type (the same bytes on the wire).
pub type EgmFeedBack = EgmPlanned;

/// Motor state.
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmMotorState {
    #[prost(enumeration = "MotorStateType", required, tag = "1")]
    pub state: i32,
}

/// `EgmMotorState.MotorStateType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Enumeration)]
#[repr(i32)]
pub enum MotorStateType {
    MotorsUndefined = 0,
    MotorsOn = 1,
    MotorsOff = 2,
}

/// State of the motion control interface.
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmMciState {
    #[prost(enumeration = "MciStateType", required, tag = "1")]
    pub state: i32,
}

/// `EgmMCIState.MCIStateType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Enumeration)]
#[repr(i32)]
pub enum MciStateType {
    MciUndefined = 0,
    MciError = 1,
    MciStopped = 2,
    MciRunning = 3,
}

/// RAPID execution state.
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmRapidCtrlExecState {
    #[prost(enumeration = "RapidCtrlExecStateType", required, tag = "1")]
    pub state: i32,
}

/// `EgmRapidCtrlExecState.RapidCtrlExecStateType`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Enumeration)]
#[repr(i32)]
pub enum RapidCtrlExecStateType {
    RapidUndefined = 0,
    RapidStopped = 1,
    RapidRunning = 2,
}

/// Test signals.
#[derive(Clone, PartialEq, Message)]
pub struct EgmTestSignals {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub signals: Vec<f64>,
}

/// Force measured by the controller's force control, of either `egm.proto` generation:
/// RobotWare 7's `optional bool fcActive = 1; repeated double force = 2` and RobotWare 6's
/// `repeated double force = 1`.
///
/// Decoding tells them apart by field 1's wire type: a varint is RobotWare 7's `fcActive`, a
/// 64-bit value (one double) or a length-delimited field (packed doubles) is RobotWare 6's
/// `force`; any other wire type is an error. Forces of both tags go to `force`. Encoding
/// writes the RobotWare 7 layout.
#[derive(Clone, PartialEq, Debug, Default)]
pub struct EgmMeasuredForce {
    /// Whether force control is active (RobotWare 7 only).
    pub fc_active: Option<bool>,
    /// `[Fx, Fy, Fz, Tx, Ty, Tz]` as sent (N, N·m).
    pub force: Vec<f64>,
}

impl Message for EgmMeasuredForce {
    fn encode_raw(&self, buf: &mut impl BufMut) {
        if let Some(active) = &self.fc_active {
            encoding::bool::encode(1, active, buf);
        }
        encoding::double::encode_repeated(2, &self.force, buf);
    }

    fn merge_field(
        &mut self,
        tag: u32,
        wire_type: WireType,
        buf: &mut impl Buf,
        ctx: DecodeContext,
    ) -> Result<(), DecodeError> {
        match (tag, wire_type) {
            // RobotWare 6: `repeated double force = 1`, unpacked or packed
            (1, WireType::SixtyFourBit | WireType::LengthDelimited) => {
                encoding::double::merge_repeated(wire_type, &mut self.force, buf, ctx)
            }
            // RobotWare 7: `optional bool fcActive = 1` (another wire type is an error)
            (1, _) => {
                encoding::bool::merge(wire_type, self.fc_active.get_or_insert(false), buf, ctx)
            }
            // RobotWare 7: `repeated double force = 2`
            (2, _) => encoding::double::merge_repeated(wire_type, &mut self.force, buf, ctx),
            _ => encoding::skip_field(wire_type, tag, buf, ctx),
        }
    }

    fn encoded_len(&self) -> usize {
        self.fc_active
            .as_ref()
            .map_or(0, |a| encoding::bool::encoded_len(1, a))
            + encoding::double::encoded_len_repeated(2, &self.force)
    }

    fn clear(&mut self) {
        self.fc_active = None;
        self.force.clear();
    }
}

/// RobotWare 6's `EgmMeasuredForce` (`repeated double force = 1`, unpacked as proto2 encodes
/// it): what an older controller sends as `EgmRobot.measuredForce`.
#[derive(Clone, PartialEq, Message)]
pub struct EgmMeasuredForceRw6 {
    #[prost(double, repeated, packed = "false", tag = "1")]
    pub force: Vec<f64>,
}

/// Collision detection.
#[derive(Clone, PartialEq, Message)]
pub struct EgmCollisionInfo {
    #[prost(bool, optional, tag = "1")]
    pub collsion_triggered: Option<bool>,
    #[prost(double, repeated, packed = "false", tag = "2")]
    pub coll_det_quota: Vec<f64>,
}

/// RAPID data exchanged with the controller.
#[derive(Clone, PartialEq, Message)]
pub struct EgmRapiDdata {
    #[prost(bool, optional, tag = "1")]
    pub dig_val: Option<bool>,
    #[prost(double, repeated, packed = "false", tag = "2")]
    pub dnum: Vec<f64>,
}

/// Controller to sensor (PC): feedback, planned pose, states.
#[derive(Clone, PartialEq, Message)]
pub struct EgmRobot {
    #[prost(message, optional, tag = "1")]
    pub header: Option<EgmHeader>,
    #[prost(message, optional, tag = "2")]
    pub feed_back: Option<EgmFeedBack>,
    #[prost(message, optional, tag = "3")]
    pub planned: Option<EgmPlanned>,
    #[prost(message, optional, tag = "4")]
    pub motor_state: Option<EgmMotorState>,
    #[prost(message, optional, tag = "5")]
    pub mci_state: Option<EgmMciState>,
    #[prost(bool, optional, tag = "6")]
    pub mci_convergence_met: Option<bool>,
    #[prost(message, optional, tag = "7")]
    pub test_signals: Option<EgmTestSignals>,
    #[prost(message, optional, tag = "8")]
    pub rapid_exec_state: Option<EgmRapidCtrlExecState>,
    #[prost(message, optional, tag = "9")]
    pub measured_force: Option<EgmMeasuredForce>,
    #[prost(double, optional, tag = "10")]
    pub utilization_rate: Option<f64>,
    #[prost(uint32, optional, tag = "11")]
    pub move_index: Option<u32>,
    #[prost(message, optional, tag = "12")]
    pub collision_info: Option<EgmCollisionInfo>,
    #[prost(message, optional, tag = "13")]
    pub rapid_from_robot: Option<EgmRapiDdata>,
}

/// Sensor (PC) to controller: the correction (planned pose) and speed reference.
#[derive(Clone, PartialEq, Message)]
pub struct EgmSensor {
    #[prost(message, optional, tag = "1")]
    pub header: Option<EgmHeader>,
    #[prost(message, optional, tag = "2")]
    pub planned: Option<EgmPlanned>,
    #[prost(message, optional, tag = "3")]
    pub speed_ref: Option<EgmSpeedRef>,
    #[prost(message, optional, tag = "4")]
    pub rapid_to_robot: Option<EgmRapiDdata>,
}

/// Sensor to controller, path correction mode.
#[derive(Clone, PartialEq, Message)]
pub struct EgmSensorPathCorr {
    #[prost(message, optional, tag = "1")]
    pub header: Option<EgmHeader>,
    #[prost(message, optional, tag = "2")]
    pub path_corr: Option<EgmPathCorr>,
}
