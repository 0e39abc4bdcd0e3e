//! The scenario schema (`hilcontact_core::schema`): the ranges it declares are the ones
//! `Plan::resolve` checks, with every problem reported in the core's wording.

mod common;

use common::table1;
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_core::schema::scenario_schema;
use hilcontact_core::{CoreError, Scenario, ScenarioIssue};

fn issues(s: &Scenario) -> Vec<ScenarioIssue> {
    match s.resolve() {
        Err(e @ CoreError::InvalidScenario { .. }) => e.issues(),
        Ok(_) => panic!("an invalid scenario resolved"),
    }
}

fn issue(key: &str, message: &str) -> ScenarioIssue {
    ScenarioIssue {
        key: key.into(),
        message: message.into(),
    }
}

#[test]
fn every_range_problem_is_reported_in_the_core_wording() {
    let mut s = table1(0.0, 0.0);
    s.servicer.mass = -1.0;
    s.simulation.plant_substeps = 0;
    s.simulation.divergence_energy_ratio = 1.0;
    s.contact.damping = -0.5;
    s.contact.stiffness = f64::INFINITY;
    s.facility.sensor_noise = f64::NAN;
    s.compensator = CompensatorConfig::Pida(ModelParams {
        forgetting: 1.5,
        stiffness_walk: -1.0,
        ..ModelParams::default()
    });
    assert_eq!(
        issues(&s),
        vec![
            issue(
                "simulation.plant_substeps",
                "must be between 1 and 1000, got 0"
            ),
            issue(
                "simulation.divergence_energy_ratio",
                "must be > 1 and <= 1e12, got 1"
            ),
            issue("servicer.mass", "must be between 0.001 and 1e7, got -1"),
            issue("contact.stiffness", "must be a finite number, got inf"),
            issue("contact.damping", "must be between 0 and 1e9, got -0.5"),
            issue("facility.sensor_noise", "must be a finite number, got NaN"),
            issue(
                "compensator.stiffness_walk",
                "must be between 0 and 1e11, got -1"
            ),
            issue(
                "compensator.forgetting",
                "must be between 0 and 1 (exclusive), got 1.5"
            ),
        ]
    );
}

#[test]
fn range_problems_and_semantic_problems_are_reported_together() {
    let mut s = table1(0.0125, 0.0);
    s.target.mass = 0.0;
    s.walls[1].normal = [0.0; 3];
    let keys: Vec<String> = issues(&s).into_iter().map(|i| i.key).collect();
    assert_eq!(
        keys,
        ["target.mass", "walls[1].normal", "facility.robot_delay"]
    );
    let err = s.resolve().unwrap_err().to_string();
    assert!(
        err.starts_with(
            "target.mass: must be between 0.001 and 1e7, got 0 (and 2 more: walls[1].normal, facility.robot_delay)"
        ),
        "{err}"
    );
}

#[test]
fn a_negative_delay_is_a_range_problem_only() {
    let s = table1(-0.001, 0.0);
    assert_eq!(
        issues(&s),
        vec![issue(
            "facility.robot_delay",
            "must be between 0 and 60, got -0.001"
        )]
    );
}

/// Every numeric scalar of the schema has a range, and every default resolves.
#[test]
fn the_schema_declares_every_range_and_default() {
    let schema = serde_json::to_value(scenario_schema()).expect("schema");
    let defs = schema["$defs"].as_object().expect("$defs");
    let mut numbers = 0;
    let mut check = |owner: &str, props: &serde_json::Map<String, serde_json::Value>| {
        for (name, p) in props {
            if matches!(p["type"].as_str(), Some("number") | Some("integer")) {
                numbers += 1;
                let bounded = ["minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"]
                    .iter()
                    .any(|b| p.get(*b).is_some());
                assert!(bounded, "{owner}.{name} has no range");
            }
            let described = p["description"].as_str().is_some_and(|d| !d.is_empty());
            assert!(
                described || name == "kind",
                "{owner}.{name} has no description"
            );
        }
    };
    for (owner, def) in defs {
        if let Some(props) = def["properties"].as_object() {
            check(owner, props);
        }
        for variant in def["oneOf"].as_array().into_iter().flatten() {
            if let Some(props) = variant["properties"].as_object() {
                check(owner, props);
            }
        }
    }
    assert!(numbers > 30, "{numbers}");
    let kinds: Vec<&str> = defs["CompensatorConfig"]["oneOf"]
        .as_array()
        .expect("oneOf")
        .iter()
        .map(|v| v["properties"]["kind"]["const"].as_str().expect("kind"))
        .collect();
    let registry: Vec<&str> = hilcontact_core::compensator::REGISTRY
        .iter()
        .map(|k| k.kind)
        .collect();
    assert_eq!(kinds, registry);
}

/// The resolved inertia is the full tensor, and resolving a resolved scenario changes nothing.
#[test]
fn the_resolved_scenario_is_a_fixed_point() {
    let plan = table1(0.01, 0.0).resolve().expect("valid");
    assert!(matches!(
        plan.scenario.servicer.inertia,
        hilcontact_core::config::Inertia::Tensor(_)
    ));
    assert_eq!(plan.scenario.resolve().expect("valid"), plan);
}
