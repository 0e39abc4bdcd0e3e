//! `model-mediated` on frictional contacts (issue 22): the identified surface's friction
//! coefficient rendered at the virtual tip (the engine's regularised Coulomb law on the virtual
//! sliding velocity), the normal fitted under friction ([`frictional_normal`]), and several
//! surfaces pressed at once (a corner) rendered as the sum of their laws; the scenario's shapes
//! as prior geometry (`prior_shapes`), rendered by the engine's own shape query.

mod common;

use common::{col, preset};
use hilcontact_core::compensator::{
    fit_contact, frictional_normal, CompensatorConfig, LawForm, PriorShapes, Rendering, Sample,
};
use hilcontact_core::contact::FrictionConfig;
use hilcontact_core::sim::simulate_plan;
use hilcontact_core::{Scenario, SimulationOutput};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};

/// Synthetic samples of a frictional linear contact: the tip pressed into a plane of normal
/// `n` (into free space) while sliding along `slide`, force `F = −F_n·n + μ·F_n·ŝ` on the frame
/// (F_n = k·d + c·ḋ), Gaussian noise `noise` N per axis.
fn synthetic(n: Vector3<f64>, mu: f64, k: f64, c: f64, noise: f64, seed: u64) -> Vec<Sample> {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let slide = n.cross(&helper).normalize();
    let (u_in, u_t, duration) = (0.02, 0.01, 0.1);
    let omega = std::f64::consts::PI / duration;
    (0..100)
        .map(|i| {
            let t = (i as f64 + 0.5) * 1e-3;
            let d = u_in / omega * (omega * t).sin();
            let rate = u_in * (omega * t).cos();
            let position = Vector3::new(0.01, 0.02, 0.0) - n * d + slide * (u_t * t);
            let velocity = -n * rate + slide * u_t;
            let f_n = (k * d + c * rate).max(0.0);
            let gauss = |r: &mut rand_pcg::Pcg64Mcg| {
                // Box-Muller
                let (a, b): (f64, f64) = (r.random_range(1e-12..1.0), r.random_range(0.0..1.0));
                (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
            };
            let e = Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng)) * noise;
            Sample {
                // on the frame: into the wall, and along the sliding (friction on the rod
                // opposes it)
                force: -n * f_n + slide * (mu * f_n) + e,
                position,
                velocity,
            }
        })
        .collect()
}

/// The fit under friction: over random normals, μ 0.1-0.3 and 0.2 N noise, the fitted normal
/// is within 0.5° of the true one, μ̂ within 0.03 and k̂ within 2 %; the mean force's direction
/// (the fit without friction) is `atan μ` off and k̂ off by several per cent.
#[test]
fn a_frictional_contact_is_fitted_along_its_normal_with_its_friction() {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(22);
    for case in 0..20 {
        let n = Vector3::new(
            -1.0,
            rng.random_range(-0.7..0.7),
            rng.random_range(-0.3..0.3),
        )
        .normalize();
        let mu = rng.random_range(0.1..0.3);
        let k = 176_275.0;
        let samples = synthetic(n, mu, k, 0.0, 0.2, case);
        let sum = samples.iter().fold(Vector3::zeros(), |s, x| s + x.force);
        let (normal, mu_hat) = frictional_normal(&samples).expect("frictional");
        let angle = (-normal).dot(&n).clamp(-1.0, 1.0).acos().to_degrees();
        let fit = fit_contact(&samples, &sum, LawForm::Linear).expect("fit");
        let hilcontact_core::contact::ContactModel::Linear(law) = fit.law else {
            panic!("linear")
        };
        let lean = (-sum.normalize()).dot(&n).acos().to_degrees();
        println!(
            "case {case}: μ {mu:.3} μ̂ {mu_hat:.3}, normal {angle:.3}° off (mean force {lean:.2}°), k̂/k {:.4}",
            law.stiffness / k
        );
        assert!(angle < 0.5, "case {case}: normal {angle}° off");
        assert!(
            (mu_hat - mu).abs() < 0.03,
            "case {case}: μ̂ {mu_hat} for {mu}"
        );
        assert!((fit.friction - mu_hat).abs() < 1e-12);
        assert!(
            (law.stiffness / k - 1.0).abs() < 0.02,
            "case {case}: k̂ {}",
            law.stiffness
        );
        assert!(fit.wall.normal.dot(&n) > 0.9999);
    }
}

/// A frictionless contact is fitted exactly as before (the mean force's direction, μ̂ 0).
#[test]
fn a_frictionless_contact_keeps_the_mean_force_fit() {
    let n = Vector3::new(-0.8924, -0.4161, 0.1736).normalize();
    let samples = synthetic(n, 0.0, 176_275.0, 30.0, 0.2, 7);
    assert!(frictional_normal(&samples).is_none());
    let sum = samples.iter().fold(Vector3::zeros(), |s, x| s + x.force);
    let fit = fit_contact(&samples, &sum, LawForm::Linear).expect("fit");
    assert_eq!(fit.friction, 0.0);
    assert_eq!(fit.wall.normal, -sum.normalize());
}

/// `oblique-6dof` with Coulomb friction `mu`, 0.2 N noise, 5 ms sensor delay, `model-mediated`
/// at `robot_delay` with the scenario's walls as its prior geometry.
fn oblique_mm(mu: f64, robot_delay: f64) -> Scenario {
    let mut s = preset("oblique-6dof");
    s.contact.friction = FrictionConfig {
        kinetic_coefficient: mu,
        ..FrictionConfig::default()
    };
    s.facility.sensor_noise = 0.2;
    s.facility.sensor_delay = 0.005;
    s.facility.robot_delay = robot_delay;
    s.compensator = CompensatorConfig::from_kind("model-mediated").expect("kind");
    if let CompensatorConfig::ModelMediated(p) = &mut s.compensator {
        p.prior_walls = s.walls.clone();
    }
    s
}

/// Per collision: (rendering, velocity error, CoF, tangential impulse error).
fn rows(out: &SimulationOutput) -> Vec<(Option<Rendering>, f64, f64, f64)> {
    out.metrics
        .collisions
        .iter()
        .filter(|c| c.reference.is_some())
        .map(|c| {
            (
                c.collision.rendering,
                c.velocity_error.unwrap_or(f64::NAN),
                c.cof.unwrap_or(f64::NAN),
                c.tangential_impulse_error.unwrap_or(f64::NAN),
            )
        })
        .collect()
}

/// Prints a run's collisions.
fn show(label: &str, out: &SimulationOutput) {
    for (n, (r, v, cof, jt)) in rows(out).iter().enumerate() {
        println!(
            "{label} collision {}: {r:?} v err {:.2} % CoF {cof:.3} J_t err {:.2} %",
            n + 1,
            100.0 * v,
            100.0 * jt
        );
    }
}

/// `oblique-6dof` with friction μ 0.1 and 0.3 at 40, 80 and 120 ms, the walls as prior
/// geometry: the first contact (the front wall) is `pida`'s (no law yet); the rear wall's
/// first contact, rendered from the prior and the law and friction identified on the front
/// wall, has its rebound velocity vector within 8 %, its CoF within 1.1 and its tangential
/// impulse within 10 % of the reference's (without the friction rendered and the normal
/// fitted under friction: see docs/compensators/model-mediated.md, "Friction and corners").
#[test]
fn the_second_surface_is_rendered_with_its_friction() {
    for mu in [0.1, 0.3] {
        for delay in [0.04, 0.08, 0.12] {
            let out = simulate_plan(&oblique_mm(mu, delay).resolve().expect("plan"));
            let label = format!("μ {mu} {} ms", delay * 1e3);
            show(&label, &out);
            let m = &out.metrics;
            assert!(m.lost_collisions.is_empty(), "{label}: lost");
            let rows = rows(&out);
            let (rendering, v, cof, jt) = rows[1];
            if rendering != Some(Rendering::Model) {
                // handed to pida (a contact the prior did not explain): pida's bounds
                assert!(v <= 0.08, "{label}: collision 2 ({rendering:?}) v err {v}");
                continue;
            }
            assert!(v <= 0.08, "{label}: collision 2 v err {v}");
            assert!((0.9..=1.1).contains(&cof), "{label}: collision 2 CoF {cof}");
            assert!(jt <= 0.10, "{label}: collision 2 J_t err {jt}");
        }
    }
}

/// The rod tip driven straight into an inside corner of `oblique-6dof`'s geometry: two walls
/// 30° either side of −x meeting in an edge along z straight ahead of the tip, and the rear
/// wall; the servicer drifts along the edge (`drift`, m/s), so the tip slides on both walls;
/// friction `mu`, 0.2 N noise, 5 ms sensor delay, `model-mediated` at `robot_delay` with the
/// walls as its prior geometry. The tip bounces between the corner and the rear wall.
fn corner_mm(mu: f64, drift: f64, robot_delay: f64) -> Scenario {
    let mut s = oblique_mm(mu, robot_delay);
    let (c, sn) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let mut a = s.walls[0].clone();
    a.name = "corner-a".into();
    a.point = [0.010, 0.10, 0.05];
    a.normal = [-c, -sn, 0.0];
    let mut b = a.clone();
    b.name = "corner-b".into();
    b.normal = [-c, sn, 0.0];
    let rear = s.walls[1].clone();
    s.walls = vec![a, b, rear];
    s.servicer.velocity = [0.02, 0.0, drift];
    s.servicer.angular_velocity = [0.0; 3];
    s.target.angular_velocity = [0.0; 3];
    s.simulation.duration = 8.0;
    if let CompensatorConfig::ModelMediated(p) = &mut s.compensator {
        p.prior_walls = s.walls.clone();
    }
    s
}

/// A calibration of the scene's walls and law (exact, small stated uncertainties; no
/// friction: a calibration has none).
fn calibrated(mut s: Scenario) -> Scenario {
    use hilcontact_core::calibration::{
        CalibratedLaw, CalibratedRobot, CalibratedWall, CalibrationFile,
    };
    use hilcontact_core::contact::ContactModelKind;
    let file = CalibrationFile {
        walls: s
            .walls
            .iter()
            .map(|w| CalibratedWall {
                name: w.name.clone(),
                point: w.point,
                normal: w.normal,
                offset_sigma: 1e-5,
                angle_sigma: 0.02,
                radius: 0.02,
                probes: 9,
                rms: 0.2,
            })
            .collect(),
        law: CalibratedLaw {
            model: ContactModelKind::Linear,
            stiffness: s.contact.stiffness,
            damping: s.contact.damping,
            exponent: 1.0,
            stiffness_sigma: 0.005 * s.contact.stiffness,
            damping_sigma: 5.0,
            exponent_sigma: 0.0,
        },
        robot: CalibratedRobot {
            delay: s.facility.robot_delay,
            ..CalibratedRobot::default()
        },
        ..CalibrationFile::default()
    };
    if let CompensatorConfig::ModelMediated(p) = &mut s.compensator {
        p.calibration = file;
        p.prior_walls.clear();
        p.prior_friction = s.contact.friction.kinetic_coefficient;
    }
    s
}

/// Asserts every reference collision is present and every collision's rebound velocity vector
/// within `v_max`, CoF within `1 ± cof_max` and tangential impulse within `jt_max`.
fn assert_faithful(label: &str, out: &SimulationOutput, v_max: f64, cof_max: f64, jt_max: f64) {
    show(label, out);
    let m = &out.metrics;
    assert!(
        m.lost_collisions.is_empty() && m.extra_collisions.is_empty(),
        "{label}"
    );
    assert!(
        m.collisions.len() >= 3,
        "{label}: {} collisions",
        m.collisions.len()
    );
    for (n, (rendering, v, cof, jt)) in rows(out).into_iter().enumerate() {
        if v.is_nan() {
            continue; // the run ended inside it
        }
        assert_eq!(
            rendering,
            Some(Rendering::Model),
            "{label} collision {}",
            n + 1
        );
        assert!(v <= v_max, "{label} collision {}: v err {v}", n + 1);
        assert!(
            (cof - 1.0).abs() <= cof_max,
            "{label} collision {}: CoF {cof}",
            n + 1
        );
        assert!(jt <= jt_max, "{label} collision {}: J_t err {jt}", n + 1);
    }
}

/// The corner with its geometry, law (a calibration) and friction coefficient (`prior_friction`)
/// known: every collision, the corner's (both walls pressed and slid on at once: the sum of
/// their laws and friction) and the rear wall's, is rendered from the first at 40, 80 and
/// 120 ms, rebound velocity vector within 3 %, CoF within 1.05, tangential impulse within
/// 5 % (measured: 1.48 %, 1.012, 2.2 %); the contacts' split (CornerFit) keeps the walls'
/// laws and re-identifies their friction. Without the friction rendered, the first corner
/// contact's rebound was 47 % off.
#[test]
fn a_corner_with_its_geometry_law_and_friction_known_is_rendered_from_the_first_contact() {
    for delay in [0.04, 0.08, 0.12] {
        let s = calibrated(corner_mm(0.2, 0.004, delay));
        let out = simulate_plan(&s.resolve().expect("plan"));
        assert_faithful(
            &format!("corner {} ms", delay * 1e3),
            &out,
            0.03,
            0.05,
            0.05,
        );
    }
}

/// `oblique-6dof` with friction μ 0.1 and 0.3, its walls, law (a calibration) and friction
/// coefficient known: each surface's first contact is rendered from the model at 40, 80 and
/// 120 ms, rebound velocity vector within 3 %, CoF within 1.05, tangential impulse within 5 %
/// (measured: 0.02 %, 1.000, 0.08 %). A third collision at μ 0.3 (the front wall again) is
/// printed, not asserted: 2.9 %, 5.4 % and 11.7 % at 40, 80, 120 ms.
#[test]
fn oblique_frictional_contacts_with_a_calibration_and_prior_friction_are_rendered_faithfully() {
    for mu in [0.1, 0.3] {
        for delay in [0.04, 0.08, 0.12] {
            let s = calibrated(oblique_mm(mu, delay));
            let out = simulate_plan(&s.resolve().expect("plan"));
            let label = format!("calibrated μ {mu} {} ms", delay * 1e3);
            show(&label, &out);
            assert!(out.metrics.lost_collisions.is_empty(), "{label}");
            for (n, (rendering, v, cof, jt)) in rows(&out).into_iter().take(2).enumerate() {
                assert_eq!(rendering, Some(Rendering::Model), "{label} {}", n + 1);
                assert!(v <= 0.03, "{label} collision {}: v err {v}", n + 1);
                assert!(
                    (cof - 1.0).abs() <= 0.05,
                    "{label} collision {}: CoF {cof}",
                    n + 1
                );
                assert!(jt <= 0.05, "{label} collision {}: J_t err {jt}", n + 1);
            }
        }
    }
}

/// A preset with shapes (`rod-in-frame`: a cylinder rod in a frame of four boxes, onto an edge
/// and into the corner of two bars; `probe-drogue`: a capsule probe in a cone mesh, into the
/// crease of two facets), μ 0.2 (static 0.25), 0.2 N noise, 5 ms sensor delay,
/// `model-mediated` at `robot_delay` with the scenario's shapes as its prior (`prior`).
fn shapes_mm(name: &str, prior: PriorShapes, robot_delay: f64) -> Scenario {
    let mut s = preset(name);
    if name == "probe-drogue" {
        common::load_drogue_mesh(&mut s);
    }
    s.facility.sensor_noise = 0.2;
    s.facility.sensor_delay = 0.005;
    s.facility.robot_delay = robot_delay;
    s.compensator = CompensatorConfig::from_kind("model-mediated").expect("kind");
    if let CompensatorConfig::ModelMediated(p) = &mut s.compensator {
        p.prior_shapes = prior;
    }
    s
}

/// Per matched collision: the energy after it (the HIL run's at its rebound sample) over the
/// reference's (in the middle of the free flight after the reference's collision), less 1.
fn energy_excess(out: &SimulationOutput) -> Vec<f64> {
    let (e_h, t_h) = (col(out, "energy"), col(out, "time"));
    let e_r = out.reference.column("energy").expect("reference energy");
    let t_r = out.reference.column("time").expect("reference time");
    let at = |t: &[f64], x: f64| t.partition_point(|&s| s < x).min(t.len() - 1);
    let refs = &out.metrics.reference_collisions;
    out.metrics
        .collisions
        .iter()
        .filter_map(|c| {
            let (i, after) = (c.reference?, c.rebound_time?);
            let r = refs.iter().position(|r| r.index == i)?;
            let next = refs.get(r + 1).map_or(t_r[t_r.len() - 1], |n| n.start);
            let e_ref = e_r[at(t_r, 0.5 * (refs[r].end + next))];
            Some(e_h[at(t_h, after)] / e_ref - 1.0)
        })
        .collect()
}

/// The shapes with their geometry and law known (`prior_shapes = "geometry-and-law"`: the
/// scenario's law and friction) are rendered from the first contact at 40, 80 and 120 ms: every
/// reference collision present and rendered by the model, rebound velocity vector within 3 %,
/// CoF within 1.05, tangential impulse within 5 % and the energy after each collision at most
/// 5 % above the reference's (measured: v err ≤ 0.8 %, CoF ≤ 1.005, energy within 0.5 %;
/// J_t ≤ 1.9 % on rod-in-frame). probe-drogue's third collision, nearly sticking in the crease
/// (the reference's tangential impulse 1.6 % of its normal one), has its tangential impulse
/// 31 % off (the virtual dynamics' own: the stiff regularised friction near sticking held over
/// each 1 ms tick, 16 % at 0.5 ms, 8 % at 0.25 ms; docs/compensators/model-mediated.md):
/// asserted only where the reference slides (J_t ≥ 5 % of J_n).
#[test]
fn shapes_with_their_geometry_and_law_known_are_rendered_from_the_first_contact() {
    for name in ["rod-in-frame", "probe-drogue"] {
        for delay in [0.04, 0.08, 0.12] {
            let s = shapes_mm(name, PriorShapes::GeometryAndLaw, delay);
            let out = simulate_plan(&s.resolve().expect("plan"));
            let label = format!("{name} {} ms", delay * 1e3);
            show(&label, &out);
            let m = &out.metrics;
            assert!(
                m.lost_collisions.is_empty() && m.extra_collisions.is_empty(),
                "{label}: lost {:?} extra {:?}",
                m.lost_collisions,
                m.extra_collisions
            );
            assert!(m.collisions.len() >= 4, "{label}: {}", m.collisions.len());
            for (n, c) in m.collisions.iter().enumerate() {
                let r = &m.reference_collisions[c.reference.expect("matched") - 1];
                let (v, cof, jt) = (
                    c.velocity_error.expect("compared"),
                    c.cof.expect("compared"),
                    c.tangential_impulse_error.expect("compared"),
                );
                let n = n + 1;
                assert_eq!(c.collision.rendering, Some(Rendering::Model), "{label} {n}");
                assert!(v <= 0.03, "{label} collision {n}: v err {v}");
                assert!(
                    (cof - 1.0).abs() <= 0.05,
                    "{label} collision {n}: CoF {cof}"
                );
                if r.tangential_impulse >= 0.05 * r.normal_impulse {
                    assert!(jt <= 0.05, "{label} collision {n}: J_t err {jt}");
                }
            }
            for (n, e) in energy_excess(&out).into_iter().enumerate() {
                println!(
                    "{label} collision {}: energy after {:+.2} %",
                    n + 1,
                    100.0 * e
                );
                assert!(e <= 0.05, "{label} collision {}: energy {e:+}", n + 1);
            }
        }
    }
}

/// The shapes' geometry known, their law not (`prior_shapes = "geometry"`): the first contact
/// is `pida`'s (`pida-law-unknown`); the law is fitted from the robot's contacts on the nominal
/// contact points, and every later collision is rendered by the model with a stiffness within
/// 2 % of the scenario's (measured: 0.02-0.6 %). Their rebounds are not asserted: the first
/// contact's error (`pida`'s, 15-95 % at these delays) has changed the state they start from.
#[test]
fn the_shapes_law_is_identified_from_the_first_contact() {
    for name in ["rod-in-frame", "probe-drogue"] {
        for delay in [0.04, 0.12] {
            let s = shapes_mm(name, PriorShapes::Geometry, delay);
            let out = simulate_plan(&s.resolve().expect("plan"));
            let label = format!("{name} {} ms", delay * 1e3);
            show(&label, &out);
            let collisions = &out.metrics.collisions;
            assert_eq!(
                collisions[0].collision.rendering,
                Some(Rendering::PidaLawUnknown),
                "{label}"
            );
            let (k, t) = (col(&out, "stiffness_estimate"), col(&out, "time"));
            let mut modelled = 0;
            for c in collisions.iter().skip(1) {
                assert_eq!(c.collision.rendering, Some(Rendering::Model), "{label}");
                // the law rendered, in the middle of the robot's contact (the model's still open)
                let mid = 0.5 * (c.collision.start + c.collision.end);
                let k_hat = k[t.partition_point(|&s| s < mid)];
                println!("{label}: k̂ {k_hat:.0} at {mid:.3} s");
                assert!(
                    (k_hat / s.contact.stiffness - 1.0).abs() < 0.02,
                    "{label}: k̂ {k_hat}"
                );
                modelled += 1;
            }
            assert!(modelled >= 1, "{label}: nothing rendered by the model");
        }
    }
}

/// `prior_shapes` needs shapes on both bodies (one line, the key named); a frictionless
/// scenario with shapes gets the nominal geometry for it (the compensators' context), and
/// without the option keeps none.
#[test]
fn the_shapes_prior_needs_shapes() {
    let mut s = preset("oblique-6dof");
    s.compensator = CompensatorConfig::from_kind("model-mediated").expect("kind");
    if let CompensatorConfig::ModelMediated(p) = &mut s.compensator {
        p.prior_shapes = PriorShapes::Geometry;
    }
    let error = s.resolve().expect_err("no shapes").to_string();
    assert!(error.contains("compensator.prior_shapes"), "{error}");
    let mut s = shapes_mm("rod-in-frame", PriorShapes::Geometry, 0.04);
    s.contact.friction = FrictionConfig::default();
    let plan = s.resolve().expect("plan");
    assert!(hilcontact_core::hil::compensator_context(&plan)
        .geometry
        .is_some());
    s.compensator = CompensatorConfig::from_kind("model-mediated").expect("kind");
    let plan = s.resolve().expect("plan");
    assert!(hilcontact_core::hil::compensator_context(&plan)
        .geometry
        .is_none());
}
