//! SRI (Sunrise Instruments) M812x interface box (M8126, M8128) over TCP: the AT command and
//! data frame codec.
//!
//! SRI's M8128 manual is not in this project's sources; this codec follows the protocol as
//! open-source clients of real M812x boxes use it (cited by repository, path):
//!
//! - [A] `ZenanLin1999/ROS_package_M8128_data_acquire`, `force_sensor/src/M8128_data_acquire.cpp`:
//!   a frame captured from a box, byte by byte: `AA 55 00 1B D1 EB` + 24 data bytes + `8B`;
//!   length `00 1B` = 27 big-endian (the bytes after the length field), package number big-endian
//!   (`rx[3]*256 + rx[4]`), checksum = sum of the 24 data bytes mod 256 (the captured frame's
//!   sum is 0x8B: a unit test checks it), values `f32` in the box's byte order (little-endian).
//! - [B] a ROS M8128 TCP client (`M8128TCPClient`, `M8218Parser`, Python): header `AA 55`,
//!   length big-endian and 27, `struct.unpack("ffffff")` (little-endian on the PC), checksum the
//!   sum of the 24 data bytes; `AT+DCKMD=SUM` selects that checksum; TCP port 4008.
//! - [C] drivers that set the box up (`AT+SMPR=100\r\n`, `AT+DCPM=(..);..;(..)\r\n`,
//!   `AT+DCPCU=MVPV\r\n`, `AT+SGDM=(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)\r\n`, `AT+GSD\r\n`,
//!   `AT+GSD=STOP\r\n`, `AT+ADJZF=1;1;1;1;1;1\r\n` named "set_zero"); a serial client that checks
//!   the answer `ACK+SMPR=300$OK\r\n`; a README with `AT+ETPT=?` → `ACK+ETPT=4008$OK\r\n`.
//!
//! Where the sources disagree (see docs/realtime.md, "SRI M812x"):
//!
//! - sample rate: `AT+SMPR=<Hz>` in most ([A]'s README, [C]), `AT+SMPF=<Hz>` in others ([B]
//!   and some serial clients; newer firmware?): the link sends SMPR by default
//!   ([`SriRateCommand`]), the emulator answers both;
//! - data mode in `AT+SGDM`: `E` in clients that read forces (the box applies its decoupling
//!   matrix and sends N, N·m as `f32`), `C` in a client that reads AD counts and applies the
//!   matrix itself (`1000·(AD − AMPZ)/65535·5/gain/excitation`, then the matrix): this link sends
//!   `E`;
//! - `AT+GSD` gets no ACK in [B] (streaming just starts) and `ACK+GSD=OK` in a mock server: the
//!   reader skips whatever precedes the first frame.
//!
//! Decoding never allocates and never panics; commands encode into a caller's buffer.

use std::io::Write;

use thiserror::Error;

/// TCP port of the M812x's command and data server (factory setting; `AT+ETPT` changes it).
pub const SRI_PORT: u16 = 4008;
/// First two bytes of every data frame.
pub const FRAME_HEADER: [u8; 2] = [0xAA, 0x55];
/// The length field of a six-channel `f32` frame with a sum checksum: package number (2) +
/// data (24) + checksum (1).
pub const FRAME_PAYLOAD_LEN: u16 = 27;
/// Size of a data frame, bytes: header (2) + length (2) + payload (27).
pub const FRAME_LEN: usize = 31;
/// Longest AT command or answer line this codec builds or reads, bytes.
pub const MAX_LINE: usize = 1024;

/// One data frame: six channels, `f32`, in the units of the box's decoupling matrix (data
/// mode `E`; SRI's calibration: N for Fx, Fy, Fz, N·m for Mx, My, Mz).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SriFrame {
    /// Package number (wraps at 65535).
    pub package: u16,
    /// `Fx, Fy, Fz` (N), `Mx, My, Mz` (N·m).
    pub values: [f32; 6],
}

impl SriFrame {
    /// The 31 bytes on the wire: `AA 55`, length 27 (big-endian), package number (big-endian),
    /// six `f32` (little-endian), the sum of the 24 data bytes mod 256.
    pub fn encode(&self) -> [u8; FRAME_LEN] {
        let mut out = [0u8; FRAME_LEN];
        out[0..2].copy_from_slice(&FRAME_HEADER);
        out[2..4].copy_from_slice(&FRAME_PAYLOAD_LEN.to_be_bytes());
        out[4..6].copy_from_slice(&self.package.to_be_bytes());
        for (i, v) in self.values.iter().enumerate() {
            out[6 + 4 * i..10 + 4 * i].copy_from_slice(&v.to_le_bytes());
        }
        out[30] = checksum(&out[6..30]);
        out
    }

    /// Parses one complete frame (exactly 31 bytes).
    pub fn decode(bytes: &[u8]) -> Result<Self, SriError> {
        let b: &[u8; FRAME_LEN] = bytes.try_into().map_err(|_| SriError::WrongSize {
            expected: FRAME_LEN,
            got: bytes.len(),
        })?;
        if b[0..2] != FRAME_HEADER {
            return Err(SriError::WrongHeader([b[0], b[1]]));
        }
        let length = u16::from_be_bytes([b[2], b[3]]);
        if length != FRAME_PAYLOAD_LEN {
            return Err(SriError::WrongLength(length));
        }
        let expected = checksum(&b[6..30]);
        if b[30] != expected {
            return Err(SriError::BadChecksum {
                expected,
                got: b[30],
            });
        }
        let mut values = [0f32; 6];
        for (i, v) in values.iter_mut().enumerate() {
            let j = 6 + 4 * i;
            *v = f32::from_le_bytes([b[j], b[j + 1], b[j + 2], b[j + 3]]);
        }
        Ok(SriFrame {
            package: u16::from_be_bytes([b[4], b[5]]),
            values,
        })
    }
}

/// The frame checksum: the sum of the data bytes, mod 256 ([A], [B]).
pub fn checksum(data: &[u8]) -> u8 {
    data.iter().fold(0u8, |s, b| s.wrapping_add(*b))
}

/// Why bytes are not a valid frame or answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum SriError {
    /// A frame does not have 31 bytes.
    #[error("wrong size: expected {expected} bytes, got {got}")]
    WrongSize {
        /// Expected size, bytes.
        expected: usize,
        /// Received size, bytes.
        got: usize,
    },
    /// A frame does not start with `AA 55`.
    #[error("wrong header {0:02x?} (expected [aa, 55])")]
    WrongHeader([u8; 2]),
    /// A frame's length field is not 27 (another data mode or channel set).
    #[error("wrong length field {0} (expected 27: six f32 channels and a sum checksum)")]
    WrongLength(u16),
    /// A frame's checksum is not the sum of its data bytes.
    #[error("bad checksum 0x{got:02x} (expected 0x{expected:02x})")]
    BadChecksum {
        /// The sum of the data bytes.
        expected: u8,
        /// The checksum byte received.
        got: u8,
    },
    /// Bytes between frames that are no frame (counted once per run of such bytes).
    #[error("{0} bytes that are no frame")]
    Garbage(usize),
    /// An answer line that is not `ACK+<command>...`.
    #[error("not an ACK line")]
    NotAck,
}

/// Reassembles frames from a TCP byte stream: frames may be split across reads or several
/// may arrive in one. A fixed buffer, no allocation. Bytes before the first valid frame (e.g.
/// an answer to `AT+GSD`) are skipped silently; after it, every run of bytes that is no frame
/// is one [`SriError::Garbage`], every frame with a wrong length field or checksum one error,
/// and the reader resynchronises on the next `AA 55`.
#[derive(Debug, Clone)]
pub struct FrameReader {
    buf: [u8; 2048],
    start: usize,
    end: usize,
    synced: bool,
}

impl Default for FrameReader {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameReader {
    /// An empty reader.
    pub fn new() -> Self {
        FrameReader {
            buf: [0u8; 2048],
            start: 0,
            end: 0,
            synced: false,
        }
    }

    /// The free space to read into (moves the unread bytes to the front first); never empty.
    pub fn space(&mut self) -> &mut [u8] {
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        if self.end == self.buf.len() {
            // full without a frame (cannot happen with frames shorter than the buffer, as
            // `next_frame` consumes them): keep the last byte, it may begin a header
            self.buf[0] = self.buf[self.end - 1];
            self.end = 1;
        }
        &mut self.buf[self.end..]
    }

    /// Takes `n` bytes written into [`space`](Self::space).
    pub fn commit(&mut self, n: usize) {
        self.end = (self.end + n).min(self.buf.len());
    }

    /// Copies `bytes` in (as much as fits at once; a convenience for tests and emulators).
    /// Returns how many were taken.
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        let space = self.space();
        let n = bytes.len().min(space.len());
        space[..n].copy_from_slice(&bytes[..n]);
        self.commit(n);
        n
    }

    /// Unread bytes held.
    pub fn pending(&self) -> usize {
        self.end - self.start
    }

    /// The next frame or error, or None when more bytes are needed.
    pub fn next_frame(&mut self) -> Option<Result<SriFrame, SriError>> {
        loop {
            let bytes = &self.buf[self.start..self.end];
            let Some(at) = bytes.windows(2).position(|w| w == FRAME_HEADER) else {
                // no header: drop all but a last 0xAA (it may begin one)
                let keep = usize::from(bytes.last() == Some(&FRAME_HEADER[0]));
                let skipped = bytes.len() - keep;
                self.start = self.end - keep;
                if skipped > 0 && self.synced {
                    self.synced = false;
                    return Some(Err(SriError::Garbage(skipped)));
                }
                return None;
            };
            if at > 0 {
                self.start += at;
                if self.synced {
                    self.synced = false;
                    return Some(Err(SriError::Garbage(at)));
                }
                continue;
            }
            if bytes.len() < 4 {
                return None;
            }
            let length = u16::from_be_bytes([bytes[2], bytes[3]]);
            if length != FRAME_PAYLOAD_LEN {
                // a false header or another data mode: skip it and resynchronise
                self.start += 2;
                let was_synced = std::mem::replace(&mut self.synced, false);
                if was_synced {
                    return Some(Err(SriError::WrongLength(length)));
                }
                continue;
            }
            if bytes.len() < FRAME_LEN {
                return None;
            }
            let result = SriFrame::decode(&bytes[..FRAME_LEN]);
            match result {
                Ok(_) => {
                    self.start += FRAME_LEN;
                    self.synced = true;
                }
                Err(_) => {
                    // a frame of the right length with a bad checksum: skip just its header,
                    // so a true header inside it is found again
                    self.start += 2;
                    self.synced = false;
                }
            }
            return Some(result);
        }
    }
}

/// Tracks the frames' 16-bit package numbers: counts the missing ones. Over TCP a package
/// number that is not newer (wrapping comparison) means the box restarted its count: taken as
/// the new reference, nothing counted lost.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PackageTracker {
    last: Option<u16>,
}

impl PackageTracker {
    /// A tracker that has seen nothing.
    pub fn new() -> Self {
        PackageTracker { last: None }
    }

    /// Accepts `package` as the newest; returns how many packages are missing before it.
    pub fn check(&mut self, package: u16) -> u32 {
        let lost = match self.last {
            Some(last) => {
                let ahead = package.wrapping_sub(last) as i16;
                if ahead > 0 {
                    ahead as u32 - 1
                } else {
                    0
                }
            }
            None => 0,
        };
        self.last = Some(package);
        lost
    }

    /// The last package number seen.
    pub fn last(&self) -> Option<u16> {
        self.last
    }
}

/// Which command sets the sample rate: the sources disagree (see the module doc).
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    schemars::JsonSchema,
)]
pub enum SriRateCommand {
    /// `AT+SMPR=<Hz>` (most clients; an answer `ACK+SMPR=300$OK` is published).
    #[default]
    #[serde(rename = "SMPR")]
    Smpr,
    /// `AT+SMPF=<Hz>` (other M8128 clients).
    #[serde(rename = "SMPF")]
    Smpf,
}

impl SriRateCommand {
    /// The command's name, e.g. `"SMPR"`.
    pub fn name(self) -> &'static str {
        match self {
            SriRateCommand::Smpr => "SMPR",
            SriRateCommand::Smpf => "SMPF",
        }
    }
}

/// An AT command to the box (built on the stack, a few per run: the matrix variant's size
/// does not matter).
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SriCommand {
    /// `AT+SMPR=<Hz>` (or SMPF): the sample rate, Hz (integer on the wire).
    SampleRate(SriRateCommand, u32),
    /// `AT+DCPM=(r1);(r2);...;(r6)`: the 6×6 decoupling matrix, row by row (its input unit
    /// set by [`SriCommand::ComputeUnitMvpv`]).
    DecouplingMatrix([[f64; 6]; 6]),
    /// `AT+DCPCU=MVPV`: the matrix multiplies the bridge signals in mV/V.
    ComputeUnitMvpv,
    /// `AT+DCKMD=SUM`: the frames' checksum is the sum of the data bytes.
    ChecksumSum,
    /// `AT+SGDM=(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)`: channels 1–6, decoupled values in
    /// engineering units (`E`), one sample per frame, moving-average filter of 1 (none).
    DataMode,
    /// `AT+ADJZF=1;1;1;1;1;1`: zero all six channels at the current load (one source).
    Zero,
    /// `AT+GSD`: stream frames continuously.
    StartStream,
    /// `AT+GSD=STOP`: stop streaming.
    StopStream,
}

impl SriCommand {
    /// The command's name as its ACK repeats it, e.g. `"SMPR"`.
    pub fn name(&self) -> &'static str {
        match self {
            SriCommand::SampleRate(c, _) => c.name(),
            SriCommand::DecouplingMatrix(_) => "DCPM",
            SriCommand::ComputeUnitMvpv => "DCPCU",
            SriCommand::ChecksumSum => "DCKMD",
            SriCommand::DataMode => "SGDM",
            SriCommand::Zero => "ADJZF",
            SriCommand::StartStream | SriCommand::StopStream => "GSD",
        }
    }

    /// Writes the command with its `\r\n` into `out`; returns its length. Never allocates;
    /// `out` of [`MAX_LINE`] bytes holds every command.
    pub fn encode(&self, out: &mut [u8]) -> usize {
        let capacity = out.len();
        let mut w = &mut out[..];
        let _ = match self {
            SriCommand::SampleRate(c, hz) => write!(w, "AT+{}={hz}\r\n", c.name()),
            SriCommand::DecouplingMatrix(m) => {
                let _ = write!(w, "AT+DCPM=");
                for (i, row) in m.iter().enumerate() {
                    let sep = if i == 0 { "" } else { ";" };
                    let _ = write!(
                        w,
                        "{sep}({:.6},{:.6},{:.6},{:.6},{:.6},{:.6})",
                        row[0], row[1], row[2], row[3], row[4], row[5]
                    );
                }
                write!(w, "\r\n")
            }
            SriCommand::ComputeUnitMvpv => write!(w, "AT+DCPCU=MVPV\r\n"),
            SriCommand::ChecksumSum => write!(w, "AT+DCKMD=SUM\r\n"),
            SriCommand::DataMode => write!(w, "AT+SGDM=(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)\r\n"),
            SriCommand::Zero => write!(w, "AT+ADJZF=1;1;1;1;1;1\r\n"),
            SriCommand::StartStream => write!(w, "AT+GSD\r\n"),
            SriCommand::StopStream => write!(w, "AT+GSD=STOP\r\n"),
        };
        capacity - w.len()
    }
}

/// An answer line: `ACK+<command>[=<parameters>]$<status>` (e.g. `ACK+SMPR=300$OK`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SriAck<'a> {
    /// The command answered, e.g. `"SMPR"`.
    pub command: &'a str,
    /// What follows `=` up to `$` (empty without `=`).
    pub parameters: &'a str,
    /// What follows the last `$` (`"OK"` when accepted; empty without `$`).
    pub status: &'a str,
}

impl<'a> SriAck<'a> {
    /// Parses one answer line (the trailing `\r\n`, if any, and surrounding blanks ignored).
    pub fn parse(line: &'a str) -> Result<Self, SriError> {
        let line = line.trim();
        let rest = line.strip_prefix("ACK+").ok_or(SriError::NotAck)?;
        let (body, status) = match rest.rfind('$') {
            Some(i) => (&rest[..i], &rest[i + 1..]),
            None => (rest, ""),
        };
        let (command, parameters) = match body.find('=') {
            Some(i) => (&body[..i], &body[i + 1..]),
            None => (body, ""),
        };
        if command.is_empty() {
            return Err(SriError::NotAck);
        }
        Ok(SriAck {
            command,
            parameters,
            status,
        })
    }

    /// Whether the box accepted the command (`$OK`).
    pub fn ok(&self) -> bool {
        self.status.eq_ignore_ascii_case("OK")
    }
}

/// A command line received by an emulated box: `AT+<command>[=<parameters>]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SriRequest<'a> {
    /// The command, e.g. `"SMPR"`.
    pub command: &'a str,
    /// What follows `=` (empty without `=`).
    pub parameters: &'a str,
}

impl<'a> SriRequest<'a> {
    /// Parses one command line (the trailing `\r\n`, if any, ignored); None if it is not
    /// `AT+...`.
    pub fn parse(line: &'a str) -> Option<Self> {
        let rest = line.trim().strip_prefix("AT+")?;
        let (command, parameters) = match rest.find('=') {
            Some(i) => (&rest[..i], &rest[i + 1..]),
            None => (rest, ""),
        };
        (!command.is_empty()).then_some(SriRequest {
            command,
            parameters,
        })
    }
}

/// Parses `AT+DCPM`'s parameters `(a,b,c,d,e,f);(...);...` into a 6×6 matrix (six rows of
/// six finite numbers). Never allocates.
pub fn parse_matrix(parameters: &str) -> Option<[[f64; 6]; 6]> {
    let mut m = [[0.0; 6]; 6];
    let mut rows = parameters.trim().split(';');
    for row in m.iter_mut() {
        let text = rows.next()?.trim();
        let inner = text.strip_prefix('(')?.strip_suffix(')')?;
        let mut values = inner.split(',');
        for v in row.iter_mut() {
            let x: f64 = values.next()?.trim().parse().ok()?;
            if !x.is_finite() {
                return None;
            }
            *v = x;
        }
        if values.next().is_some() {
            return None;
        }
    }
    rows.next().is_none().then_some(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The frame captured from a box in [A]'s comment (its leading `AA` is the previous
    /// frame's "tail" there).
    const CAPTURED: [u8; 31] = [
        0xAA, 0x55, 0x00, 0x1B, 0xD1, 0xEB, 0x41, 0xA3, 0xA4, 0x3E, 0xCA, 0xD1, 0xB4, 0x3F, 0x36,
        0x06, 0x12, 0xBE, 0x6A, 0x6F, 0x83, 0x3B, 0x24, 0x02, 0x56, 0xBB, 0x00, 0xEA, 0x3C, 0x37,
        0x8B,
    ];

    fn frame(package: u16, x: f32) -> SriFrame {
        SriFrame {
            package,
            values: [x, -2.5, 100.25, 0.5, -0.125, 3.0e-3],
        }
    }

    #[test]
    fn the_captured_frame_decodes_and_its_checksum_is_the_data_sum() {
        let f = SriFrame::decode(&CAPTURED).unwrap();
        assert_eq!(f.package, 0xD1EB);
        assert!((f.values[0] - 0.321_558).abs() < 1e-6, "{:?}", f.values);
        assert!((f.values[1] - 1.412_652).abs() < 1e-6);
        assert!((f.values[2] + 0.142_602).abs() < 1e-6);
        assert_eq!(checksum(&CAPTURED[6..30]), 0x8B);
        assert_eq!(f.encode(), CAPTURED);
    }

    #[test]
    fn frames_round_trip_and_bad_ones_are_errors() {
        let f = frame(7, 1.5);
        let b = f.encode();
        assert_eq!(&b[..6], &[0xAA, 0x55, 0x00, 0x1B, 0x00, 0x07]);
        assert_eq!(&b[6..10], &1.5f32.to_le_bytes());
        assert_eq!(SriFrame::decode(&b), Ok(f));
        let mut bad = b;
        bad[30] ^= 1;
        assert!(matches!(
            SriFrame::decode(&bad),
            Err(SriError::BadChecksum { .. })
        ));
        let mut bad = b;
        bad[1] = 0x56;
        assert_eq!(
            SriFrame::decode(&bad),
            Err(SriError::WrongHeader([0xAA, 0x56]))
        );
        let mut bad = b;
        bad[3] = 0x1A;
        assert_eq!(SriFrame::decode(&bad), Err(SriError::WrongLength(26)));
        assert_eq!(
            SriFrame::decode(&b[..30]),
            Err(SriError::WrongSize {
                expected: 31,
                got: 30
            })
        );
    }

    fn drain(r: &mut FrameReader) -> Vec<Result<SriFrame, SriError>> {
        std::iter::from_fn(|| r.next_frame()).collect()
    }

    #[test]
    fn frames_split_across_reads_and_concatenated_are_reassembled() {
        let mut stream = Vec::new();
        for k in 0..5 {
            stream.extend_from_slice(&frame(k, k as f32).encode());
        }
        // every split size, including one byte at a time
        for chunk in 1..=stream.len() {
            let mut r = FrameReader::new();
            let mut got = Vec::new();
            for part in stream.chunks(chunk) {
                assert_eq!(r.push(part), part.len());
                got.extend(drain(&mut r));
            }
            let want: Vec<_> = (0..5).map(|k| Ok(frame(k, k as f32))).collect();
            assert_eq!(got, want, "chunk {chunk}");
            assert_eq!(r.pending(), 0);
        }
    }

    #[test]
    fn a_text_answer_before_the_first_frame_is_skipped_silently() {
        let mut r = FrameReader::new();
        r.push(b"ACK+GSD=OK\r\n");
        r.push(&frame(1, 1.0).encode());
        assert_eq!(drain(&mut r), vec![Ok(frame(1, 1.0))]);
    }

    #[test]
    fn garbage_wrong_header_and_bad_checksum_resynchronise() {
        let mut r = FrameReader::new();
        r.push(&frame(1, 1.0).encode());
        r.push(b"\x01\x02\xAA\x56junk");
        r.push(&frame(2, 2.0).encode());
        let mut bad = frame(3, 3.0).encode();
        bad[30] ^= 0xFF;
        r.push(&bad);
        r.push(&frame(4, 4.0).encode());
        let mut wrong_len = frame(5, 5.0).encode();
        wrong_len[3] = 0x20;
        r.push(&wrong_len);
        r.push(&frame(6, 6.0).encode());
        let got = drain(&mut r);
        assert_eq!(got[0], Ok(frame(1, 1.0)));
        assert_eq!(got[1], Err(SriError::Garbage(8)));
        assert_eq!(got[2], Ok(frame(2, 2.0)));
        assert!(matches!(got[3], Err(SriError::BadChecksum { .. })));
        // the bad frame's body is skipped without a second error
        assert_eq!(got[4], Ok(frame(4, 4.0)));
        assert_eq!(got[5], Err(SriError::WrongLength(0x20)));
        assert_eq!(got[6], Ok(frame(6, 6.0)));
        assert_eq!(got.len(), 7, "{got:?}");
    }

    #[test]
    fn package_gaps_are_counted_lost_and_wrap() {
        let mut t = PackageTracker::new();
        assert_eq!(t.check(10), 0);
        assert_eq!(t.check(11), 0);
        assert_eq!(t.check(15), 3);
        assert_eq!(t.check(15), 0); // a repeat (box restart): nothing lost
        let mut w = PackageTracker::new();
        w.check(65534);
        assert_eq!(w.check(1), 2); // 65535, 0 missing
        assert_eq!(w.last(), Some(1));
    }

    #[test]
    fn commands_are_the_published_strings() {
        let mut buf = [0u8; MAX_LINE];
        let s = |c: SriCommand, buf: &mut [u8]| {
            let n = c.encode(buf);
            String::from_utf8(buf[..n].to_vec()).unwrap()
        };
        assert_eq!(
            s(SriCommand::SampleRate(SriRateCommand::Smpr, 1000), &mut buf),
            "AT+SMPR=1000\r\n"
        );
        assert_eq!(
            s(SriCommand::SampleRate(SriRateCommand::Smpf, 500), &mut buf),
            "AT+SMPF=500\r\n"
        );
        assert_eq!(
            s(SriCommand::DataMode, &mut buf),
            "AT+SGDM=(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)\r\n"
        );
        assert_eq!(
            s(SriCommand::ComputeUnitMvpv, &mut buf),
            "AT+DCPCU=MVPV\r\n"
        );
        assert_eq!(s(SriCommand::ChecksumSum, &mut buf), "AT+DCKMD=SUM\r\n");
        assert_eq!(s(SriCommand::StartStream, &mut buf), "AT+GSD\r\n");
        assert_eq!(s(SriCommand::StopStream, &mut buf), "AT+GSD=STOP\r\n");
        assert_eq!(s(SriCommand::Zero, &mut buf), "AT+ADJZF=1;1;1;1;1;1\r\n");
        let mut m = [[0.0; 6]; 6];
        for (i, row) in m.iter_mut().enumerate() {
            row[i] = 2497.565 + i as f64;
        }
        m[5][0] = -1.25e-3;
        let text = s(SriCommand::DecouplingMatrix(m), &mut buf);
        assert!(text.starts_with("AT+DCPM=(2497.565000,0.000000,"), "{text}");
        assert!(text.ends_with(";(-0.001250,0.000000,0.000000,0.000000,0.000000,2502.565000)\r\n"));
        let request = SriRequest::parse(&text).unwrap();
        assert_eq!(request.command, "DCPM");
        assert_eq!(parse_matrix(request.parameters), Some(m));
        // the largest matrix fits the line
        let big = [[-123_456_789.123_456; 6]; 6];
        let n = SriCommand::DecouplingMatrix(big).encode(&mut buf);
        assert!(n < MAX_LINE && buf[..n].ends_with(b")\r\n"));
    }

    #[test]
    fn acks_parse() {
        let a = SriAck::parse("ACK+SMPR=300$OK\r\n").unwrap();
        assert_eq!(
            (a.command, a.parameters, a.status, a.ok()),
            ("SMPR", "300", "OK", true)
        );
        let a = SriAck::parse("ACK+ETPT=4008$OK").unwrap();
        assert_eq!((a.command, a.parameters), ("ETPT", "4008"));
        let a = SriAck::parse("ACK+SGDM=(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)$OK").unwrap();
        assert_eq!(a.parameters, "(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)");
        let a = SriAck::parse("ACK+SMPR=99999$ERROR").unwrap();
        assert!(!a.ok());
        assert_eq!(SriAck::parse("AT+SMPR=1"), Err(SriError::NotAck));
        assert_eq!(SriAck::parse("ACK+"), Err(SriError::NotAck));
        assert_eq!(parse_matrix("(1,2,3,4,5,6)"), None);
    }

    proptest! {
        #[test]
        fn random_bytes_never_panic(chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..80), 0..20)) {
            let mut r = FrameReader::new();
            for c in &chunks {
                let mut rest = &c[..];
                while !rest.is_empty() {
                    let n = r.push(rest);
                    rest = &rest[n..];
                    while let Some(x) = r.next_frame() {
                        if let Ok(f) = x {
                            prop_assert!(f.values.len() == 6);
                        }
                    }
                }
                let _ = SriFrame::decode(c);
                if let Ok(s) = std::str::from_utf8(c) {
                    let _ = SriAck::parse(s);
                    let _ = SriRequest::parse(s);
                    let _ = parse_matrix(s);
                }
            }
            prop_assert!(r.pending() <= 2048);
        }

        #[test]
        fn frames_survive_garbage_between_them(
            packages in proptest::collection::vec(any::<u16>(), 1..10),
            junk in proptest::collection::vec(proptest::collection::vec(0u8..0xAA, 0..40), 10),
            split in 1usize..40,
        ) {
            // junk without 0xAA cannot fake a header: every frame is found, every junk run
            // after a frame is one Garbage
            let mut stream = Vec::new();
            for (p, j) in packages.iter().zip(&junk) {
                stream.extend_from_slice(j);
                stream.extend_from_slice(&frame(*p, *p as f32).encode());
            }
            let mut r = FrameReader::new();
            let mut got = Vec::new();
            for part in stream.chunks(split) {
                r.push(part);
                got.extend(drain(&mut r));
            }
            let frames: Vec<u16> = got.iter().filter_map(|x| x.as_ref().ok().map(|f| f.package)).collect();
            prop_assert_eq!(&frames, &packages);
            let garbage = got.iter().filter(|x| x.is_err()).count();
            let expected = junk.iter().take(packages.len()).skip(1).filter(|j| !j.is_empty()).count();
            prop_assert_eq!(garbage, expected);
        }
    }
}
