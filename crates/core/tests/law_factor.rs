//! `Contact::law_factor`: the stiffness of the whole contact along its normal is
//! `law_factor·k`, which the identification metric compares an estimate with. The walls' sum
//! `Σᵢ (nᵢ·n̂)²` against finite differences of the contact force on random corners, and the
//! shapes' measured factor against analytic values (a cube flat on a plate: 4; a sphere in a
//! V-groove of half-angle θ: 2cos²θ).

mod common;

use common::preset;
use hilcontact_core::config::ShapeConfig;
use hilcontact_core::frames::RelativeMotion;
use hilcontact_core::{Plan, Scenario};
use nalgebra::{UnitQuaternion, Vector3};
use proptest::prelude::*;
use serde_json::json;

/// `paper-table1` with its walls replaced by `walls` (point, normal), no damping, the servicer
/// at rest.
fn with_walls(walls: &[([f64; 3], [f64; 3])]) -> Scenario {
    let mut s = preset("paper-table1");
    s.walls = walls
        .iter()
        .map(|(p, n)| serde_json::from_value(json!({"point": p, "normal": n})).unwrap())
        .collect();
    s.contact.damping = 0.0;
    s
}

/// The plan's relative motion at rest, moved so that the servicer's body point `body` sits at
/// `at` (`t`, m).
fn placed(plan: &Plan, body: &Vector3<f64>, at: &Vector3<f64>) -> RelativeMotion {
    let mut rel = plan.system.relative_motion(&plan.initial);
    rel.velocity = Vector3::zeros();
    rel.angular_velocity = Vector3::zeros();
    rel.position += at - rel.point(body);
    rel
}

/// The contact's stiffness along `n` by a central difference of the normal force's component
/// along `n` under a translation of the servicer along `n` (N/m).
fn stiffness_along(plan: &Plan, rel: &RelativeMotion, n: &Vector3<f64>, h: f64) -> f64 {
    let force_at = |s: f64| {
        let mut r = *rel;
        r.position += n * s;
        let c = plan.system.contact_at(&r, 0.0);
        (c.force - c.friction_force).dot(n)
    };
    -(force_at(h) - force_at(-h)) / (2.0 * h)
}

/// The direction of the contact's summed normal force.
fn normal_of(plan: &Plan, rel: &RelativeMotion) -> Vector3<f64> {
    let c = plan.system.contact_at(rel, 0.0);
    (c.force - c.friction_force).normalize()
}

#[test]
fn one_wall_counts_one_law_exactly_and_no_contact_none() {
    let s = with_walls(&[([0.5, 0.0, 0.0], [-1.0, 0.0, 0.0])]);
    let plan = s.resolve().unwrap();
    let rod = plan.system.rod_tip;
    let touching = placed(&plan, &rod, &Vector3::new(0.5004, 0.01, -0.02));
    assert_eq!(plan.system.contact_at(&touching, 0.0).law_factor, 1.0);
    let free = placed(&plan, &rod, &Vector3::new(0.49, 0.0, 0.0));
    assert_eq!(plan.system.contact_at(&free, 0.0).law_factor, 0.0);
}

#[test]
fn a_v_groove_of_two_walls_is_two_cos_squared_as_stiff() {
    // two walls at ±θ from −x: pressed along −x, each penetrates d, the summed normal is −x,
    // and the stiffness along it is 2k·cos²θ
    for theta in [0.1f64, 0.4, 0.7, 1.0] {
        let (c, sn) = (theta.cos(), theta.sin());
        let s = with_walls(&[
            ([0.5, 0.0, 0.0], [-c, sn, 0.0]),
            ([0.5, 0.0, 0.0], [-c, -sn, 0.0]),
        ]);
        let plan = s.resolve().unwrap();
        let rod = plan.system.rod_tip;
        let rel = placed(&plan, &rod, &Vector3::new(0.5003, 0.0, 0.0));
        let contact = plan.system.contact_at(&rel, 0.0);
        let expected = 2.0 * c * c;
        assert!(
            (contact.law_factor - expected).abs() < 1e-12,
            "θ {theta}: {} vs {expected}",
            contact.law_factor
        );
        let n = normal_of(&plan, &rel);
        let k = stiffness_along(&plan, &rel, &n, 1e-6);
        let k_law = plan.scenario.contact.stiffness;
        assert!(
            (k / (contact.law_factor * k_law) - 1.0).abs() < 1e-6,
            "θ {theta}: {k} vs {}",
            contact.law_factor * k_law
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 64,
        ..ProptestConfig::default()
    })]

    /// Two or three walls with random normals (each within 50° of −x) through a common point,
    /// the rod tip pressed into all of them: the finite-difference stiffness of the contact
    /// along its summed normal is `law_factor·k`.
    #[test]
    fn random_corners_are_as_stiff_along_their_normal_as_the_factor_says(
        count in 2usize..4,
        angles in proptest::collection::vec((0.0f64..0.87, -3.2f64..3.2), 3),
        push in (0.0001f64..0.001, 0.0001f64..0.001, 0.0001f64..0.001),
    ) {
        let corner = Vector3::new(0.5, 0.02, -0.01);
        let walls: Vec<([f64; 3], [f64; 3])> = angles[..count]
            .iter()
            .map(|&(tilt, about)| {
                let n = Vector3::new(-tilt.cos(), tilt.sin() * about.cos(), tilt.sin() * about.sin());
                (corner.into(), n.into())
            })
            .collect();
        let plan = with_walls(&walls).resolve().unwrap();
        // the tip a little behind every wall: inside the corner by `push` along each
        // normal's opposite, summed
        let normals: Vec<Vector3<f64>> =
            walls.iter().map(|(_, n)| Vector3::from(*n)).collect();
        let depth = [push.0, push.1, push.2];
        let tip = normals
            .iter()
            .zip(depth)
            .fold(corner, |p, (n, d)| p - n * d);
        let rod = plan.system.rod_tip;
        let rel = placed(&plan, &rod, &tip);
        let contact = plan.system.contact_at(&rel, 0.0);
        let pushing = walls
            .iter()
            .filter(|(p, n)| (Vector3::from(*p) - tip).dot(&Vector3::from(*n)) > 0.0)
            .count();
        prop_assume!(pushing >= 2);
        // every wall's penetration must stay positive over the difference's step
        let least = walls
            .iter()
            .map(|(p, n)| (Vector3::from(*p) - tip).dot(&Vector3::from(*n)))
            .filter(|d| *d > 0.0)
            .fold(f64::INFINITY, f64::min);
        let n = normal_of(&plan, &rel);
        let k = stiffness_along(&plan, &rel, &n, 1e-3 * least);
        let k_law = plan.scenario.contact.stiffness;
        prop_assert!(contact.law_factor > 0.0 && contact.law_factor <= pushing as f64 + 1e-12);
        // the walls' sum is what the measurement finds too
        let measured = plan.system.law_factor_at(&rel, &hilcontact_core::world::Contact {
            law_factor: f64::NAN,
            ..contact
        });
        prop_assert!((measured / contact.law_factor - 1.0).abs() < 1e-6, "{} vs {}", measured, contact.law_factor);
        prop_assert!(
            (k / (contact.law_factor * k_law) - 1.0).abs() < 1e-6,
            "{} walls pushing: {} vs {}", pushing, k, contact.law_factor * k_law
        );
    }
}

/// A shape from its keys.
fn shape(keys: serde_json::Value) -> ShapeConfig {
    serde_json::from_value(keys).expect("a valid shape table")
}

/// `paper-table1` without walls, servicer shapes `servicer` and target shapes `target`, no
/// damping.
fn with_shapes(servicer: Vec<ShapeConfig>, target: Vec<ShapeConfig>) -> Plan {
    let mut s = preset("paper-table1");
    s.walls.clear();
    s.servicer.shapes = servicer;
    s.target.shapes = target;
    s.contact.damping = 0.0;
    // placed apart at the start (the plan refuses interpenetrating shapes)
    s.servicer.position = [0.0, 0.0, 0.0];
    s.target.position = [0.0, 0.0, 0.0];
    s.resolve().unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn a_cube_flat_on_a_plate_is_four_laws_and_a_sphere_in_a_groove_two_cos_squared() {
    // a cube of side a, its −x face pressed flat on a plane: four corners, one normal
    let a = 0.1;
    let plane =
        |p: [f64; 3], n: [f64; 3]| shape(json!({"kind": "half-space", "position": p, "normal": n}));
    let cube = shape(json!({"kind": "box", "size": [a, a, a], "margin": 0.001}));
    let plan = with_shapes(vec![cube], vec![plane([0.2, 0.0, 0.0], [-1.0, 0.0, 0.0])]);
    let mut rel = plan.system.relative_motion(&plan.initial);
    rel.velocity = Vector3::zeros();
    rel.angular_velocity = Vector3::zeros();
    rel.orientation = UnitQuaternion::identity();
    rel.position = Vector3::new(0.2 - 0.5 * a + 0.0004, 0.0, 0.0);
    let contact = plan.system.contact_at(&rel, 0.0);
    assert!(
        contact.law_factor.is_nan(),
        "shapes' points: measured, not summed"
    );
    let factor = plan.system.law_factor_at(&rel, &contact);
    assert!((factor - 4.0).abs() < 1e-6, "cube: {factor}");
    let n = normal_of(&plan, &rel);
    let k = stiffness_along(&plan, &rel, &n, 1e-7);
    let k_law = plan.scenario.contact.stiffness;
    assert!(
        (k / (4.0 * k_law) - 1.0).abs() < 1e-5,
        "cube: {k} vs {}",
        4.0 * k_law
    );

    // a sphere in a groove of two planes at ±θ from −x
    let (r, theta) = (0.05f64, 0.5f64);
    let (c, s) = (theta.cos(), theta.sin());
    let sphere = shape(json!({"kind": "sphere", "radius": r}));
    let plan = with_shapes(
        vec![sphere],
        vec![
            plane([0.3, 0.0, 0.0], [-c, s, 0.0]),
            plane([0.3, 0.0, 0.0], [-c, -s, 0.0]),
        ],
    );
    let mut rel = plan.system.relative_motion(&plan.initial);
    rel.velocity = Vector3::zeros();
    rel.angular_velocity = Vector3::zeros();
    // the centre at distance r − 0.3 mm from both planes, on the groove's axis
    rel.position = Vector3::new(0.3 - (r - 0.0003) / c, 0.0, 0.0);
    let contact = plan.system.contact_at(&rel, 0.0);
    let factor = plan.system.law_factor_at(&rel, &contact);
    assert!(
        (factor - 2.0 * c * c).abs() < 1e-6,
        "groove: {factor} vs {}",
        2.0 * c * c
    );
    let n = normal_of(&plan, &rel);
    let k = stiffness_along(&plan, &rel, &n, 1e-7);
    assert!(
        (k / (2.0 * c * c * k_law) - 1.0).abs() < 1e-5,
        "groove: {k} vs {}",
        2.0 * c * c * k_law
    );
}
