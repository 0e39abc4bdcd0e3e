//! Bad input to the core: every value that once wrapped, aborted or panicked while turned into
//! control ticks (delays of 1e300 s or 2^70 s, a duration of 1e308 s, a period of 1e-308 s)
//! is a `ScenarioError` naming its key; the plan is never built from it. Python refuses these
//! first, but the core must not rely on it.

mod common;

use common::table1;
use hilcontact_core::{CoreError, Scenario};

/// The keys of the problems `resolve` reports (it must not panic).
fn rejected(s: &Scenario) -> Vec<String> {
    match s.resolve() {
        Err(e @ CoreError::InvalidScenario { .. }) => {
            e.issues().into_iter().map(|i| i.key).collect()
        }
        Ok(_) => panic!("an invalid scenario resolved"),
    }
}

fn message(s: &Scenario) -> String {
    s.resolve().expect_err("invalid").to_string()
}

#[test]
fn huge_and_tiny_times_are_errors_naming_the_key() {
    let two_70 = 2f64.powi(70);
    let cases: Vec<(&str, Box<dyn Fn(&mut Scenario)>)> = vec![
        (
            "facility.robot_delay",
            Box::new(|s| s.facility.robot_delay = 1e300),
        ),
        (
            "facility.robot_delay",
            Box::new(move |s| s.facility.robot_delay = two_70),
        ),
        (
            "facility.sensor_delay",
            Box::new(move |s| s.facility.sensor_delay = two_70),
        ),
        (
            "facility.robot_delay",
            Box::new(|s| s.facility.robot_delay = 1e-320),
        ),
        (
            "facility.robot_delay",
            Box::new(|s| s.facility.robot_delay = 1e-308),
        ),
        (
            "facility.sensor_delay",
            Box::new(|s| s.facility.sensor_delay = f64::INFINITY),
        ),
        (
            "simulation.duration",
            Box::new(|s| s.simulation.duration = 1e308),
        ),
        (
            "simulation.duration",
            Box::new(move |s| s.simulation.duration = two_70),
        ),
        (
            "simulation.period",
            Box::new(|s| s.simulation.period = 1e-308),
        ),
        (
            "simulation.period",
            Box::new(|s| s.simulation.period = 5e-7),
        ),
        (
            "simulation.reference_substeps",
            Box::new(|s| s.simulation.reference_substeps = u32::MAX),
        ),
        (
            "simulation.plant_substeps",
            Box::new(|s| s.simulation.plant_substeps = 1_000_000_000),
        ),
        (
            "contact.stiffness",
            Box::new(|s| s.contact.stiffness = 1e308),
        ),
        (
            "contact.stiffness",
            Box::new(move |s| s.contact.stiffness = two_70),
        ),
        ("rod.tip", Box::new(|s| s.rod.tip = [1e308, 0.0, 0.0])),
        (
            "servicer.velocity",
            Box::new(|s| s.servicer.velocity = [0.0, 1e4, 0.0]),
        ),
        (
            "walls[0].normal",
            Box::new(|s| s.walls[0].normal = [1e300, 1e300, 0.0]),
        ),
        ("servicer.mass", Box::new(|s| s.servicer.mass = 1e-300)),
        (
            "target.inertia",
            Box::new(|s| {
                s.target.inertia = hilcontact_core::config::Inertia::Principal([1e-300, 1.0, 1.0])
            }),
        ),
    ];
    for (key, set) in cases {
        let mut s = table1(0.01, 0.0);
        set(&mut s);
        assert_eq!(rejected(&s), [key], "{}", message(&s));
    }
}

#[test]
fn a_delay_longer_than_the_run_or_below_a_period_names_the_key_and_the_limit() {
    let mut s = table1(0.01, 0.0);
    s.simulation.duration = 0.005;
    assert_eq!(
        message(&s),
        "facility.robot_delay: 0.01 s is longer than the run (simulation.duration = 0.005 s)"
    );
    let s = table1(1e-320, 0.0);
    assert!(
        message(&s).starts_with("facility.robot_delay: 1e-320 s is not a whole number of periods"),
        "{}",
        message(&s)
    );
}

#[test]
fn too_many_ticks_are_refused_before_anything_is_allocated() {
    let mut s = table1(0.0, 0.0);
    s.simulation.duration = 86400.0;
    s.simulation.period = 1e-6;
    assert_eq!(
        message(&s),
        "simulation.duration: 86400 s at simulation.period = 1e-6 s is 8.64e10 control periods; at most 1e9 are allowed"
    );
}

#[test]
fn a_resolved_delay_is_the_whole_periods_it_runs_as() {
    let plan = table1(0.010000000001, 0.0).resolve().expect("valid");
    assert_eq!(plan.facility.robot_delay_ticks, 10);
    assert_eq!(plan.scenario.facility.robot_delay, 0.01);
}

#[test]
fn a_contact_the_reference_cannot_resolve_is_refused() {
    let mut s = table1(0.0, 0.0);
    s.servicer.mass = 0.001;
    s.contact.stiffness = 1e11;
    assert_eq!(rejected(&s), ["contact.stiffness"], "{}", message(&s));
    s.simulation.reference_substeps = 1000;
    s.simulation.period = 1e-6;
    s.resolve().expect("resolved with 1 ns steps");
    let mut s = table1(0.0, 0.0);
    s.servicer.mass = 10.0;
    s.contact.damping = 1e9;
    assert_eq!(rejected(&s), ["contact.damping"], "{}", message(&s));
}

#[test]
fn names_must_be_valid_folder_names() {
    for name in ["a/b", "a\0b", ".", "..", "", " ", "tab\there"] {
        let mut s = table1(0.0, 0.0);
        s.name = name.into();
        assert_eq!(rejected(&s), ["name"], "{name:?}");
    }
    let mut s = table1(0.0, 0.0);
    s.name = "x".repeat(300);
    let m = message(&s);
    assert!(
        m.starts_with("name: must be 1 to 100 characters") && m.contains("(300 characters)"),
        "{m}"
    );
    s.name = "é".repeat(100);
    s.resolve().expect("100 characters are fine");
}
