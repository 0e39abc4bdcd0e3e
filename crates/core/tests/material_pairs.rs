//! Friction per pair of shape materials (`[[contact.friction.pairs]]`): a listed pair takes its
//! coefficients (an oblique sliding impact loses `μ_pair(1+e)|v_n|`), every other contact the
//! table's; listing the table's own coefficients changes nothing; the pair table's layout
//! (servicer shape × target shape, either order of the materials); the refusals.

mod common;

use common::preset;
use hilcontact_core::config::{Inertia, ShapeConfig};
use hilcontact_core::contact::MaterialPairFriction;
use hilcontact_core::sim::simulate;
use hilcontact_core::Scenario;
use serde_json::json;

fn shape(keys: serde_json::Value) -> ShapeConfig {
    serde_json::from_value(keys).expect("a valid shape table")
}

fn pair(a: &str, b: &str, kinetic: f64, static_coefficient: f64) -> MaterialPairFriction {
    MaterialPairFriction {
        materials: [a.to_string(), b.to_string()],
        kinetic_coefficient: kinetic,
        static_coefficient,
    }
}

const R: f64 = 0.05;
const V_N: f64 = 0.02;
const V_T: f64 = 0.05;

/// A sphere of `material` (radius R, at the origin) sliding at (V_N, V_T, 0) into a plane of
/// `rubber` at x = R + 1 mm facing −x, on a target too heavy to move; the table's friction
/// μ = 0.1, damping 300 N·s/m, 0.1 ms period.
fn sliding_sphere(material: &str, pairs: Vec<MaterialPairFriction>) -> Scenario {
    let mut s = preset("paper-table1");
    s.walls.clear();
    s.servicer.shapes = vec![shape(
        json!({"kind": "sphere", "radius": R, "material": material}),
    )];
    s.target.shapes = vec![shape(json!({
        "kind": "half-space", "position": [R + 0.001, 0.0, 0.0], "normal": [-1.0, 0.0, 0.0],
        "material": "rubber"
    }))];
    s.servicer.position = [0.0; 3];
    s.servicer.velocity = [V_N, V_T, 0.0];
    s.servicer.angular_velocity = [0.0; 3];
    s.target.position = [0.0; 3];
    s.target.mass = 1e7;
    s.target.inertia = Inertia::Principal([1e7; 3]);
    s.simulation.duration = 0.3;
    s.simulation.period = 1e-4;
    s.simulation.reference_substeps = 4;
    s.facility.robot_delay = 0.0;
    s.contact.damping = 300.0;
    s.contact.friction.kinetic_coefficient = 0.1;
    s.contact.friction.static_coefficient = 0.1;
    s.contact.friction.stick_velocity = 1e-4;
    s.contact.friction.pairs = pairs;
    s
}

/// The servicer's velocity at the end of the ideal reference.
fn end_velocity(s: &Scenario) -> nalgebra::Vector3<f64> {
    let plan = s.resolve().unwrap_or_else(|e| panic!("{e}"));
    let mut x = plan.initial;
    for _ in 0..plan.ticks {
        plan.system
            .step_reference(&mut x, plan.period, plan.reference_substeps);
    }
    x.servicer.velocity
}

#[test]
fn a_listed_pair_slides_with_its_own_coefficient_and_others_with_the_tables() {
    let frictionless = vec![pair("steel", "rubber", 0.0, 0.0)];
    let v0 = end_velocity(&sliding_sphere("steel", frictionless));
    let e = -v0.x / V_N;
    assert!(e > 0.8 && e < 1.0, "restitution {e}");
    assert!(
        (v0.y - V_T).abs() < 1e-9,
        "a frictionless pair took {}",
        V_T - v0.y
    );
    for (mu, order) in [(0.3, false), (0.45, true)] {
        let p = if order {
            pair("rubber", "steel", mu, mu)
        } else {
            pair("steel", "rubber", mu, mu)
        };
        // steel on rubber: the pair's μ, in either order of the names
        let lost = V_T - end_velocity(&sliding_sphere("steel", vec![p.clone()])).y;
        let expected = mu * (1.0 + e) * V_N;
        assert!(
            (lost - expected).abs() < 0.01 * expected,
            "steel on rubber, μ = {mu}: lost {lost} m/s, expected {expected}"
        );
        // aluminium on rubber is not listed: the table's μ = 0.1 (a steel sphere far from
        // the plane keeps the pair's material in the scene)
        let mut aluminium = sliding_sphere("aluminium", vec![p]);
        aluminium.servicer.shapes.push(shape(
            json!({"kind": "sphere", "radius": 0.01, "position": [-1.0, 0.0, 0.0],
                   "material": "steel"}),
        ));
        let lost = V_T - end_velocity(&aluminium).y;
        let expected = 0.1 * (1.0 + e) * V_N;
        assert!(
            (lost - expected).abs() < 0.01 * expected,
            "aluminium on rubber: lost {lost} m/s, expected the table's {expected}"
        );
    }
}

#[test]
fn listing_the_tables_own_coefficients_changes_nothing() {
    let mut plain = sliding_sphere("steel", Vec::new());
    let mut listed = sliding_sphere("steel", vec![pair("rubber", "steel", 0.1, 0.1)]);
    for s in [&mut plain, &mut listed] {
        s.facility.robot_delay = 0.002;
        s.simulation.duration = 0.1;
    }
    let a = simulate(&plain).expect("runs");
    let b = simulate(&listed).expect("runs");
    assert_eq!(a.timeseries, b.timeseries, "the HIL runs differ");
    assert_eq!(a.reference, b.reference, "the references differ");
}

#[test]
fn the_pair_table_is_laid_out_servicer_by_target() {
    // servicer: steel (0), aluminium (1); target: steel (0), rubber (1), ptfe (2), all apart
    let mut s = sliding_sphere("steel", Vec::new());
    s.servicer.shapes = vec![
        shape(json!({"kind": "sphere", "radius": 0.01, "material": "steel"})),
        shape(
            json!({"kind": "sphere", "radius": 0.01, "position": [0.0, 0.5, 0.0],
                     "material": "aluminium"}),
        ),
    ];
    s.target.shapes = ["steel", "rubber", "ptfe"]
        .iter()
        .enumerate()
        .map(|(i, m)| {
            shape(json!({"kind": "box", "size": [0.1, 0.1, 0.1],
                         "position": [1.0, i as f64, 0.0], "material": m}))
        })
        .collect();
    s.contact.friction.pairs = vec![
        pair("rubber", "steel", 0.5, 0.6),
        pair("aluminium", "steel", 0.2, 0.0),
        pair("ptfe", "aluminium", 0.0, 0.0),
    ];
    let plan = s.resolve().unwrap_or_else(|e| panic!("{e}"));
    let c = &plan.system.contact;
    assert_eq!(c.shape_friction.len(), 6);
    let mu = |a, b| c.friction_between(a, b).map(|f| f.kinetic_coefficient);
    let mu_s = |a, b| c.friction_between(a, b).map(|f| f.static_coefficient);
    assert_eq!(mu(0, 0), Some(0.1), "steel-steel: the table's");
    assert_eq!(
        (mu(0, 1), mu_s(0, 1)),
        (Some(0.5), Some(0.6)),
        "steel-rubber"
    );
    assert_eq!(mu(0, 2), Some(0.1), "steel-ptfe: the table's");
    assert_eq!(
        (mu(1, 0), mu_s(1, 0)),
        (Some(0.2), Some(0.2)),
        "aluminium-steel"
    );
    assert_eq!(mu(1, 1), Some(0.1), "aluminium-rubber: the table's");
    assert_eq!(mu(1, 2), None, "aluminium-ptfe: frictionless");
    // the facility's hardware (mounted) keeps the table
    assert_eq!(plan.nominal.contact.shape_friction, c.shape_friction);
}

#[test]
fn bad_pairs_are_refused_naming_the_key() {
    let refused = |s: Scenario, key: &str, words: &str| {
        let err = s.resolve().expect_err("refused").to_string();
        assert!(err.contains(key) && err.contains(words), "{key}: {err}");
    };
    refused(
        sliding_sphere("steel", vec![pair("steel", "rubbr", 0.2, 0.2)]),
        "contact.friction.pairs[0].materials",
        "rubbr",
    );
    refused(
        sliding_sphere(
            "steel",
            vec![
                pair("steel", "rubber", 0.2, 0.2),
                pair("rubber", "steel", 0.3, 0.3),
            ],
        ),
        "contact.friction.pairs[1].materials",
        "twice",
    );
    refused(
        sliding_sphere("steel", vec![pair("steel", "rubber", 0.3, 0.2)]),
        "contact.friction.pairs[0].static",
        "below the kinetic",
    );
    refused(
        sliding_sphere("steel", vec![pair("steel", "", 0.3, 0.3)]),
        "contact.friction.pairs[0].materials",
        "empty",
    );
    refused(
        sliding_sphere("steel", vec![pair("steel", "rubber", 2.5, 0.0)]),
        "contact.friction.pairs[0].kinetic",
        "",
    );
    let mut walls = preset("paper-table1");
    walls.contact.friction.pairs = vec![pair("steel", "rubber", 0.2, 0.2)];
    refused(walls, "contact.friction.pairs", "shapes on both bodies");
}
