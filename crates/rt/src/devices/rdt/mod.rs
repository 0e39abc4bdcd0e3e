//! ATI Net F/T over RDT, both sides: [`RdtSensor`] is the [`SensorLink`] of the loop (RDT over
//! UDP, codec in [`self::codec`]; counts per unit and the configured units from
//! `/netftapi2.xml` over HTTP, [`self::netftapi`], unless given), [`RdtEndpoint`] the emulated
//! sensor's [`SensorEndpoint`] (configurable units: fault injection for clients that ignore
//! them).
//!
//! A record is accepted when it comes from the sensor's address, is 36 bytes, has a sequence
//! number newer than the last accepted one (gaps are counted as `lost`) and status 0; its
//! counts divided by the counts per unit are the wrench (sensor frame, N and N·m).

pub mod codec;
pub mod netftapi;

use std::net::SocketAddr;
use std::time::Duration;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use self::codec::{CountsPerUnit, RdtCommand, RdtRecord, RdtRequest, RDT_PORT};
use self::netftapi::{
    fetch_counts, netftapi_xml, ForceUnit, NetFtApiServer, SensorCalibration, TorqueUnit,
};
use super::transport::{bind_address_for, decode_counted, SequenceTracker, UdpInbox};
use super::{
    check_host, local_addr, resolve, sequence_counted, EmulatedSensor, EndpointContext,
    LinkContext, LinkStats, SensorDevice, SensorEndpoint, SensorLink, Wrench,
};
use crate::error::{Result, RtError};

/// Options of an RDT sensor link (`[sensor] kind = "rdt"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RdtOptions {
    /// Host of the F/T sensor (Net F/T) (CLI `--sensor`).
    pub host: String,
    /// RDT port of the sensor (49152) (CLI `--sensor-port`).
    pub port: u16,
    /// HTTP port of the sensor's `/netftapi2.xml` (80) (CLI `--http-port`).
    pub http_port: u16,
    /// Counts per N (> 0); with `counts_per_torque`, skips reading `/netftapi2.xml`.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub counts_per_force: Option<f64>,
    /// Counts per N·m (> 0); with `counts_per_force`.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
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
    inbox: UdpInbox<2048>,
    peer: SocketAddr,
    /// Counts per N and per N·m.
    counts: CountsPerUnit,
    /// What `/netftapi2.xml` said (None: the counts were given in the options).
    calibration: Option<SensorCalibration>,
    sequence: SequenceTracker,
    stats: LinkStats,
    bias_pending: bool,
}

/// An RDT link's options once parsed ([`SensorDevice::parse`] of [`RdtSensor`]): the host's form checked, the
/// counts per unit given (both positive) or to be read from `/netftapi2.xml`.
#[derive(Debug, Clone, PartialEq)]
pub struct RdtConfig {
    options: RdtOptions,
    /// Counts per N and per N·m, when given in the options.
    counts: Option<CountsPerUnit>,
}

impl RdtSensor {
    /// Parses the options ([`SensorDevice::parse`] of [`RdtSensor`]) and opens the link ([`RdtSensor::open_parsed`]).
    pub fn open(o: &RdtOptions, context: &LinkContext) -> Result<Self> {
        Self::open_parsed(&Self::parse(o)?, context)
    }

    /// The counts per N and per N·m in use.
    pub fn counts(&self) -> CountsPerUnit {
        self.counts
    }

    /// What the sensor's `/netftapi2.xml` said: its configured force and torque units (the
    /// page's counts are per these) and whether they were assumed (N, N·m: the page gives
    /// none). None when the counts were given in the options (per N and N·m).
    pub fn calibration(&self) -> Option<SensorCalibration> {
        self.calibration
    }

    fn request(&mut self, command: RdtCommand) {
        let bytes = RdtRequest {
            command,
            sample_count: 0,
        }
        .encode();
        let sent = self.inbox.socket().send_to(&bytes, self.peer);
        self.stats.count_send(sent);
    }
}

impl SensorDevice for RdtSensor {
    type Options = RdtOptions;
    type Config = RdtConfig;

    /// Checks the host's form and the counts per unit (both positive, or neither), once.
    fn parse(options: &RdtOptions) -> Result<RdtConfig> {
        check_host("sensor host", &options.host)?;
        let counts = match (options.counts_per_force, options.counts_per_torque) {
            (Some(force), Some(torque)) => {
                if !(force.is_finite() && force > 0.0 && torque.is_finite() && torque > 0.0) {
                    return Err(RtError::option(
                        "counts_per_force",
                        "counts per unit must be positive numbers",
                    ));
                }
                Some(CountsPerUnit { force, torque })
            }
            (None, None) => None,
            _ => {
                return Err(RtError::option(
                    "counts_per_force",
                    "give both counts_per_force and counts_per_torque, or neither",
                ))
            }
        };
        Ok(RdtConfig {
            options: options.clone(),
            counts,
        })
    }

    /// Reads the counts per unit and the configured units (HTTP, unless both counts are given,
    /// then per N and N·m) and binds the client socket.
    fn open_parsed(c: &RdtConfig, context: &LinkContext) -> Result<Self> {
        let o = &c.options;
        let (counts, calibration) = match c.counts {
            Some(counts) => (counts, None),
            None => {
                // a box still booting refuses the connection: the page is asked again until
                // connect_timeout; any other answer (a bad page) is final
                let give_up =
                    std::time::Instant::now() + Duration::from_secs_f64(context.connect_timeout);
                let c = loop {
                    let attempt = fetch_counts(&o.host, o.http_port, Duration::from_secs_f64(context.connect_timeout.clamp(0.1, 5.0)));
                    match attempt {
                        Err(RtError::Io { .. }) if std::time::Instant::now() + Duration::from_millis(100) < give_up => {
                            std::thread::sleep(Duration::from_millis(100));
                        }
                        other => break other,
                    }
                }
                .map_err(|e| RtError::Connect(format!("cannot read the sensor's counts per unit within {} s (connect_timeout): {e} (or give counts_per_force and counts_per_torque)", context.connect_timeout)))?;
                (c.counts, Some(c))
            }
        };
        let peer = resolve("sensor_host", &o.host, o.port)?;
        Ok(RdtSensor {
            inbox: UdpInbox::bind("RDT client", bind_address_for(peer, o.local_port))?,
            peer,
            counts,
            calibration,
            sequence: SequenceTracker::new(),
            stats: LinkStats::default(),
            bias_pending: o.bias,
        })
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
        let peer = self.peer;
        while let Some((bytes, _)) = self.inbox.next(&mut self.stats, |from| from == peer) {
            let Some(record) = decode_counted(RdtRecord::decode(bytes), &mut self.stats) else {
                continue;
            };
            if !sequence_counted(&mut self.sequence, record.rdt_sequence, &mut self.stats) {
                continue;
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

    super::link::stats_accessors!();

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert("counts_per_force".into(), self.counts.force.into());
        m.insert("counts_per_torque".into(), self.counts.torque.into());
        // the sensor's configured units and where they came from
        let (force, torque, source) = match self.calibration {
            None => (ForceUnit::N, TorqueUnit::Nm, "options"),
            Some(c) if c.units_assumed => (
                c.force_unit,
                c.torque_unit,
                "assumed: netftapi2.xml gives no unit",
            ),
            Some(c) => (c.force_unit, c.torque_unit, "netftapi2.xml"),
        };
        m.insert(
            "sensor_units".into(),
            serde_json::json!({"force": force.name(), "torque": torque.name(), "source": source}),
        );
        m
    }
}

/// Options of the emulated RDT sensor (`[sensor] kind = "rdt"` of the emulator's options).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RdtEndpointOptions {
    /// Address the sensor's RDT and HTTP servers bind to (CLI `--bind-host`).
    pub bind_host: String,
    /// RDT (UDP) port (49152 on a real sensor) (CLI `--sensor-port`).
    pub port: u16,
    /// HTTP port of `/netftapi2.xml` (80 on a real sensor; 0 = no HTTP server) (CLI
    /// `--http-port`).
    pub http_port: u16,
    /// Counts per `force_unit` of the records (`cfgcpf`, > 0) (CLI `--counts-per-force`).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub counts_per_force: f64,
    /// Counts per `torque_unit` of the records (`cfgcpt`, > 0) (CLI `--counts-per-torque`).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub counts_per_torque: f64,
    /// The configured force unit (`scfgfu`/`cfgfu`): `"N"` (default), `"lbf"`, `"klbf"`,
    /// `"kN"`, `"kgf"`, `"gf"`. Another unit than N tests that a client reads the units.
    #[schemars(extend("enum" = ["lbf", "N", "klbf", "kN", "kgf", "gf"]))]
    pub force_unit: String,
    /// The configured torque unit (`scfgtu`/`cfgtu`): `"N-m"` (default), `"lbf-in"`,
    /// `"lbf-ft"`, `"N-mm"`, `"kgf-cm"`, `"kN-m"`.
    #[schemars(extend("enum" = ["lbf-in", "lbf-ft", "N-m", "N-mm", "kgf-cm", "kN-m"]))]
    pub torque_unit: String,
}

impl Default for RdtEndpointOptions {
    fn default() -> Self {
        RdtEndpointOptions {
            bind_host: "127.0.0.1".into(),
            port: RDT_PORT,
            http_port: 80,
            counts_per_force: CountsPerUnit::default().force,
            counts_per_torque: CountsPerUnit::default().torque,
            force_unit: ForceUnit::N.name().into(),
            torque_unit: TorqueUnit::Nm.name().into(),
        }
    }
}

/// The emulated Net F/T sensor. A start request (0x0002, or 0x0003 answered the same way)
/// makes it stream one 36-byte record per sample to the requesting address, `sample_count`
/// records or until a stop (0x0000); 0x0042 biases the output by the current reading.
/// `rdt_sequence` counts the records sent, `ft_sequence` the samples taken (one per control
/// period, streaming or not), as the real sensor keeps them. `/netftapi2.xml` gives the counts
/// per configured unit and the units; the records count in those units. A count beyond the
/// `i32` range saturates and sets status `0x80010000`.
pub struct RdtEndpoint {
    inbox: UdpInbox<2048>,
    address: SocketAddr,
    http: Option<NetFtApiServer>,
    /// Counts per N and per N·m (the options' counts per configured unit, converted).
    counts: CountsPerUnit,
    /// Streaming destination.
    client: Option<SocketAddr>,
    /// Records left to send (None = until stopped).
    remaining: Option<u32>,
    rdt_sequence: u32,
    ft_sequence: u32,
    /// The bias subtracted from every reading: force N, moment N·m.
    bias: ([f64; 3], [f64; 3]),
    /// The newest sample: force N, moment N·m.
    last_reading: ([f64; 3], [f64; 3]),
    stats: LinkStats,
}

/// The emulated RDT sensor's options once parsed ([`EmulatedSensor::parse`] of [`RdtEndpoint`]): positive
/// counts per configured unit, and the units.
#[derive(Debug, Clone, PartialEq)]
pub struct RdtEndpointConfig {
    options: RdtEndpointOptions,
    force_unit: ForceUnit,
    torque_unit: TorqueUnit,
}

impl RdtEndpoint {
    /// Parses the options ([`EmulatedSensor::parse`] of [`RdtEndpoint`]) and opens the endpoint
    /// ([`RdtEndpoint::open_parsed`]).
    pub fn open(o: &RdtEndpointOptions, context: &EndpointContext) -> Result<Self> {
        Self::open_parsed(&Self::parse(o)?, context)
    }

    fn send_record(&mut self) {
        let Some(client) = self.client else { return };
        if self.remaining == Some(0) {
            self.client = None;
            return;
        }
        let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let (reading, bias) = (self.last_reading, self.bias);
        let (counts, saturated) = self
            .counts
            .to_counts(&sub(reading.0, bias.0), &sub(reading.1, bias.1));
        self.rdt_sequence = self.rdt_sequence.wrapping_add(1);
        let record = RdtRecord {
            rdt_sequence: self.rdt_sequence,
            ft_sequence: self.ft_sequence,
            // bit 31 (error) and bit 16 (saturation) when a gauge is out of range
            status: if saturated { 0x8001_0000 } else { 0 },
            counts,
        };
        let sent = self.inbox.socket().send_to(&record.encode(), client);
        self.stats.count_send(sent);
        if let Some(n) = self.remaining.as_mut() {
            *n -= 1;
        }
    }
}

impl EmulatedSensor for RdtEndpoint {
    type Options = RdtEndpointOptions;
    type Config = RdtEndpointConfig;

    /// Checks the counts per unit (positive) and the units (known names), once.
    fn parse(options: &RdtEndpointOptions) -> Result<RdtEndpointConfig> {
        let o = options;
        for (key, v) in [
            ("counts_per_force", o.counts_per_force),
            ("counts_per_torque", o.counts_per_torque),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(RtError::option(
                    key,
                    format!("must be a positive number, got {v}"),
                ));
            }
        }
        let force_unit = ForceUnit::from_name(&o.force_unit).ok_or_else(|| {
            RtError::option(
                "force_unit",
                format!(
                    "unknown force unit {:?}; one of lbf, N, klbf, kN, kgf, gf",
                    o.force_unit
                ),
            )
        })?;
        let torque_unit = TorqueUnit::from_name(&o.torque_unit).ok_or_else(|| {
            RtError::option(
                "torque_unit",
                format!(
                    "unknown torque unit {:?}; one of lbf-in, lbf-ft, N-m, N-mm, kgf-cm, kN-m",
                    o.torque_unit
                ),
            )
        })?;
        Ok(RdtEndpointConfig {
            options: options.clone(),
            force_unit,
            torque_unit,
        })
    }

    /// Binds the RDT socket and starts the HTTP server (unless `http_port` is 0).
    fn open_parsed(c: &RdtEndpointConfig, context: &EndpointContext) -> Result<Self> {
        let (o, force_unit, torque_unit) = (&c.options, c.force_unit, c.torque_unit);
        // the page's counts are per configured unit; the records count the wrench in those units
        let per_unit = CountsPerUnit {
            force: o.counts_per_force,
            torque: o.counts_per_torque,
        };
        let counts = CountsPerUnit {
            force: o.counts_per_force / force_unit.newtons(),
            torque: o.counts_per_torque / torque_unit.newton_metres(),
        };
        let inbox = UdpInbox::bind("sensor (RDT)", resolve("bind_host", &o.bind_host, o.port)?)?;
        let address = local_addr("sensor (RDT)", inbox.socket())?;
        let http = if o.http_port == 0 {
            None
        } else {
            let addr = resolve("bind_host", &o.bind_host, o.http_port)?;
            let xml = netftapi_xml(&per_unit, force_unit, torque_unit, 1.0 / context.period);
            Some(NetFtApiServer::start(addr, xml).map_err(|e| match e {
                RtError::Io { context, kind, errno, message } => RtError::Io {
                    context,
                    kind,
                    errno,
                    message: format!("{message} (a real sensor serves port 80; choose another with --http-port and give the runtime the same)"),
                },
                other => other,
            })?)
        };
        Ok(RdtEndpoint {
            inbox,
            address,
            http,
            counts,
            client: None,
            remaining: None,
            rdt_sequence: 0,
            ft_sequence: 0,
            bias: ([0.0; 3], [0.0; 3]),
            last_reading: ([0.0; 3], [0.0; 3]),
            stats: LinkStats::default(),
        })
    }
}

impl SensorEndpoint for RdtEndpoint {
    fn name(&self) -> &'static str {
        "RDT"
    }

    fn address(&self) -> SocketAddr {
        self.address
    }

    fn http_address(&self) -> Option<SocketAddr> {
        self.http.as_ref().map(|h| h.address())
    }

    fn serve(&mut self) {
        // the HTTP server's socket errors (its own thread) count as the sensor's
        if let Some(http) = &self.http {
            let (receive, send) = http.take_errors();
            self.stats.send_errors += send;
            self.stats.io_errors += receive + send;
        }
        while let Some((bytes, from)) = self.inbox.next(&mut self.stats, |_| true) {
            let Some(request) = decode_counted(RdtRequest::decode(bytes), &mut self.stats) else {
                continue;
            };
            self.stats.accepted += 1;
            match request.command {
                RdtCommand::StartRealtime | RdtCommand::StartBuffered => {
                    self.client = Some(from);
                    self.remaining = (request.sample_count > 0).then_some(request.sample_count);
                }
                RdtCommand::Stop => {
                    self.client = None;
                    self.remaining = None;
                }
                RdtCommand::SetBias => self.bias = self.last_reading,
            }
        }
    }

    fn sample(&mut self, wrench: &Wrench, send: bool) {
        self.last_reading = (wrench.force.into(), wrench.moment.into());
        self.ft_sequence = self.ft_sequence.wrapping_add(1);
        if send {
            self.send_record();
        }
    }

    fn stats(&self) -> &LinkStats {
        &self.stats
    }
}
