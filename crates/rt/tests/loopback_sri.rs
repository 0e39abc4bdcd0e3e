//! The emulated facility and the real-time loop on loopback with the sensor an SRI M812x box
//! (AT commands and binary frames over TCP) and the robot ABB EGM.

mod common;

use common::{
    assert_ran_to_its_end, assert_rebound_kept, covs, delayed, loopback_sri_options, print_metrics,
    run_both,
};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use serde_json::Value;
use std::time::Duration;

/// Runs the loop against the emulator at 20 ms robot delay; returns the metrics.
fn run(kind: CompensatorConfig, duration: f64) -> Value {
    let s = delayed(kind, duration);
    let wait = Duration::from_secs_f64(duration + 30.0);
    let (out, status) = run_both(&s, &loopback_sri_options(), wait);
    assert!(
        status.sensor.sent > 0 && status.corrections > 0,
        "{status:?}"
    );
    print_metrics(&out.metrics);
    out.metrics
}

#[test]
fn sri_pida_at_20ms_keeps_the_rebound_speed_in_real_time() {
    let m = run(CompensatorConfig::Pida(ModelParams::default()), 3.5);
    assert_ran_to_its_end(&m);
    eprintln!("CoV {:?}", covs(&m));
    assert_rebound_kept(&m, 3);
    let rt = &m["realtime"];
    assert_eq!(rt["ticks"], 3501);
    assert_eq!(rt["stop"]["kind"], "completed");
    let sensor = &rt["sensor"];
    assert_eq!(sensor["malformed"], 0, "{sensor}");
    assert_eq!(sensor["invalid"], 0, "{sensor}");
    assert_eq!(sensor["lost"], 0, "{sensor}");
    assert_eq!(sensor["io_errors"], 0, "{sensor}");
    assert!(sensor["accepted"].as_u64().unwrap() >= 3000, "{sensor}");
}

#[test]
fn sri_uncompensated_loop_is_stopped_by_the_force_limit() {
    let m = run(CompensatorConfig::default(), 6.0);
    assert_eq!(m["status"], "stopped");
    assert_eq!(m["realtime"]["stop"]["kind"], "predicted-force-limit");
    assert_eq!(m["realtime"]["stop"]["exit_code"], 3);
    let covs = covs(&m);
    assert!(covs.first().is_some_and(|c| *c > 1.3), "{covs:?}");
}
