//! The units and scale check on loopback against the emulated facility: a sensor that reports
//! kgf or lbf while the loop takes N is stopped at the first contact with the likely unit
//! named, before the hardware feels more than the force limit, and released (no force left on
//! the rod); a sensor in N passes with a ratio near 1.

mod common;

use std::time::Duration;

use common::{delayed, loopback_options, print_metrics, run_both};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_rt::ReportedUnit;

fn run(unit: ReportedUnit, compensator: CompensatorConfig) -> (serde_json::Value, f64, f64) {
    let s = delayed(compensator, 4.0);
    let (mut emu, rt) = loopback_options();
    emu.sensor_unit = unit;
    // the emulated hardware at the loop's priority: starved on a busy machine, its robot
    // stopped short of the wall while the loop went on (a predicted-limit stop, no contact)
    emu.scheduling = Some(rt.scheduling);
    let (out, status) = run_both(&s, &(emu, rt), Duration::from_secs(30));
    let m = out.metrics;
    print_metrics(&m);
    eprintln!(
        "{unit:?}: stop {}; emulator peak {:.1} N, at the end {:.1} N",
        m["realtime"]["stop"], status.peak_contact_force, status.contact_force
    );
    (m, status.peak_contact_force, status.contact_force)
}

#[test]
fn a_sensor_in_kgf_or_lbf_is_stopped_at_the_first_contact_naming_the_unit() {
    for (unit, name, factor) in [
        (ReportedUnit::Kgf, "kgf", 9.80665),
        (ReportedUnit::Lbf, "lbf", 4.448222),
    ] {
        for compensator in [
            CompensatorConfig::default(),
            CompensatorConfig::Pida(ModelParams::default()),
        ] {
            let (m, peak, end) = run(unit, compensator);
            let stop = &m["realtime"]["stop"];
            assert_eq!(stop["kind"], "units", "{stop}");
            let reason = stop["reason"].as_str().unwrap();
            assert!(reason.contains(name), "{reason}");
            let ratio = stop["value"].as_f64().unwrap();
            assert!(
                (ratio * factor - 1.0).abs() < 0.25,
                "ratio {ratio} for {name}"
            );
            assert!(peak <= 1.1 * 500.0, "the hardware felt {peak:.1} N");
            assert!(end < 5.0, "the rod stayed pressed with {end:.1} N");
        }
    }
}

#[test]
fn a_sensor_in_newtons_passes_the_check() {
    let (m, _, _) = run(
        ReportedUnit::N,
        CompensatorConfig::Pida(ModelParams::default()),
    );
    let safety = &m["realtime"]["safety"];
    let ratio = safety["units_ratio"].as_f64().expect("checked");
    assert!((0.75..=1.33).contains(&ratio), "{safety}");
    assert_eq!(m["realtime"]["stop"]["kind"], "completed");
}
