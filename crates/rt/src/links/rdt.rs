//! [`SensorLink`] for an ATI Net F/T sensor: RDT over UDP (codec in [`crate::rdt`]), counts per
//! unit from `/netftapi2.xml` over HTTP ([`crate::netftapi`]) unless given.
//!
//! A record is accepted when it comes from the sensor's address, is 36 bytes, has a sequence
//! number newer than the last accepted one (gaps are counted as `lost`) and status 0; its
//! counts divided by the counts per unit are the wrench (sensor frame, N and N·m).

use std::net::{SocketAddr, UdpSocket};
use std::time::Duration;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::{recv_counted, LinkContext, LinkStats, SensorLink, Wrench};
use crate::emulator::{bind_udp, resolve};
use crate::error::{Result, RtError};
use crate::netftapi::fetch_counts;
use crate::rdt::{
    CountsPerUnit, RdtCommand, RdtRecord, RdtRequest, SequenceTracker, SequenceVerdict, RDT_PORT,
};

/// Options of an RDT sensor link (`[sensor] kind = "rdt"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RdtOptions {
    /// Host of the F/T sensor (Net F/T) (CLI `--sensor`).
    pub host: String,
    /// RDT port of the sensor (49152) (CLI `--sensor-port`).
    pub port: u16,
    /// HTTP port of the sensor's `/netftapi2.xml` (80) (CLI `--http-port`).
    pub http_port: u16,
    /// Counts per N; with `counts_per_torque`, skips reading `/netftapi2.xml`.
    pub counts_per_force: Option<f64>,
    /// Counts per N·m.
    pub counts_per_torque: Option<f64>,
    /// Local UDP port of the RDT client (0 = any free port) (CLI `--rdt-local-port`).
    pub local_port: u16,
    /// Send the sensor a bias command (0x0042) before streaming: the rod must be free.
    pub bias: bool,
}

impl Default for RdtOptions {
    fn default() -> Self {
        RdtOptions {
            host: "127.0.0.1".into(),
            port: RDT_PORT,
            http_port: 80,
            counts_per_force: None,
            counts_per_torque: None,
            local_port: 0,
            bias: false,
        }
    }
}

/// The RDT client of an ATI Net F/T sensor.
pub struct RdtSensor {
    socket: UdpSocket,
    peer: SocketAddr,
    counts: CountsPerUnit,
    sequence: SequenceTracker,
    stats: LinkStats,
    bias_pending: bool,
    buf: [u8; 2048],
}

impl RdtSensor {
    /// Validates the options, reads the counts per unit (HTTP, unless both are given) and
    /// binds the client socket.
    pub fn open(o: &RdtOptions, context: &LinkContext) -> Result<Self> {
        let counts = match (o.counts_per_force, o.counts_per_torque) {
            (Some(force), Some(torque)) => {
                if !(force.is_finite() && force > 0.0 && torque.is_finite() && torque > 0.0) {
                    return Err(RtError::option("counts_per_force", "counts per unit must be positive numbers"));
                }
                CountsPerUnit { force, torque }
            }
            (None, None) => fetch_counts(&o.host, o.http_port, Duration::from_secs_f64(context.connect_timeout.min(5.0)))
                .map_err(|e| RtError::Connect(format!("cannot read the sensor's counts per unit: {e} (or give counts_per_force and counts_per_torque)")))?,
            _ => return Err(RtError::option("counts_per_force", "give both counts_per_force and counts_per_torque, or neither")),
        };
        let peer = resolve("sensor_host", &o.host, o.port)?;
        let bind: SocketAddr = if peer.ip().is_loopback() {
            ([127, 0, 0, 1], o.local_port).into()
        } else {
            ([0, 0, 0, 0], o.local_port).into()
        };
        Ok(RdtSensor {
            socket: bind_udp("RDT client", bind)?,
            peer,
            counts,
            sequence: SequenceTracker::new(),
            stats: LinkStats::default(),
            bias_pending: o.bias,
            buf: [0u8; 2048],
        })
    }

    /// The counts per unit in use.
    pub fn counts(&self) -> CountsPerUnit {
        self.counts
    }

    fn request(&mut self, command: RdtCommand) {
        let bytes = RdtRequest {
            command,
            sample_count: 0,
        }
        .encode();
        let sent = self.socket.send_to(&bytes, self.peer);
        self.stats.count_send(sent);
    }
}

impl SensorLink for RdtSensor {
    fn name(&self) -> &'static str {
        "RDT"
    }

    fn describe(&self) -> String {
        format!("the sensor at {}", self.peer)
    }

    fn start_streaming(&mut self) {
        if std::mem::take(&mut self.bias_pending) {
            self.bias();
        }
        self.request(RdtCommand::StartRealtime);
    }

    fn stop_streaming(&mut self) {
        for _ in 0..2 {
            self.request(RdtCommand::Stop);
        }
    }

    fn bias(&mut self) {
        self.request(RdtCommand::SetBias);
    }

    fn poll(&mut self, _now_ns: u64) -> Option<Wrench> {
        let mut newest = None;
        while let Some((n, from)) = recv_counted(&self.socket, &mut self.buf, &mut self.stats) {
            self.stats.received += 1;
            if from != self.peer {
                self.stats.foreign += 1;
                continue;
            }
            let Ok(record) = RdtRecord::decode(&self.buf[..n]) else {
                self.stats.malformed += 1;
                continue;
            };
            match self.sequence.check(record.rdt_sequence) {
                SequenceVerdict::Stale => {
                    self.stats.stale += 1;
                    continue;
                }
                SequenceVerdict::Gap(n) => self.stats.lost += n as u64,
                SequenceVerdict::First | SequenceVerdict::Next => {}
            }
            // a record with an error status arrived (not lost) but its values are not used
            if record.status != 0 {
                self.stats.invalid += 1;
                continue;
            }
            let (f, m) = self.counts.to_wrench(&record.counts);
            newest = Some(Wrench {
                force: Vector3::from(f),
                moment: Vector3::from(m),
            });
            self.stats.accepted += 1;
        }
        newest
    }

    fn stats(&self) -> &LinkStats {
        &self.stats
    }

    fn stats_mut(&mut self) -> &mut LinkStats {
        &mut self.stats
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert("counts_per_force".into(), self.counts.force.into());
        m.insert("counts_per_torque".into(), self.counts.torque.into());
        m
    }
}
