//! ABB's `egm.proto` (package `abb.egm`, proto2) as `prost` messages.
//!
//! Field numbers, types and labels follow the `egm.proto` that ships with RobotWare 7 (and with
//! the `abb-robot-client` Python package, whose compiled descriptor was used to check every
//! tag). The `abbegm` crate carries an older revision in which `EgmMeasuredForce.force` has
//! tag 1 (now `fcActive`) and `EgmRobot` stops at tag 10, so a current controller's message
//! with a measured force would not decode with it; hence these definitions, encoded and
//! decoded by `prost` (no hand-written wire code).

#![allow(missing_docs)] // the names are ABB's; each message says what it is

use prost::{Enumeration, Message};

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

/// Euler angles, degrees.
#[derive(Clone, Copy, PartialEq, Message)]
pub struct EgmEuler {
    #[prost(double, required, tag = "1")]
    pub x: f64,
    #[prost(double, required, tag = "2")]
    pub y: f64,
    #[prost(double, required, tag = "3")]
    pub z: f64,
}

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

/// Planned (commanded) position: joints or pose.
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

/// Measured (actual) position of the robot.
#[derive(Clone, PartialEq, Message)]
pub struct EgmFeedBack {
    #[prost(message, optional, tag = "1")]
    pub joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "2")]
    pub cartesian: Option<EgmPose>,
    #[prost(message, optional, tag = "3")]
    pub external_joints: Option<EgmJoints>,
    #[prost(message, optional, tag = "4")]
    pub time: Option<EgmClock>,
}

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

/// Force measured by the controller's force control.
#[derive(Clone, PartialEq, Message)]
pub struct EgmMeasuredForce {
    #[prost(bool, optional, tag = "1")]
    pub fc_active: Option<bool>,
    #[prost(double, repeated, packed = "false", tag = "2")]
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
