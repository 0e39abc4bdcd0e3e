//! Contact episodes (docs/model.md "Metrics"): the normal and tangential impulse of each
//! collision against analytic truths (a point mass sliding on a plane, a point mass into a
//! corner of two walls), their errors against the reference (0, not NaN, without friction),
//! and the HIL loop without delay reproducing the reference's episodes.

mod common;

use common::preset;
use hilcontact_core::config::Inertia;
use hilcontact_core::contact::{FrictionConfig, WallConfig};
use hilcontact_core::metrics::{Collision, ComparedCollision};
use hilcontact_core::sim::{run_reference, simulate};
use hilcontact_core::stop::Status;
use hilcontact_core::Scenario;
use nalgebra::Vector3;

fn friction(mu: f64) -> FrictionConfig {
    FrictionConfig {
        static_coefficient: mu,
        kinetic_coefficient: mu,
        stick_velocity: 1e-4,
        stribeck_velocity: 5e-3,
        ..FrictionConfig::default()
    }
}

/// A point mass of 300 kg (the rod tip at the servicer's centre of mass: friction has no
/// lever) against a target so heavy that it does not move, starting 1 mm from the front wall
/// of `paper-table1` (normal −x) with velocity `v`; no delay, 0.1 ms period.
fn point_mass(v: [f64; 3], damping: f64, mu: f64) -> Scenario {
    let mut s = preset("paper-table1");
    s.rod.tip = [0.0, 0.0, 0.0];
    s.servicer.position = [0.010 - 0.001, 0.0, 0.0];
    s.servicer.velocity = v;
    s.target.mass = 1e7;
    s.target.inertia = Inertia::Principal([1e7; 3]);
    s.contact.damping = damping;
    s.contact.friction = if mu > 0.0 {
        friction(mu)
    } else {
        FrictionConfig::default()
    };
    s.simulation.duration = 0.3;
    s.simulation.period = 1e-4;
    s.simulation.reference_substeps = 4;
    s.facility.robot_delay = 0.0;
    s
}

/// The servicer's velocity change over the reference run, m/s (`t`: the target does not move).
fn velocity_change(s: &Scenario) -> Vector3<f64> {
    let plan = s.resolve().unwrap_or_else(|e| panic!("{e}"));
    let (trace, _) = run_reference(&plan, false);
    trace.velocity.last().unwrap() - trace.velocity[0]
}

fn only(collisions: &[Collision]) -> &Collision {
    assert_eq!(collisions.len(), 1, "{collisions:?}");
    assert!(collisions[0].complete);
    &collisions[0]
}

fn compared(c: &ComparedCollision) -> [f64; 4] {
    [
        c.velocity_error.unwrap(),
        c.direction_error.unwrap(),
        c.normal_impulse_error.unwrap(),
        c.tangential_impulse_error.unwrap(),
    ]
}

#[test]
fn a_sliding_point_mass_gets_mu_times_its_normal_impulse_tangentially() {
    let (m, v_n, v_t) = (300.0, 0.02, 0.03);
    for (mu, c) in [(0.1, 300.0), (0.2, 0.0), (0.3, 300.0)] {
        // sliding all through: μ(1+e)v_n < v_t
        let s = point_mass([v_n, v_t, 0.0], c, mu);
        let out = simulate(&s).unwrap();
        let r = only(&out.metrics.reference_collisions);
        // Coulomb's μ·F_n, regularised: μ·F_n·s/√(s² + v_ε²), s ≥ 19 mm/s ≫ v_ε = 0.1 mm/s
        assert!(
            (r.tangential_impulse / r.normal_impulse - mu).abs() < 1e-4 * mu,
            "μ {mu}: J_t {} J_n {}",
            r.tangential_impulse,
            r.normal_impulse
        );
        // the impulses are the momentum the contact gave the mass, normal and tangential
        let dv = velocity_change(&s);
        let (j_n, j_t) = (m * dv.x.abs(), m * dv.y.abs());
        assert!(
            (r.normal_impulse / j_n - 1.0).abs() < 2e-3,
            "μ {mu}: J_n {} vs m·Δv_n {j_n}",
            r.normal_impulse
        );
        assert!(
            (r.tangential_impulse / j_t - 1.0).abs() < 2e-3,
            "μ {mu}: J_t {} vs m·Δv_t {j_t}",
            r.tangential_impulse
        );
        // no delay: the HIL episode is the reference's
        let h = &out.metrics.collisions[0];
        let [v_err, dir, jn_err, jt_err] = compared(h);
        assert!(v_err < 1e-3 && dir < 0.06, "μ {mu}: {:?}", compared(h));
        assert!(jn_err < 1e-3 && jt_err < 1e-3, "μ {mu}: {:?}", compared(h));
        assert_eq!(
            out.metrics.status,
            Status::Ok,
            "{:?}",
            out.metrics.violations
        );
    }
}

#[test]
fn a_frictionless_episode_has_no_tangential_impulse_and_its_error_is_zero() {
    let out = simulate(&point_mass([0.02, 0.03, 0.0], 300.0, 0.0)).unwrap();
    let r = only(&out.metrics.reference_collisions);
    assert_eq!(r.tangential_impulse, 0.0);
    let h = &out.metrics.collisions[0];
    assert_eq!(h.collision.tangential_impulse, 0.0);
    assert_eq!(h.tangential_impulse_error, Some(0.0));
    assert_eq!(out.metrics.summary.worst_tangential_impulse_error, 0.0);
    // oblique-6dof without friction, no delay: every episode compared, errors 0 not NaN
    let mut s = preset("oblique-6dof");
    s.facility.robot_delay = 0.0;
    let out = simulate(&s).unwrap();
    assert!(out.metrics.collisions.len() >= 2);
    for c in &out.metrics.collisions {
        assert_eq!(c.tangential_impulse_error, Some(0.0), "{c:?}");
        assert!(c.normal_impulse_error.unwrap() < 1e-3, "{c:?}");
        assert!(c.direction_error.unwrap() < 0.06, "{c:?}");
        assert!(c.collision.peak_moment > 0.0);
        assert!((c.peak_moment_ratio.unwrap() - 1.0).abs() < 1e-3, "{c:?}");
    }
}

#[test]
fn a_point_mass_into_a_corner_is_one_episode_pushed_by_both_walls() {
    // the front wall (normal −x) and a side wall (normal −y), both 1 mm ahead of the tip
    let m = 300.0;
    let mut s = point_mass([0.02, 0.01, 0.0], 300.0, 0.0);
    s.servicer.position = [0.009, 0.009, 0.0];
    s.walls = vec![
        WallConfig {
            name: "front".into(),
            point: [0.010, 0.0, 0.0],
            normal: [-1.0, 0.0, 0.0],
        },
        WallConfig {
            name: "side".into(),
            point: [0.0, 0.010, 0.0],
            normal: [0.0, -1.0, 0.0],
        },
    ];
    let out = simulate(&s).unwrap();
    let r = only(&out.metrics.reference_collisions);
    let dv = velocity_change(&s);
    // both walls pushed: the velocity turned back along x and y in one episode
    assert!(dv.x < -0.03 && dv.y < -0.015, "{dv:?}");
    assert!(
        (r.normal_impulse / (m * dv.norm()) - 1.0).abs() < 2e-3,
        "J_n {} vs m|Δv| {}",
        r.normal_impulse,
        m * dv.norm()
    );
    assert_eq!(r.tangential_impulse, 0.0);
    assert_eq!(out.metrics.collisions.len(), 1);
    let [v_err, dir, jn_err, jt_err] = compared(&out.metrics.collisions[0]);
    assert!(v_err < 1e-3 && dir < 0.06 && jn_err < 1e-3 && jt_err == 0.0);
    // with friction the corner's two walls each rub along the other's normal
    let mut rough = s.clone();
    rough.servicer.velocity = [0.02, 0.01, 0.005];
    rough.contact.friction = friction(0.2);
    let out = simulate(&rough).unwrap();
    let r = only(&out.metrics.reference_collisions);
    assert!(r.tangential_impulse > 0.05 * r.normal_impulse, "{r:?}");
    let [v_err, _, jn_err, jt_err] = compared(&out.metrics.collisions[0]);
    assert!(v_err < 1e-3 && jn_err < 1e-3 && jt_err < 1e-3);
}
