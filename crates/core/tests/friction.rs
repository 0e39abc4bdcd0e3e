//! Coulomb friction (`[contact.friction]`): analytic truths of an oblique impact, the energy
//! it dissipates, the conservation laws, and the HIL loop without delay against the reference.

mod common;

use common::{oblique_6dof, preset};
use hilcontact_core::contact::FrictionConfig;
use hilcontact_core::sim::{run_reference, simulate};
use hilcontact_core::stop::Status;
use hilcontact_core::Scenario;
use nalgebra::Vector3;
use proptest::prelude::*;

fn friction(mu_s: f64, mu_k: f64, stick_velocity: f64) -> FrictionConfig {
    FrictionConfig {
        static_coefficient: mu_s,
        kinetic_coefficient: mu_k,
        stick_velocity,
        stribeck_velocity: 5e-3,
        ..FrictionConfig::default()
    }
}

/// A point mass (the rod tip at the servicer's centre of mass, so friction has no lever) of
/// 300 kg hitting the front wall of `paper-table1` (normal −x) at `v_n` with a tangential
/// velocity `v_t` along y; the target is so heavy that it does not move. One contact.
fn point_mass(v_n: f64, v_t: f64, damping: f64, friction: Option<FrictionConfig>) -> Scenario {
    let friction = friction.unwrap_or_default();
    let mut s = preset("paper-table1");
    s.rod.tip = [0.0, 0.0, 0.0];
    s.servicer.position = [0.010 - 0.001, 0.0, 0.0];
    s.servicer.velocity = [v_n, v_t, 0.0];
    s.target.mass = 1e7;
    s.target.inertia = hilcontact_core::config::Inertia::Principal([1e7; 3]);
    s.contact.damping = damping;
    s.contact.friction = friction;
    s.simulation.duration = 0.2;
    s.simulation.period = 1e-4;
    s.simulation.reference_substeps = 4;
    s.facility.robot_delay = 0.0;
    s
}

/// The servicer's velocity (world = `t`, the target does not move) at the end of the reference.
fn final_velocity(s: &Scenario) -> Vector3<f64> {
    let plan = s.resolve().unwrap_or_else(|e| panic!("{e}"));
    let (trace, _) = run_reference(&plan, false);
    *trace.velocity.last().unwrap()
}

#[test]
fn sliding_impact_loses_mu_times_one_plus_e_times_normal_speed() {
    let (v_n, v_t, c) = (0.02, 0.03, 300.0);
    // the restitution of the same contact without friction
    let e = final_velocity(&point_mass(v_n, v_t, c, None)).x.abs() / v_n;
    assert!(e > 0.8 && e < 1.0, "restitution {e}");
    for mu in [0.1, 0.2, 0.3] {
        let v = final_velocity(&point_mass(v_n, v_t, c, Some(friction(mu, mu, 1e-4))));
        let expected = mu * (1.0 + e) * v_n;
        assert!(v_t - v.y > 0.0, "friction slows the sliding");
        assert!(
            ((v_t - v.y) / expected - 1.0).abs() < 0.01,
            "μ = {mu}: Δv_t {} vs μ(1+e)|v_n| = {expected}",
            v_t - v.y
        );
        // the normal rebound is friction's business only through the law: unchanged
        assert!((v.x.abs() / v_n - e).abs() < 1e-6, "normal rebound {}", v.x);
        assert!(v.z.abs() < 1e-12);
    }
}

#[test]
fn below_the_friction_cone_the_contact_sticks() {
    let (v_n, c, mu) = (0.02, 300.0, 0.3);
    let e = final_velocity(&point_mass(v_n, 0.0, c, None)).x.abs() / v_n;
    // the friction cone: the normal impulse could stop a tangential speed of μ(1+e)|v_n|
    let cone = mu * (1.0 + e) * v_n;
    for v_t in [0.1 * cone, 0.5 * cone, 0.8 * cone] {
        let v = final_velocity(&point_mass(v_n, v_t, c, Some(friction(mu, mu, 1e-4))));
        assert!(
            v.y.abs() < 0.02 * v_t,
            "v_t {v_t}: left sliding at {} (sticking leaves at most creep)",
            v.y
        );
        assert!(
            v.y > -1e-4 * v_t,
            "friction never reverses the sliding: {}",
            v.y
        );
    }
    // and just above the cone it slides out with what the cone leaves
    let v_t = 1.5 * cone;
    let v = final_velocity(&point_mass(v_n, v_t, c, Some(friction(mu, mu, 1e-4))));
    assert!(
        ((v_t - v.y) / cone - 1.0).abs() < 0.02,
        "{} vs {cone}",
        v_t - v.y
    );
}

#[test]
fn a_static_peak_takes_more_at_low_sliding_speed_only() {
    // μ_s > μ_k matters where the sliding speed is within the Stribeck velocity
    let (v_n, c) = (0.02, 300.0);
    let fast = |mu_s| final_velocity(&point_mass(v_n, 0.05, c, Some(friction(mu_s, 0.1, 1e-4))));
    let (plain, peaked) = (fast(0.1), fast(0.3));
    assert!(
        (plain.y - peaked.y).abs() < 1e-3 * 0.05,
        "fast sliding: μ_k alone ({} vs {})",
        plain.y,
        peaked.y
    );
    let slow = |mu_s| final_velocity(&point_mass(v_n, 0.006, c, Some(friction(mu_s, 0.1, 1e-4))));
    assert!(
        slow(0.3).y < slow(0.1).y,
        "the static peak slows a slow slide more"
    );
}

#[test]
fn friction_dissipates_exactly_what_the_energy_lost_in_an_elastic_contact() {
    // undamped law: every joule lost is friction's, and the reference books it
    for (v_t, mu) in [(0.03, 0.2), (0.004, 0.3), (0.01, 0.15)] {
        let s = point_mass(0.02, v_t, 0.0, Some(friction(mu, mu, 1e-3)));
        let out = simulate(&s).unwrap();
        let e = &out.metrics.energy;
        let lost = e.initial - e.reference_final;
        assert!(lost > 0.0);
        assert!(
            (e.reference_friction_work / lost - 1.0).abs() < 1e-4,
            "v_t {v_t}: friction work {} vs energy lost {lost}",
            e.reference_friction_work
        );
        let column = out.reference.column("friction_work").unwrap();
        assert_eq!(*column.last().unwrap(), e.reference_friction_work);
        assert!(
            column.windows(2).all(|w| w[1] >= w[0]),
            "never negative work"
        );
    }
    // without friction it books nothing
    let out = simulate(&point_mass(0.02, 0.03, 300.0, None)).unwrap();
    assert_eq!(out.metrics.energy.reference_friction_work, 0.0);
}

/// `oblique-6dof` with friction: random spins, drift, tilt and offset.
fn frictional_6dof(case: Scenario, mu: f64) -> Scenario {
    let mut s = case;
    s.contact.friction = friction(mu * 1.2, mu, 1e-3);
    s.facility.robot_delay = 0.0;
    s.facility.sensor_delay = 0.0;
    s.facility.sensor_noise = 0.0;
    s.facility.torque_noise = 0.0;
    s
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 8, ..ProptestConfig::default() })]

    #[test]
    fn momentum_of_the_pair_is_conserved_through_frictional_contact(
        case in common::oblique_6dof_cases(0.03, 0.003, 0.5, 0.2),
        mu in 0.05..0.4f64,
    ) {
        let s = frictional_6dof(case, mu);
        let plan = s.resolve().unwrap();
        let system = &plan.system;
        let mut x = plan.initial;
        let (p0, l0) = (system.linear_momentum(&x), system.angular_momentum(&x));
        let mut work = 0.0;
        for _ in 0..plan.ticks {
            work += system.step_reference(&mut x, plan.period, plan.reference_substeps);
        }
        prop_assert!(work >= 0.0, "friction never does positive work");
        let (p1, l1) = (system.linear_momentum(&x), system.angular_momentum(&x));
        prop_assert!((p1 - p0).norm() <= 1e-9 * (1.0 + p0.norm()), "p {p0} → {p1}");
        prop_assert!((l1 - l0).norm() <= 1e-7 * (1.0 + l0.norm()), "L {l0} → {l1}");
    }

    /// The loop holds the measured force over a period (zero-order hold): a force that
    /// depends on velocity (damping, friction) is therefore reproduced to first order in the
    /// period (`without_delay_friction_converges_to_the_reference_at_first_order`), and in
    /// proportion to μ: the first collision within max(1e-3, 1.2e-2·μ) at 0.25 ms (later ones
    /// carry the earlier ones' error), where a frictionless contact is within 1e-5 at 1 ms.
    /// (Drawn cases showed 2.17e-3 at μ = 0.28 and 3.09e-3 at μ = 0.388: 7.8e-3·μ and 8.0e-3·μ,
    /// so the bound leaves 1.5 times the worst seen; a fixed 3e-3 failed the second.)
    #[test]
    fn without_delay_the_loop_reproduces_a_frictional_reference_at_a_quarter_millisecond(
        case in common::oblique_6dof_cases(0.03, 0.003, 0.5, 0.2),
        mu in 0.05..0.4f64,
    ) {
        let mut s = frictional_6dof(case, mu);
        s.simulation.period = 2.5e-4;
        let m = simulate(&s).unwrap().metrics;
        // a tilted wall may turn the rod past it: only cases that touch say anything
        prop_assume!(!m.reference_collisions.is_empty());
        prop_assert!(m.lost_collisions.is_empty() && m.extra_collisions.is_empty());
        prop_assert_eq!(m.status, Status::Ok, "{:?}", m.violations);
        // (a contact still going at the end of the run has no rebound to compare); a later
        // collision also carries what the earlier ones left
        for (i, c) in m.collisions.iter().enumerate() {
            let first = (1.2e-2 * mu).max(1e-3);
            let bound = if i == 0 { first } else { 5e-3f64.max(2.0 * first) };
            if let Some(e) = c.velocity_error {
                prop_assert!(e <= bound, "collision {}: velocity error {}", c.collision.index, e);
            }
        }
    }
}

#[test]
fn without_delay_friction_converges_to_the_reference_at_first_order() {
    // the worst rebound velocity error at 1, 0.5 and 0.25 ms: halves with the period (the
    // same holds for a damped contact without friction: a velocity-dependent force held over a
    // period), while a frictionless undamped contact stays below 1e-5 at every period
    let worst = |period: f64, mu: f64| {
        let mut s = frictional_6dof(
            oblique_6dof(
                ([0.01, 0.02, -0.015], [0.005, -0.01, 0.02]),
                [0.001, -0.002, 0.0005],
                [0.3, 0.2],
                [0.1, -0.1],
            ),
            mu,
        );
        if mu == 0.0 {
            s.contact.friction = FrictionConfig::default();
        }
        s.simulation.period = period;
        let m = simulate(&s).unwrap().metrics;
        assert!(m.lost_collisions.is_empty() && m.extra_collisions.is_empty());
        m.collisions
            .iter()
            .map(|c| c.velocity_error.unwrap())
            .fold(0.0, f64::max)
    };
    let errors: Vec<f64> = [1e-3, 5e-4, 2.5e-4]
        .iter()
        .map(|&t| worst(t, 0.1))
        .collect();
    assert!(errors[0] < 5e-3, "{errors:?}");
    for pair in errors.windows(2) {
        let ratio = pair[0] / pair[1];
        assert!((1.7..2.3).contains(&ratio), "first order: {errors:?}");
    }
    assert!(errors[2] < 1e-3, "{errors:?}");
    assert!(worst(1e-3, 0.0) < 1e-5);
}

#[test]
fn a_frictional_oblique_impact_turns_the_rebound() {
    // the rebound direction with friction differs from the frictionless one, toward the normal
    let base = oblique_6dof(([0.0; 3], [0.0; 3]), [0.0; 3], [0.4, 0.0], [0.0, 0.0]);
    let run = |mu: Option<f64>| {
        let mut s = base.clone();
        s.contact.friction = mu.map_or_else(FrictionConfig::default, |mu| friction(mu, mu, 1e-3));
        s.facility.robot_delay = 0.0;
        simulate(&s).unwrap().metrics
    };
    let (free, rough) = (run(None), run(Some(0.3)));
    let c0 = &free.reference_collisions[0];
    let c1 = &rough.reference_collisions[0];
    assert!(rough.energy.reference_friction_work > 0.0);
    assert!(
        c1.peak_force > 0.0 && c0.peak_force > 0.0,
        "both runs touch the front wall"
    );
    assert!(
        rough.energy.reference_final < free.energy.reference_final,
        "friction takes energy out: {} vs {}",
        rough.energy.reference_final,
        free.energy.reference_final
    );
}

#[test]
fn a_static_coefficient_below_the_kinetic_one_is_refused_naming_the_key() {
    let mut s = preset("paper-table1");
    s.contact.friction = friction(0.1, 0.2, 1e-3);
    let err = s.resolve().unwrap_err().to_string();
    assert!(err.contains("contact.friction.static"), "{err}");
}
