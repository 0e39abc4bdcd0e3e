//! Faults named as what they were, on loopback against the emulated facility: an SRI box that
//! resets its TCP connection, one whose frames have wrong checksums, and a box still booting
//! (its TCP port, or an ATI sensor's HTTP page, comes up after `hil` started: the start waits
//! within `connect_timeout` and proceeds).

mod common;

use std::time::Duration;

use common::{
    delayed, finish_both, loopback_options, loopback_sri_options, print_metrics, run_both,
};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_rt::devices::rdt::RdtOptions;
use hilcontact_rt::devices::EmulatedSensorOptions;
use hilcontact_rt::{FacilityHandle, HilHandle, SensorOptions};

fn sri_with(
    configure: impl FnOnce(&mut hilcontact_rt::devices::sri::SriEndpointOptions),
) -> serde_json::Value {
    let s = delayed(CompensatorConfig::Pida(ModelParams::default()), 4.0);
    let (mut emu, rt) = loopback_sri_options();
    if let EmulatedSensorOptions::Sri(o) = &mut emu.sensor {
        configure(o);
    }
    let (out, _) = run_both(&s, &(emu, rt), Duration::from_secs(30));
    print_metrics(&out.metrics);
    out.metrics
}

#[test]
fn an_sri_tcp_reset_is_named_in_the_stop_and_the_counters() {
    let m = sri_with(|o| o.reset_after_frames = Some(500));
    let rt = &m["realtime"];
    assert_eq!(rt["stop"]["kind"], "sensor-connection", "{}", rt["stop"]);
    let reason = rt["stop"]["reason"].as_str().unwrap();
    assert!(reason.contains("reset (TCP RST)"), "{reason}");
    assert_eq!(rt["sensor_faults"]["connection"], "reset");
    assert!(rt["sensor"]["io_errors"].as_u64().unwrap() >= 1);
}

#[test]
fn sri_checksum_errors_are_named_in_the_stop_and_the_counters() {
    let m = sri_with(|o| o.bad_checksum_after_frames = Some(500));
    let rt = &m["realtime"];
    assert_eq!(rt["stop"]["kind"], "sensor-checksum", "{}", rt["stop"]);
    assert!(rt["stop"]["reason"].as_str().unwrap().contains("checksum"));
    assert_eq!(rt["stop"]["limit"], 10.0);
    assert!(rt["sensor_faults"]["checksum_errors"].as_u64().unwrap() >= 10);
}

/// Starts the emulator `after` the loop was started (a box still booting), in a thread, while
/// the loop's start waits; both finish.
fn late_facility(
    emu: hilcontact_rt::EmulatorOptions,
    rt: hilcontact_rt::RuntimeOptions,
    after: Duration,
) -> serde_json::Value {
    let s = delayed(CompensatorConfig::Pida(ModelParams::default()), 1.5);
    let s2 = s.clone();
    let booting = std::thread::spawn(move || {
        std::thread::sleep(after);
        FacilityHandle::start(&s2, &emu).unwrap()
    });
    let started = std::time::Instant::now();
    let hil = HilHandle::start(&s, &rt).expect("the start waits for the box");
    let facility = booting.join().unwrap();
    assert!(started.elapsed() >= after / 2);
    let (out, _) = finish_both(facility, hil, Duration::from_secs(30));
    let m = out.expect("the run").metrics;
    print_metrics(&m);
    m
}

#[test]
fn an_sri_box_still_booting_is_waited_for() {
    let (emu, mut rt) = loopback_sri_options();
    rt.connect_timeout = 5.0;
    let m = late_facility(emu, rt, Duration::from_secs(1));
    assert_eq!(m["realtime"]["stop"]["kind"], "completed");
}

#[test]
fn an_ati_http_page_still_booting_is_waited_for() {
    let (mut emu, mut rt) = loopback_options();
    let http = common::free_tcp_port();
    if let EmulatedSensorOptions::Rdt(o) = &mut emu.sensor {
        o.http_port = http;
    }
    if let SensorOptions::Rdt(o) = &rt.sensor {
        rt.sensor = SensorOptions::Rdt(RdtOptions {
            http_port: http,
            counts_per_force: None,
            counts_per_torque: None,
            ..o.clone()
        });
    }
    rt.connect_timeout = 5.0;
    let m = late_facility(emu, rt, Duration::from_secs(1));
    assert_eq!(m["realtime"]["stop"]["kind"], "completed");
    assert!(m["realtime"]["counts_per_force"].as_f64().is_some());
}
