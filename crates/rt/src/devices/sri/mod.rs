//! SRI (Sunrise Instruments) M812x interface box (M8126, M8128) over TCP, both sides:
//! [`SriSensor`] is the [`SensorLink`] of the loop (codec and sources in [`self::codec`]),
//! [`SriEndpoint`] the emulated box's [`SensorEndpoint`].
//!
//! At open the link connects (within `connect_timeout`) and configures the box with AT
//! commands, each answered `ACK+<command>=...$OK` and checked: `AT+GSD=STOP` (a stream left
//! running by an earlier client; not answered), `AT+DCKMD=SUM` (sum checksum),
//! `AT+SGDM=(A01,...,A06);E;1;(WMA:1)` (six channels, decoupled values in engineering units, no
//! filter), `AT+SMPR=<Hz>` (the loop's rate unless given), and with a decoupling matrix in the
//! options `AT+DCPCU=MVPV` and `AT+DCPM=(...)`. Streaming starts with `AT+GSD`; [`SensorLink::poll`]
//! then reads whatever arrived without blocking and returns the newest valid frame.
//!
//! A frame is accepted when its length field is 27 and its checksum the sum of its data bytes,
//! and its six values are finite; gaps in the package numbers are counted `lost`; bytes that
//! are no frame count one `malformed` per run. The values are N and N·m as the box's
//! decoupling matrix gives them (SRI calibrates in N and N·m; the box cannot be asked its
//! units: `realtime.sensor.sensor_units` records the assumption).

pub mod codec;

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::time::{Duration, Instant};

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use self::codec::{
    parse_matrix, FrameReader, SriAck, SriCommand, SriFrame, SriRateCommand, SriRequest, FRAME_LEN,
    MAX_LINE, SRI_PORT,
};
use super::transport::SequenceTracker;
use super::{
    check_host, resolve, EmulatedSensor, EndpointContext, LinkContext, LinkFault, LinkStats,
    SensorDevice, SensorEndpoint, SensorLink, Transport, Wrench,
};
use crate::error::{Result, RtError};
use hilcontact_core::stop::StopKind;

/// Options of an SRI M812x sensor link (`[sensor] kind = "sri"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SriOptions {
    /// Host of the M812x box (CLI `--sensor`; SRI's factory address is 192.168.0.108).
    pub host: String,
    /// TCP port of the box (4008) (CLI `--sensor-port`).
    pub port: u16,
    /// Sample rate asked of the box, Hz (sent as an integer; None: the loop's rate,
    /// 1 / period; 1 to 100000 once rounded).
    #[schemars(range(min = 0.5), extend("exclusiveMaximum" = 100000.5))]
    pub sample_rate: Option<f64>,
    /// The sample rate command: `"SMPR"` (default) or `"SMPF"` (the sources disagree; see
    /// docs/realtime.md).
    pub rate_command: SriRateCommand,
    /// The 6×6 decoupling matrix from the sensor's calibration sheet, row by row, applied by
    /// the box to the bridge signals in mV/V (sent with `AT+DCPCU=MVPV`); None: the matrix
    /// stored in the box is used.
    pub decoupling_matrix: Option<Box<[[f64; 6]; 6]>>,
    /// Consecutive frames with a wrong checksum (or length) after which the run stops
    /// (`sensor-checksum`; >= 1).
    #[schemars(range(min = 1))]
    pub max_checksum_errors: u64,
}

impl Default for SriOptions {
    fn default() -> Self {
        SriOptions {
            host: "127.0.0.1".into(),
            port: SRI_PORT,
            sample_rate: None,
            rate_command: SriRateCommand::Smpr,
            decoupling_matrix: None,
            max_checksum_errors: 10,
        }
    }
}

/// The TCP client of an SRI M812x interface box.
pub struct SriSensor {
    stream: TcpStream,
    peer: SocketAddr,
    /// The sample rate set, Hz.
    rate: u32,
    rate_command: SriRateCommand,
    matrix_sent: bool,
    reader: FrameReader,
    packages: SequenceTracker<u16>,
    /// The connection was closed or failed: nothing more is read.
    closed: bool,
    /// How the connection ended, when the box ended it: "reset" (TCP RST) or "closed".
    closed_by_box: Option<&'static str>,
    /// Frames with a wrong checksum or length: in a row, in all, and the limit in a row.
    checksum_run: u64,
    checksum_errors: u64,
    max_checksum_errors: u64,
    stats: LinkStats,
    line: [u8; MAX_LINE],
}

/// An SRI link's options once parsed ([`SensorDevice::parse`] of [`SriSensor`]): the host's form, the sample rate
/// (if given) and the decoupling matrix checked.
#[derive(Debug, Clone, PartialEq)]
pub struct SriConfig {
    options: SriOptions,
}

/// The sample rate `hz` (Hz) if the box takes it (1 to 100000 once rounded).
fn check_rate(hz: f64) -> Result<u32> {
    if !(hz.is_finite() && (1.0..=100_000.0).contains(&hz.round())) {
        return Err(RtError::option(
            "sample_rate",
            format!("must be between 1 and 100000 Hz, got {hz}"),
        ));
    }
    Ok(hz.round() as u32)
}

impl SriConfig {
    /// The sample rate asked of the box with the scenario's control period `period` (s), Hz:
    /// the one given, else the loop's rate; an error if the box does not take it.
    pub fn sample_rate(&self, period: f64) -> Result<u32> {
        check_rate(self.options.sample_rate.unwrap_or(1.0 / period))
    }
}

impl SriSensor {
    /// Parses the options ([`SensorDevice::parse`] of [`SriSensor`]) and opens the link
    /// ([`SriSensor::open_parsed`]).
    pub fn open(o: &SriOptions, context: &LinkContext) -> Result<Self> {
        Self::open_parsed(&Self::parse(o)?, context)
    }

    /// The sample rate set, Hz.
    pub fn sample_rate(&self) -> u32 {
        self.rate
    }

    /// Writes one command (never allocates); a failed or short write is counted.
    fn send(&mut self, command: SriCommand) {
        if self.closed {
            return;
        }
        let n = command.encode(&mut self.line);
        let result = match self.stream.write(&self.line[..n]) {
            Ok(k) if k == n => Ok(()),
            Ok(_) => Err(()),
            Err(_) => Err(()),
        };
        self.stats.count_send(result);
    }

    /// Reads (blocking, up to `timeout`) until the answer to `command` arrives; anything
    /// else (frames of an earlier stream, other answers) is skipped. A refusal or no answer is
    /// an error naming the command.
    fn expect_ack(
        &mut self,
        command: SriCommand,
        pending: &mut Vec<u8>,
        timeout: Duration,
    ) -> Result<()> {
        let name = command.name();
        let deadline = Instant::now() + timeout;
        let mut chunk = [0u8; 1024];
        loop {
            // complete answer lines in what was read so far
            while let Some(at) = pending.windows(4).position(|w| w == b"ACK+") {
                let Some(end) = pending[at..].iter().position(|b| *b == b'\n') else {
                    break;
                };
                let line = String::from_utf8_lossy(&pending[at..at + end]).into_owned();
                pending.drain(..at + end + 1);
                let Ok(ack) = SriAck::parse(&line) else {
                    continue;
                };
                if ack.command != name {
                    continue;
                }
                if ack.ok() {
                    return Ok(());
                }
                let mut sent = [0u8; MAX_LINE];
                let n = command.encode(&mut sent);
                return Err(RtError::Protocol(format!(
                    "the SRI box at {} refused {:?}: answered {:?}",
                    self.peer,
                    String::from_utf8_lossy(&sent[..n]).trim_end(),
                    line.trim_end()
                )));
            }
            if Instant::now() >= deadline {
                return Err(RtError::Connect(format!(
                    "the SRI box at {} did not answer AT+{name} within {:.1} s (is it an M812x on its TCP port?)",
                    self.peer,
                    timeout.as_secs_f64()
                )));
            }
            match self.stream.read(&mut chunk) {
                Ok(0) => {
                    return Err(RtError::Connect(format!(
                        "the SRI box at {} closed the connection after AT+{name}",
                        self.peer
                    )))
                }
                Ok(n) => pending.extend_from_slice(&chunk[..n]),
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(RtError::io(format!("SRI box at {}", self.peer), &e)),
            }
        }
    }

    fn drain(&mut self, newest: &mut Option<Wrench>) {
        while let Some(result) = self.reader.next_frame() {
            self.stats.received += 1;
            let Ok(frame) = result else {
                self.stats.malformed += 1;
                self.checksum_errors += 1;
                self.checksum_run += 1;
                continue;
            };
            self.checksum_run = 0;
            self.stats.lost += self.packages.advance(frame.package) as u64;
            let v = frame.values;
            if !v.iter().all(|x| x.is_finite()) {
                self.stats.invalid += 1;
                continue;
            }
            *newest = Some(Wrench {
                force: Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64),
                moment: Vector3::new(v[3] as f64, v[4] as f64, v[5] as f64),
            });
            self.stats.accepted += 1;
        }
    }
}

impl SensorDevice for SriSensor {
    type Options = SriOptions;
    type Config = SriConfig;
    const TRANSPORT: Transport = Transport::TcpClient;

    /// Checks the host's form, the sample rate (if given) and the decoupling matrix, once.
    fn parse(options: &SriOptions) -> Result<SriConfig> {
        check_host("sensor host", &options.host)?;
        if let Some(hz) = options.sample_rate {
            check_rate(hz)?;
        }
        if let Some(m) = &options.decoupling_matrix {
            if !m.iter().flatten().all(|v| v.is_finite()) {
                return Err(RtError::option(
                    "decoupling_matrix",
                    "must be 6 rows of 6 finite numbers",
                ));
            }
        }
        Ok(SriConfig {
            options: options.clone(),
        })
    }

    fn check_period(config: &SriConfig, period: f64) -> Result<()> {
        config.sample_rate(period).map(|_| ())
    }

    /// Connects (within `context.connect_timeout`), configures the box (blocking, each answer
    /// checked) and leaves the socket non-blocking, not yet streaming.
    fn open_parsed(c: &SriConfig, context: &LinkContext) -> Result<Self> {
        let o = &c.options;
        let rate = c.sample_rate(context.period)?;
        let peer = resolve("sensor_host", &o.host, o.port)?;
        let timeout = Duration::from_secs_f64(context.connect_timeout.max(0.1));
        // a box still booting refuses the connection: retried until connect_timeout
        let give_up = std::time::Instant::now() + timeout;
        let stream = loop {
            let left = give_up.saturating_duration_since(std::time::Instant::now());
            match TcpStream::connect_timeout(&peer, left.max(Duration::from_millis(10))) {
                Ok(stream) => break stream,
                Err(e) if std::time::Instant::now() + Duration::from_millis(100) < give_up => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(100));
                }
                Err(e) => {
                    return Err(RtError::Connect(format!(
                        "cannot connect to the SRI box at {peer} (TCP) within {:.1} s (connect_timeout): {e}",
                        timeout.as_secs_f64()
                    )))
                }
            }
        };
        let io = |e: std::io::Error| RtError::io(format!("SRI box at {peer}"), &e);
        stream.set_nodelay(true).map_err(io)?;
        stream
            .set_read_timeout(Some(timeout.min(Duration::from_secs(2))))
            .map_err(io)?;
        let mut link = SriSensor {
            stream,
            peer,
            rate,
            rate_command: o.rate_command,
            matrix_sent: o.decoupling_matrix.is_some(),
            reader: FrameReader::new(),
            packages: SequenceTracker::new(),
            closed: false,
            closed_by_box: None,
            checksum_run: 0,
            checksum_errors: 0,
            max_checksum_errors: o.max_checksum_errors.max(1),
            stats: LinkStats::default(),
            line: [0u8; MAX_LINE],
        };
        // a stream left running by an earlier client would bury the answers
        link.send(SriCommand::StopStream);
        let mut configuration = vec![
            SriCommand::ChecksumSum,
            SriCommand::DataMode,
            SriCommand::SampleRate(o.rate_command, link.rate),
        ];
        if let Some(m) = &o.decoupling_matrix {
            configuration.push(SriCommand::ComputeUnitMvpv);
            configuration.push(SriCommand::DecouplingMatrix(**m));
        }
        let mut pending = Vec::new();
        for command in configuration {
            link.send(command);
            link.expect_ack(command, &mut pending, timeout)?;
        }
        link.stream.set_nonblocking(true).map_err(io)?;
        Ok(link)
    }
}

impl SensorLink for SriSensor {
    fn transport(&self) -> Transport {
        <Self as SensorDevice>::TRANSPORT
    }

    fn name(&self) -> &'static str {
        "SRI"
    }

    fn describe(&self) -> String {
        format!("the SRI box at {}", self.peer)
    }

    fn start_streaming(&mut self) {
        self.send(SriCommand::StartStream);
    }

    fn stop_streaming(&mut self) {
        self.send(SriCommand::StopStream);
    }

    /// `AT+ADJZF=1;1;1;1;1;1` (zero all channels; from one open-source driver, not the
    /// manual). Its answer arrives between frames and counts one `malformed`. The runtime's
    /// offset measurement at start ([`crate::offset`]) does not need it.
    fn bias(&mut self) {
        self.send(SriCommand::Zero);
    }

    fn poll(&mut self, _now_ns: u64) -> Option<Wrench> {
        let mut newest = None;
        // at most 64 reads per tick (128 KiB), so a flood cannot spin the tick
        for _ in 0..64 {
            if self.closed {
                break;
            }
            match self.stream.read(self.reader.space()) {
                Ok(0) => {
                    // the box closed the connection: counted once, named, and a stop
                    self.closed = true;
                    self.closed_by_box = Some("closed");
                    self.stats.io_errors += 1;
                }
                Ok(n) => {
                    self.reader.commit(n);
                    self.drain(&mut newest);
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(e) => {
                    self.closed = true;
                    self.closed_by_box = Some(match e.kind() {
                        ErrorKind::ConnectionReset | ErrorKind::ConnectionAborted => "reset",
                        _ => "failed",
                    });
                    self.stats.io_errors += 1;
                }
            }
        }
        newest
    }

    super::link::stats_accessors!();

    fn fault(&self) -> Option<LinkFault> {
        if let Some(how) = self.closed_by_box {
            return Some(LinkFault {
                kind: StopKind::SensorConnection,
                value: match how {
                    "reset" => 1.0,
                    "closed" => 0.0,
                    _ => 2.0,
                },
                limit: f64::NAN,
            });
        }
        (self.checksum_run >= self.max_checksum_errors).then_some(LinkFault {
            kind: StopKind::SensorChecksum,
            value: self.checksum_run as f64,
            limit: self.max_checksum_errors as f64,
        })
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut m = serde_json::Map::new();
        m.insert(
            "sensor_faults".into(),
            serde_json::json!({
                "connection": self.closed_by_box,
                "checksum_errors": self.checksum_errors,
                "max_checksum_errors": self.max_checksum_errors,
            }),
        );
        m.insert("sensor_sample_rate".into(), self.rate.into());
        m.insert(
            "sensor_rate_command".into(),
            self.rate_command.name().into(),
        );
        m.insert(
            "sensor_decoupling_matrix".into(),
            if self.matrix_sent {
                "options"
            } else {
                "the box's"
            }
            .into(),
        );
        m.insert(
            "sensor_units".into(),
            serde_json::json!({"force": "N", "torque": "N-m",
                "source": "assumed: data mode E gives the decoupling matrix's units (SRI calibrates in N, N·m)"}),
        );
        m
    }
}

/// Options of the emulated SRI box (`[sensor] kind = "sri"` of the emulator's options).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SriEndpointOptions {
    /// Address the box's TCP server binds to (CLI `--bind-host`).
    pub bind_host: String,
    /// TCP port (4008 on a real box) (CLI `--sensor-port`).
    pub port: u16,
    /// Fault injection: after this many frames streamed the box resets the connection
    /// (TCP RST; None = never; >= 1).
    #[schemars(range(min = 1))]
    pub reset_after_frames: Option<u64>,
    /// Fault injection: from this many frames streamed on, every frame has a wrong checksum
    /// (None = never; >= 1).
    #[schemars(range(min = 1))]
    pub bad_checksum_after_frames: Option<u64>,
}

impl Default for SriEndpointOptions {
    fn default() -> Self {
        SriEndpointOptions {
            bind_host: "127.0.0.1".into(),
            port: SRI_PORT,
            reset_after_frames: None,
            bad_checksum_after_frames: None,
        }
    }
}

/// Makes the close of `stream` a reset (TCP RST: `SO_LINGER` with a zero timeout).
fn reset(stream: &TcpStream) {
    use std::os::fd::AsRawFd;
    let linger = libc::linger {
        l_onoff: 1,
        l_linger: 0,
    };
    // SAFETY: a valid socket descriptor and a `linger` of the size passed
    unsafe {
        libc::setsockopt(
            stream.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_LINGER,
            (&linger as *const libc::linger).cast(),
            std::mem::size_of::<libc::linger>() as libc::socklen_t,
        );
    }
}

/// The emulated M812x box: a TCP server (one client; a new connection replaces the old)
/// answering the AT commands `ACK+<command>=<parameters>$OK` (`$ERROR` for a value it does not
/// take), and streaming one frame of the measured wrench (N, N·m, as `f32`) per sample while
/// `AT+GSD` is on, at the rate set by `AT+SMPR`/`AT+SMPF` (at most one frame per control
/// period; the default is the control rate). It takes data mode `E` with channels A01–A06 only
/// and checksum mode `SUM` only; a decoupling matrix is stored and acknowledged, not applied
/// (the emulated wrench is already decoupled); `AT+ADJZF` zeroes at the current reading.
/// Accepting, reading and sending never block and never allocate.
pub struct SriEndpoint {
    listener: TcpListener,
    address: SocketAddr,
    client: Option<TcpStream>,
    /// The command line being received, and its length (a line longer than `MAX_LINE` is
    /// dropped whole: `overlong`).
    line: [u8; MAX_LINE],
    line_len: usize,
    overlong: bool,
    /// Bytes waiting to be sent (answers and frames), and their length.
    out: Box<[u8; 16384]>,
    out_len: usize,
    streaming: bool,
    period: f64,
    /// Sample rate, Hz.
    rate: f64,
    /// Accumulated fraction of a frame due (the rate's decimation).
    due: f64,
    package: u16,
    matrix: Option<[[f64; 6]; 6]>,
    bias: [f64; 6],
    last_reading: [f64; 6],
    stats: LinkStats,
    read_buf: [u8; 512],
    /// Frames streamed, and the fault injection ([`SriEndpointOptions`]).
    frames: u64,
    reset_after_frames: Option<u64>,
    bad_checksum_after_frames: Option<u64>,
}

impl SriEndpoint {
    /// Binds the box's TCP server (non-blocking).
    pub fn open(o: &SriEndpointOptions, context: &EndpointContext) -> Result<Self> {
        let addr = resolve("bind_host", &o.bind_host, o.port)?;
        let what = "sensor (SRI)";
        let listener = TcpListener::bind(addr)
            .map_err(|e| RtError::io(format!("{what}: cannot listen on TCP {addr}"), &e))?;
        listener
            .set_nonblocking(true)
            .map_err(|e| RtError::io(what, &e))?;
        let address = listener.local_addr().map_err(|e| RtError::io(what, &e))?;
        Ok(SriEndpoint {
            listener,
            address,
            client: None,
            line: [0u8; MAX_LINE],
            line_len: 0,
            overlong: false,
            out: Box::new([0u8; 16384]),
            out_len: 0,
            streaming: false,
            period: context.period,
            rate: 1.0 / context.period,
            due: 0.0,
            package: 0,
            matrix: None,
            bias: [0.0; 6],
            last_reading: [0.0; 6],
            stats: LinkStats::default(),
            read_buf: [0u8; 512],
            frames: 0,
            reset_after_frames: o.reset_after_frames,
            bad_checksum_after_frames: o.bad_checksum_after_frames,
        })
    }

    /// The decoupling matrix a client set (`AT+DCPM`), if any.
    pub fn matrix(&self) -> Option<[[f64; 6]; 6]> {
        self.matrix
    }

    /// The sample rate, Hz.
    pub fn sample_rate(&self) -> f64 {
        self.rate
    }

    fn drop_client(&mut self) {
        self.client = None;
        self.streaming = false;
        self.out_len = 0;
        self.line_len = 0;
        self.overlong = false;
    }

    /// Appends bytes to the output; false (counted as a failed send) when they do not fit.
    fn queue(&mut self, bytes: &[u8]) -> bool {
        if self.out_len + bytes.len() > self.out.len() {
            self.stats.send_errors += 1;
            self.stats.io_errors += 1;
            return false;
        }
        self.out[self.out_len..self.out_len + bytes.len()].copy_from_slice(bytes);
        self.out_len += bytes.len();
        true
    }

    /// Sends what is queued, as far as the socket takes it.
    fn flush(&mut self) {
        while self.out_len > 0 {
            let Some(client) = self.client.as_mut() else {
                self.out_len = 0;
                return;
            };
            match client.write(&self.out[..self.out_len]) {
                Ok(0) => {
                    self.stats.io_errors += 1;
                    self.drop_client();
                }
                Ok(n) => {
                    self.out.copy_within(n..self.out_len, 0);
                    self.out_len -= n;
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => return,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => {
                    self.stats.io_errors += 1;
                    self.drop_client();
                }
            }
        }
    }

    /// Answers one command line (in `self.line[..self.line_len]`).
    fn handle_line(&mut self) {
        let mut copy = [0u8; MAX_LINE];
        let n = self.line_len;
        copy[..n].copy_from_slice(&self.line[..n]);
        self.line_len = 0;
        let Ok(text) = std::str::from_utf8(&copy[..n]) else {
            self.stats.received += 1;
            self.stats.malformed += 1;
            return;
        };
        if text.trim().is_empty() {
            return;
        }
        self.stats.received += 1;
        let Some(request) = SriRequest::parse(text) else {
            self.stats.malformed += 1;
            return;
        };
        let p = request.parameters.trim();
        let ok = match request.command {
            "SMPR" | "SMPF" => match p.parse::<u32>() {
                Ok(hz) if (1..=100_000).contains(&hz) => {
                    self.rate = hz as f64;
                    true
                }
                _ => false,
            },
            "SGDM" => p.starts_with("(A01,A02,A03,A04,A05,A06);E;"),
            "DCKMD" => p == "SUM",
            "DCPCU" => p == "MVPV",
            "DCPM" => match parse_matrix(p) {
                Some(m) => {
                    self.matrix = Some(m);
                    true
                }
                None => false,
            },
            "ADJZF" => {
                self.bias = self.last_reading;
                true
            }
            "GSD" => {
                // streaming starts or stops without an answer (as clients of real boxes read it)
                match p {
                    "" => self.streaming = true,
                    "STOP" => self.streaming = false,
                    _ => self.stats.invalid += 1,
                }
                self.stats.accepted += u64::from(p.is_empty() || p == "STOP");
                return;
            }
            _ => false,
        };
        if ok {
            self.stats.accepted += 1;
        } else {
            self.stats.invalid += 1;
        }
        let mut answer = [0u8; MAX_LINE + 32];
        let capacity = answer.len();
        let mut w = &mut answer[..];
        let status = if ok { "OK" } else { "ERROR" };
        let _ = write!(w, "ACK+{}={}$", request.command, p);
        let _ = write!(w, "{status}\r\n");
        let len = capacity - w.len();
        // answers are not samples: `sent` counts frames only
        self.queue(&answer[..len]);
    }
}

impl EmulatedSensor for SriEndpoint {
    type Options = SriEndpointOptions;
    type Config = SriEndpointOptions;

    fn parse(options: &SriEndpointOptions) -> Result<SriEndpointOptions> {
        Ok(options.clone())
    }

    fn open_parsed(config: &SriEndpointOptions, context: &EndpointContext) -> Result<Self> {
        Self::open(config, context)
    }
}

impl SensorEndpoint for SriEndpoint {
    fn transport(&self) -> Transport {
        Transport::TcpServer
    }

    fn name(&self) -> &'static str {
        "SRI"
    }

    fn address(&self) -> SocketAddr {
        self.address
    }

    fn serve(&mut self) {
        // a new connection replaces the old one
        loop {
            match self.listener.accept() {
                Ok((stream, _)) => {
                    if stream.set_nonblocking(true).is_err() {
                        self.stats.io_errors += 1;
                        continue;
                    }
                    let _ = stream.set_nodelay(true);
                    self.drop_client();
                    self.client = Some(stream);
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(_) => {
                    self.stats.io_errors += 1;
                    break;
                }
            }
        }
        for _ in 0..64 {
            let Some(client) = self.client.as_mut() else {
                break;
            };
            match client.read(&mut self.read_buf) {
                Ok(0) => {
                    self.drop_client();
                    break;
                }
                Ok(n) => {
                    for i in 0..n {
                        let b = self.read_buf[i];
                        if b == b'\n' {
                            if std::mem::take(&mut self.overlong) {
                                self.line_len = 0;
                                self.stats.received += 1;
                                self.stats.malformed += 1;
                            } else {
                                self.handle_line();
                            }
                        } else if self.line_len < MAX_LINE {
                            self.line[self.line_len] = b;
                            self.line_len += 1;
                        } else {
                            self.overlong = true;
                        }
                    }
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                Err(_) => {
                    self.stats.io_errors += 1;
                    self.drop_client();
                    break;
                }
            }
        }
        self.flush();
    }

    fn sample(&mut self, wrench: &Wrench, send: bool) {
        let f = &wrench.force;
        let m = &wrench.moment;
        self.last_reading = [f.x, f.y, f.z, m.x, m.y, m.z];
        if !(self.streaming && self.client.is_some()) {
            self.due = 0.0;
            return;
        }
        // at most one frame per control period; a lower rate sends every n-th sample
        self.due = (self.due + self.rate * self.period).min(2.0);
        if self.due < 1.0 - 1e-9 {
            return;
        }
        self.due -= 1.0;
        if !send {
            return;
        }
        let mut values = [0f32; 6];
        for (i, v) in values.iter_mut().enumerate() {
            *v = (self.last_reading[i] - self.bias[i]) as f32;
        }
        self.package = self.package.wrapping_add(1);
        let mut frame = SriFrame {
            package: self.package,
            values,
        }
        .encode();
        self.frames += 1;
        if self
            .bad_checksum_after_frames
            .is_some_and(|n| self.frames >= n)
        {
            frame[FRAME_LEN - 1] = frame[FRAME_LEN - 1].wrapping_add(1);
        }
        if self.queue(&frame) {
            self.stats.sent += 1;
        }
        self.flush();
        if self.reset_after_frames.is_some_and(|n| self.frames >= n) {
            self.reset_after_frames = None;
            if let Some(client) = &self.client {
                reset(client);
            }
            self.drop_client();
        }
    }

    fn stats(&self) -> &LinkStats {
        &self.stats
    }
}
