//! ATI Net F/T Raw Data Transfer (RDT) over UDP: the request and record codec.
//!
//! Wire format (all big-endian), as the Net F/T manual (ATI 9620-05-NET FT, section "RDT")
//! defines it and as independent clients (`NetFT` on PyPI) use it:
//!
//! - request, 8 bytes, client to sensor port 49152: `u16 header = 0x1234`, `u16 command`,
//!   `u32 sample_count` (0 = stream until stopped);
//! - record, 36 bytes, sensor to the requesting address: `u32 rdt_sequence` (one per RDT
//!   packet sent), `u32 ft_sequence` (one per internal sample, counting also the samples not
//!   sent), `u32 status` (0 = healthy), then `Fx, Fy, Fz, Tx, Ty, Tz` as `i32` counts.
//!
//! Counts convert to N and N·m through the counts per force/torque (`cfgcpf`, `cfgcpt`) that
//! the sensor serves in `/netftapi2.xml` (see [`super::netftapi`]).
//!
//! Decoding never allocates and never panics: a datagram of the wrong size or header is an
//! [`RdtError`].

use crate::devices::transport::DecodeError;
use thiserror::Error;

/// The sensor's RDT port (fixed on a real Net F/T).
pub const RDT_PORT: u16 = 49152;
/// First two bytes of every request.
pub const RDT_HEADER: u16 = 0x1234;
/// Size of a request, bytes.
pub const REQUEST_LEN: usize = 8;
/// Size of a record, bytes.
pub const RECORD_LEN: usize = 36;

/// An RDT command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RdtCommand {
    /// 0x0000: stop streaming.
    Stop,
    /// 0x0002: start high-speed real-time streaming (one record per packet).
    StartRealtime,
    /// 0x0003: start high-speed buffered streaming (the emulator answers it as real-time).
    StartBuffered,
    /// 0x0042: set the software bias to the current reading.
    SetBias,
}

impl RdtCommand {
    /// The command's code on the wire.
    pub fn code(self) -> u16 {
        match self {
            RdtCommand::Stop => 0x0000,
            RdtCommand::StartRealtime => 0x0002,
            RdtCommand::StartBuffered => 0x0003,
            RdtCommand::SetBias => 0x0042,
        }
    }

    /// The command of a code, if it is one this crate handles.
    pub fn from_code(code: u16) -> Option<Self> {
        match code {
            0x0000 => Some(RdtCommand::Stop),
            0x0002 => Some(RdtCommand::StartRealtime),
            0x0003 => Some(RdtCommand::StartBuffered),
            0x0042 => Some(RdtCommand::SetBias),
            _ => None,
        }
    }
}

/// Why a datagram is not a valid request or record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum RdtError {
    /// The datagram does not have the size of a request or a record.
    #[error("wrong size: expected {expected} bytes, got {got}")]
    WrongSize {
        /// Expected size, bytes.
        expected: usize,
        /// Received size, bytes.
        got: usize,
    },
    /// A request does not start with 0x1234.
    #[error("wrong header 0x{0:04x} (expected 0x1234)")]
    WrongHeader(u16),
    /// A request carries a command this crate does not handle.
    #[error("unknown command 0x{0:04x}")]
    UnknownCommand(u16),
}

/// RDT decoding errors as the counters see them: every one is a malformed datagram (a record's
/// error status is checked after decoding, and counted invalid).
impl DecodeError for RdtError {
    fn is_malformed(&self) -> bool {
        true
    }
}

/// A request from a client.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RdtRequest {
    /// The command.
    pub command: RdtCommand,
    /// Number of records to send, 0 = until stopped.
    pub sample_count: u32,
}

impl RdtRequest {
    /// The 8 bytes on the wire.
    pub fn encode(&self) -> [u8; REQUEST_LEN] {
        let mut out = [0u8; REQUEST_LEN];
        out[0..2].copy_from_slice(&RDT_HEADER.to_be_bytes());
        out[2..4].copy_from_slice(&self.command.code().to_be_bytes());
        out[4..8].copy_from_slice(&self.sample_count.to_be_bytes());
        out
    }

    /// Parses a request datagram.
    pub fn decode(datagram: &[u8]) -> Result<Self, RdtError> {
        let bytes: &[u8; REQUEST_LEN] = datagram.try_into().map_err(|_| RdtError::WrongSize {
            expected: REQUEST_LEN,
            got: datagram.len(),
        })?;
        let header = u16::from_be_bytes([bytes[0], bytes[1]]);
        if header != RDT_HEADER {
            return Err(RdtError::WrongHeader(header));
        }
        let code = u16::from_be_bytes([bytes[2], bytes[3]]);
        let command = RdtCommand::from_code(code).ok_or(RdtError::UnknownCommand(code))?;
        Ok(RdtRequest {
            command,
            sample_count: u32::from_be_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]),
        })
    }
}

/// A record from the sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RdtRecord {
    /// Sequence number of the RDT packet (one per packet sent).
    pub rdt_sequence: u32,
    /// Sequence number of the internal sample (one per sample taken, sent or not).
    pub ft_sequence: u32,
    /// Status word, 0 = healthy.
    pub status: u32,
    /// `Fx, Fy, Fz, Tx, Ty, Tz`, counts.
    pub counts: [i32; 6],
}

impl RdtRecord {
    /// The 36 bytes on the wire.
    pub fn encode(&self) -> [u8; RECORD_LEN] {
        let mut out = [0u8; RECORD_LEN];
        out[0..4].copy_from_slice(&self.rdt_sequence.to_be_bytes());
        out[4..8].copy_from_slice(&self.ft_sequence.to_be_bytes());
        out[8..12].copy_from_slice(&self.status.to_be_bytes());
        for (i, c) in self.counts.iter().enumerate() {
            out[12 + 4 * i..16 + 4 * i].copy_from_slice(&c.to_be_bytes());
        }
        out
    }

    /// Parses a record datagram (exactly 36 bytes).
    pub fn decode(datagram: &[u8]) -> Result<Self, RdtError> {
        let b: &[u8; RECORD_LEN] = datagram.try_into().map_err(|_| RdtError::WrongSize {
            expected: RECORD_LEN,
            got: datagram.len(),
        })?;
        let word = |i: usize| [b[i], b[i + 1], b[i + 2], b[i + 3]];
        let mut counts = [0i32; 6];
        for (i, c) in counts.iter_mut().enumerate() {
            *c = i32::from_be_bytes(word(12 + 4 * i));
        }
        Ok(RdtRecord {
            rdt_sequence: u32::from_be_bytes(word(0)),
            ft_sequence: u32::from_be_bytes(word(4)),
            status: u32::from_be_bytes(word(8)),
            counts,
        })
    }
}

/// The sensor's calibration scale: counts per N and per N·m (`cfgcpf`, `cfgcpt`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CountsPerUnit {
    /// Counts per N (> 0).
    pub force: f64,
    /// Counts per N·m (> 0).
    pub torque: f64,
}

impl Default for CountsPerUnit {
    /// 1 000 000 counts per N and per N·m, the Net F/T's usual configuration.
    fn default() -> Self {
        CountsPerUnit {
            force: 1.0e6,
            torque: 1.0e6,
        }
    }
}

impl CountsPerUnit {
    /// Force (N) and moment (N·m) of a record's counts.
    pub fn to_wrench(&self, counts: &[i32; 6]) -> ([f64; 3], [f64; 3]) {
        let f = |i: usize| counts[i] as f64 / self.force;
        let t = |i: usize| counts[i] as f64 / self.torque;
        ([f(0), f(1), f(2)], [t(3), t(4), t(5)])
    }

    /// Counts of a force (N) and moment (N·m), rounded and saturated at the `i32` range;
    /// the flag says whether any axis saturated (a NaN saturates to 0 and sets it too).
    pub fn to_counts(&self, force: &[f64; 3], moment: &[f64; 3]) -> ([i32; 6], bool) {
        let mut counts = [0i32; 6];
        let mut saturated = false;
        for i in 0..6 {
            let value = if i < 3 {
                force[i] * self.force
            } else {
                moment[i - 3] * self.torque
            };
            let rounded = value.round();
            if !(rounded >= i32::MIN as f64 && rounded <= i32::MAX as f64) {
                saturated = true;
            }
            counts[i] = rounded as i32; // `as` saturates, NaN to 0
        }
        (counts, saturated)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::devices::transport::{SequenceTracker, SequenceVerdict};
    use proptest::prelude::*;

    #[test]
    fn request_matches_the_netft_client_bytes() {
        // NetFT: struct.pack('!HHI', 0x1234, 2, 0)
        let r = RdtRequest {
            command: RdtCommand::StartRealtime,
            sample_count: 0,
        };
        assert_eq!(r.encode(), [0x12, 0x34, 0x00, 0x02, 0, 0, 0, 0]);
        let bias = RdtRequest {
            command: RdtCommand::SetBias,
            sample_count: 7,
        };
        assert_eq!(bias.encode(), [0x12, 0x34, 0x00, 0x42, 0, 0, 0, 7]);
        assert_eq!(RdtRequest::decode(&bias.encode()), Ok(bias));
    }

    #[test]
    fn record_layout_is_big_endian() {
        let r = RdtRecord {
            rdt_sequence: 1,
            ft_sequence: 0x0102_0304,
            status: 0,
            counts: [-1, 2, 0, 0, 0, 0x7fff_ffff],
        };
        let b = r.encode();
        assert_eq!(&b[0..4], &[0, 0, 0, 1]);
        assert_eq!(&b[4..8], &[1, 2, 3, 4]);
        assert_eq!(&b[12..16], &[0xff, 0xff, 0xff, 0xff]);
        assert_eq!(&b[32..36], &[0x7f, 0xff, 0xff, 0xff]);
        assert_eq!(RdtRecord::decode(&b), Ok(r));
    }

    #[test]
    fn malformed_requests_are_errors() {
        assert_eq!(
            RdtRequest::decode(&[0x12, 0x34, 0, 2, 0, 0, 0]),
            Err(RdtError::WrongSize {
                expected: 8,
                got: 7
            })
        );
        assert_eq!(
            RdtRequest::decode(&[0x12, 0x35, 0, 2, 0, 0, 0, 0]),
            Err(RdtError::WrongHeader(0x1235))
        );
        assert_eq!(
            RdtRequest::decode(&[0x12, 0x34, 0, 9, 0, 0, 0, 0]),
            Err(RdtError::UnknownCommand(9))
        );
        assert_eq!(
            RdtRecord::decode(&[0u8; 35]),
            Err(RdtError::WrongSize {
                expected: 36,
                got: 35
            })
        );
        assert_eq!(
            RdtRecord::decode(&[0u8; 72]),
            Err(RdtError::WrongSize {
                expected: 36,
                got: 72
            })
        );
        assert_eq!(
            RdtRecord::decode(&[]),
            Err(RdtError::WrongSize {
                expected: 36,
                got: 0
            })
        );
    }

    #[test]
    fn counts_convert_both_ways_and_saturate() {
        let cpu = CountsPerUnit {
            force: 1.0e6,
            torque: 2.0e5,
        };
        let (counts, sat) = cpu.to_counts(&[881.375, -0.5, 0.0], &[0.0, 132.20625, -1.0]);
        assert!(!sat);
        assert_eq!(counts, [881_375_000, -500_000, 0, 0, 26_441_250, -200_000]);
        let (f, m) = cpu.to_wrench(&counts);
        assert!((f[0] - 881.375).abs() < 1e-9 && (m[1] - 132.20625).abs() < 1e-9);
        let (counts, sat) = cpu.to_counts(&[5000.0, f64::NAN, 0.0], &[0.0; 3]);
        assert!(sat);
        assert_eq!(counts[0], i32::MAX);
        assert_eq!(counts[1], 0);
    }

    #[test]
    fn sequences_accept_newer_count_gaps_drop_duplicates() {
        let mut s: SequenceTracker = SequenceTracker::new();
        assert_eq!(s.check(10), SequenceVerdict::First);
        assert_eq!(s.check(11), SequenceVerdict::Next);
        assert_eq!(s.check(11), SequenceVerdict::Stale);
        assert_eq!(s.check(9), SequenceVerdict::Stale);
        assert_eq!(s.check(15), SequenceVerdict::Gap(3));
        assert_eq!(s.last(), Some(15));
        let mut w: SequenceTracker = SequenceTracker::new();
        w.check(u32::MAX);
        assert_eq!(w.check(0), SequenceVerdict::Next); // wraps
        assert_eq!(w.check(u32::MAX), SequenceVerdict::Stale);
    }

    proptest! {
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..100)) {
            let request = RdtRequest::decode(&bytes);
            let record = RdtRecord::decode(&bytes);
            prop_assert_eq!(record.is_ok(), bytes.len() == RECORD_LEN);
            if let Ok(r) = request {
                prop_assert_eq!(&r.encode()[..], &bytes[..]);
            }
        }

        #[test]
        fn records_round_trip(a in any::<u32>(), b in any::<u32>(), c in any::<u32>(), counts in any::<[i32; 6]>()) {
            let r = RdtRecord { rdt_sequence: a, ft_sequence: b, status: c, counts };
            prop_assert_eq!(RdtRecord::decode(&r.encode()), Ok(r));
        }

        #[test]
        fn sequence_tracker_accepts_only_increasing(seqs in proptest::collection::vec(any::<u16>(), 1..50)) {
            let mut s: SequenceTracker = SequenceTracker::new();
            let mut last: Option<u32> = None;
            for q in seqs {
                let q = q as u32;
                let v = s.check(q);
                match last {
                    None => prop_assert_eq!(v, SequenceVerdict::First),
                    Some(l) if q <= l => prop_assert_eq!(v, SequenceVerdict::Stale),
                    Some(l) if q == l + 1 => prop_assert_eq!(v, SequenceVerdict::Next),
                    Some(l) => prop_assert_eq!(v, SequenceVerdict::Gap(q - l - 1)),
                }
                if last.is_none_or(|l| q > l) { last = Some(q); }
            }
        }
    }
}
