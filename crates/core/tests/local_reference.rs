//! The local (restarted) reference of each HIL collision (docs/model.md "Metrics",
//! `metrics::local_comparison`): the ideal reference run again from the virtual state just
//! before each collision, so that each contact is read on its own.

mod common;

use common::preset as preset_file;

/// A preset with the local references asked for (`metrics.local_references`, off by default).
fn preset(name: &str) -> Scenario {
    let mut s = preset_file(name);
    s.metrics.local_references = true;
    s
}
use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_core::compensator::PriorShapes;
use hilcontact_core::compensator::Rendering;
use hilcontact_core::sim::{
    run_hil, run_metrics, run_reference, run_reference_from, simulate_plan, trace_metrics,
};
use hilcontact_core::{Scenario, SimulationOutput};

/// Every collision's global and local errors, one line each.
fn show(label: &str, out: &SimulationOutput) {
    let pct = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{:.3}", 100.0 * x));
    let num = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.4}"));
    for c in &out.metrics.collisions {
        println!(
            "{label} #{} start {:.3} restart {}: v err {} % / local {} %, CoF {} / local {}, \
             J_t err {} % / local {} %, J_n err {} % / local {} %",
            c.collision.index,
            c.collision.start,
            num(c.local_start),
            pct(c.velocity_error),
            pct(c.local_velocity_error),
            num(c.cof),
            num(c.local_cof),
            pct(c.tangential_impulse_error),
            pct(c.local_tangential_impulse_error),
            pct(c.normal_impulse_error),
            pct(c.local_normal_impulse_error),
        );
    }
    let s = &out.metrics.summary;
    println!(
        "{label}: worst local (from judge_from {}): v err {:.3} %, CoF {:.4}, J_t err {:.3} %, \
         J_n err {:.3} %",
        out.metrics.tolerances.judge_from,
        100.0 * s.worst_local_velocity_error,
        s.worst_local_cof,
        100.0 * s.worst_local_tangential_impulse_error,
        100.0 * s.worst_local_normal_impulse_error,
    );
}

/// A preset at zero delay (robot, sensor; no noise) with its own compensator.
fn zero_delay(name: &str) -> Scenario {
    let mut s = preset(name);
    s.facility.robot_delay = 0.0;
    s.facility.sensor_delay = 0.0;
    s.facility.sensor_noise = 0.0;
    s
}

/// `rod-in-frame` with 0.2 N noise and a 5 ms sensor delay, `model-mediated` at `robot_delay`
/// with the scenario's shapes as its prior geometry (`prior_shapes = "geometry"`): the first
/// contact `pida`'s (the law unknown), every later one the model's.
fn rod_in_frame_mm(robot_delay: f64) -> Scenario {
    let mut s = preset("rod-in-frame");
    s.facility.sensor_noise = 0.2;
    s.facility.sensor_delay = 0.005;
    s.facility.robot_delay = robot_delay;
    s.compensator = CompensatorConfig::from_kind("model-mediated").expect("kind");
    if let CompensatorConfig::ModelMediated(p) = &mut s.compensator {
        p.prior_shapes = PriorShapes::Geometry;
    }
    s
}

/// The local errors of a collision: rebound velocity error, |CoF − 1|, tangential and normal
/// impulse errors (fractions).
fn local_errors(c: &hilcontact_core::metrics::ComparedCollision) -> [f64; 4] {
    let n = c.collision.index;
    [
        c.local_velocity_error
            .unwrap_or_else(|| panic!("#{n}: no local v err")),
        (c.local_cof.unwrap_or_else(|| panic!("#{n}: no local CoF")) - 1.0).abs(),
        c.local_tangential_impulse_error
            .unwrap_or_else(|| panic!("#{n}: no local J_t err")),
        c.local_normal_impulse_error
            .unwrap_or_else(|| panic!("#{n}: no local J_n err")),
    ]
}

/// At zero delay (no noise) the HIL loop is the reference but for its own step: every
/// collision of `paper-table1` and `oblique-6dof` is within 1e-3 of its local reference
/// (measured: ≤ 5e-5), and `rod-in-frame`'s from the second on (measured ≤ 5e-5; its first,
/// against the same state as the global reference, keeps the 1 ms loop's own error on the
/// frictional edge contact: v err 0.17 %, J_t err 1.8 %, the global one's to 1e-4).
#[test]
fn local_errors_vanish_at_zero_delay() {
    for name in ["paper-table1", "oblique-6dof", "rod-in-frame"] {
        let out = simulate_plan(&zero_delay(name).resolve().expect("plan"));
        show(&format!("{name} 0 ms"), &out);
        let collisions = &out.metrics.collisions;
        assert!(collisions.len() >= 2, "{name}: {}", collisions.len());
        for c in collisions.iter().filter(|c| c.collision.complete) {
            let n = c.collision.index;
            let local = local_errors(c);
            if name == "rod-in-frame" && n == 1 {
                let global = [
                    c.velocity_error.expect("v"),
                    (c.cof.expect("CoF") - 1.0).abs(),
                    c.tangential_impulse_error.expect("J_t"),
                    c.normal_impulse_error.expect("J_n"),
                ];
                // the same contact from the same state (the velocity read earlier)
                for (l, g) in local.iter().zip(global) {
                    assert!((l - g).abs() <= 1e-4, "{name} #1: {l} vs {g}");
                }
                continue;
            }
            for e in local {
                assert!(e <= 1e-3, "{name} #{n}: local errors {local:?}");
            }
        }
    }
}

/// The local reference is the ideal reference's own integration: restarted from the
/// reference's state at any tick, it gives the reference's samples from there, to the bit;
/// and the first collision's local reference, restarted from the virtual state before the
/// first contact (the same state as the reference's, to rounding, as nothing has acted on the
/// virtual bodies yet), gives the global metrics of the first collision: CoF and impulse
/// errors to rounding, the rebound velocity error within 2e-3 (read once the local reference
/// has settled, earlier in the free flight than the global rebound sample: measured 7e-8 on
/// `paper-table1` at 20 ms, 1.2e-3 on `rod-in-frame` at 80 ms, whose bodies spin).
#[test]
fn the_first_collisions_local_reference_is_the_global_ones() {
    for name in [
        "paper-table1",
        "oblique-6dof",
        "rod-in-frame",
        "probe-drogue",
    ] {
        let mut s = preset(name);
        if name == "probe-drogue" {
            common::load_drogue_mesh(&mut s);
        }
        let plan = s.resolve().expect("plan");
        let (global, _) = run_reference(&plan, false);
        let first = global
            .force
            .iter()
            .position(|&f| f > plan.contact_threshold);
        let k0 = first.expect("a contact") - 5;
        let mut x = plan.initial;
        for _ in 0..k0 {
            plan.system
                .step_reference(&mut x, plan.period, plan.reference_substeps);
        }
        let n = (k0 + 2000).min(plan.ticks);
        let (local, _) = run_reference_from(&plan, &x, k0, n, false, |_| false);
        assert_eq!(local.len(), n - k0 + 1, "{name}");
        for (i, k) in (k0..=n).enumerate() {
            assert_eq!(
                local.time[i].to_bits(),
                global.time[k].to_bits(),
                "{name} {k}"
            );
            assert_eq!(
                local.force[i].to_bits(),
                global.force[k].to_bits(),
                "{name} {k}"
            );
            assert_eq!(local.velocity[i], global.velocity[k], "{name} {k}");
        }
    }
    for (label, s) in [
        ("paper-table1 pida 20 ms", {
            let mut s = preset("paper-table1");
            s.facility.robot_delay = 0.02;
            s.compensator = CompensatorConfig::from_kind("pida").expect("kind");
            s
        }),
        ("rod-in-frame mm geometry 80 ms", rod_in_frame_mm(0.08)),
    ] {
        let out = simulate_plan(&s.resolve().expect("plan"));
        let c = &out.metrics.collisions[0];
        let pairs = [
            (c.local_velocity_error, c.velocity_error),
            (c.local_cof, c.cof),
            (c.local_tangential_impulse_error, c.tangential_impulse_error),
            (c.local_normal_impulse_error, c.normal_impulse_error),
        ];
        for (n, (l, g)) in pairs.into_iter().enumerate() {
            let (l, g) = (l.expect("local"), g.expect("global"));
            println!("{label} #1: local {l:.12} global {g:.12}");
            // the velocity error: read earlier in the free flight (once settled), where a
            // spinning pair's rebound velocity has turned less
            let tol = if n == 0 {
                2e-3
            } else {
                1e-9 * g.abs().max(1.0)
            };
            assert!((l - g).abs() <= tol, "{label}: {l} vs {g}");
        }
    }
}

/// Where the global errors compound but each contact is faithful: on `rod-in-frame` at 80 ms
/// with the shapes' geometry known and their law not, the first contact is `pida`'s (95 %
/// off), so every later collision starts from another state and is far off the global
/// reference (collision 3: 127 %; 2 matches none), though the model renders each well:
/// against their local references, from the second collision on, the rebound velocity is
/// within 3 % (measured 1.7, 2.7 %), CoF within 1.005 (0.9984-0.9989) and the normal
/// impulse within 0.5 % (≤ 0.20 %); the tangential impulse within 6 % (measured 0.6, 5.0 %:
/// collision 3 at the 5 %). The verdict stays the global metrics' one
/// (`unfaithful`). (On the branch that wrote this test the run had four collisions, the fourth
/// 1.4 % off locally; merged with the same session's cylinder–box closed form and pida changes
/// it has three, the later collisions' numbers moved by up to 0.2 points: a run that rattles
/// at 80 ms amplifies any change.)
#[test]
fn local_errors_are_small_where_global_errors_compound() {
    let out = simulate_plan(&rod_in_frame_mm(0.08).resolve().expect("plan"));
    show("rod-in-frame mm geometry 80 ms", &out);
    let m = &out.metrics;
    assert_eq!(
        m.collisions[0].collision.rendering,
        Some(Rendering::PidaLawUnknown)
    );
    assert!(m.collisions.len() >= 3, "{}", m.collisions.len());
    let later = &m.collisions[1..];
    let far = later
        .iter()
        .filter(|c| c.reference.is_none() || c.velocity_error.is_some_and(|e| e > 0.5))
        .count();
    assert!(far >= 2, "the global errors do not compound here");
    for c in later.iter().filter(|c| c.collision.complete) {
        let n = c.collision.index;
        assert_eq!(c.collision.rendering, Some(Rendering::Model), "#{n}");
        let [v, cof, jt, jn] = local_errors(c);
        assert!(v <= 0.03, "#{n}: local v err {v}");
        assert!(cof <= 0.005, "#{n}: local |CoF - 1| {cof}");
        assert!(jt <= 0.06, "#{n}: local J_t err {jt}");
        assert!(jn <= 0.005, "#{n}: local J_n err {jn}");
    }
    assert_eq!(m.status, hilcontact_core::stop::Status::Unfaithful);
}

/// Without the virtual states (a real-time run's or a replay's trace) there is no local
/// reference: every local error is none and the summary's worst NaN; the global metrics are
/// the same as with them.
#[test]
fn the_local_references_are_off_by_default() {
    let mut s = preset_file("rod-in-frame");
    assert!(!s.metrics.local_references);
    s.facility.robot_delay = 0.02;
    s.compensator = CompensatorConfig::from_kind("pida").expect("kind");
    let off = simulate_plan(&s.resolve().expect("plan")).metrics;
    s.metrics.local_references = true;
    let on = simulate_plan(&s.resolve().expect("plan")).metrics;
    assert!(off
        .collisions
        .iter()
        .all(|c| c.local_velocity_error.is_none()));
    assert!(on
        .collisions
        .iter()
        .any(|c| c.local_velocity_error.is_some()));
    assert_eq!(
        off.summary.worst_velocity_error,
        on.summary.worst_velocity_error
    );
    assert_eq!(off.status, on.status);
}

#[test]
fn without_states_the_local_errors_are_missing() {
    let mut s = preset("rod-in-frame");
    s.facility.robot_delay = 0.02;
    s.compensator = CompensatorConfig::from_kind("pida").expect("kind");
    let plan = s.resolve().expect("plan");
    let (reference, _) = run_reference(&plan, false);
    let hil = run_hil(&plan, f64::INFINITY, false);
    let with = run_metrics(&plan, &reference, &hil);
    let without = trace_metrics(
        &plan,
        &reference,
        &hil.trace,
        hil.estimates_contact,
        hil.stop,
    );
    assert!(with
        .collisions
        .iter()
        .any(|c| c.local_velocity_error.is_some()));
    for c in &without.collisions {
        assert_eq!(c.local_start, None);
        assert_eq!(c.local_velocity_error, None);
        assert_eq!(c.local_cof, None);
        assert_eq!(c.local_tangential_impulse_error, None);
        assert_eq!(c.local_normal_impulse_error, None);
    }
    assert!(without.summary.worst_local_velocity_error.is_nan());
    assert!(without.summary.worst_local_cof.is_nan());
    assert_eq!(with.status, without.status);
    assert_eq!(with.violations, without.violations);
    for (a, b) in with.collisions.iter().zip(&without.collisions) {
        assert_eq!(a.velocity_error, b.velocity_error);
        assert_eq!(a.cof, b.cof);
        assert_eq!(a.tangential_impulse_error, b.tangential_impulse_error);
    }
}
