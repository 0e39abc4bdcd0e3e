//! ABB Externally Guided Motion (EGM) over UDP: the controller streams `EgmRobot` feedback
//! (typically every 4 ms) to a configured address and port; the PC answers each with an
//! `EgmSensor` correction (a planned Cartesian pose and a speed reference) sent back to the
//! address the feedback came from.
//!
//! Codecs with validation for both directions, on preallocated messages and buffers: after
//! construction, decoding a valid datagram and encoding never allocate (repeated fields keep
//! capacity for the largest datagram accepted, [`EGM_MAX_DATAGRAM`]). A datagram that `prost`
//! rejects is the one path that allocates (prost boxes its error); it is counted and dropped.
//!
//! Validation: size (1..=[`EGM_MAX_DATAGRAM`] bytes), a header with a sequence number and the
//! right message type (`MSGTYPE_DATA` from the robot, `MSGTYPE_CORRECTION` from the PC), a
//! Cartesian pose with position and quaternion, all finite, positions within
//! [`EGM_MAX_POSITION_MM`], quaternion norm within [`QUATERNION_TOLERANCE`] of 1.
//!
//! Feedback of both `egm.proto` generations decodes: RobotWare 6 and 7 differ, for the fields
//! a controller sends, only in `EgmMeasuredForce`, whose field 1 is RobotWare 6's `force` and
//! RobotWare 7's `fcActive`; [`EgmMeasuredForce`] tells them apart by wire type (see
//! [`super::proto`]). The measured force is reported when it has six finite values; it is
//! not validated further, as the loop does not use it.

use prost::Message;
use thiserror::Error;

use super::proto::*;
use crate::devices::pose::{PoseMm, TargetMm};

/// Default UDP port of the PC side (the port the controller's EGM transmission is configured to).
pub const EGM_PORT: u16 = 6510;
/// Largest datagram accepted, bytes (a feedback message is about 200 bytes).
pub const EGM_MAX_DATAGRAM: usize = 1400;
/// The controller's EGM period, s (250 Hz).
pub const EGM_PERIOD: f64 = 0.004;
/// Largest accepted coordinate, mm (100 m).
pub const EGM_MAX_POSITION_MM: f64 = 1.0e5;
/// Largest accepted speed component, mm/s or deg/s.
pub const EGM_MAX_SPEED: f64 = 1.0e5;
/// Accepted deviation of a quaternion's norm from 1.
pub const QUATERNION_TOLERANCE: f64 = 1.0e-3;

/// Capacity of each repeated field: more doubles than the largest datagram can hold.
const REPEATED_CAPACITY: usize = EGM_MAX_DATAGRAM / 8 + 1;

/// Why an EGM datagram was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum EgmError {
    /// Empty or larger than [`EGM_MAX_DATAGRAM`].
    #[error("wrong size: {0} bytes")]
    WrongSize(usize),
    /// Not a valid protobuf encoding of the message.
    #[error("not a valid protobuf message")]
    Decode,
    /// No header or no sequence number.
    #[error("no header sequence number")]
    MissingHeader,
    /// The header's message type is not the expected one.
    #[error("message type {0}")]
    WrongType(i32),
    /// No Cartesian pose (position and quaternion), e.g. a joint-space message.
    #[error("no cartesian pose")]
    MissingPose,
    /// A NaN or infinite value.
    #[error("a value is not finite")]
    NonFinite,
    /// A position or speed beyond the accepted range.
    #[error("a value is out of range")]
    OutOfRange,
    /// The quaternion is not of unit norm.
    #[error("quaternion norm is not 1")]
    BadQuaternion,
}

/// What the runtime reads from an `EgmRobot` message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotFeedback {
    /// Header sequence number.
    pub seqno: u32,
    /// Header time stamp, ms.
    pub tm_ms: u32,
    /// `feedBack.time` in seconds, if sent.
    pub clock: Option<f64>,
    /// The actual (measured) pose.
    pub actual: PoseMm,
    /// The planned pose, if sent.
    pub planned: Option<PoseMm>,
    /// Motors on (`None` if not sent).
    pub motors_on: Option<bool>,
    /// `measuredForce`, `[Fx, Fy, Fz, Tx, Ty, Tz]` (N, N·m) in either generation's layout;
    /// `None` unless sent with exactly six finite values.
    pub measured_force: Option<[f64; 6]>,
}

impl RobotFeedback {
    /// The robot's time of the feedback, s: `feedBack.time` if sent, else the header's `tm`.
    pub fn robot_time(&self) -> f64 {
        self.clock.unwrap_or(self.tm_ms as f64 * 1e-3)
    }
}

/// What the emulated robot reads from an `EgmSensor` message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    /// Header sequence number.
    pub seqno: u32,
    /// The commanded pose and speed reference (zero speed if none was sent).
    pub target: TargetMm,
}

fn repeated() -> Vec<f64> {
    Vec::with_capacity(REPEATED_CAPACITY)
}

fn joints() -> Option<EgmJoints> {
    Some(EgmJoints { joints: repeated() })
}

fn clear_joints(j: &mut Option<EgmJoints>) {
    match j {
        Some(j) => j.joints.clear(),
        None => *j = joints(),
    }
}

/// An empty [`EgmPlanned`] (or [`EgmFeedBack`]) with room for joints.
fn planned() -> EgmPlanned {
    EgmPlanned {
        joints: joints(),
        cartesian: None,
        external_joints: joints(),
        time: None,
    }
}

/// Empties an [`EgmPlanned`] (or [`EgmFeedBack`]) in place, keeping its buffers.
fn clear_planned(p: &mut Option<EgmPlanned>) {
    let p = p.get_or_insert_with(planned);
    clear_joints(&mut p.joints);
    clear_joints(&mut p.external_joints);
    p.cartesian = None;
    p.time = None;
}

/// Empties RAPID data in place, keeping its buffer (no allocation once it exists).
fn clear_rapid(r: &mut Option<EgmRapiDdata>) {
    let r = r.get_or_insert_with(|| EgmRapiDdata {
        dig_val: None,
        dnum: repeated(),
    });
    r.dig_val = None;
    r.dnum.clear();
}

fn check_pose(pose: &EgmPose) -> Result<PoseMm, EgmError> {
    let (Some(p), Some(q)) = (pose.pos, pose.orient) else {
        return Err(EgmError::MissingPose);
    };
    let position_mm = [p.x, p.y, p.z];
    let orientation = [q.u0, q.u1, q.u2, q.u3];
    if !position_mm
        .iter()
        .chain(orientation.iter())
        .all(|v| v.is_finite())
    {
        return Err(EgmError::NonFinite);
    }
    if position_mm.iter().any(|v| v.abs() > EGM_MAX_POSITION_MM) {
        return Err(EgmError::OutOfRange);
    }
    let norm = orientation.iter().map(|v| v * v).sum::<f64>().sqrt();
    if (norm - 1.0).abs() > QUATERNION_TOLERANCE {
        return Err(EgmError::BadQuaternion);
    }
    Ok(PoseMm {
        position_mm,
        orientation: orientation.map(|v| v / norm),
    })
}

fn check_header(header: &Option<EgmHeader>, expected: MessageType) -> Result<(u32, u32), EgmError> {
    let Some(h) = header else {
        return Err(EgmError::MissingHeader);
    };
    let Some(seqno) = h.seqno else {
        return Err(EgmError::MissingHeader);
    };
    let mtype = h.mtype.unwrap_or(MessageType::Undefined as i32);
    if mtype != expected as i32 {
        return Err(EgmError::WrongType(mtype));
    }
    Ok((seqno, h.tm.unwrap_or(0)))
}

/// Six finite values as an array, else None.
fn six_finite(values: &[f64]) -> Option<[f64; 6]> {
    let six: [f64; 6] = values.try_into().ok()?;
    six.iter().all(|v| v.is_finite()).then_some(six)
}

fn check_size(datagram: &[u8]) -> Result<(), EgmError> {
    if datagram.is_empty() || datagram.len() > EGM_MAX_DATAGRAM {
        Err(EgmError::WrongSize(datagram.len()))
    } else {
        Ok(())
    }
}

/// `Default` as `new()` (with the buffers allocated) for the decoders and encoders below.
macro_rules! default_is_new {
    ($($name:ident),+) => {
        $(impl Default for $name {
            fn default() -> Self {
                Self::new()
            }
        })+
    };
}
default_is_new!(
    RobotDecoder,
    CorrectionDecoder,
    CorrectionEncoder,
    FeedbackEncoder
);

/// Decodes `EgmRobot` feedback into a preallocated message.
pub struct RobotDecoder {
    msg: EgmRobot,
}

impl RobotDecoder {
    /// A decoder with room for the largest accepted datagram.
    pub fn new() -> Self {
        let msg = EgmRobot {
            feed_back: Some(planned()),
            planned: Some(planned()),
            test_signals: Some(EgmTestSignals {
                signals: repeated(),
            }),
            measured_force: Some(EgmMeasuredForce {
                fc_active: None,
                force: repeated(),
            }),
            collision_info: Some(EgmCollisionInfo {
                collsion_triggered: None,
                coll_det_quota: repeated(),
            }),
            rapid_from_robot: Some(EgmRapiDdata {
                dig_val: None,
                dnum: repeated(),
            }),
            ..Default::default()
        };
        RobotDecoder { msg }
    }

    /// Forgets the last message's values, keeping every repeated field's capacity.
    fn reset(&mut self) {
        let m = &mut self.msg;
        m.header = None;
        m.motor_state = None;
        m.mci_state = None;
        m.mci_convergence_met = None;
        m.rapid_exec_state = None;
        m.utilization_rate = None;
        m.move_index = None;
        clear_planned(&mut m.feed_back);
        clear_planned(&mut m.planned);
        m.test_signals
            .get_or_insert_with(|| EgmTestSignals {
                signals: repeated(),
            })
            .signals
            .clear();
        let f = m.measured_force.get_or_insert_with(|| EgmMeasuredForce {
            fc_active: None,
            force: repeated(),
        });
        f.fc_active = None;
        f.force.clear();
        let c = m.collision_info.get_or_insert_with(|| EgmCollisionInfo {
            collsion_triggered: None,
            coll_det_quota: repeated(),
        });
        c.collsion_triggered = None;
        c.coll_det_quota.clear();
        clear_rapid(&mut m.rapid_from_robot);
    }

    /// Decodes and validates one datagram.
    pub fn decode(&mut self, datagram: &[u8]) -> Result<RobotFeedback, EgmError> {
        check_size(datagram)?;
        self.reset();
        self.msg.merge(datagram).map_err(|_| EgmError::Decode)?;
        let m = &self.msg;
        let (seqno, tm_ms) = check_header(&m.header, MessageType::Data)?;
        let fb = m.feed_back.as_ref().ok_or(EgmError::MissingPose)?;
        let actual = check_pose(fb.cartesian.as_ref().ok_or(EgmError::MissingPose)?)?;
        let clock = fb.time.map(|c| c.sec as f64 + c.usec as f64 * 1e-6);
        if clock.is_some_and(|c| !c.is_finite()) {
            return Err(EgmError::NonFinite);
        }
        let planned = match m.planned.as_ref().and_then(|p| p.cartesian.as_ref()) {
            Some(pose) => Some(check_pose(pose)?),
            None => None,
        };
        let motors_on = m
            .motor_state
            .map(|s| s.state == MotorStateType::MotorsOn as i32);
        let measured_force = m.measured_force.as_ref().and_then(|f| six_finite(&f.force));
        Ok(RobotFeedback {
            seqno,
            tm_ms,
            clock,
            actual,
            planned,
            motors_on,
            measured_force,
        })
    }
}

/// Decodes `EgmSensor` corrections into a preallocated message (the robot's side).
pub struct CorrectionDecoder {
    msg: EgmSensor,
}

impl CorrectionDecoder {
    /// A decoder with room for the largest accepted datagram.
    pub fn new() -> Self {
        CorrectionDecoder {
            msg: EgmSensor {
                header: None,
                planned: Some(planned()),
                speed_ref: Some(EgmSpeedRef {
                    joints: joints(),
                    cartesians: Some(EgmCartesianSpeed { value: repeated() }),
                    external_joints: joints(),
                }),
                rapid_to_robot: Some(EgmRapiDdata {
                    dig_val: None,
                    dnum: repeated(),
                }),
            },
        }
    }

    fn reset(&mut self) {
        let m = &mut self.msg;
        m.header = None;
        clear_planned(&mut m.planned);
        let s = m.speed_ref.get_or_insert_with(|| EgmSpeedRef {
            joints: joints(),
            cartesians: None,
            external_joints: joints(),
        });
        clear_joints(&mut s.joints);
        clear_joints(&mut s.external_joints);
        match &mut s.cartesians {
            Some(c) => c.value.clear(),
            None => s.cartesians = Some(EgmCartesianSpeed { value: repeated() }),
        }
        clear_rapid(&mut m.rapid_to_robot);
    }

    /// Decodes and validates one datagram. A speed reference other than 6 values (or none)
    /// gives zero speed.
    pub fn decode(&mut self, datagram: &[u8]) -> Result<Correction, EgmError> {
        check_size(datagram)?;
        self.reset();
        self.msg.merge(datagram).map_err(|_| EgmError::Decode)?;
        let m = &self.msg;
        let (seqno, _) = check_header(&m.header, MessageType::Correction)?;
        let pose = check_pose(
            m.planned
                .as_ref()
                .and_then(|p| p.cartesian.as_ref())
                .ok_or(EgmError::MissingPose)?,
        )?;
        let mut speed = [0.0; 6];
        if let Some(values) = m
            .speed_ref
            .as_ref()
            .and_then(|s| s.cartesians.as_ref())
            .map(|c| &c.value)
        {
            if values.len() == 6 {
                if !values.iter().all(|v| v.is_finite()) {
                    return Err(EgmError::NonFinite);
                }
                if values.iter().any(|v| v.abs() > EGM_MAX_SPEED) {
                    return Err(EgmError::OutOfRange);
                }
                speed.copy_from_slice(values);
            }
        }
        Ok(Correction {
            seqno,
            target: TargetMm { pose, speed },
        })
    }
}

/// A pose and a time without joints, as the emulated robot sends its feedback and plan.
fn clocked_pose() -> EgmPlanned {
    EgmPlanned {
        joints: None,
        cartesian: None,
        external_joints: None,
        time: Some(EgmClock { sec: 0, usec: 0 }),
    }
}

fn pose_message(p: &PoseMm) -> EgmPose {
    let [x, y, z] = p.position_mm;
    let [u0, u1, u2, u3] = p.orientation;
    EgmPose {
        pos: Some(EgmCartesian { x, y, z }),
        orient: Some(EgmQuaternion { u0, u1, u2, u3 }),
        euler: None,
    }
}

/// Encodes `EgmSensor` corrections (the PC's side) into a preallocated buffer.
pub struct CorrectionEncoder {
    msg: EgmSensor,
    buf: Vec<u8>,
}

impl CorrectionEncoder {
    /// An encoder with its message and buffer allocated.
    pub fn new() -> Self {
        let msg = EgmSensor {
            header: Some(EgmHeader {
                seqno: Some(0),
                tm: Some(0),
                mtype: Some(MessageType::Correction as i32),
            }),
            planned: Some(EgmPlanned {
                joints: None,
                cartesian: Some(pose_message(&PoseMm::default())),
                external_joints: None,
                time: None,
            }),
            speed_ref: Some(EgmSpeedRef {
                joints: None,
                cartesians: Some(EgmCartesianSpeed {
                    value: Vec::with_capacity(6),
                }),
                external_joints: None,
            }),
            rapid_to_robot: None,
        };
        CorrectionEncoder {
            msg,
            buf: Vec::with_capacity(EGM_MAX_DATAGRAM),
        }
    }

    /// The datagram of a correction: sequence number, time stamp (ms) and target.
    pub fn encode(&mut self, seqno: u32, tm_ms: u32, target: &TargetMm) -> &[u8] {
        if let Some(h) = self.msg.header.as_mut() {
            h.seqno = Some(seqno);
            h.tm = Some(tm_ms);
        }
        if let Some(p) = self.msg.planned.as_mut() {
            p.cartesian = Some(pose_message(&target.pose));
        }
        if let Some(c) = self
            .msg
            .speed_ref
            .as_mut()
            .and_then(|s| s.cartesians.as_mut())
        {
            c.value.clear();
            c.value.extend_from_slice(&target.speed);
        }
        self.buf.clear();
        // Encoding into a Vec with enough capacity cannot fail; a failure would leave it empty.
        let _ = self.msg.encode(&mut self.buf);
        &self.buf
    }
}

/// Encodes `EgmRobot` feedback (the emulated controller's side) into a preallocated buffer.
pub struct FeedbackEncoder {
    msg: EgmRobot,
    /// RobotWare 6's `measuredForce`, sent after the other fields (None: RobotWare 7 feedback,
    /// without a measured force).
    measured_force_rw6: Option<EgmMeasuredForceRw6>,
    buf: Vec<u8>,
}

impl FeedbackEncoder {
    /// An encoder with its message and buffer allocated. The emulated robot has no joint
    /// model, so joints are not sent; motors are on, MCI and RAPID running.
    pub fn new() -> Self {
        let msg = EgmRobot {
            header: Some(EgmHeader {
                seqno: Some(0),
                tm: Some(0),
                mtype: Some(MessageType::Data as i32),
            }),
            feed_back: Some(clocked_pose()),
            planned: Some(clocked_pose()),
            motor_state: Some(EgmMotorState {
                state: MotorStateType::MotorsOn as i32,
            }),
            mci_state: Some(EgmMciState {
                state: MciStateType::MciRunning as i32,
            }),
            mci_convergence_met: Some(true),
            rapid_exec_state: Some(EgmRapidCtrlExecState {
                state: RapidCtrlExecStateType::RapidRunning as i32,
            }),
            utilization_rate: Some(0.0),
            ..Default::default()
        };
        FeedbackEncoder {
            msg,
            measured_force_rw6: None,
            buf: Vec::with_capacity(EGM_MAX_DATAGRAM),
        }
    }

    /// An encoder of a RobotWare 6 controller's feedback: as [`FeedbackEncoder::new`], plus
    /// `measuredForce` in RobotWare 6's layout (`repeated double force = 1`, six zeros: the
    /// emulated robot has no force control), which RobotWare 7's `egm.proto` cannot decode.
    pub fn robotware6() -> Self {
        FeedbackEncoder {
            measured_force_rw6: Some(EgmMeasuredForceRw6 {
                force: vec![0.0; 6],
            }),
            ..Self::new()
        }
    }

    /// The datagram of a feedback message: sequence number, time stamp (ms), controller time
    /// (µs), actual and planned pose.
    pub fn encode(&mut self, seqno: u32, time_us: u64, actual: &PoseMm, planned: &PoseMm) -> &[u8] {
        let clock = EgmClock {
            sec: time_us / 1_000_000,
            usec: time_us % 1_000_000,
        };
        if let Some(h) = self.msg.header.as_mut() {
            h.seqno = Some(seqno);
            h.tm = Some((time_us / 1000) as u32);
        }
        for (message, pose) in [
            (&mut self.msg.feed_back, actual),
            (&mut self.msg.planned, planned),
        ] {
            if let Some(m) = message.as_mut() {
                m.cartesian = Some(pose_message(pose));
                m.time = Some(clock);
            }
        }
        self.buf.clear();
        let _ = self.msg.encode(&mut self.buf);
        if let Some(force) = &self.measured_force_rw6 {
            // field 9 after field 10: protobuf fields may come in any order
            prost::encoding::message::encode(9, force, &mut self.buf);
        }
        &self.buf
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn pose(x: f64) -> PoseMm {
        PoseMm {
            position_mm: [x, 2.0, -3.0],
            orientation: [1.0, 0.0, 0.0, 0.0],
        }
    }

    #[test]
    fn feedback_round_trips() {
        let mut enc = FeedbackEncoder::new();
        let bytes = enc
            .encode(42, 1_234_567, &pose(-995.0), &pose(-990.0))
            .to_vec();
        let mut dec = RobotDecoder::new();
        let fb = dec.decode(&bytes).unwrap();
        assert_eq!(fb.seqno, 42);
        assert_eq!(fb.tm_ms, 1234);
        assert!((fb.robot_time() - 1.234567).abs() < 1e-12);
        assert_eq!(fb.actual, pose(-995.0));
        assert_eq!(fb.planned, Some(pose(-990.0)));
        assert_eq!(fb.motors_on, Some(true));
    }

    #[test]
    fn correction_round_trips_and_decoder_forgets_old_values() {
        let mut enc = CorrectionEncoder::new();
        let target = TargetMm {
            pose: pose(5.0),
            speed: [20.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        };
        let bytes = enc.encode(7, 100, &target).to_vec();
        let mut dec = CorrectionDecoder::new();
        assert_eq!(dec.decode(&bytes).unwrap(), Correction { seqno: 7, target });
        // a second message without speed reference: zero speed, not the previous one
        let mut m = EgmSensor::decode(&bytes[..]).unwrap();
        m.speed_ref = None;
        assert_eq!(
            dec.decode(&m.encode_to_vec()).unwrap().target.speed,
            [0.0; 6]
        );
    }

    #[test]
    fn malformed_feedback_is_rejected() {
        let mut dec = RobotDecoder::new();
        let mut enc = FeedbackEncoder::new();
        let good = enc.encode(1, 0, &pose(1.0), &pose(1.0)).to_vec();
        assert_eq!(dec.decode(&[]), Err(EgmError::WrongSize(0)));
        assert_eq!(
            dec.decode(&vec![0u8; EGM_MAX_DATAGRAM + 1]),
            Err(EgmError::WrongSize(EGM_MAX_DATAGRAM + 1))
        );
        assert_eq!(dec.decode(&good[..good.len() - 3]), Err(EgmError::Decode));
        let edit = |f: &dyn Fn(&mut EgmRobot)| {
            let mut m = EgmRobot::decode(&good[..]).unwrap();
            f(&mut m);
            m.encode_to_vec()
        };
        let d = |b: Vec<u8>| RobotDecoder::new().decode(&b);
        fn cartesian(m: &mut EgmRobot) -> &mut EgmPose {
            m.feed_back.as_mut().unwrap().cartesian.as_mut().unwrap()
        }
        assert_eq!(d(edit(&|m| m.header = None)), Err(EgmError::MissingHeader));
        assert_eq!(
            d(edit(&|m| m.header.as_mut().unwrap().mtype = Some(3))),
            Err(EgmError::WrongType(3))
        );
        assert_eq!(d(edit(&|m| m.feed_back = None)), Err(EgmError::MissingPose));
        assert_eq!(
            d(edit(&|m| cartesian(m).pos.as_mut().unwrap().x = f64::NAN)),
            Err(EgmError::NonFinite)
        );
        assert_eq!(
            d(edit(&|m| cartesian(m).pos.as_mut().unwrap().y = 2e5)),
            Err(EgmError::OutOfRange)
        );
        assert_eq!(
            d(edit(&|m| cartesian(m).orient.as_mut().unwrap().u0 = 0.5)),
            Err(EgmError::BadQuaternion)
        );
        // an RDT record is not EGM (a default one: 36 zero bytes)
        assert!(d(vec![0u8; 36]).is_err());
        // the decoder still works after errors
        assert!(dec.decode(&good).is_ok());
    }

    /// An `EgmRobot` datagram from `FeedbackEncoder` (no measured force) with `body` (an
    /// encoded `measuredForce` body) appended as field 9.
    fn with_measured_force(seqno: u32, body: &[u8]) -> Vec<u8> {
        let mut bytes = FeedbackEncoder::new()
            .encode(seqno, 8000, &pose(-995.0), &pose(-990.0))
            .to_vec();
        prost::encoding::bytes::encode(9, &body.to_vec(), &mut bytes);
        bytes
    }

    const FORCE: [f64; 6] = [1.5, -2.0, 30.25, 0.1, -0.2, 0.0];

    #[test]
    fn current_proto_measured_force_decodes() {
        // RobotWare 7: measuredForce { fcActive = 1; force = 2 }
        let mut enc = FeedbackEncoder::new();
        let mut m = EgmRobot::decode(enc.encode(3, 0, &pose(1.0), &pose(1.0))).unwrap();
        m.measured_force = Some(EgmMeasuredForce {
            fc_active: Some(true),
            force: FORCE.to_vec(),
        });
        m.move_index = Some(9);
        let fb = RobotDecoder::new().decode(&m.encode_to_vec()).unwrap();
        assert_eq!(fb.seqno, 3);
        assert_eq!(fb.actual, pose(1.0));
        assert_eq!(fb.measured_force, Some(FORCE));
        // the hand-written message round-trips in RobotWare 7's layout, fcActive false included
        for fc_active in [Some(true), Some(false), None] {
            let f = EgmMeasuredForce {
                fc_active,
                force: FORCE.to_vec(),
            };
            let bytes = f.encode_to_vec();
            assert_eq!(bytes.len(), f.encoded_len());
            assert_eq!(EgmMeasuredForce::decode(&bytes[..]).unwrap(), f);
        }
        // packed RobotWare 7 forces decode too
        let mut body = Vec::new();
        prost::encoding::bool::encode(1, &false, &mut body);
        prost::encoding::double::encode_packed(2, &FORCE, &mut body);
        let fb = RobotDecoder::new()
            .decode(&with_measured_force(4, &body))
            .unwrap();
        assert_eq!(fb.measured_force, Some(FORCE));
    }

    #[test]
    fn robotware6_measured_force_decodes_unpacked_and_packed() {
        // RobotWare 6: measuredForce { repeated double force = 1 }, unpacked (wire type 1, as
        // proto2 encodes it) and packed (wire type 2)
        let unpacked = EgmMeasuredForceRw6 {
            force: FORCE.to_vec(),
        }
        .encode_to_vec();
        assert_eq!(unpacked[0], (1 << 3) | 1);
        let mut packed = Vec::new();
        prost::encoding::double::encode_packed(1, &FORCE, &mut packed);
        assert_eq!(packed[0], (1 << 3) | 2);
        let mut dec = RobotDecoder::new();
        for (seqno, body) in [(1, &unpacked), (2, &packed)] {
            let fb = dec.decode(&with_measured_force(seqno, body)).unwrap();
            assert_eq!(fb.seqno, seqno);
            assert_eq!(fb.tm_ms, 8);
            assert_eq!(fb.actual, pose(-995.0));
            assert_eq!(fb.planned, Some(pose(-990.0)));
            assert_eq!(fb.measured_force, Some(FORCE));
            assert_eq!(dec.msg.measured_force.as_ref().unwrap().fc_active, None);
        }
        // the emulated RobotWare 6 controller's feedback decodes (zero force)
        let bytes = FeedbackEncoder::robotware6()
            .encode(7, 4000, &pose(-995.0), &pose(-995.0))
            .to_vec();
        let fb = dec.decode(&bytes).unwrap();
        assert_eq!((fb.seqno, fb.actual), (7, pose(-995.0)));
        assert_eq!(fb.measured_force, Some([0.0; 6]));
    }

    /// RobotWare 7's `EgmMeasuredForce` as a `prost` derive would decode it (the definition
    /// before both generations were accepted).
    #[derive(Clone, PartialEq, Message)]
    struct DerivedRw7Force {
        #[prost(bool, optional, tag = "1")]
        fc_active: Option<bool>,
        #[prost(double, repeated, packed = "false", tag = "2")]
        force: Vec<f64>,
    }

    #[derive(Clone, PartialEq, Message)]
    struct DerivedRw7Robot {
        #[prost(message, optional, tag = "9")]
        measured_force: Option<DerivedRw7Force>,
    }

    #[test]
    fn robotware6_feedback_is_what_a_derived_robotware7_proto_rejects() {
        let rw6 = FeedbackEncoder::robotware6()
            .encode(1, 0, &pose(1.0), &pose(1.0))
            .to_vec();
        assert!(DerivedRw7Robot::decode(&rw6[..]).is_err());
        let rw7 = FeedbackEncoder::new()
            .encode(1, 0, &pose(1.0), &pose(1.0))
            .to_vec();
        assert!(DerivedRw7Robot::decode(&rw7[..]).is_ok());
        assert!(RobotDecoder::new().decode(&rw6).is_ok());
    }

    #[test]
    fn bad_measured_force_is_rejected_or_left_out() {
        let d = |body: &[u8]| RobotDecoder::new().decode(&with_measured_force(1, body));
        // field 1 neither a bool nor doubles: 32-bit, a start group, packed doubles of a
        // length that is not a multiple of 8, a truncated varint
        let mut fixed32 = Vec::new();
        prost::encoding::float::encode(1, &1.0, &mut fixed32);
        for garbage in [
            &fixed32[..],
            &[(1 << 3) | 3, (1 << 3) | 4][..],
            &[(1 << 3) | 2, 5, 0, 0, 0, 0, 0][..],
            &[(1 << 3) | 2, 9, 0, 0, 0, 0, 0, 0, 0, 0, 0][..],
            &[1 << 3, 0x80][..],
            &[(1 << 3) | 1, 0, 0, 0][..],
        ] {
            assert_eq!(d(garbage), Err(EgmError::Decode), "{garbage:?}");
        }
        // well-formed but not six finite values: the pose is used, the force left out
        let five = EgmMeasuredForceRw6 {
            force: FORCE[..5].to_vec(),
        }
        .encode_to_vec();
        let mut nan = FORCE;
        nan[2] = f64::NAN;
        let nan = EgmMeasuredForceRw6 {
            force: nan.to_vec(),
        }
        .encode_to_vec();
        for body in [&five, &nan] {
            let fb = d(body).unwrap();
            assert_eq!((fb.actual, fb.measured_force), (pose(-995.0), None));
        }
    }

    #[test]
    fn decoder_forgets_the_measured_force_and_keeps_its_buffer() {
        let mut dec = RobotDecoder::new();
        let force = |dec: &RobotDecoder| dec.msg.measured_force.as_ref().unwrap().force.as_ptr();
        let buffer = force(&dec);
        let rw6 = with_measured_force(
            1,
            &EgmMeasuredForceRw6 {
                force: FORCE.to_vec(),
            }
            .encode_to_vec(),
        );
        assert_eq!(dec.decode(&rw6).unwrap().measured_force, Some(FORCE));
        let plain = FeedbackEncoder::new()
            .encode(2, 0, &pose(1.0), &pose(1.0))
            .to_vec();
        assert_eq!(dec.decode(&plain).unwrap().measured_force, None);
        // a force field of nearly as many doubles as a datagram can hold: no reallocation
        let mut body = Vec::new();
        prost::encoding::double::encode_packed(1, &[0.5; 140], &mut body);
        let big = with_measured_force(3, &body);
        assert!(big.len() <= EGM_MAX_DATAGRAM);
        assert_eq!(dec.decode(&big).unwrap().measured_force, None);
        assert_eq!(force(&dec), buffer);
    }

    proptest! {
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let _ = RobotDecoder::new().decode(&bytes);
            let _ = CorrectionDecoder::new().decode(&bytes);
        }

        #[test]
        fn mutated_feedback_never_panics_and_stays_valid_when_accepted(flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6)) {
            let mut enc = FeedbackEncoder::new();
            let mut bytes = enc.encode(5, 4000, &pose(-995.0), &pose(-995.0)).to_vec();
            for (i, v) in flips {
                let i = i.index(bytes.len());
                bytes[i] = v;
            }
            if let Ok(fb) = RobotDecoder::new().decode(&bytes) {
                prop_assert!(fb.actual.position_mm.iter().all(|v| v.is_finite() && v.abs() <= EGM_MAX_POSITION_MM));
                let n: f64 = fb.actual.orientation.iter().map(|v| v * v).sum::<f64>().sqrt();
                prop_assert!((n - 1.0).abs() < 1e-9);
            }
        }
    }
}
