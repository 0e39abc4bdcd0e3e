//! The runtime against a scripted sensor and robot (plain sockets in the test): malformed,
//! invalid, duplicate, out-of-sequence and foreign datagrams are each counted exactly and never
//! reach the dynamics; when the robot goes silent the watchdog stops the run, the robot gets
//! the hold command (its last fed-back pose, zero speed) and the sensor a stop request.

mod common;

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use common::{
    assert_stop, count_datagrams, pose, preset, rdt_record, send_feedback, watchdog, Corrections,
    ScriptedPeers,
};
use hilcontact_rt::devices::egm::codec::FeedbackEncoder;
use hilcontact_rt::devices::egm::EgmOptions;
use hilcontact_rt::devices::pose::PoseMm;
use hilcontact_rt::devices::rdt::codec::{RdtCommand, RdtRequest};
use hilcontact_rt::devices::rdt::RdtOptions;
use hilcontact_rt::safety::SafetyLimits;
use hilcontact_rt::{HilHandle, RobotOptions, RuntimeOptions, SensorOptions};

/// `paper-table1` run for `duration` s, its walls moved 1 m back: the scripted sensor reads
/// no force, as a rod that touches nothing (with the walls where they are, the predictive
/// limit and the units check rightly stop a run whose commanded rod is in a wall while the
/// sensor reads zero, before the fault a test injects).
fn table1_for(duration: f64) -> hilcontact_core::Scenario {
    let mut s = preset("paper-table1");
    s.simulation.duration = duration;
    for wall in &mut s.walls {
        for i in 0..3 {
            wall.point[i] -= wall.normal[i];
        }
    }
    s
}

#[test]
fn bad_packets_are_counted_and_dropped_and_the_robot_watchdog_stops_the_run() {
    let s = table1_for(5.0);
    let peers = ScriptedPeers::bind();
    let foreign = UdpSocket::bind("127.0.0.1:0").unwrap();
    let (sensor, robot, egm) = (&peers.sensor, &peers.robot, peers.egm);
    let options = RuntimeOptions {
        limits: watchdog(200.0),
        ..peers.options(false)
    };
    let (hil, request, client) = peers.start(&s, &options);
    assert_eq!(
        RdtRequest::decode(&request).unwrap().command,
        RdtCommand::StartRealtime
    );

    let mut feedback = FeedbackEncoder::new();
    let initial = pose(-995.0, 1.0); // the servicer's CoM in t, mm: where paper-table1 starts
    let (mut rdt_seq, mut egm_seq) = (0u32, 0u32);
    // the corrections the robot receives, drained as they come (the socket buffer is small)
    let mut corrections = Corrections::new();
    let start = Instant::now();
    for ms in 0..700u32 {
        corrections.drain(robot);
        rdt_seq += 1;
        sensor.send_to(&rdt_record(rdt_seq, 0), client).unwrap();
        if ms % 4 == 0 && ms < 500 {
            egm_seq += 1;
            send_feedback(robot, egm, &mut feedback, egm_seq, ms, &initial).unwrap();
        }
        if ms == 200 {
            // sensor: 3 malformed, 2 stale, a gap of 4, 1 error status, 2 foreign
            for len in [35usize, 37, 72] {
                sensor.send_to(&vec![0u8; len], client).unwrap();
            }
            sensor.send_to(&rdt_record(rdt_seq, 0), client).unwrap();
            sensor.send_to(&rdt_record(rdt_seq - 1, 0), client).unwrap();
            rdt_seq += 5;
            sensor.send_to(&rdt_record(rdt_seq, 0), client).unwrap();
            rdt_seq += 1;
            sensor
                .send_to(&rdt_record(rdt_seq, 0x8000_0000), client)
                .unwrap();
            foreign
                .send_to(&rdt_record(rdt_seq + 1, 0), client)
                .unwrap();
            foreign
                .send_to(&rdt_record(rdt_seq + 2, 0), client)
                .unwrap();
            // robot: 2 malformed, 2 invalid (NaN, quaternion norm 0.5), 1 stale, 1 foreign, a gap of 2
            robot.send_to(&[0xff, 0xff, 0xff], egm).unwrap();
            robot.send_to(&rdt_record(1, 0), egm).unwrap();
            for (from, seq, actual) in [
                (robot, egm_seq + 1, pose(f64::NAN, 1.0)),
                (robot, egm_seq + 1, pose(-995.0, 0.5)),
                (robot, egm_seq, initial),
                (&foreign, egm_seq + 1, pose(-900.0, 1.0)),
            ] {
                let bytes = feedback.encode(seq, 0, &actual, &initial);
                from.send_to(bytes, egm).unwrap();
            }
            egm_seq += 2;
        }
        let next = start + Duration::from_millis(ms as u64 + 1);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
        if hil.is_finished() {
            break;
        }
    }
    assert!(
        hil.wait(Duration::from_secs(5)),
        "the watchdog did not stop the run"
    );
    let out = hil.finish().unwrap();
    let m = &out.metrics;
    let rt = &m["realtime"];
    assert_eq!(m["status"], "stopped", "{}", m["reason"]);
    assert_stop(m, "robot-watchdog");
    assert_eq!(out.exit_code, 3);
    let sensor_counts = [
        ("malformed", 3),
        ("stale", 2),
        ("lost", 4),
        ("invalid", 1),
        ("foreign", 2),
    ];
    let robot_counts = [
        ("malformed", 2),
        ("invalid", 2),
        ("stale", 1),
        ("foreign", 1),
        ("lost", 2),
    ];
    for (stats, counts) in [(&rt["sensor"], sensor_counts), (&rt["robot"], robot_counts)] {
        for (key, n) in counts {
            assert_eq!(stats[key].as_u64(), Some(n), "{key}: {stats}");
        }
    }
    // nothing bad reached the dynamics: the actual tip stayed where the robot is
    let column = |name: &str| out.timeseries.column(name).unwrap().to_vec();
    assert!(column("actual_tip_position_x")
        .iter()
        .all(|x| (x - 0.005).abs() < 1e-9));
    assert!(column("energy").iter().all(|e| e.is_finite()));
    let stop_time = rt["stop"]["time"].as_f64().unwrap();
    assert!(
        (0.45..0.75).contains(&stop_time),
        "stopped at {stop_time} s"
    );

    // after the stop: hold corrections at the last fed-back pose, then an RDT stop request
    corrections.drain(robot);
    let hold = corrections
        .all
        .last()
        .expect("no correction received")
        .target;
    assert_eq!(hold.pose, initial);
    assert_eq!(hold.speed, [0.0; 6]);
    sensor.set_nonblocking(true).unwrap();
    let mut stops = 0;
    let mut buf = [0u8; 64];
    while let Ok(n) = sensor.recv(&mut buf) {
        if RdtRequest::decode(&buf[..n]).is_ok_and(|r| r.command == RdtCommand::Stop) {
            stops += 1;
        }
    }
    assert!(stops >= 1, "no RDT stop request");
}

/// A robot outside `start_tolerance` is refused, and nothing that could move it is sent. Named
/// with `--robot`: before its first feedback nothing at all, then only holds at its own
/// fed-back pose at rest (a correction toward the scenario's start would be executed by a real
/// controller). Not named: it is never locked onto (it is not at the start), nothing at all is
/// sent, and the error says where its feedback was.
#[test]
fn a_refused_start_commands_no_motion() {
    for named in [true, false] {
        let (error, corrections, away) = refused_start(named);
        if named {
            assert!(
                error.contains("50.0 mm from the scenario's initial position"),
                "{error}"
            );
            assert!(
                !corrections.is_empty(),
                "the refusal holds the robot where it is"
            );
        } else {
            assert!(
                error.contains("50.0 mm from the scenario's start") && error.contains("--robot"),
                "{error}"
            );
            assert!(corrections.is_empty(), "sent {corrections:?}");
        }
        for c in &corrections {
            assert_eq!(c.pose, away, "a correction toward another pose was sent");
            assert_eq!(c.speed, [0.0; 6]);
        }
    }
}

/// A start refused because the robot is 50 mm short of the scenario's start (-995 mm), with
/// the robot named (`robot_host`) or not: the error, the corrections received, the robot's pose.
fn refused_start(named: bool) -> (String, Vec<hilcontact_rt::devices::pose::TargetMm>, PoseMm) {
    let s = table1_for(2.0);
    let peers = ScriptedPeers::bind();
    let options = RuntimeOptions {
        connect_timeout: if named { 5.0 } else { 1.0 },
        ..peers.options(named)
    };
    let (hil, _, client) = peers.start(&s, &options);
    let away = pose(-1045.0, 1.0);
    let mut feedback = FeedbackEncoder::new();
    let mut corrections = Corrections::new();
    peers.play(client, 10, &hil, |seq| {
        if seq.is_multiple_of(4) {
            send_feedback(&peers.robot, peers.egm, &mut feedback, seq / 4, seq, &away).unwrap();
        }
        corrections.drain(&peers.robot);
    });
    assert!(hil.wait(Duration::from_secs(5)));
    let Err(error) = hil.finish() else {
        panic!("the start must be refused")
    };
    corrections.drain(&peers.robot);
    let targets = corrections.all.iter().map(|c| c.target).collect();
    (error.to_string(), targets, away)
}

/// Without `--robot`, a foreign EGM sender that started first (another robot, 200 mm from the
/// scenario's start) is never locked onto: the robot at the start is, every correction goes
/// to it, and the foreign sender's datagrams are counted.
#[test]
fn a_foreign_sender_that_starts_first_is_not_the_robot() {
    let s = table1_for(0.5);
    let peers = ScriptedPeers::bind();
    let foreign = UdpSocket::bind("127.0.0.1:0").unwrap();
    let options = RuntimeOptions {
        limits: watchdog(500.0),
        ..peers.options(false)
    };
    let (hil, _, client) = peers.start(&s, &options);
    let (mut robot_feedback, mut foreign_feedback) =
        (FeedbackEncoder::new(), FeedbackEncoder::new());
    let elsewhere = pose(-1195.0, 1.0);
    foreign.set_nonblocking(true).unwrap();
    let (mut to_robot, mut to_foreign) = (0, 0);
    let (robot, egm) = (&peers.robot, peers.egm);
    peers.play(client, 15, &hil, |ms| {
        if ms.is_multiple_of(4) {
            // the foreign sender from the start, with a high sequence number; the robot 100 ms later
            send_feedback(
                &foreign,
                egm,
                &mut foreign_feedback,
                1000 + ms,
                ms,
                &elsewhere,
            )
            .unwrap();
            if ms > 100 {
                // the robot follows the command: 20 mm/s from the start
                let t = (ms - 100) as f64 * 1e-3;
                let p = pose(-995.0 + 20.0 * t, 1.0);
                send_feedback(robot, egm, &mut robot_feedback, ms / 4, ms, &p).unwrap();
            }
        }
        to_robot += count_datagrams(robot);
        to_foreign += count_datagrams(&foreign);
    });
    assert!(hil.wait(Duration::from_secs(5)));
    let out = hil.finish().unwrap_or_else(|e| panic!("{e}"));
    let rt = &out.metrics["realtime"];
    assert_stop(&out.metrics, "completed");
    assert_eq!(
        rt["robot_address"].as_str().unwrap(),
        robot.local_addr().unwrap().to_string()
    );
    assert_eq!(to_foreign, 0, "corrections went to the foreign sender");
    assert!(to_robot > 100, "{to_robot} corrections to the robot");
    assert!(
        rt["robot"]["foreign"].as_u64().unwrap() >= 100,
        "{}",
        rt["robot"]
    );
}

/// What a scripted run saw: the output (or the error) and every correction the robot got.
struct Scripted {
    output: hilcontact_rt::Result<hilcontact_rt::report::HilOutput>,
    corrections: Vec<hilcontact_rt::devices::egm::codec::Correction>,
}

/// Runs `s` against a scripted sensor (zero wrench, a record per ms) and a scripted robot that
/// sends `robot_pose(ms)` every 4 ms (None: nothing), until the run ends (at most 15 s).
fn run_scripted(
    s: &hilcontact_core::Scenario,
    limits: SafetyLimits,
    mut robot_pose: impl FnMut(u32) -> Option<PoseMm>,
) -> Scripted {
    let peers = ScriptedPeers::bind();
    let options = RuntimeOptions {
        limits,
        ..peers.options(false)
    };
    let (hil, _, client) = peers.start(s, &options);
    let mut feedback = FeedbackEncoder::new();
    let mut corrections = Corrections::new();
    let mut egm_seq = 0u32;
    peers.play(client, 15, &hil, |ms| {
        if ms.is_multiple_of(4) {
            if let Some(p) = robot_pose(ms) {
                egm_seq += 1;
                send_feedback(&peers.robot, peers.egm, &mut feedback, egm_seq, ms, &p).unwrap();
            }
        }
        corrections.drain(&peers.robot);
    });
    assert!(hil.wait(Duration::from_secs(5)), "the run did not end");
    let output = hil.finish();
    corrections.drain(&peers.robot);
    Scripted {
        output,
        corrections: corrections.all,
    }
}

/// Feedback that stays at the start while the command moves (paper-table1: 20 mm/s, the
/// sensor reads no contact) is a tracking stop once every command of the 0.5 s window is
/// 10 mm away (at about 1.0 s), long before the workspace limit (100 mm, 5 s); the hold that
/// follows targets a checked pose at rest.
#[test]
fn frozen_feedback_is_a_tracking_stop() {
    let s = table1_for(6.0);
    let limits = watchdog(500.0); // a busy machine must not trip the watchdog first
    let frozen = pose(-995.0, 1.0);
    let run = run_scripted(&s, limits, |_| Some(frozen));
    let out = run.output.expect("the run starts");
    let rt = &out.metrics["realtime"];
    assert_stop(&out.metrics, "tracking");
    assert_eq!(out.exit_code, 3);
    let time = rt["stop"]["time"].as_f64().unwrap();
    assert!((0.9..1.3).contains(&time), "stopped at {time} s");
    let value = rt["stop"]["value"].as_f64().unwrap();
    assert!((0.010..0.012).contains(&value), "deviation {value} m");
    let last = run.corrections.last().expect("a hold was sent").target;
    assert_eq!(last.speed, [0.0; 6]);
    // the hold is at the robot's own pose (10 mm from the last command: trusted) ...
    assert_eq!(last.pose, frozen);
    // ... and no command ever left the workspace
    assert!(run
        .corrections
        .iter()
        .all(|c| (c.target.pose.position_mm[0] + 995.0).abs() < 100.0));
}

/// A 300 mm feedback jump (inside any plausibility bound of the protocol) is counted and
/// rejected, every message of it: the loop never sees the bogus pose, the robot watchdog stops
/// the run, and the hold never targets the bogus pose.
#[test]
fn a_300_mm_feedback_jump_is_counted_and_never_held() {
    let s = table1_for(6.0);
    let limits = watchdog(200.0);
    // the robot follows the command (20 mm/s from -995 mm), then reports 300 mm off from 0.3 s
    let run = run_scripted(&s, limits, |ms| {
        let t = ms as f64 * 1e-3;
        let x = -995.0 + 20.0 * t.min(0.3);
        Some(pose(if t < 0.3 { x } else { x + 300.0 }, 1.0))
    });
    let out = run.output.expect("the run starts");
    let rt = &out.metrics["realtime"];
    assert_stop(&out.metrics, "robot-watchdog");
    assert!(
        rt["robot"]["invalid"].as_u64().unwrap() >= 20,
        "{}",
        rt["robot"]
    );
    let column = out.timeseries.column("actual_tip_position_x").unwrap();
    assert!(
        column.iter().all(|x| *x < 0.05),
        "the bogus pose reached the loop"
    );
    for c in &run.corrections {
        assert!(
            (c.target.pose.position_mm[0] + 995.0).abs() < 50.0,
            "a correction toward {:?}",
            c.target.pose
        );
    }
}

/// Options that are bad input are refused as such (an option error naming the key) before any
/// socket is opened or any peer is asked: not as a connection error after trying to connect.
#[test]
fn bad_options_are_refused_before_any_socket_is_opened() {
    use hilcontact_rt::devices::rsi::RsiOptions;
    use hilcontact_rt::RtError;

    let s = preset("paper-table1");
    let egm = |rotation: [f64; 4], robot_host: Option<&str>| {
        RobotOptions::Egm(EgmOptions {
            rotation,
            robot_host: robot_host.map(String::from),
            ..Default::default()
        })
    };
    let rdt = |host: &str| {
        SensorOptions::Rdt(RdtOptions {
            host: host.into(),
            ..Default::default()
        })
    };
    let cases = [
        (
            RuntimeOptions {
                robot: egm([0.0; 4], None),
                ..Default::default()
            },
            "egm_rotation",
        ),
        (
            RuntimeOptions {
                robot: egm([1.0, 0.0, 0.0, 0.0], Some("1.2.3.999")),
                ..Default::default()
            },
            "robot_host",
        ),
        (
            RuntimeOptions {
                sensor: rdt("999.1.1.1"),
                ..Default::default()
            },
            "sensor host",
        ),
        (
            RuntimeOptions {
                sensor: rdt("bad host"),
                ..Default::default()
            },
            "sensor host",
        ),
        (
            RuntimeOptions {
                connect_timeout: 1e308,
                ..Default::default()
            },
            "connect_timeout",
        ),
        (
            RuntimeOptions {
                connect_timeout: f64::NAN,
                ..Default::default()
            },
            "connect_timeout",
        ),
        (
            RuntimeOptions {
                robot: RobotOptions::Rsi(RsiOptions {
                    rotation: [0.0; 4],
                    ..Default::default()
                }),
                ..Default::default()
            },
            "egm_rotation",
        ),
    ];
    for (options, key) in cases {
        match HilHandle::start(&s, &options) {
            Err(RtError::Option { key: k, message }) => assert_eq!(k, key, "{message}"),
            Err(other) => panic!("{key}: not an option error: {other}"),
            Ok(_) => panic!("{key}: started"),
        }
        match hilcontact_rt::check(&s, &options, 0.1) {
            Err(RtError::Option { key: k, .. }) => assert_eq!(k, key),
            Err(other) => panic!("{key}: check: not an option error: {other}"),
            Ok(_) => panic!("{key}: check ran"),
        }
    }
}
