//! Helpers shared by the real-time tests: options that meet on loopback, the start and finish
//! of a run against the emulator, scripted peers on plain sockets, device contexts, and the
//! checks of a run's metrics that several tests make.
#![allow(dead_code)]

use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_core::world::RelativeMotion;
use hilcontact_core::Scenario;
use hilcontact_rt::devices::egm::codec::{Correction, CorrectionDecoder, FeedbackEncoder};
use hilcontact_rt::devices::egm::{EgmEndpointOptions, EgmOptions};
use hilcontact_rt::devices::pose::PoseMm;
use hilcontact_rt::devices::rdt::codec::RdtRecord;
use hilcontact_rt::devices::rdt::{RdtEndpointOptions, RdtOptions};
use hilcontact_rt::devices::{
    EmulatedRobotOptions, EmulatedSensorOptions, EndpointContext, LinkContext,
};
use hilcontact_rt::emulator::FacilityStatus;
use hilcontact_rt::report::HilOutput;
use hilcontact_rt::safety::SafetyLimits;
use hilcontact_rt::{
    EmulatorOptions, FacilityHandle, HilHandle, RobotOptions, RuntimeOptions, SensorOptions,
};
use nalgebra::{UnitQuaternion, Vector3};
use serde_json::Value;

/// The core's test helpers (`preset`), one file for both crates.
#[path = "../../core/tests/common/mod.rs"]
mod core_common;
#[allow(unused_imports)] // not every test file reads a preset
pub use core_common::preset;

/// `paper-table1` with a 20 ms robot delay, run for `duration` s by `compensator`.
pub fn delayed(compensator: CompensatorConfig, duration: f64) -> Scenario {
    let mut s = preset("paper-table1");
    s.facility.robot_delay = 0.02;
    s.simulation.duration = duration;
    s.compensator = compensator;
    s
}

/// A UDP port that was free a moment ago.
pub fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A TCP port that was free a moment ago.
pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Safety limits with the robot watchdog at `ms` and the rest at their defaults.
pub fn watchdog(ms: f64) -> SafetyLimits {
    SafetyLimits {
        watchdog_ms: ms,
        ..Default::default()
    }
}

/// EGM options of the loop listening on 127.0.0.1:`port`.
fn egm_on_loopback(port: u16) -> RobotOptions {
    RobotOptions::Egm(EgmOptions {
        port,
        bind_host: "127.0.0.1".into(),
        ..Default::default()
    })
}

/// Emulator and runtime options that meet on loopback, without HTTP (counts given).
pub fn loopback_options() -> (EmulatorOptions, RuntimeOptions) {
    let sensor_port = free_udp_port();
    let egm_port = free_udp_port();
    let sensor = RdtEndpointOptions {
        port: sensor_port,
        http_port: 0,
        ..Default::default()
    };
    let runtime = RuntimeOptions {
        // a generous watchdog: the emulator runs at normal priority and a busy machine can
        // starve it for more than the default 50 ms (the watchdog's own tests set theirs)
        limits: watchdog(500.0),
        sensor: SensorOptions::Rdt(RdtOptions {
            port: sensor_port,
            counts_per_force: Some(sensor.counts_per_force),
            counts_per_torque: Some(sensor.counts_per_torque),
            ..Default::default()
        }),
        robot: egm_on_loopback(egm_port),
        ..Default::default()
    };
    let emulator = EmulatorOptions {
        sensor: EmulatedSensorOptions::Rdt(sensor),
        robot: EmulatedRobotOptions::Egm(EgmEndpointOptions {
            port: egm_port,
            ..Default::default()
        }),
        ..Default::default()
    };
    (emulator, runtime)
}

/// [`loopback_options`] with the sensor an SRI M812x box (TCP) instead of a Net F/T.
pub fn loopback_sri_options() -> (EmulatorOptions, RuntimeOptions) {
    use hilcontact_rt::devices::sri::{SriEndpointOptions, SriOptions};
    let (mut emulator, mut runtime) = loopback_options();
    let port = free_tcp_port();
    emulator.sensor = EmulatedSensorOptions::Sri(SriEndpointOptions {
        port,
        ..Default::default()
    });
    runtime.sensor = SensorOptions::Sri(SriOptions {
        port,
        ..Default::default()
    });
    (emulator, runtime)
}

/// Emulator and runtime options that meet on loopback with the robot on KUKA RSI (sensor RDT,
/// without HTTP); the scenario's period must be the RSI cycle (0.004 s).
pub fn rsi_loopback_options() -> (EmulatorOptions, RuntimeOptions) {
    use hilcontact_rt::devices::rsi::{RsiEndpointOptions, RsiOptions};
    let (mut emulator, mut runtime) = loopback_options();
    let port = free_udp_port();
    runtime.robot = RobotOptions::Rsi(RsiOptions {
        port,
        bind_host: "127.0.0.1".into(),
        ..Default::default()
    });
    emulator.robot = EmulatedRobotOptions::Rsi(RsiEndpointOptions {
        port,
        ..Default::default()
    });
    (emulator, runtime)
}

/// Starts the emulated facility with `emu`, then the loop with `rt`, both on `s`.
pub fn start_both(
    s: &Scenario,
    emu: &EmulatorOptions,
    rt: &RuntimeOptions,
) -> (FacilityHandle, HilHandle) {
    let facility = FacilityHandle::start(s, emu).unwrap();
    let hil = HilHandle::start(s, rt).unwrap();
    (facility, hil)
}

/// Waits (at most `wait`) for the loop to end, then for the emulator: the loop's output (or
/// its error) and the emulator's last status.
pub fn finish_both(
    facility: FacilityHandle,
    hil: HilHandle,
    wait: Duration,
) -> (hilcontact_rt::Result<HilOutput>, FacilityStatus) {
    assert!(hil.wait(wait), "the run did not end");
    let out = hil.finish();
    let status = facility.join();
    (out, status)
}

/// Runs the loop on `s` against the emulator (at most `wait`); its output, which must be one,
/// and the emulator's status.
pub fn run_both(
    s: &Scenario,
    (emu, rt): &(EmulatorOptions, RuntimeOptions),
    wait: Duration,
) -> (HilOutput, FacilityStatus) {
    let (facility, hil) = start_both(s, emu, rt);
    let (out, status) = finish_both(facility, hil, wait);
    let out = out.unwrap_or_else(|e| panic!("{e}; emulator: {status:?}"));
    (out, status)
}

/// Prints the run's `realtime` and `collisions` metrics (shown when a test fails).
pub fn print_metrics(m: &Value) {
    for key in ["realtime", "collisions"] {
        eprintln!("{}", serde_json::to_string_pretty(&m[key]).unwrap());
    }
}

/// The coefficients of restitution of the run's collisions.
pub fn covs(m: &Value) -> Vec<f64> {
    m["collisions"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|c| c["cov"].as_f64())
        .collect()
}

/// The run ran to its end: `ok`, or `unfaithful` (a busy machine's late ticks may cost some
/// force fidelity; not the subject of the tests that ask this).
pub fn assert_ran_to_its_end(m: &Value) {
    assert!(
        m["status"] == "ok" || m["status"] == "unfaithful",
        "{}: {}",
        m["status"],
        m["reason"]
    );
}

/// At least `at_least` collisions, each keeping the rebound speed (CoV within 0.9 to 1.1).
pub fn assert_rebound_kept(m: &Value, at_least: usize) {
    let covs = covs(m);
    assert!(covs.len() >= at_least, "{covs:?}");
    for cov in &covs {
        assert!((0.9..=1.1).contains(cov), "CoV {cov} in {covs:?}");
    }
}

/// The run's stop was of `kind` (the reason shown otherwise).
pub fn assert_stop(m: &Value, kind: &str) {
    assert_eq!(m["realtime"]["stop"]["kind"], kind, "{}", m["reason"]);
}

/// The context of an emulated endpoint at 1 kHz, at rest at the origin.
pub fn endpoint_context() -> EndpointContext {
    EndpointContext {
        period: 0.001,
        initial: RelativeMotion {
            position: Vector3::zeros(),
            orientation: UnitQuaternion::identity(),
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        },
    }
}

/// The context of a link at 1 kHz that gives up connecting after `connect_timeout` s.
pub fn link_context(connect_timeout: f64) -> LinkContext {
    LinkContext {
        period: 0.001,
        connect_timeout,
        start: None,
    }
}

/// A pose on the x axis (mm) with the quaternion (w, 0, 0, 0).
pub fn pose(x: f64, w: f64) -> PoseMm {
    PoseMm {
        position_mm: [x, 0.0, 0.0],
        orientation: [w, 0.0, 0.0, 0.0],
    }
}

/// An RDT record of a zero wrench numbered `seq`, with `status`.
pub fn rdt_record(seq: u32, status: u32) -> Vec<u8> {
    RdtRecord {
        rdt_sequence: seq,
        ft_sequence: seq,
        status,
        counts: [0; 6],
    }
    .encode()
    .to_vec()
}

/// Sends EGM feedback from `socket` to `to`: number `seq`, robot time `ms`, at `pose` (actual
/// and planned).
pub fn send_feedback(
    socket: &UdpSocket,
    to: SocketAddr,
    encoder: &mut FeedbackEncoder,
    seq: u32,
    ms: u32,
    pose: &PoseMm,
) -> std::io::Result<usize> {
    socket.send_to(encoder.encode(seq, ms as u64 * 1000, pose, pose), to)
}

/// How many datagrams wait on the non-blocking `socket` (read and dropped).
pub fn count_datagrams(socket: &UdpSocket) -> usize {
    let mut big = [0u8; 2048];
    let mut n = 0;
    while socket.recv(&mut big).is_ok() {
        n += 1;
    }
    n
}

/// A scripted RDT sensor and a scripted EGM robot on plain loopback sockets, for the loop (or
/// `check`) to meet.
pub struct ScriptedPeers {
    /// The sensor's socket (reads time out after 5 s).
    pub sensor: UdpSocket,
    /// The robot's socket (non-blocking).
    pub robot: UdpSocket,
    /// Where the loop listens for EGM.
    pub egm: SocketAddr,
}

impl ScriptedPeers {
    pub fn bind() -> Self {
        let sensor = UdpSocket::bind("127.0.0.1:0").unwrap();
        let robot = UdpSocket::bind("127.0.0.1:0").unwrap();
        sensor
            .set_read_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        robot.set_nonblocking(true).unwrap();
        let egm = ([127, 0, 0, 1], free_udp_port()).into();
        ScriptedPeers { sensor, robot, egm }
    }

    /// Runtime options that meet these peers (counts of 1e6 per unit: no HTTP query); `named`:
    /// the robot's address given (`robot_host`, as `--robot`).
    pub fn options(&self, named: bool) -> RuntimeOptions {
        let mut robot = egm_on_loopback(self.egm.port());
        if named {
            let RobotOptions::Egm(o) = &mut robot else {
                unreachable!()
            };
            o.robot_host = Some("127.0.0.1".into());
        }
        RuntimeOptions {
            sensor: SensorOptions::Rdt(RdtOptions {
                port: self.sensor.local_addr().unwrap().port(),
                counts_per_force: Some(1e6),
                counts_per_torque: Some(1e6),
                ..Default::default()
            }),
            robot,
            ..Default::default()
        }
    }

    /// Waits for the loop's first request to the sensor: its bytes, and the loop's address.
    pub fn first_request(&self) -> (Vec<u8>, SocketAddr) {
        let mut buf = [0u8; 64];
        let (n, client) = self.sensor.recv_from(&mut buf).unwrap();
        (buf[..n].to_vec(), client)
    }

    /// Starts the loop on `s` with `options` (met by these peers), and waits for its first
    /// request to the sensor: the run, the request's bytes and the loop's address.
    pub fn start(
        &self,
        s: &Scenario,
        options: &RuntimeOptions,
    ) -> (HilHandle, Vec<u8>, SocketAddr) {
        let hil = HilHandle::start(s, options).unwrap();
        let (request, client) = self.first_request();
        (hil, request, client)
    }

    /// The script, on its own millisecond count (a busy machine slows it, never skips it): every
    /// millisecond `ms` (from 1) a zero-wrench record numbered `ms` to `client`, then
    /// `robot(ms)`, until `until` has ended or `limit_s` seconds have passed.
    pub fn play(
        &self,
        client: SocketAddr,
        limit_s: u64,
        until: &impl Ends,
        mut robot: impl FnMut(u32),
    ) {
        let start = Instant::now();
        let mut ms = 0u32;
        while !until.ended() && start.elapsed() < Duration::from_secs(limit_s) {
            ms += 1;
            self.sensor.send_to(&rdt_record(ms, 0), client).unwrap();
            robot(ms);
            std::thread::sleep(Duration::from_millis(1));
        }
    }
}

/// What a script plays against until it ends: a run, or a thread (`check`).
pub trait Ends {
    fn ended(&self) -> bool;
}

impl Ends for HilHandle {
    fn ended(&self) -> bool {
        self.is_finished()
    }
}

impl<T> Ends for std::thread::JoinHandle<T> {
    fn ended(&self) -> bool {
        self.is_finished()
    }
}

/// Every correction a scripted robot received, in order.
pub struct Corrections {
    decoder: CorrectionDecoder,
    pub all: Vec<Correction>,
}

impl Corrections {
    pub fn new() -> Self {
        Corrections {
            decoder: CorrectionDecoder::new(),
            all: Vec::new(),
        }
    }

    /// Reads (and decodes) what waits on the robot's non-blocking `socket`.
    pub fn drain(&mut self, socket: &UdpSocket) {
        let mut big = [0u8; 2048];
        while let Ok(n) = socket.recv(&mut big) {
            self.all.push(self.decoder.decode(&big[..n]).unwrap());
        }
    }
}
