//! Analytic truths (spec anchors.md): two-body collision, conservation laws.

mod common;

use common::{preset, table1};
use hilcontact_core::config::{ContactModelKind, Inertia};
use hilcontact_core::metrics::collisions;
use hilcontact_core::sim::run_reference;
use hilcontact_core::world::{FrameWrench, TwoBodyState, TwoBodySystem};
use hilcontact_core::Scenario;
use nalgebra::Vector3;
use proptest::prelude::*;

/// Table 1 with a fine tick (0.1 ms) so that contact times resolve to 0.1 %.
fn fine(mut s: Scenario) -> Scenario {
    s.simulation.period = 1e-4;
    s.simulation.reference_substeps = 2;
    s.simulation.duration = 1.0;
    s.metrics.contact_threshold = 1e-9;
    s
}

struct Measured {
    contact_time: f64,
    peak_force: f64,
    restitution: f64,
}

/// First collision of the ideal reference.
fn first_collision(s: &Scenario) -> Measured {
    let (trace, _) = run_reference(&s.resolve().unwrap(), false);
    let c = &collisions(&trace, s.metrics.contact_threshold)[0];
    Measured {
        contact_time: c.end - c.start,
        peak_force: c.peak_force,
        restitution: c.rebound_speed.unwrap() / trace.velocity[0].norm(),
    }
}

fn reduced_mass(s: &Scenario) -> f64 {
    s.servicer.mass * s.target.mass / (s.servicer.mass + s.target.mass)
}

fn within(value: f64, expected: f64, rel: f64) -> bool {
    (value / expected - 1.0).abs() <= rel
}

#[test]
fn undamped_collision_matches_analytic_two_body_solution() {
    let s = fine(table1(0.0, 0.0));
    let (mu, k, v0) = (reduced_mass(&s), s.contact.stiffness, 0.02);
    let m = first_collision(&s);
    let t_c = std::f64::consts::PI * (mu / k).sqrt();
    let f_max = v0 * (mu * k).sqrt();
    assert!(
        within(m.contact_time, t_c, 0.01),
        "contact time {} vs {}",
        m.contact_time,
        t_c
    );
    assert!(
        within(m.peak_force, f_max, 0.01),
        "peak {} vs {}",
        m.peak_force,
        f_max
    );
    assert!(
        within(m.restitution, 1.0, 0.001),
        "restitution {}",
        m.restitution
    );
    // and the paper's numbers: 4 Hz contact, 140.3 N
    assert!(within(1.0 / (2.0 * t_c), 4.0, 0.001));
    assert!(within(m.peak_force, 140.28, 0.001));
}

/// The damped linear contact in closed form: `x(t) = v0/ω_d e^{−ζωt} sin ω_d t`, with the
/// no-pull clamp ending the contact where `k x + c ẋ = 0`. Returns (contact time, peak force, rebound).
fn damped_closed_form(mu: f64, k: f64, c: f64, v0: f64) -> (f64, f64, f64) {
    let w = (k / mu).sqrt();
    let zeta = c / (2.0 * (mu * k).sqrt());
    let wd = w * (1.0 - zeta * zeta).sqrt();
    let x = |t: f64| v0 / wd * (-zeta * w * t).exp() * (wd * t).sin();
    let xd =
        |t: f64| v0 * (-zeta * w * t).exp() * ((wd * t).cos() - zeta * w / wd * (wd * t).sin());
    let force = |t: f64| k * x(t) + c * xd(t);
    let (mut t, dt, mut peak) = (0.0, 1e-7, 0.0f64);
    while force(t + dt) > 0.0 {
        t += dt;
        peak = peak.max(force(t));
    }
    (t, peak, -xd(t))
}

#[test]
fn damped_collision_matches_closed_form_and_restitution_formula() {
    for damping in [130.0, 500.0] {
        let mut s = fine(table1(0.0, 0.0));
        s.contact.damping = damping;
        let (mu, k, v0) = (reduced_mass(&s), s.contact.stiffness, 0.02);
        let (t_c, f_max, v_out) = damped_closed_form(mu, k, damping, v0);
        let m = first_collision(&s);
        assert!(
            within(m.contact_time, t_c, 0.01),
            "c={damping}: contact time {} vs {}",
            m.contact_time,
            t_c
        );
        assert!(
            within(m.peak_force, f_max, 0.01),
            "c={damping}: peak {} vs {}",
            m.peak_force,
            f_max
        );
        assert!(
            within(m.restitution, v_out / v0, 0.01),
            "c={damping}: restitution {} vs {}",
            m.restitution,
            v_out / v0
        );
        // light damping: the textbook restitution exp(−ζπ/√(1−ζ²)) within 1 %
        let zeta = damping / (2.0 * (mu * k).sqrt());
        let e = (-zeta * std::f64::consts::PI / (1.0 - zeta * zeta).sqrt()).exp();
        assert!(
            within(m.restitution, e, 0.01),
            "c={damping}: restitution {} vs formula {}",
            m.restitution,
            e
        );
        assert!(m.restitution < 0.999, "damping must dissipate");
    }
}

#[test]
fn hunt_crossley_collision_matches_energy_balance() {
    let mut s = fine(table1(0.0, 0.0));
    s.contact.model = ContactModelKind::HuntCrossley;
    s.contact.exponent = 1.5;
    s.contact.stiffness = 5.0e7; // N/m^1.5
    let (mu, k, n, v0) = (reduced_mass(&s), s.contact.stiffness, 1.5, 0.02);
    // ½ μ v0² = k d^(n+1)/(n+1)  →  peak force k d^n
    let d_max = (0.5 * mu * v0 * v0 * (n + 1.0) / k).powf(1.0 / (n + 1.0));
    let m = first_collision(&s);
    assert!(
        within(m.peak_force, k * d_max.powf(n), 0.01),
        "peak {} vs {}",
        m.peak_force,
        k * d_max.powf(n)
    );
    assert!(
        within(m.restitution, 1.0, 0.002),
        "restitution {}",
        m.restitution
    );
}

/// Reference collisions (rebound speed, peak force) of a scenario at a number of RK4 substeps.
fn reference_collisions(s: &Scenario, substeps: u32) -> Vec<(f64, f64)> {
    let mut s = s.clone();
    s.simulation.reference_substeps = substeps;
    let (trace, _) = run_reference(&s.resolve().unwrap(), false);
    collisions(&trace, s.metrics.contact_threshold)
        .iter()
        .map(|c| (c.rebound_speed.unwrap_or(f64::NAN), c.peak_force))
        .collect()
}

#[test]
fn reference_locates_contact_start_and_end_so_one_substep_is_as_good_as_a_hundred() {
    // Damped contacts jump at their start (c·ḋ) and kink at their end; without locating these,
    // one RK4 step per millisecond is off by ~1e-4 in rebound speed (8e-5 on 2.64 Hz). Hunt-
    // Crossley (only C¹ at contact start: 2e-6 here) and the
    // oblique, spinning case too.
    let mut hunt = table1(0.0, 0.0);
    hunt.contact.model = ContactModelKind::HuntCrossley;
    hunt.contact.exponent = 1.5;
    hunt.contact.stiffness = 5.0e7;
    hunt.contact.damping = 2.0e7;
    for (name, s) in [
        ("2.64 Hz damped", preset("paper-exp-2.64hz")),
        ("Hunt-Crossley", hunt),
        ("oblique", preset("oblique-6dof")),
    ] {
        let coarse = reference_collisions(&s, 1);
        let fine = reference_collisions(&s, 100);
        assert!(
            coarse.len() >= 2 && coarse.len() == fine.len(),
            "{name}: {} vs {} collisions",
            coarse.len(),
            fine.len()
        );
        for ((v1, f1), (v100, f100)) in coarse.iter().zip(&fine) {
            assert!(within(*v1, *v100, 1e-5), "{name}: rebound {v1} vs {v100}");
            assert!(within(*f1, *f100, 1e-5), "{name}: peak {f1} vs {f100}");
        }
    }
}

#[test]
fn reference_free_flight_step_matches_fine_rk4() {
    // one force-free step per period while clear of the walls: same motion as RK4 at 0.1 ms
    let s = tumbling();
    let system = s.resolve().unwrap().system;
    let (mut x, mut y) = (s.resolve().unwrap().initial, s.resolve().unwrap().initial);
    for _ in 0..5_000 {
        system.step_reference(&mut x, 1e-3, 1);
        for _ in 0..10 {
            system.step_rk4(&mut y, 1e-4);
        }
    }
    assert!((x.servicer.position - y.servicer.position).norm() < 1e-9);
    assert!(x.servicer.orientation.angle_to(&y.servicer.orientation) < 1e-9);
    assert!(x.target.orientation.angle_to(&y.target.orientation) < 1e-9);
    assert!((x.servicer.angular_velocity - y.servicer.angular_velocity).norm() < 1e-9);
}

/// A tumbling two-body system far from any wall, with full inertia tensors.
fn tumbling() -> Scenario {
    let mut s = preset("oblique-6dof");
    s.servicer.angular_velocity = [0.05, -0.03, 0.08];
    s.target.angular_velocity = [-0.02, 0.04, 0.01];
    s.target.inertia = Inertia::Tensor([
        [3684.0, 50.0, -20.0],
        [50.0, 3200.0, 10.0],
        [-20.0, 10.0, 4100.0],
    ]);
    for w in &mut s.walls {
        w.point[0] *= 1000.0; // 10 m away: no contact
    }
    s
}

fn assert_conserved(
    system: &TwoBodySystem,
    x0: &TwoBodyState,
    x: &TwoBodyState,
    tol: f64,
    with_potential: bool,
) {
    let e = |x: &TwoBodyState| {
        system.energy(x)
            + if with_potential {
                system.contact_potential_energy(x)
            } else {
                0.0
            }
    };
    let (p0, l0) = (system.linear_momentum(x0), system.angular_momentum(x0));
    assert!(
        (system.linear_momentum(x) - p0).norm() <= tol * p0.norm().max(1e-3),
        "momentum"
    );
    assert!(
        (system.angular_momentum(x) - l0).norm() <= tol * l0.norm().max(1e-3),
        "angular momentum"
    );
    assert!(
        (e(x) / e(x0) - 1.0).abs() <= tol,
        "energy {} vs {}",
        e(x),
        e(x0)
    );
}

/// The admittance-type compensators' velocity correction is an impulse at the rod tip: it
/// changes the tip's relative velocity by exactly `K·J` (the mobility), the kinetic energy by
/// exactly `J·(u + K·J/2)`, and neither momentum nor angular momentum; `correct_tip_velocity`
/// makes exactly the velocity change it is asked for. Checked on a tumbling pair whose target
/// is turned, so that the world and `t` frames differ.
#[test]
fn an_impulse_at_the_rod_tip_moves_it_by_its_mobility_and_conserves_momentum() {
    let plan = tumbling().resolve().unwrap();
    let system = &plan.system;
    let mut x0 = plan.initial;
    x0.target.orientation =
        nalgebra::UnitQuaternion::from_euler_angles(0.3, -0.2, 0.7) * x0.target.orientation;
    x0.servicer.orientation =
        nalgebra::UnitQuaternion::from_euler_angles(-0.1, 0.4, 0.2) * x0.servicer.orientation;
    let tip = |x: &TwoBodyState| system.relative_motion(x).point_velocity(&system.rod_tip);
    let k = system.tip_mobility(&x0);
    assert!((k - k.transpose()).norm() < 1e-12 * k.norm(), "K symmetric");
    assert!(k.cholesky().is_some(), "K positive definite");
    // larger than the reduced mass's 1/μ along every axis: the bodies also turn
    let mu = system.reduced_mass();
    assert!((0..3).all(|i| k[(i, i)] >= 1.0 / mu));
    let j = Vector3::new(3.0, -1.0, 2.0);
    let mut x = x0;
    system.apply_tip_impulse(&mut x, &j);
    let (u0, u1) = (tip(&x0), tip(&x));
    assert!(
        ((u1 - u0) - k * j).norm() < 1e-12,
        "{:?} vs {:?}",
        u1 - u0,
        k * j
    );
    let de = system.energy(&x) - system.energy(&x0);
    let expected = j.dot(&(u0 + k * j * 0.5));
    assert!((de - expected).abs() < 1e-12, "{de} vs {expected}");
    assert!((system.linear_momentum(&x) - system.linear_momentum(&x0)).norm() < 1e-12);
    assert!((system.angular_momentum(&x) - system.angular_momentum(&x0)).norm() < 1e-9);
    let dv = Vector3::new(-1e-3, 2e-4, 5e-4);
    let mut y = x0;
    system.correct_tip_velocity(&mut y, &dv);
    assert!((tip(&y) - tip(&x0) - dv).norm() < 1e-12);
}

#[test]
fn free_flight_conserves_momentum_angular_momentum_and_energy() {
    let s = tumbling();
    let system = s.resolve().unwrap().system;
    let x0 = s.resolve().unwrap().initial;
    // RK4 (the reference integrator)
    let mut x = x0;
    for _ in 0..50_000 {
        system.step_rk4(&mut x, 1e-4);
    }
    assert_conserved(&system, &x0, &x, 1e-9, false);
    // the virtual dynamics of the HIL loop, with no wrench
    let mut y = x0;
    for _ in 0..5_000 {
        system.step_virtual(&mut y, &FrameWrench::default(), 1e-3);
    }
    assert_conserved(&system, &x0, &y, 1e-7, false);
    // and the two integrators agree on where the bodies went
    assert!((x.servicer.position - y.servicer.position).norm() < 1e-6);
    assert!(x.servicer.orientation.angle_to(&y.servicer.orientation) < 1e-5);
}

#[test]
fn contact_is_internal_reference_conserves_momentum_and_total_energy() {
    // the oblique case: contact forces and moments on both bodies
    let s = preset("oblique-6dof");
    let system = s.resolve().unwrap().system;
    let x0 = s.resolve().unwrap().initial;
    let mut x = x0;
    let mut max_moment = 0.0f64;
    for _ in 0..40_000 {
        system.step_rk4(&mut x, 1e-4);
        let c = system.contact(&x);
        max_moment = max_moment.max(c.tip.cross(&c.force).norm());
    }
    assert!(
        max_moment > 1.0,
        "the oblique preset must produce moments, got {max_moment}"
    );
    assert!(
        (x.servicer.angular_velocity - x0.servicer.angular_velocity).norm() > 1e-4,
        "and rotation"
    );
    assert_conserved(&system, &x0, &x, 1e-6, true);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Any wrench applied by the virtual dynamics is internal: momentum and angular momentum
    /// of the pair are conserved for any state and wrench.
    #[test]
    fn virtual_dynamics_wrench_is_internal(
        f in prop::array::uniform3(-500.0f64..500.0),
        m in prop::array::uniform3(-50.0f64..50.0),
        w in prop::array::uniform3(-0.2f64..0.2),
        q in prop::array::uniform4(-1.0f64..1.0),
    ) {
        let mut s = tumbling();
        s.servicer.angular_velocity = w;
        prop_assume!(q.iter().map(|x| x * x).sum::<f64>() > 0.1);
        s.target.orientation = q;
        let system = s.resolve().unwrap().system;
        let x0 = s.resolve().unwrap().initial;
        let mut x = x0;
        let wrench = FrameWrench { force: Vector3::from(f), moment: Vector3::from(m) };
        for _ in 0..20 {
            system.step_virtual(&mut x, &wrench, 1e-3);
        }
        let dp = (system.linear_momentum(&x) - system.linear_momentum(&x0)).norm();
        // angular momentum about the world origin: the pair exchanges only internal wrenches.
        // The attitude update is second order, so allow 1e-4 of the angular impulse applied
        // (a wrong sign or lever arm would change it by the whole impulse).
        let dl = (system.angular_momentum(&x) - system.angular_momentum(&x0)).norm();
        let impulse = 20.0 * 1e-3 * (wrench.moment.norm() + 2.0 * wrench.force.norm());
        prop_assert!(dp < 1e-9, "momentum changed by {}", dp);
        prop_assert!(dl < 1e-4 * impulse, "angular momentum changed by {} (impulse {})", dl, impulse);
    }
}
