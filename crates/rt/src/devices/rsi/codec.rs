//! KUKA RobotSensorInterface (RSI) over Ethernet (the RSI context's `ETHERNET` object, RSI
//! 3.x / 4.x): the XML codec of both directions.
//!
//! Every interpolation cycle (IPO_FAST: 4 ms; or 12 ms) the controller sends its state to the
//! PC over UDP, and the PC must answer each message with its correction, echoing the
//! message's `<IPOC>` time stamp, before the controller's deadline:
//!
//! ```text
//! robot → PC   <Rob Type="KUKA"><RIst X="…" Y="…" Z="…" A="…" B="…" C="…"/><RSol …/>
//!              <Delay D="0"/><IPOC>4711</IPOC></Rob>
//! PC → robot   <Sen Type="ImFree"><RKorr X="…" Y="…" Z="…" A="…" B="…" C="…"/><IPOC>4711</IPOC></Sen>
//! ```
//!
//! Poses and corrections are Cartesian: X, Y, Z in mm, A, B, C in degrees, rotations about Z,
//! Y and X (KUKA's ZYX Euler angles: `R = Rz(A)·Ry(B)·Rx(C)`, [`abc_to_quaternion`]). The
//! element names and the `Type` attribute come from the controller's ETHERNET configuration
//! file (`SENTYPE`, the `SEND`/`RECEIVE` element tags), so they are parameters here
//! ([`RsiNames`]).
//!
//! The scanner reads only what the link needs (the root, the state element's six attributes,
//! the optional `RSol` and `Delay`, the `IPOC`) straight from the received bytes; encoding
//! writes into a fixed buffer. Neither allocates. Validation: the root element, the pose
//! element with its six attributes as numbers, an `IPOC` of digits (all [`RsiError`]s but
//! [`RsiError::NonFinite`] mean a malformed datagram); every number finite and within
//! [`RSI_MAX_VALUE`].

use crate::devices::transport::DecodeError;
use std::io::Write;

use nalgebra::UnitQuaternion;
use thiserror::Error;

/// Default UDP port of the PC side (the `PORT` of the ETHERNET configuration file).
pub const RSI_PORT: u16 = 59152;
/// The controller's default cycle, s (IPO_FAST, 250 Hz).
pub const RSI_PERIOD: f64 = 0.004;
/// The cycles a controller offers, s (IPO_FAST 4 ms, IPO 12 ms).
pub const RSI_PERIODS: [f64; 2] = [0.004, 0.012];
/// Largest datagram accepted, bytes (a state message with joints and I/O is under 1 kB).
pub const RSI_MAX_DATAGRAM: usize = 4096;
/// Largest accepted coordinate, mm or degrees (100 m).
pub const RSI_MAX_VALUE: f64 = 1.0e5;
/// Longest element name or `Type` accepted in the options, characters.
pub const RSI_MAX_NAME: usize = 32;
/// Size of an encoder's buffer, bytes: six numbers within [`RSI_MAX_VALUE`] and names of at
/// most [`RSI_MAX_NAME`] fit many times over.
const ENCODE_CAPACITY: usize = 1024;

/// Why an RSI datagram was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum RsiError {
    /// Empty or larger than [`RSI_MAX_DATAGRAM`].
    #[error("wrong size: {0} bytes")]
    WrongSize(usize),
    /// The root element (`Rob` from the robot, `Sen` from the PC) is missing.
    #[error("no root element")]
    MissingRoot,
    /// The `Type` attribute of `Sen` is not the configured one.
    #[error("wrong Type")]
    WrongType,
    /// The pose element (`RIst`, `RKorr`, …) is missing or lacks one of X, Y, Z, A, B, C.
    #[error("no pose element")]
    MissingPose,
    /// A number does not parse.
    #[error("not a number")]
    BadNumber,
    /// No `<IPOC>` of digits.
    #[error("no IPOC")]
    MissingIpoc,
    /// A value is not finite or beyond [`RSI_MAX_VALUE`].
    #[error("non-finite or out-of-range value")]
    NonFinite,
}

/// RSI decoding errors as the counters see them: every error but non-finite values is a
/// malformed datagram.
impl DecodeError for RsiError {
    fn is_malformed(&self) -> bool {
        !matches!(self, RsiError::NonFinite)
    }
}

/// The names the controller's ETHERNET configuration file gives the messages' parts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RsiNames {
    /// `Type` of the PC's `<Sen>` (the file's `SENTYPE`, e.g. `ImFree`).
    pub sen_type: String,
    /// The robot's Cartesian actual pose element (`DEF_RIst`: `RIst`).
    pub state: String,
    /// The PC's Cartesian correction element (the `RECEIVE` tags `RKorr.X` …: `RKorr`).
    pub correction: String,
}

impl Default for RsiNames {
    fn default() -> Self {
        RsiNames {
            sen_type: "ImFree".into(),
            state: "RIst".into(),
            correction: "RKorr".into(),
        }
    }
}

impl RsiNames {
    /// Checks that every name is an XML name of 1..=[`RSI_MAX_NAME`] ASCII letters, digits,
    /// `_`, `-` or `.` starting with a letter; returns the offending option and value.
    pub fn validate(&self) -> std::result::Result<(), (&'static str, String)> {
        for (key, name) in [
            ("sen_type", &self.sen_type),
            ("state_element", &self.state),
            ("correction_element", &self.correction),
        ] {
            let ok = !name.is_empty()
                && name.len() <= RSI_MAX_NAME
                && name.as_bytes()[0].is_ascii_alphabetic()
                && name
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-' || b == b'.');
            if !ok {
                return Err((key, name.clone()));
            }
        }
        Ok(())
    }
}

/// A Cartesian pose or correction: `[X, Y, Z]` mm, then `[A, B, C]` degrees.
pub type KukaPose = [f64; 6];

/// The robot's state message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RsiState {
    /// The actual pose (`RIst`), mm and degrees.
    pub actual: KukaPose,
    /// The setpoint pose (`RSol`), if sent.
    pub setpoint: Option<KukaPose>,
    /// The controller's count of late answers (`Delay D`), if sent.
    pub delay: Option<u64>,
    /// The time stamp to echo.
    pub ipoc: u64,
}

/// The PC's answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RsiAnswer {
    /// The correction, mm and degrees.
    pub correction: KukaPose,
    /// The echoed time stamp.
    pub ipoc: u64,
    /// The end signal: `<Stop>1</Stop>` ([`END_ELEMENT`]) in the answer.
    pub end: bool,
}

/// The answer's end-of-session element: `<Stop>1</Stop>` asks the controller to end the
/// sensor-guided motion (a `RECEIVE` element `Stop`, `TYPE="BOOL"`, wired to the RSI
/// context's STOP object, or to `ST_BREAKMOVE` in RSI 2.x), after which `RSI_MOVECORR()`
/// returns and the KRL program goes on to `RSI_OFF()`.
pub const END_ELEMENT: &str = "Stop";

/// The rotation of KUKA angles `A, B, C` (degrees): `Rz(A)·Ry(B)·Rx(C)`.
pub fn abc_to_quaternion(a: f64, b: f64, c: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_euler_angles(c.to_radians(), b.to_radians(), a.to_radians())
}

/// KUKA angles `[A, B, C]` (degrees) of a rotation (the inverse of [`abc_to_quaternion`]; B in
/// −90..=90°).
pub fn quaternion_to_abc(q: &UnitQuaternion<f64>) -> [f64; 3] {
    let (roll, pitch, yaw) = q.euler_angles();
    [yaw.to_degrees(), pitch.to_degrees(), roll.to_degrees()]
}

/// Decodes the robot's state message; `state` names the actual pose element (`RIst`).
pub fn decode_state(xml: &[u8], state: &str) -> Result<RsiState, RsiError> {
    check_size(xml)?;
    find_element(xml, b"Rob").ok_or(RsiError::MissingRoot)?;
    let actual = pose(xml, state.as_bytes())?;
    let setpoint = match find_element(xml, b"RSol") {
        Some(at) => Some(pose_at(xml, at)?),
        None => None,
    };
    let delay = match find_element(xml, b"Delay").and_then(|at| attribute(xml, at, b"D")) {
        Some(v) => Some(digits(v).ok_or(RsiError::BadNumber)?),
        None => None,
    };
    Ok(RsiState {
        actual,
        setpoint,
        delay,
        ipoc: ipoc(xml)?,
    })
}

/// Decodes the PC's answer: root `Sen` with `Type = sen_type`, the correction element and the
/// IPOC.
pub fn decode_answer(xml: &[u8], names: &RsiNames) -> Result<RsiAnswer, RsiError> {
    check_size(xml)?;
    let root = find_element(xml, b"Sen").ok_or(RsiError::MissingRoot)?;
    if attribute(xml, root, b"Type") != Some(names.sen_type.as_bytes()) {
        return Err(RsiError::WrongType);
    }
    Ok(RsiAnswer {
        correction: pose(xml, names.correction.as_bytes())?,
        ipoc: ipoc(xml)?,
        end: element_text(xml, END_ELEMENT.as_bytes()).is_some_and(|t| t == b"1"),
    })
}

/// Writes the PC's answers into a fixed buffer (never allocates).
#[derive(Debug, Clone)]
pub struct AnswerEncoder {
    names: RsiNames,
    buf: [u8; ENCODE_CAPACITY],
}

impl AnswerEncoder {
    /// An encoder for the configured names (validate them first: [`RsiNames::validate`]).
    pub fn new(names: RsiNames) -> Self {
        AnswerEncoder {
            names,
            buf: [0; ENCODE_CAPACITY],
        }
    }

    /// `<Sen Type="…"><RKorr X=… …/><IPOC>…</IPOC></Sen>` (4 decimals: 0.1 µm, 0.0001°).
    pub fn encode(&mut self, correction: &KukaPose, ipoc: u64) -> &[u8] {
        self.encode_with_end(correction, ipoc, false)
    }

    /// [`AnswerEncoder::encode`], with the end signal `<Stop>1</Stop>` ([`END_ELEMENT`])
    /// before the IPOC when `end`.
    pub fn encode_with_end(&mut self, correction: &KukaPose, ipoc: u64, end: bool) -> &[u8] {
        let n = &self.names;
        let [x, y, z, a, b, c] = *correction;
        let mut cursor = &mut self.buf[..];
        let stop = if end { "<Stop>1</Stop>" } else { "" };
        let written = write!(
            cursor,
            "<Sen Type=\"{}\"><{} X=\"{x:.4}\" Y=\"{y:.4}\" Z=\"{z:.4}\" A=\"{a:.4}\" B=\"{b:.4}\" C=\"{c:.4}\" />{stop}<IPOC>{ipoc}</IPOC></Sen>",
            n.sen_type, n.correction
        );
        let left = cursor.len();
        finish(&self.buf, left, written)
    }
}

/// Writes the robot's state messages into a fixed buffer (the emulated controller; never
/// allocates).
#[derive(Debug, Clone)]
pub struct StateEncoder {
    state: String,
    buf: [u8; ENCODE_CAPACITY],
}

impl StateEncoder {
    /// An encoder whose actual pose element is `state` (`RIst`).
    pub fn new(state: &str) -> Self {
        StateEncoder {
            state: state.into(),
            buf: [0; ENCODE_CAPACITY],
        }
    }

    /// `<Rob Type="KUKA"><RIst …/><RSol …/><Delay D="…"/><IPOC>…</IPOC></Rob>`.
    pub fn encode(
        &mut self,
        actual: &KukaPose,
        setpoint: &KukaPose,
        delay: u64,
        ipoc: u64,
    ) -> &[u8] {
        let [x, y, z, a, b, c] = *actual;
        let [sx, sy, sz, sa, sb, sc] = *setpoint;
        let mut cursor = &mut self.buf[..];
        let written = write!(
            cursor,
            "<Rob Type=\"KUKA\"><{} X=\"{x:.4}\" Y=\"{y:.4}\" Z=\"{z:.4}\" A=\"{a:.4}\" B=\"{b:.4}\" C=\"{c:.4}\" /><RSol X=\"{sx:.4}\" Y=\"{sy:.4}\" Z=\"{sz:.4}\" A=\"{sa:.4}\" B=\"{sb:.4}\" C=\"{sc:.4}\" /><Delay D=\"{delay}\" /><IPOC>{ipoc}</IPOC></Rob>",
            self.state
        );
        let left = cursor.len();
        finish(&self.buf, left, written)
    }
}

/// The written part of `buf` (`left` bytes unused); nothing if the message did not fit.
fn finish(buf: &[u8], left: usize, written: std::io::Result<()>) -> &[u8] {
    match written {
        Ok(()) => &buf[..buf.len() - left],
        Err(_) => &[],
    }
}

fn check_size(xml: &[u8]) -> Result<(), RsiError> {
    if xml.is_empty() || xml.len() > RSI_MAX_DATAGRAM {
        return Err(RsiError::WrongSize(xml.len()));
    }
    Ok(())
}

/// The six attributes X, Y, Z, A, B, C of element `name`.
fn pose(xml: &[u8], name: &[u8]) -> Result<KukaPose, RsiError> {
    let at = find_element(xml, name).ok_or(RsiError::MissingPose)?;
    pose_at(xml, at)
}

/// The six attributes X, Y, Z, A, B, C of the element whose attributes start at `at`.
fn pose_at(xml: &[u8], at: usize) -> Result<KukaPose, RsiError> {
    let mut pose = [0.0; 6];
    for (v, key) in pose.iter_mut().zip([b"X", b"Y", b"Z", b"A", b"B", b"C"]) {
        let text = attribute(xml, at, key).ok_or(RsiError::MissingPose)?;
        *v = number(text)?;
    }
    Ok(pose)
}

/// A finite number within [`RSI_MAX_VALUE`] (surrounding blanks allowed).
fn number(text: &[u8]) -> Result<f64, RsiError> {
    let text = std::str::from_utf8(trim(text)).map_err(|_| RsiError::BadNumber)?;
    let v: f64 = text.parse().map_err(|_| RsiError::BadNumber)?;
    if !(v.is_finite() && v.abs() <= RSI_MAX_VALUE) {
        return Err(RsiError::NonFinite);
    }
    Ok(v)
}

/// A decimal integer that fits a `u64` (surrounding blanks allowed).
fn digits(text: &[u8]) -> Option<u64> {
    let text = trim(text);
    if text.is_empty() {
        return None;
    }
    text.iter().try_fold(0u64, |n, d| {
        if !d.is_ascii_digit() {
            return None;
        }
        n.checked_mul(10)?.checked_add(u64::from(d - b'0'))
    })
}

/// The `<IPOC>` time stamp.
fn ipoc(xml: &[u8]) -> Result<u64, RsiError> {
    let at = find_element(xml, b"IPOC").ok_or(RsiError::MissingIpoc)?;
    let rest = &xml[at..];
    let open = rest
        .iter()
        .position(|&b| b == b'>')
        .ok_or(RsiError::MissingIpoc)?;
    let rest = &rest[open + 1..];
    let close = rest
        .iter()
        .position(|&b| b == b'<')
        .ok_or(RsiError::MissingIpoc)?;
    digits(&rest[..close]).ok_or(RsiError::MissingIpoc)
}

/// The trimmed text of the first element `name` (`<name>text</name>`), if any.
fn element_text<'a>(xml: &'a [u8], name: &[u8]) -> Option<&'a [u8]> {
    let at = find_element(xml, name)?;
    let rest = &xml[at..];
    let open = rest.iter().position(|&b| b == b'>')?;
    let rest = &rest[open + 1..];
    let close = rest.iter().position(|&b| b == b'<')?;
    Some(trim(&rest[..close]))
}

fn trim(mut s: &[u8]) -> &[u8] {
    while let [first, rest @ ..] = s {
        if !first.is_ascii_whitespace() {
            break;
        }
        s = rest;
    }
    while let [rest @ .., last] = s {
        if !last.is_ascii_whitespace() {
            break;
        }
        s = rest;
    }
    s
}

/// The position just after the name of the first start tag `<name` (followed by a blank, `/`
/// or `>`).
fn find_element(xml: &[u8], name: &[u8]) -> Option<usize> {
    let mut from = 0;
    while from < xml.len() {
        let lt = from + xml[from..].iter().position(|&b| b == b'<')?;
        let start = lt + 1;
        let end = start + name.len();
        if xml.get(start..end) == Some(name)
            && matches!(xml.get(end), Some(b) if b.is_ascii_whitespace() || *b == b'/' || *b == b'>')
        {
            return Some(end);
        }
        from = start;
    }
    None
}

/// The value of attribute `key` of the start tag whose attributes begin at `at` (up to its
/// `>`), quoted with `"` or `'`.
fn attribute<'a>(xml: &'a [u8], at: usize, key: &[u8]) -> Option<&'a [u8]> {
    let mut i = at;
    let skip_blanks = |mut i: usize| {
        while i < xml.len() && xml[i].is_ascii_whitespace() {
            i += 1;
        }
        i
    };
    loop {
        i = skip_blanks(i);
        match xml.get(i)? {
            b'/' | b'>' => return None,
            _ => {}
        }
        let name_start = i;
        while i < xml.len()
            && !xml[i].is_ascii_whitespace()
            && !matches!(xml[i], b'=' | b'/' | b'>')
        {
            i += 1;
        }
        let name = &xml[name_start..i];
        i = skip_blanks(i);
        if xml.get(i) != Some(&b'=') {
            return None; // not `name="value"`: malformed tag
        }
        i = skip_blanks(i + 1);
        let quote = *xml.get(i)?;
        if quote != b'"' && quote != b'\'' {
            return None;
        }
        let value_start = i + 1;
        let len = xml.get(value_start..)?.iter().position(|&b| b == quote)?;
        let value = &xml[value_start..value_start + len];
        if name == key {
            return Some(value);
        }
        i = value_start + len + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const STATE: &str = r#"<Rob Type="KUKA">
  <RIst X="-995.0000" Y="0.5" Z="1200.25" A="90.0" B="-1.5" C="179.9"/>
  <RSol X="-995.1" Y="0.0" Z="1200.0" A="90.0" B="0.0" C="180.0"/>
  <AIPos A1="0.0" A2="-90.0" A3="90.0" A4="0.0" A5="0.0" A6="0.0"/>
  <ASPos A1="0.0" A2="-90.0" A3="90.0" A4="0.0" A5="0.0" A6="0.0"/>
  <Delay D="3"/>
  <IPOC>123456</IPOC>
</Rob>"#;

    #[test]
    fn a_controllers_state_message_decodes() {
        let s = decode_state(STATE.as_bytes(), "RIst").unwrap();
        assert_eq!(s.actual, [-995.0, 0.5, 1200.25, 90.0, -1.5, 179.9]);
        assert_eq!(s.setpoint, Some([-995.1, 0.0, 1200.0, 90.0, 0.0, 180.0]));
        assert_eq!(s.delay, Some(3));
        assert_eq!(s.ipoc, 123456);
        // without RSol and Delay, with single quotes and an XML declaration
        let bare = "<?xml version='1.0'?><Rob Type='KUKA'><RIst X='1' Y='2' Z='3' A='4' B='5' C='6'/><IPOC> 7 </IPOC></Rob>";
        let s = decode_state(bare.as_bytes(), "RIst").unwrap();
        assert_eq!(s.actual, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!((s.setpoint, s.delay, s.ipoc), (None, None, 7));
    }

    #[test]
    fn state_and_answer_round_trip() {
        let mut enc = StateEncoder::new("RIst");
        let actual = [-995.1234, 0.5, 1200.25, 90.0, -1.5, 179.9];
        let setpoint = [-995.0, 0.0, 1200.0, 90.0, 0.0, -180.0];
        let bytes = enc.encode(&actual, &setpoint, 2, 987_654_321).to_vec();
        let s = decode_state(&bytes, "RIst").unwrap();
        assert_eq!(s.actual, actual);
        assert_eq!(s.setpoint, Some(setpoint));
        assert_eq!((s.delay, s.ipoc), (Some(2), 987_654_321));

        let names = RsiNames::default();
        let mut enc = AnswerEncoder::new(names.clone());
        let korr = [0.1234, -5.0, 20.0001, 0.5, -0.25, 0.0];
        let bytes = enc.encode(&korr, 987_654_321).to_vec();
        let text = std::str::from_utf8(&bytes).unwrap();
        assert!(
            text.starts_with("<Sen Type=\"ImFree\"><RKorr X=\"0.1234\""),
            "{text}"
        );
        assert!(text.ends_with("<IPOC>987654321</IPOC></Sen>"), "{text}");
        let a = decode_answer(&bytes, &names).unwrap();
        assert_eq!(a.correction, korr);
        assert_eq!(a.ipoc, 987_654_321);
    }

    #[test]
    fn the_names_are_the_configured_ones() {
        let names = RsiNames {
            sen_type: "HilContact".into(),
            state: "RIst2".into(),
            correction: "Korr".into(),
        };
        assert!(names.validate().is_ok());
        let bytes = AnswerEncoder::new(names.clone())
            .encode(&[0.0; 6], 1)
            .to_vec();
        assert!(decode_answer(&bytes, &names).is_ok());
        // another Type, or the default element names, are not this configuration's
        assert_eq!(
            decode_answer(&bytes, &RsiNames::default()),
            Err(RsiError::WrongType)
        );
        let other = RsiNames {
            correction: "RKorr".into(),
            ..names.clone()
        };
        assert_eq!(decode_answer(&bytes, &other), Err(RsiError::MissingPose));
        // `RIst` is not `RIst2`, nor the reverse
        assert_eq!(
            decode_state(STATE.as_bytes(), "RIst2"),
            Err(RsiError::MissingPose)
        );
        for bad in ["", "1abc", "a b", "a\"b", &"x".repeat(RSI_MAX_NAME + 1)] {
            let names = RsiNames {
                correction: bad.into(),
                ..RsiNames::default()
            };
            assert_eq!(names.validate().unwrap_err().0, "correction_element");
        }
    }

    #[test]
    fn malformed_and_invalid_messages_are_errors() {
        let ok = STATE;
        let cases: &[(&str, RsiError)] = &[
            ("", RsiError::WrongSize(0)),
            ("<Sen Type=\"ImFree\"></Sen>", RsiError::MissingRoot),
            (
                "<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\"/><IPOC>1</IPOC></Rob>",
                RsiError::MissingPose,
            ),
            (
                "<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"x\"/><IPOC>1</IPOC></Rob>",
                RsiError::BadNumber,
            ),
            (
                "<Rob><RIst X=\"NaN\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>1</IPOC></Rob>",
                RsiError::NonFinite,
            ),
            (
                "<Rob><RIst X=\"inf\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>1</IPOC></Rob>",
                RsiError::NonFinite,
            ),
            (
                "<Rob><RIst X=\"1e6\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>1</IPOC></Rob>",
                RsiError::NonFinite,
            ),
            (
                "<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/></Rob>",
                RsiError::MissingIpoc,
            ),
            (
                "<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>-1</IPOC></Rob>",
                RsiError::MissingIpoc,
            ),
            (
                "<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC></IPOC></Rob>",
                RsiError::MissingIpoc,
            ),
            (
                "<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><IPOC>99999999999999999999</IPOC></Rob>",
                RsiError::MissingIpoc,
            ),
            (
                "<Rob><RIst X=\"1\" Y=\"2\" Z=\"3\" A=\"4\" B=\"5\" C=\"6\"/><Delay D=\"x\"/><IPOC>1</IPOC></Rob>",
                RsiError::BadNumber,
            ),
            ("<Rob><RIst X=1 Y=2/><IPOC>1</IPOC></Rob>", RsiError::MissingPose),
        ];
        for (xml, error) in cases {
            assert_eq!(decode_state(xml.as_bytes(), "RIst"), Err(*error), "{xml}");
            assert_eq!(error.is_malformed(), *error != RsiError::NonFinite);
        }
        assert!(decode_state(ok.as_bytes(), "RIst").is_ok());
        let big = vec![b' '; RSI_MAX_DATAGRAM + 1];
        assert_eq!(
            decode_state(&big, "RIst"),
            Err(RsiError::WrongSize(RSI_MAX_DATAGRAM + 1))
        );
        // an answer without IPOC, or with a NaN correction
        let names = RsiNames::default();
        let no_ipoc =
            "<Sen Type=\"ImFree\"><RKorr X=\"0\" Y=\"0\" Z=\"0\" A=\"0\" B=\"0\" C=\"0\"/></Sen>";
        assert_eq!(
            decode_answer(no_ipoc.as_bytes(), &names),
            Err(RsiError::MissingIpoc)
        );
        let nan = "<Sen Type=\"ImFree\"><RKorr X=\"nan\" Y=\"0\" Z=\"0\" A=\"0\" B=\"0\" C=\"0\"/><IPOC>5</IPOC></Sen>";
        assert_eq!(
            decode_answer(nan.as_bytes(), &names),
            Err(RsiError::NonFinite)
        );
    }

    #[test]
    fn kuka_angles_are_zyx_euler() {
        // A about Z: x goes to y
        let q = abc_to_quaternion(90.0, 0.0, 0.0);
        let v = q * nalgebra::Vector3::x();
        assert!((v - nalgebra::Vector3::y()).norm() < 1e-12);
        // C about X: y goes to z
        let v = abc_to_quaternion(0.0, 0.0, 90.0) * nalgebra::Vector3::y();
        assert!((v - nalgebra::Vector3::z()).norm() < 1e-12);
        // B about Y: z goes to x
        let v = abc_to_quaternion(0.0, 90.0, 0.0) * nalgebra::Vector3::z();
        assert!((v - nalgebra::Vector3::x()).norm() < 1e-12);
        // R = Rz(A) Ry(B) Rx(C), and back
        let (a, b, c) = (30.0, -20.0, 170.0);
        let composed = abc_to_quaternion(a, 0.0, 0.0)
            * abc_to_quaternion(0.0, b, 0.0)
            * abc_to_quaternion(0.0, 0.0, c);
        assert!(composed.angle_to(&abc_to_quaternion(a, b, c)) < 1e-12);
        let back = quaternion_to_abc(&abc_to_quaternion(a, b, c));
        for (x, y) in back.iter().zip([a, b, c]) {
            assert!((x - y).abs() < 1e-9, "{back:?}");
        }
    }

    proptest! {
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let _ = decode_state(&bytes, "RIst");
            let _ = decode_answer(&bytes, &RsiNames::default());
        }

        #[test]
        fn mutated_messages_never_panic_and_stay_valid_when_accepted(flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6)) {
            let mut bytes = STATE.as_bytes().to_vec();
            for (i, v) in flips {
                let i = i.index(bytes.len());
                bytes[i] = v;
            }
            if let Ok(s) = decode_state(&bytes, "RIst") {
                prop_assert!(s.actual.iter().all(|v| v.is_finite() && v.abs() <= RSI_MAX_VALUE));
            }
        }

        #[test]
        fn answers_round_trip(korr in proptest::array::uniform6(-1.0e4..1.0e4f64), ipoc in any::<u64>()) {
            let names = RsiNames::default();
            let bytes = AnswerEncoder::new(names.clone()).encode(&korr, ipoc).to_vec();
            let a = decode_answer(&bytes, &names).unwrap();
            prop_assert_eq!(a.ipoc, ipoc);
            for (x, y) in a.correction.iter().zip(korr) {
                prop_assert!((x - y).abs() <= 0.5e-4 + 1e-9);
            }
        }
    }
}
