//! KUKA RSI on loopback against the emulated controller: the robot's cycle measured from its
//! IPOC (both directions of a mismatch refused before anything moves), the scenario's own
//! period stepped several times per robot cycle, the loop's own late-answer limit before the
//! controller's, and the end of the session with the end signal.

mod common;

use std::time::Duration;

use common::{
    assert_stop, delayed, finish_both, print_metrics, rsi_loopback_options, run_both, start_both,
};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_rt::devices::EmulatedRobotOptions;
use hilcontact_rt::RobotOptions;

/// RSI options with the controller's cycle `robot` s and the PC's configured cycle `pc` s.
fn cycles(
    robot: f64,
    pc: f64,
) -> (
    hilcontact_rt::EmulatorOptions,
    hilcontact_rt::RuntimeOptions,
) {
    let (mut emu, mut rt) = rsi_loopback_options();
    if let (RobotOptions::Rsi(link), EmulatedRobotOptions::Rsi(endpoint)) =
        (&mut rt.robot, &mut emu.robot)
    {
        link.period = pc;
        endpoint.period = robot;
    }
    (emu, rt)
}

/// A wrong cycle, either way, is refused at the start with both numbers; the emulated robot
/// never left the start (nothing was commanded but holds at its own pose).
#[test]
fn a_wrong_robot_cycle_is_refused_at_the_start_with_both_numbers() {
    let s = delayed(CompensatorConfig::default(), 5.0);
    for (robot, pc, measured, configured) in [
        (0.012, 0.004, "12.0 ms", "configured 4.0 ms"),
        (0.004, 0.012, "4.0 ms", "configured 12.0 ms"),
    ] {
        let (emu, rt) = cycles(robot, pc);
        let (facility, hil) = start_both(&s, &emu, &rt);
        let (out, status) = finish_both(facility, hil, Duration::from_secs(20));
        let e = out.err().expect("refused").to_string();
        eprintln!(
            "robot {robot} s, PC {pc} s: {e}; peak {}",
            status.peak_contact_force
        );
        assert!(e.contains(measured) && e.contains(configured), "{e}");
        assert!(e.contains("cycle"), "{e}");
        assert_eq!(status.peak_contact_force, 0.0, "{status:?}");
    }
}

/// paper-table1 as it is (period 1 ms) on RSI's 4 ms cycle: four virtual steps per message,
/// the run completes with every tick of the scenario, the session ends with the end signal
/// (the controller records a clean end, no error), and the measured cycle is 4 ms.
#[test]
fn a_preset_runs_on_rsi_as_it_is_and_ends_the_session_cleanly() {
    let s = delayed(CompensatorConfig::Pida(ModelParams::default()), 2.5);
    assert_eq!(s.simulation.period, 0.001);
    let (emu, rt) = rsi_loopback_options();
    let (out, status) = run_both(&s, &(emu, rt), Duration::from_secs(30));
    let m = out.metrics;
    print_metrics(&m);
    assert_stop(&m, "completed");
    let rt = &m["realtime"];
    assert_eq!(rt["ticks"], 2501);
    assert_eq!(rt["safety"]["steps_per_cycle"], 4);
    let cycle = rt["safety"]["robot_cycle"].as_f64().unwrap();
    assert!((cycle - 0.004).abs() < 1e-9, "{cycle}");
    assert_eq!(rt["safety"]["session_ended_cleanly"], true);
    assert_eq!(status.session_ended_cleanly, Some(true), "{status:?}");
    assert!(m["collisions"].as_array().unwrap().len() >= 2);
}

/// The loop counts its own late answers and stops at `max_late_answers`, before the
/// controller's `max_late`: a deadline of 1 µs makes every answer late to the loop (the
/// controller, whose limit is its cycle, takes them in time), so the loop stops itself with
/// `late-answers`, and ends the session cleanly.
#[test]
fn the_loop_stops_on_its_own_late_answers_before_the_controller() {
    let s = delayed(CompensatorConfig::default(), 5.0);
    let (emu, mut rt) = rsi_loopback_options();
    if let RobotOptions::Rsi(link) = &mut rt.robot {
        link.deadline = 1e-6;
        link.max_late_answers = 20;
    }
    let (out, status) = run_both(&s, &(emu, rt), Duration::from_secs(30));
    let m = out.metrics;
    let stop = &m["realtime"]["stop"];
    eprintln!("{stop}");
    assert_eq!(stop["kind"], "late-answers", "{stop}");
    assert_eq!(stop["limit"], 20.0);
    assert!(stop["reason"]
        .as_str()
        .unwrap()
        .contains("max_late_answers"));
    assert!(
        m["realtime"]["rsi"]["answers_late"].as_u64().unwrap() >= 20,
        "{}",
        m["realtime"]["rsi"]
    );
    // the controller never reached its own limit: no error on its side
    assert_eq!(status.session_ended_cleanly, Some(true), "{status:?}");
}

/// A controller whose IPOC falls back (restarted) is named: `robot-sequence`, not a watchdog.
#[test]
fn an_ipoc_going_backwards_is_named() {
    let s = delayed(CompensatorConfig::Pida(ModelParams::default()), 4.0);
    let (mut emu, rt) = rsi_loopback_options();
    if let EmulatedRobotOptions::Rsi(endpoint) = &mut emu.robot {
        endpoint.ipoc_back_after = Some(200);
    }
    let (out, _) = run_both(&s, &(emu, rt), Duration::from_secs(30));
    let stop = &out.metrics["realtime"]["stop"];
    assert_eq!(stop["kind"], "robot-sequence", "{stop}");
    assert!(stop["reason"].as_str().unwrap().contains("IPOC"), "{stop}");
    assert!(stop["value"].as_f64().unwrap() >= 900.0, "{stop}");
}
