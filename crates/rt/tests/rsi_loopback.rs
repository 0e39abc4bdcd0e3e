//! The loop and the emulated facility on loopback with the robot on KUKA RSI (sensor RDT): the
//! robot paces the loop (one tick per 4 ms state message), each message is answered once with
//! its IPOC; and the emulated controller's side alone, scripted: IPOCs, answers, and the stop
//! after `max_late` consecutive late cycles.

mod common;

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use common::{
    assert_ran_to_its_end, assert_rebound_kept, assert_stop, covs, delayed, print_metrics,
    rsi_loopback_options, run_both,
};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_core::Scenario;
use hilcontact_rt::devices::rsi::codec::{decode_state, AnswerEncoder, RsiNames};
use hilcontact_rt::devices::rsi::{CorrectionMode, RsiEndpointOptions, RsiOptions};
use hilcontact_rt::devices::EmulatedRobotOptions;
use hilcontact_rt::{EmulatorOptions, FacilityHandle, RobotOptions};
use serde_json::Value;

/// paper-table1 at the RSI cycle (4 ms) with a 20 ms robot delay.
fn scenario(kind: CompensatorConfig, duration: f64) -> Scenario {
    let mut s = delayed(kind, duration);
    s.simulation.period = 0.004;
    s
}

/// Runs the loop against the emulator, both on RSI with `mode`; returns the metrics.
fn run(s: &Scenario, mode: CorrectionMode) -> Value {
    let (mut emu, mut rt) = rsi_loopback_options();
    if let (RobotOptions::Rsi(link), EmulatedRobotOptions::Rsi(endpoint)) =
        (&mut rt.robot, &mut emu.robot)
    {
        link.correction = mode;
        endpoint.correction = mode;
    }
    let wait = Duration::from_secs_f64(s.simulation.duration + 20.0);
    let (out, status) = run_both(s, &(emu, rt), wait);
    let m = out.metrics;
    print_metrics(&m);
    eprintln!("emulator: {:?}", status.robot);
    assert_eq!(status.robot_protocol, "RSI");
    // the controller got an answer to (nearly) every message, with its IPOC
    assert!(status.robot.accepted > 0, "{status:?}");
    assert_eq!(status.robot.invalid, 0, "{status:?}");
    assert_eq!(status.robot.malformed, 0, "{status:?}");
    m
}

#[test]
fn rsi_pida_at_20ms_keeps_the_rebound_speed() {
    let s = scenario(CompensatorConfig::Pida(ModelParams::default()), 3.5);
    let m = run(&s, CorrectionMode::Absolute);
    assert_ran_to_its_end(&m);
    assert_stop(&m, "completed");
    let rt = &m["realtime"];
    assert_eq!(rt["pacing"], "robot");
    assert_eq!(rt["ticks"], 876);
    assert_eq!(rt["samples_dropped"], 0);
    assert_rebound_kept(&m, 3);
    // one answer per tick (and per start-up message): measured, and rarely superseded
    let rsi = &rt["rsi"];
    let latency = &rsi["answer_latency_us"];
    assert!(latency["count"].as_u64().unwrap() >= 876, "{rsi}");
    // (a busy machine that wakes the loop late lets a few state messages be superseded)
    assert!(rsi["unanswered"].as_u64().unwrap() <= 88, "{rsi}");
    assert!(latency["p50"].as_f64().unwrap() < 1000.0, "{rsi}");
    assert_eq!(rt["robot"]["stale"], 0);
}

#[test]
fn rsi_relative_corrections_run_the_same() {
    let s = scenario(CompensatorConfig::Pida(ModelParams::default()), 2.5);
    let m = run(&s, CorrectionMode::Relative);
    assert_stop(&m, "completed");
    assert_rebound_kept(&m, 2);
}

#[test]
fn rsi_uncompensated_loop_is_stopped_by_the_force_limit() {
    let s = scenario(CompensatorConfig::default(), 6.0);
    let m = run(&s, CorrectionMode::Absolute);
    assert_eq!(m["status"], "stopped");
    assert_eq!(m["realtime"]["stop"]["kind"], "predicted-force-limit");
    assert_eq!(m["realtime"]["stop"]["exit_code"], 3);
    assert!(covs(&m).first().is_some_and(|c| *c > 1.3), "{:?}", covs(&m));
}

/// The emulated controller alone, against a scripted PC: IPOCs advance by the cycle in ms, an
/// answer with the message's IPOC is taken (its correction moves the setpoint `RSol`), one with
/// another IPOC is not, and after `max_late` consecutive unanswered cycles it stops sending.
#[test]
fn the_emulated_controller_takes_echoed_answers_and_stops_when_they_are_late() {
    let s = scenario(CompensatorConfig::default(), 60.0);
    let pc = UdpSocket::bind("127.0.0.1:0").unwrap();
    pc.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    let emu = EmulatorOptions {
        robot: EmulatedRobotOptions::Rsi(RsiEndpointOptions {
            port: pc.local_addr().unwrap().port(),
            max_late: 5,
            ..Default::default()
        }),
        sensor: rsi_loopback_options().0.sensor, // on a free port
        ..Default::default()
    };
    let facility = FacilityHandle::start(&s, &emu).unwrap();
    let mut buf = [0u8; 4096];
    let mut encoder = AnswerEncoder::new(RsiNames::default());
    // before the PC's first answer, unanswered messages are neither late nor a reason to stop
    // (the KRL program starts RSI once the PC listens): 20 ignored, then answered
    for _ in 0..20 {
        pc.recv_from(&mut buf).unwrap();
    }
    // answer 50 messages: the first with a wrong IPOC, then correctly, 1 mm along x
    let mut ipocs = Vec::new();
    let mut setpoint_x = Vec::new();
    for i in 0..50 {
        let (n, from) = pc.recv_from(&mut buf).unwrap();
        let state = decode_state(&buf[..n], "RIst").unwrap();
        ipocs.push(state.ipoc);
        setpoint_x.push(state.setpoint.unwrap()[0]);
        let ipoc = if i == 0 {
            state.ipoc + 1_000_000
        } else {
            state.ipoc
        };
        let answer = encoder.encode(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0], ipoc);
        pc.send_to(answer, from).unwrap();
    }
    for w in ipocs.windows(2) {
        assert_eq!(w[1] - w[0], 4, "{ipocs:?}");
    }
    // the start is the scenario's initial pose (mm); corrected by 1 mm once answered
    assert!((setpoint_x[0] + 995.0).abs() < 1e-3, "{setpoint_x:?}");
    assert!((setpoint_x[49] + 994.0).abs() < 1e-3, "{setpoint_x:?}");
    // now silent: at most max_late more messages, then none
    let begun = Instant::now();
    let mut more = 0;
    pc.set_read_timeout(Some(Duration::from_millis(300)))
        .unwrap();
    while pc.recv_from(&mut buf).is_ok() {
        more += 1;
        assert!(begun.elapsed() < Duration::from_secs(5));
    }
    let status = facility.join();
    // 5 when every answer was in time; a busy machine may have made some late already (an
    // answer after the next message is `stale`)
    assert!((1..=5).contains(&more), "{more} more; {status:?}");
    assert_eq!(status.robot.invalid, 1, "{status:?}");
    assert_eq!(status.robot.accepted + status.robot.stale, 49, "{status:?}");
    assert!(status.robot.accepted >= 40, "{status:?}");
    assert!(status.robot.late >= 5, "{status:?}");
    assert!(status.robot.sent >= 20 + 50 + more, "{status:?}");
}

/// RSI options in TOML, as `[robot] kind = "rsi"`.
#[test]
fn rsi_options_read_from_toml() {
    let text = r#"
        [robot]
        kind = "rsi"
        port = 49200
        period = 0.012
        sen_type = "HilContact"
        correction = "relative"
    "#;
    let o: hilcontact_rt::RuntimeOptions = toml::from_str(text).unwrap();
    let RobotOptions::Rsi(rsi) = o.robot else {
        panic!("{o:?}")
    };
    assert_eq!(
        rsi,
        RsiOptions {
            port: 49200,
            period: 0.012,
            sen_type: "HilContact".into(),
            correction: CorrectionMode::Relative,
            ..Default::default()
        }
    );
    let e: EmulatorOptions = toml::from_str("[robot]\nkind = \"rsi\"\nmax_late = 3\n").unwrap();
    assert!(matches!(
        e.robot,
        EmulatedRobotOptions::Rsi(RsiEndpointOptions { max_late: 3, .. })
    ));
}
