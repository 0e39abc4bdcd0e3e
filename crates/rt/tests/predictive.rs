//! The predictive force limit, across processes' worth of sockets on loopback against the
//! emulated facility: an uncompensated loop at 20 and 40 ms robot delay is stopped before the
//! command that would press the rod beyond the force limit is sent, so the force the emulated
//! hardware feels (its own contact force, not the sensor's) stays within 10 % of the limit;
//! the measured line stays as the second one.

mod common;

use std::time::Duration;

use common::{delayed, loopback_options, print_metrics, rsi_loopback_options, run_both};
use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_rt::safety::SafetyLimits;

/// Runs `none` at `delay` s robot delay on (EGM, RDT) or (RSI, RDT); returns the metrics and
/// the emulator's peak contact force.
fn uncompensated(delay: f64, rsi: bool, predictive: bool) -> (serde_json::Value, f64) {
    let mut s = delayed(CompensatorConfig::default(), 8.0);
    s.facility.robot_delay = delay;
    let (emu, mut rt) = if rsi {
        rsi_loopback_options()
    } else {
        loopback_options()
    };
    rt.limits = SafetyLimits {
        predictive,
        ..rt.limits
    };
    let (out, status) = run_both(&s, &(emu, rt), Duration::from_secs(30));
    let m = out.metrics;
    print_metrics(&m);
    eprintln!(
        "delay {delay} s, rsi {rsi}: stop {}, emulator peak contact force {:.1} N",
        m["realtime"]["stop"], status.peak_contact_force
    );
    (m, status.peak_contact_force)
}

fn check_predictive_stop(m: &serde_json::Value, peak: f64) {
    let rt = &m["realtime"];
    let limit = rt["options"]["limits"]["force_limit"].as_f64().unwrap();
    assert_eq!(
        rt["stop"]["kind"], "predicted-force-limit",
        "{}",
        rt["stop"]
    );
    assert_eq!(rt["stop"]["exit_code"], 3);
    assert_eq!(rt["safety"]["limit_line"], "predicted");
    let predicted = rt["safety"]["predicted_peak_force"].as_f64().unwrap();
    assert!(predicted <= limit, "{predicted}");
    assert!(rt["stop"]["value"].as_f64().unwrap() > limit);
    assert!(
        peak <= 1.1 * limit,
        "the hardware felt {peak:.1} N, limit {limit} N"
    );
    // the stop released the contact: retreat then hold (the emulator's force at the end is
    // read by the callers that care)
    assert!(peak > 0.5 * limit, "the loop pressed on: {peak:.1} N");
}

#[test]
fn uncompensated_at_20ms_is_stopped_before_the_hardware_feels_the_limit() {
    let (m, peak) = uncompensated(0.02, false, true);
    check_predictive_stop(&m, peak);
}

#[test]
fn uncompensated_at_40ms_is_stopped_before_the_hardware_feels_the_limit() {
    let (m, peak) = uncompensated(0.04, false, true);
    check_predictive_stop(&m, peak);
}

#[test]
fn uncompensated_at_20ms_on_rsi_is_stopped_before_the_hardware_feels_the_limit() {
    let (m, peak) = uncompensated(0.02, true, true);
    check_predictive_stop(&m, peak);
}

/// Without the predictive line, the measured one stops the run, late: the hardware has felt
/// more than the limit by then (the 852 N for 503 N measured at 20 ms).
#[test]
fn the_measured_line_alone_stops_late() {
    let (m, peak) = uncompensated(0.04, false, false);
    let rt = &m["realtime"];
    assert_eq!(rt["stop"]["kind"], "force-limit", "{}", rt["stop"]);
    assert_eq!(rt["safety"]["limit_line"], "measured");
    assert!(peak > 1.1 * 500.0, "{peak}");
}
