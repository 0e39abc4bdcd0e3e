//! The device-link seam: a robot-paced loop with a test-only robot link (one tick per robot
//! packet, each answered with its packet counter echoed, as KUKA RSI needs), socket errors
//! counted per link, the grouped options (kinds) as TOML/JSON, and the RDT link reading a
//! sensor configured in other units than N and N·m.

mod common;

use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use common::{
    assert_stop, endpoint_context, free_tcp_port, free_udp_port, link_context, preset, watchdog,
};
use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_core::world::RelativeMotion;
use hilcontact_rt::clock::now_ns;
use hilcontact_rt::devices::egm::EgmOptions;
use hilcontact_rt::devices::rdt::codec::{RdtCommand, RdtRecord, RdtRequest};
use hilcontact_rt::devices::rdt::netftapi::{ForceUnit, TorqueUnit};
use hilcontact_rt::devices::rdt::{RdtEndpoint, RdtEndpointOptions, RdtOptions, RdtSensor};
use hilcontact_rt::devices::{wait_readable, LinkStats, Pacing, SensorEndpoint, Wrench};
use hilcontact_rt::feedback::FeedbackEstimator;
use hilcontact_rt::offset::{OffsetMode, OffsetOptions};
use hilcontact_rt::safety::CYCLE_WINDOW;
use hilcontact_rt::{
    HilHandle, RobotLink, RobotOptions, RuntimeOptions, SensorLink, SensorOptions,
};
use nalgebra::{UnitQuaternion, Vector3};

/// Feedback packet of the test robot: counter (u64), robot time (f64, s), position (3 × f64,
/// m, `t`), big-endian. The answer: the counter echoed, then the command position.
const PACKET: usize = 40;
const ANSWER: usize = 32;
const PERIOD: f64 = 0.002;

/// A robot-paced link over UDP: the loop answers each packet (RSI-like).
struct FakePacedRobot {
    socket: UdpSocket,
    peer: Option<SocketAddr>,
    last_counter: Option<u64>,
    answered: Option<u64>,
    stats: LinkStats,
    buf: [u8; 256],
}

impl FakePacedRobot {
    fn new(socket: UdpSocket) -> Self {
        FakePacedRobot {
            socket,
            peer: None,
            last_counter: None,
            answered: None,
            stats: LinkStats::default(),
            buf: [0; 256],
        }
    }
}

impl RobotLink for FakePacedRobot {
    fn name(&self) -> &'static str {
        "FAKE"
    }
    fn describe(&self) -> String {
        "the test robot".into()
    }
    fn pacing(&self) -> Pacing {
        Pacing::Robot
    }
    fn feedback_period(&self) -> f64 {
        PERIOD
    }
    fn poll(&mut self, now: u64, estimator: &mut FeedbackEstimator) -> usize {
        let mut accepted = 0;
        while let Some((n, from)) =
            hilcontact_rt::devices::recv_counted(&self.socket, &mut self.buf, &mut self.stats)
        {
            self.stats.received += 1;
            if n != PACKET {
                self.stats.malformed += 1;
                continue;
            }
            let f = |i: usize| f64::from_be_bytes(self.buf[i..i + 8].try_into().unwrap());
            let counter = u64::from_be_bytes(self.buf[..8].try_into().unwrap());
            estimator.push(
                f(8),
                now,
                Vector3::new(f(16), f(24), f(32)),
                UnitQuaternion::identity(),
            );
            self.peer = Some(from);
            self.last_counter = Some(counter);
            self.stats.accepted += 1;
            accepted += 1;
        }
        accepted
    }
    fn wait(&mut self, deadline_ns: u64, estimator: &mut FeedbackEstimator) -> usize {
        while wait_readable(&self.socket, deadline_ns) {
            let n = self.poll(now_ns(), estimator);
            if n > 0 {
                return n;
            }
        }
        0
    }
    fn send(&mut self, command: &RelativeMotion, _clock_ns: u64) {
        // one answer per packet, echoing its counter
        let (Some(peer), Some(counter)) = (self.peer, self.last_counter) else {
            return;
        };
        if self.answered == Some(counter) {
            return;
        }
        self.answered = Some(counter);
        let mut out = [0u8; ANSWER];
        out[..8].copy_from_slice(&counter.to_be_bytes());
        for (i, v) in command.position.iter().enumerate() {
            out[8 + 8 * i..16 + 8 * i].copy_from_slice(&v.to_be_bytes());
        }
        let sent = self.socket.send_to(&out, peer);
        self.stats.count_send(sent);
    }
    fn peer(&self) -> Option<SocketAddr> {
        self.peer
    }
    fn stats(&self) -> &LinkStats {
        &self.stats
    }
    fn stats_mut(&mut self) -> &mut LinkStats {
        &mut self.stats
    }
}

/// A sensor that always has a new zero wrench (no contact in this test).
#[derive(Default)]
struct FreeSensor {
    stats: LinkStats,
}

impl SensorLink for FreeSensor {
    fn name(&self) -> &'static str {
        "FREE"
    }
    fn describe(&self) -> String {
        "the free sensor".into()
    }
    fn start_streaming(&mut self) {}
    fn stop_streaming(&mut self) {}
    fn bias(&mut self) {}
    fn poll(&mut self, _now_ns: u64) -> Option<Wrench> {
        self.stats.received += 1;
        self.stats.accepted += 1;
        Some(Wrench::default())
    }
    fn stats(&self) -> &LinkStats {
        &self.stats
    }
    fn stats_mut(&mut self) -> &mut LinkStats {
        &mut self.stats
    }
}

#[test]
fn robot_paced_loop_runs_one_tick_per_robot_packet_and_answers_each() {
    let mut s = preset("paper-table1");
    s.simulation.period = PERIOD;
    s.simulation.duration = 10.0;
    s.compensator = CompensatorConfig::default();
    // the walls 1 m back: the free sensor reads no force, as a rod that touches nothing (with
    // the walls where they are, the predictive limit and the units check rightly stop a run
    // whose commanded rod is in a wall while the sensor reads zero)
    for wall in &mut s.walls {
        for i in 0..3 {
            wall.point[i] -= wall.normal[i];
        }
    }
    let link_socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    link_socket.set_nonblocking(true).unwrap();
    let link_addr = link_socket.local_addr().unwrap();
    let robot = FakePacedRobot::new(link_socket);
    let options = RuntimeOptions {
        limits: watchdog(100.0),
        // no offset measurement at start: its holds would be answered like the run's ticks
        offset: OffsetOptions {
            mode: OffsetMode::Off,
            ..Default::default()
        },
        ..Default::default()
    };
    // the robot: a packet every 2 ms at the scenario's start pose, 300 of them after the
    // loop answers the first, then silence (the watchdog stops the run). It waits for the
    // answer to each packet before sending the next (up to 50 ms), so that a busy test
    // machine cannot make two packets arrive in one loop wake-up; the packets that were
    // not answered in time are counted and allowed for below.
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket.set_nonblocking(true).unwrap(); // (SO_RCVTIMEO has jiffy resolution)
    let done = Arc::new(AtomicBool::new(false));
    let hil = HilHandle::start_with_links(
        &s,
        &options,
        Box::new(FreeSensor::default()),
        Box::new(robot),
    )
    .unwrap();
    let flag = done.clone();
    let robot_thread = std::thread::spawn(move || {
        let mut echoed = Vec::new();
        let mut unanswered = 0u64;
        let mut counter = 0u64;
        let mut running_from = None;
        let mut buf = [0u8; 64];
        while !flag.load(Ordering::Relaxed) && counter < 5000 {
            counter += 1;
            let mut packet = [0u8; PACKET];
            packet[..8].copy_from_slice(&counter.to_be_bytes());
            packet[8..16].copy_from_slice(&(counter as f64 * PERIOD).to_be_bytes());
            packet[16..24].copy_from_slice(&(-0.995f64).to_be_bytes());
            socket.send_to(&packet, link_addr).unwrap();
            let sent_at = Instant::now();
            let (period, patience) = (Duration::from_secs_f64(PERIOD), Duration::from_millis(50));
            let mut answered = false;
            while sent_at.elapsed() < period || (!answered && sent_at.elapsed() < patience) {
                match socket.recv(&mut buf) {
                    Ok(n) => {
                        assert_eq!(n, ANSWER);
                        let c = u64::from_be_bytes(buf[..8].try_into().unwrap());
                        answered |= c == counter;
                        echoed.push(c);
                    }
                    Err(_) => std::thread::sleep(Duration::from_micros(50)),
                }
            }
            if !answered && running_from.is_some() {
                unanswered += 1;
            }
            if running_from.is_none() && !echoed.is_empty() {
                running_from = Some(counter);
            }
            if running_from.is_some_and(|c| counter >= c + 300) {
                break;
            }
        }
        (counter, running_from, echoed, unanswered)
    });
    assert!(hil.wait(Duration::from_secs(20)), "the run did not end");
    done.store(true, Ordering::Relaxed);
    let (sent, running_from, echoed, unanswered) = robot_thread.join().unwrap();
    let out = hil.finish().unwrap();
    let rt = &out.metrics["realtime"];
    assert_stop(&out.metrics, "robot-watchdog");
    assert!(
        out.metrics["reason"]
            .as_str()
            .unwrap()
            .contains("no valid FAKE feedback"),
        "{}",
        out.metrics["reason"]
    );
    assert_eq!(rt["pacing"], "robot");
    // each packet answered once, in order, echoing its counter
    assert!(echoed.windows(2).all(|w| w[1] > w[0]), "{echoed:?}");
    let running_from = running_from.unwrap();
    // one tick per packet after the first answer (the connect phase answered the first
    // ones, among them the CYCLE_WINDOW steps that measure the robot's cycle); the last tick
    // is the watchdog's, after the silence
    let ticks = rt["ticks"].as_u64().unwrap();
    let packets = sent - running_from + 1 - u64::from(CYCLE_WINDOW);
    let slack = 3 + unanswered;
    assert!(
        ticks + slack >= packets && ticks <= packets + 3,
        "{ticks} ticks for {packets} packets (sent {sent}, running from {running_from}, {} echoed, {unanswered} not answered in 50 ms, stop {})",
        echoed.len(),
        rt["stop"]
    );
    assert!(
        echoed.len() as u64 + slack >= packets,
        "{} answers for {packets} packets",
        echoed.len()
    );
    // virtual time advances by one period per packet
    let time = out.timeseries.column("time").unwrap();
    assert!(time
        .windows(2)
        .all(|w| ((w[1] - w[0]) - PERIOD).abs() < 1e-12));
    let robot_stats = &rt["robot"];
    assert_eq!(robot_stats["io_errors"], 0);
    assert!(robot_stats["sent"].as_u64().unwrap() >= ticks - 1);
}

/// A robot that paces the loop every 2 ms takes a scenario period that divides its cycle
/// (1 ms: two virtual steps per packet, the run starts) and refuses one that does not (3 ms),
/// naming both numbers.
#[test]
fn robot_paced_link_needs_a_scenario_period_that_divides_its_cycle() {
    let mut s = preset("paper-table1");
    s.simulation.period = 0.003;
    s.facility.round_delays = true;
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let robot = FakePacedRobot::new(socket);
    let sensor = FreeSensor::default();
    let err = HilHandle::start_with_links(
        &s,
        &RuntimeOptions::default(),
        Box::new(sensor),
        Box::new(robot),
    )
    .err()
    .unwrap();
    let err = err.to_string();
    assert!(err.contains("simulation.period"), "{err}");
    assert!(err.contains("0.002 s") && err.contains("0.003 s"), "{err}");
    // 1 ms divides 2 ms: started (and stopped at once: nothing answers)
    let s = preset("paper-table1");
    let hil = HilHandle::start_with_links(
        &s,
        &RuntimeOptions {
            connect_timeout: 0.2,
            ..Default::default()
        },
        Box::new(FreeSensor::default()),
        Box::new(FakePacedRobot::new(UdpSocket::bind("127.0.0.1:0").unwrap())),
    )
    .expect("a period that divides the cycle is taken");
    hil.stop();
    assert!(hil.wait(std::time::Duration::from_secs(10)));
}

#[test]
fn socket_errors_are_counted_per_link() {
    // a sensor at the broadcast address: the kernel refuses the request (no SO_BROADCAST);
    // the error is counted, not dropped
    let port = free_udp_port();
    let mut sensor = RdtSensor::open(
        &RdtOptions {
            host: "255.255.255.255".into(),
            port,
            counts_per_force: Some(1e6),
            counts_per_torque: Some(1e6),
            ..Default::default()
        },
        &link_context(1.0),
    )
    .unwrap();
    sensor.start_streaming();
    std::thread::sleep(Duration::from_millis(50));
    assert!(sensor.poll(now_ns()).is_none());
    sensor.stop_streaming();
    let stats = *sensor.stats();
    assert_eq!((stats.sent, stats.received), (0, 0), "{stats:?}");
    assert_eq!((stats.send_errors, stats.io_errors), (3, 3), "{stats:?}");
    let json = serde_json::to_value(stats).unwrap();
    assert_eq!(json["io_errors"], stats.io_errors);
}

#[test]
fn options_are_grouped_per_device_kind() {
    let text = r#"
        connect_timeout = 2.0
        [sensor]
        kind = "rdt"
        host = "192.168.1.1"
        port = 49153
        counts_per_force = 1000000.0
        counts_per_torque = 1000000.0
        [robot]
        kind = "egm"
        port = 6511
        offset_mm = [1.0, 2.0, 3.0]
    "#;
    let o: RuntimeOptions = toml::from_str(text).unwrap();
    let SensorOptions::Rdt(sensor) = &o.sensor else {
        panic!("{:?}", o.sensor)
    };
    let RobotOptions::Egm(robot) = &o.robot else {
        panic!("EGM options expected")
    };
    assert_eq!(
        (sensor.host.as_str(), sensor.port, sensor.http_port),
        ("192.168.1.1", 49153, 80)
    );
    assert_eq!((robot.port, robot.bind_host.as_str()), (6511, "0.0.0.0"));
    assert_eq!(robot.offset_mm, [1.0, 2.0, 3.0]);
    assert_eq!(o.connect_timeout, 2.0);
    // defaults are today's
    let d = RuntimeOptions::default();
    let json = serde_json::to_value(&d).unwrap();
    assert_eq!(json["sensor"]["kind"], "rdt");
    assert_eq!(json["sensor"]["port"], 49152);
    assert_eq!(json["robot"]["kind"], "egm");
    assert_eq!(json["robot"]["port"], 6510);
    assert_eq!(json["robot"]["bind_host"], "0.0.0.0");
    assert_eq!(serde_json::from_value::<RuntimeOptions>(json).unwrap(), d);
    assert_eq!(
        RobotOptions::default(),
        RobotOptions::Egm(EgmOptions::default())
    );
    // an unknown kind, a key of another kind, and a missing kind are errors
    for bad in [
        r#"{"robot": {"kind": "fri"}}"#,
        r#"{"robot": {"kind": "egm", "http_port": 80}}"#,
        r#"{"robot": {"kind": "rsi", "offset": 80}}"#,
        r#"{"sensor": {"port": 5}}"#,
    ] {
        assert!(
            serde_json::from_str::<RuntimeOptions>(bad).is_err(),
            "{bad} was accepted"
        );
    }
}

#[test]
fn rdt_link_reads_a_sensor_configured_in_lbf_and_lbf_in_in_n_and_n_m() {
    // the emulated sensor counts 1e6 per lbf and per lbf·in, and says so on its page
    let mut endpoint = RdtEndpoint::open(
        &RdtEndpointOptions {
            port: free_udp_port(),
            http_port: free_tcp_port(),
            counts_per_force: 1e6,
            counts_per_torque: 1e6,
            force_unit: "lbf".into(),
            torque_unit: "lbf-in".into(),
            ..Default::default()
        },
        &endpoint_context(),
    )
    .unwrap();
    let wrench = Wrench {
        force: Vector3::new(100.0, -250.0, 40.0),
        moment: Vector3::new(10.0, -3.0, 0.5),
    };

    // the records count the wrench in lbf and lbf·in: 100 N = 22.48 lbf, 10 N·m = 88.5 lbf·in
    let raw = UdpSocket::bind("127.0.0.1:0").unwrap();
    raw.set_read_timeout(Some(Duration::from_millis(20)))
        .unwrap();
    let start = RdtRequest {
        command: RdtCommand::StartRealtime,
        sample_count: 1,
    };
    raw.send_to(&start.encode(), endpoint.address()).unwrap();
    let mut buf = [0u8; 64];
    let deadline = Instant::now() + Duration::from_secs(2);
    let record = loop {
        assert!(
            Instant::now() < deadline,
            "no record from the emulated sensor"
        );
        endpoint.serve();
        endpoint.sample(&wrench, true);
        if let Ok(n) = raw.recv(&mut buf) {
            break RdtRecord::decode(&buf[..n]).unwrap();
        }
    };
    let lbf = 4.448_221_615_260_5;
    let lbf_in = 0.112_984_829_027_617;
    assert_eq!(record.counts[0], (100.0 / lbf * 1e6_f64).round() as i32);
    assert_eq!(record.counts[3], (10.0 / lbf_in * 1e6_f64).round() as i32);

    // the RDT link reads the units from /netftapi2.xml and the wrench back in N and N·m
    let mut sensor = RdtSensor::open(
        &RdtOptions {
            host: "127.0.0.1".into(),
            port: endpoint.address().port(),
            http_port: endpoint.http_address().unwrap().port(),
            ..Default::default()
        },
        &link_context(2.0),
    )
    .unwrap();
    let calibration = sensor.calibration().unwrap();
    assert_eq!(
        (
            calibration.force_unit,
            calibration.torque_unit,
            calibration.units_assumed
        ),
        (ForceUnit::Lbf, TorqueUnit::LbfIn, false)
    );
    let units = &sensor.report()["sensor_units"];
    assert_eq!(
        units,
        &serde_json::json!({"force": "lbf", "torque": "lbf-in", "source": "netftapi2.xml"})
    );
    sensor.start_streaming();
    let deadline = Instant::now() + Duration::from_secs(2);
    let read = loop {
        assert!(
            Instant::now() < deadline,
            "no wrench from the emulated sensor"
        );
        endpoint.serve();
        endpoint.sample(&wrench, true);
        std::thread::sleep(Duration::from_millis(1));
        if let Some(w) = sensor.poll(now_ns()) {
            break w;
        }
    };
    sensor.stop_streaming();
    let near = |got: f64, want: f64| (got - want).abs() <= 1e-3 * want.abs();
    for i in 0..3 {
        assert!(
            near(read.force[i], wrench.force[i]),
            "force {i}: read {} N, sent {} N",
            read.force[i],
            wrench.force[i]
        );
        assert!(
            near(read.moment[i], wrench.moment[i]),
            "moment {i}: read {} N·m, sent {} N·m",
            read.moment[i],
            wrench.moment[i]
        );
    }
}

#[test]
fn emulated_sensor_rejects_unknown_units() {
    for (force, torque, key) in [
        ("stone", "N-m", "force_unit"),
        ("N", "oz-in", "torque_unit"),
    ] {
        let err = RdtEndpoint::open(
            &RdtEndpointOptions {
                port: 0,
                http_port: 0,
                force_unit: force.into(),
                torque_unit: torque.into(),
                ..Default::default()
            },
            &endpoint_context(),
        )
        .err()
        .unwrap()
        .to_string();
        assert!(err.contains(key), "{err}");
    }
}
