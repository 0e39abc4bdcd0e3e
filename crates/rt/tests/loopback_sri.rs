//! The emulated facility and the real-time loop on loopback with the sensor an SRI M812x box
//! (AT commands and binary frames over TCP) and the robot ABB EGM.

mod common;

use common::{loopback_sri_options, preset};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_rt::{FacilityHandle, HilHandle};
use serde_json::Value;
use std::time::Duration;

/// Runs the loop against the emulator at 20 ms robot delay; returns the metrics.
fn run(kind: CompensatorConfig, duration: f64) -> Value {
    let mut s = preset("paper-table1");
    s.facility.robot_delay = 0.02;
    s.simulation.duration = duration;
    s.compensator = kind;
    let (emu, rt) = loopback_sri_options();
    let facility = FacilityHandle::start(&s, &emu).unwrap();
    let hil = HilHandle::start(&s, &rt).unwrap();
    assert!(hil.wait(Duration::from_secs_f64(duration + 30.0)));
    let out = hil.finish();
    let status = facility.join();
    let out = out.unwrap_or_else(|e| panic!("{e}; emulator: {status:?}"));
    assert!(
        status.sensor.sent > 0 && status.corrections > 0,
        "{status:?}"
    );
    eprintln!(
        "{}",
        serde_json::to_string_pretty(&out.metrics["realtime"]).unwrap()
    );
    eprintln!(
        "{}",
        serde_json::to_string_pretty(&out.metrics["collisions"]).unwrap()
    );
    out.metrics
}

fn covs(m: &Value) -> Vec<f64> {
    m["collisions"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|c| c["cov"].as_f64())
        .collect()
}

#[test]
fn sri_pida_at_20ms_keeps_the_rebound_speed_in_real_time() {
    let m = run(CompensatorConfig::Pida(ModelParams::default()), 3.5);
    assert!(
        m["status"] == "ok" || m["status"] == "unfaithful",
        "{}: {}",
        m["status"],
        m["reason"]
    );
    let covs = covs(&m);
    eprintln!("CoV {covs:?}");
    assert!(covs.len() >= 3, "{covs:?}");
    for cov in &covs {
        assert!((0.9..=1.1).contains(cov), "CoV {cov} in {covs:?}");
    }
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
    assert_eq!(m["realtime"]["stop"]["kind"], "force-limit");
    assert_eq!(m["realtime"]["stop"]["exit_code"], 3);
    let covs = covs(&m);
    assert!(covs.first().is_some_and(|c| *c > 1.3), "{covs:?}");
}
