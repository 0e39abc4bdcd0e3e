//! Transport written once for every device: the host option's form ([`check_host`]), address
//! resolution and UDP binding ([`resolve`], [`bind_udp`], [`local_addr`]), counted receives
//! ([`recv_counted`]), the one sequence rule ([`SequenceTracker`], [`sequence_counted`]) and
//! the robot-paced wait ([`wait_readable`]). Every socket error and every dropped datagram is
//! counted in the caller's [`LinkStats`]; nothing here allocates after opening.

use std::io::ErrorKind;
use std::net::{SocketAddr, ToSocketAddrs, UdpSocket};

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

/// Tracks a stream's sequence numbers (wrapping `u32`): accepts only newer packets and
/// counts the missing ones. Never allocates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SequenceTracker {
    last: Option<u32>,
}

impl SequenceTracker {
    /// A tracker that has seen nothing.
    pub fn new() -> Self {
        SequenceTracker { last: None }
    }

    /// The last accepted sequence number.
    pub fn last(&self) -> Option<u32> {
        self.last
    }

    /// Classifies `seq` and, unless it is stale, accepts it as the newest. A jump of more
    /// than 2³¹ backwards is taken as older (wrapping comparison).
    pub fn check(&mut self, seq: u32) -> SequenceVerdict {
        let Some(last) = self.last else {
            self.last = Some(seq);
            return SequenceVerdict::First;
        };
        let ahead = seq.wrapping_sub(last) as i32;
        if ahead <= 0 {
            return SequenceVerdict::Stale;
        }
        self.last = Some(seq);
        if ahead == 1 {
            SequenceVerdict::Next
        } else {
            SequenceVerdict::Gap(ahead as u32 - 1)
        }
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
pub fn sequence_counted(tracker: &mut SequenceTracker, seq: u32, stats: &mut LinkStats) -> bool {
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
