//! Transport written once for every device: the host option's form ([`check_host`]), address
//! resolution and UDP binding ([`resolve`], [`bind_udp`], [`local_addr`]), counted receives
//! ([`recv_counted`]) and the receive loop with its peer filter ([`UdpInbox`]), the one
//! classification of decoding errors ([`DecodeError`], [`decode_counted`]), the one sequence
//! rule ([`SequenceTracker`], [`sequence_counted`]), the local address facing a peer
//! ([`bind_address_for`]) and the robot-paced wait ([`wait_readable`]). Every socket error and every dropped datagram is
//! counted in the caller's [`LinkStats`]; nothing here allocates after opening.

use std::io::ErrorKind;
use std::net::{IpAddr, SocketAddr, ToSocketAddrs, UdpSocket};

use super::link::LinkStats;
use crate::clock::now_ns;
use crate::error::{Result, RtError};

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

/// What a sequence number says about a packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SequenceVerdict {
    /// The first packet seen.
    First,
    /// The packet after the last accepted one.
    Next,
    /// Newer than the last accepted one, with this many packets missing in between.
    Gap(u32),
    /// The same as the last accepted one (a duplicate) or older (reordered): drop it.
    Stale,
}

/// A protocol's sequence number: how many packets `self` is ahead of `last` (> 0: newer, 1 =
/// the next one; <= 0: the same or older).
pub trait SequenceNumber: Copy {
    /// Packets from `last` to `self`.
    fn ahead(self, last: Self) -> i64;
}

/// RDT and EGM: a wrapping `u32` counter (a jump of more than 2³¹ backwards is older).
impl SequenceNumber for u32 {
    fn ahead(self, last: u32) -> i64 {
        self.wrapping_sub(last) as i32 as i64
    }
}

/// SRI: a wrapping `u16` package number.
impl SequenceNumber for u16 {
    fn ahead(self, last: u16) -> i64 {
        self.wrapping_sub(last) as i16 as i64
    }
}

/// KUKA RSI: the IPOC time stamp (ms) and the controller's cycle (ms); a newer IPOC is at
/// least one cycle ahead, rounded to whole cycles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ipoc {
    /// The time stamp, ms.
    pub ms: u64,
    /// The cycle, ms (at least 1).
    pub step_ms: u64,
}

impl SequenceNumber for Ipoc {
    fn ahead(self, last: Ipoc) -> i64 {
        if self.ms <= last.ms {
            return 0;
        }
        let step = self.step_ms.max(1);
        ((self.ms - last.ms + step / 2) / step).clamp(1, i64::MAX as u64) as i64
    }
}

/// Tracks a stream's sequence numbers: accepts only newer packets and counts the missing
/// ones ([`SequenceTracker::check`]), or, for a stream that is never reordered, accepts every
/// packet and counts the gaps ([`SequenceTracker::advance`]). The one sequence rule of every
/// link and endpoint. Never allocates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SequenceTracker<T = u32> {
    last: Option<T>,
}

impl<T: SequenceNumber> SequenceTracker<T> {
    /// A tracker that has seen nothing.
    pub fn new() -> Self {
        SequenceTracker { last: None }
    }

    /// The last accepted sequence number.
    pub fn last(&self) -> Option<T> {
        self.last
    }

    /// Classifies `seq` and, unless it is stale, accepts it as the newest.
    pub fn check(&mut self, seq: T) -> SequenceVerdict {
        let Some(last) = self.last else {
            self.last = Some(seq);
            return SequenceVerdict::First;
        };
        let ahead = seq.ahead(last);
        if ahead <= 0 {
            return SequenceVerdict::Stale;
        }
        self.last = Some(seq);
        if ahead == 1 {
            SequenceVerdict::Next
        } else {
            SequenceVerdict::Gap((ahead - 1).min(u32::MAX as i64) as u32)
        }
    }

    /// Accepts `seq` as the newest whatever it is (a repeat or a restart counts nothing);
    /// returns how many are missing before it.
    pub fn advance(&mut self, seq: T) -> u32 {
        let lost = match self.last {
            Some(last) => (seq.ahead(last) - 1).clamp(0, u32::MAX as i64) as u32,
            None => 0,
        };
        self.last = Some(seq);
        lost
    }
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
pub fn sequence_counted<T: SequenceNumber>(
    tracker: &mut SequenceTracker<T>,
    seq: T,
    stats: &mut LinkStats,
) -> bool {
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

/// A decoding error as the counters see it: a malformed datagram (not the protocol's
/// bytes: wrong size, header, type, or undecodable) or an invalid one (the protocol's bytes,
/// values not usable: non-finite, out of range, an error status).
pub trait DecodeError {
    /// Whether the datagram is malformed (else: invalid).
    fn is_malformed(&self) -> bool;
}

/// The decoded message, or None with the error counted (`malformed` or `invalid`): the one
/// classification of decoding errors of every link and endpoint.
pub fn decode_counted<T, E: DecodeError>(
    decoded: std::result::Result<T, E>,
    stats: &mut LinkStats,
) -> Option<T> {
    match decoded {
        Ok(message) => Some(message),
        Err(e) if e.is_malformed() => {
            stats.malformed += 1;
            None
        }
        Err(_) => {
            stats.invalid += 1;
            None
        }
    }
}

/// A non-blocking UDP socket with its receive buffer of `N` bytes: the receive loop of every
/// UDP link and endpoint, written once. [`UdpInbox::next`] counts every datagram `received`,
/// drops and counts `foreign` the ones whose sender the caller's filter refuses, and every
/// socket error (`io_errors`). Never allocates after opening.
pub struct UdpInbox<const N: usize> {
    socket: UdpSocket,
    buf: [u8; N],
}

impl<const N: usize> UdpInbox<N> {
    /// Binds a non-blocking UDP socket on `addr`; `what` names it for the message.
    pub fn bind(what: &str, addr: SocketAddr) -> Result<Self> {
        Ok(UdpInbox {
            socket: bind_udp(what, addr)?,
            buf: [0u8; N],
        })
    }

    /// The socket (to send from, to wait on).
    pub fn socket(&self) -> &UdpSocket {
        &self.socket
    }

    /// The next datagram waiting whose sender `admits` accepts: its bytes and sender, or None
    /// when nothing is waiting. Counts into `stats`.
    pub fn next(
        &mut self,
        stats: &mut LinkStats,
        mut admits: impl FnMut(SocketAddr) -> bool,
    ) -> Option<(&[u8], SocketAddr)> {
        loop {
            let (n, from) = recv_counted(&self.socket, &mut self.buf, stats)?;
            stats.received += 1;
            if admits(from) {
                return Some((&self.buf[..n], from));
            }
            stats.foreign += 1;
        }
    }
}

/// The local address to bind on `port` to talk to `peer`: loopback when the peer is (the
/// emulator and the loop on one machine), else every interface of the peer's family.
pub fn bind_address_for(peer: SocketAddr, port: u16) -> SocketAddr {
    match peer.ip() {
        IpAddr::V4(ip) if ip.is_loopback() => SocketAddr::from(([127, 0, 0, 1], port)),
        IpAddr::V4(_) => SocketAddr::from(([0, 0, 0, 0], port)),
        IpAddr::V6(_) => SocketAddr::from(([0u16; 8], port)),
    }
}
