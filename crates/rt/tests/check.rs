//! `hilcontact check`: a dry run against the emulated facility and against scripted peers. It
//! reports both links and the verdict of the run's start checks, and commands nothing: the
//! emulator counts no correction, a scripted robot receives no datagram.

mod common;

use std::time::Duration;

use common::{count_datagrams, loopback_options, pose, preset, send_feedback, ScriptedPeers};
use hilcontact_rt::devices::egm::codec::FeedbackEncoder;
use hilcontact_rt::{check, FacilityHandle};

/// Against the emulator with an unbiased sensor: a run would start; the offset is the injected
/// one, the rates are the devices' (1 kHz RDT, 250 Hz EGM; generous bounds for a busy
/// machine), and nothing was commanded.
#[test]
fn against_the_emulator_a_run_would_start_and_nothing_is_commanded() {
    let s = preset("paper-table1");
    let (mut emu, rt) = loopback_options();
    let offset = [3.0, -2.0, 20.0, 0.0, 0.0, 0.0];
    emu.sensor_offset = offset;
    let facility = FacilityHandle::start(&s, &emu).unwrap();
    let report = check(&s, &rt, 1.0).unwrap();
    let status = facility.join();
    assert!(report.would_start, "{:?}", report.reasons);
    assert!(report.reasons.is_empty());
    let measured = report.sensor.offset.unwrap();
    for (i, (a, b)) in measured.iter().zip(offset).enumerate() {
        assert!(
            (a - b).abs() < 0.2,
            "offset[{i}] measured {a}, injected {b}"
        );
    }
    assert!(report.sensor.noise.unwrap().iter().all(|v| *v >= 0.0));
    let (sensor_hz, robot_hz) = (report.sensor.rate.unwrap(), report.robot.rate.unwrap());
    assert!(
        (500.0..1500.0).contains(&sensor_hz),
        "sensor {sensor_hz} Hz"
    );
    assert!((125.0..375.0).contains(&robot_hz), "robot {robot_hz} Hz");
    assert_eq!(report.sensor.protocol, "RDT");
    assert!(report.sensor.report.contains_key("counts_per_force"));
    assert_eq!(report.robot.protocol, "EGM");
    assert!(report.robot.peer.is_some());
    assert!(report.robot.start_distance.unwrap() < 1e-3);
    assert_eq!(report.robot.stats.sent, 0);
    assert_eq!(status.corrections, 0, "the emulator was commanded");
    assert_eq!(status.robot.received, 0, "the emulator received datagrams");
    let json = serde_json::to_value(&report).unwrap();
    assert_eq!(json["would_start"], true);
    assert_eq!(json["sensor"]["offset_mode"], "measure");
}

/// An 80 N offset with the rod free: a run would refuse, naming the bound.
#[test]
fn an_80_n_offset_would_refuse() {
    let s = preset("paper-table1");
    let (mut emu, rt) = loopback_options();
    emu.sensor_offset = [0.0, 0.0, 80.0, 0.0, 0.0, 0.0];
    let facility = FacilityHandle::start(&s, &emu).unwrap();
    let report = check(&s, &rt, 0.5).unwrap();
    let status = facility.join();
    assert!(!report.would_start);
    assert_eq!(report.reasons.len(), 1, "{:?}", report.reasons);
    assert!(
        report.reasons[0].contains("80.") && report.reasons[0].contains("offset.max_force"),
        "{:?}",
        report.reasons
    );
    assert!((report.sensor.offset_force.unwrap() - 80.0).abs() < 0.5);
    assert_eq!(status.corrections, 0);
}

/// A scripted robot 50 mm short of the scenario's start (-995 mm), named with `robot_host` or
/// not: a run would refuse with the distance in the reason, and the robot's socket received
/// nothing at all.
#[test]
fn a_robot_50_mm_from_the_start_would_refuse_and_receives_nothing() {
    for named in [true, false] {
        let (reasons, received) = scripted_check(named);
        assert_eq!(reasons.len(), 1, "{reasons:?}");
        if named {
            assert!(
                reasons[0].contains("50.0 mm from the scenario's initial position"),
                "{reasons:?}"
            );
        } else {
            assert!(
                reasons[0].starts_with("no EGM feedback from the robot")
                    && reasons[0].contains("50.0 mm from the scenario's start")
                    && reasons[0].contains("--robot"),
                "{reasons:?}"
            );
        }
        assert_eq!(received, 0, "the robot received {received} datagrams");
    }
}

/// Runs `check` (0.5 s) against a scripted RDT sensor (zero wrench) and a scripted EGM robot at
/// -1045 mm; returns the reasons and the datagrams the robot received.
fn scripted_check(named: bool) -> (Vec<String>, usize) {
    let s = preset("paper-table1");
    let peers = ScriptedPeers::bind();
    let options = peers.options(named);
    let checker = std::thread::spawn(move || check(&s, &options, 0.5));
    let (_, client) = peers.first_request();
    let away = pose(-1045.0, 1.0);
    let mut feedback = FeedbackEncoder::new();
    let mut received = 0;
    peers.play(client, 10, &checker, |seq| {
        if seq.is_multiple_of(4) {
            let _ = send_feedback(&peers.robot, peers.egm, &mut feedback, seq / 4, seq, &away);
        }
        received += count_datagrams(&peers.robot);
    });
    let report = checker.join().unwrap().unwrap();
    std::thread::sleep(Duration::from_millis(50));
    received += count_datagrams(&peers.robot);
    assert!(!report.would_start);
    assert_eq!(report.robot.stats.sent, 0);
    assert!(report.sensor.stats.accepted > 0);
    (report.reasons, received)
}
