//! Where `pida`'s force fidelity and rebound direction go on a general 6-DOF scene with a
//! noisy, delayed sensor (docs/compensators/pida.md, "6-DOF with noise"):
//! `cargo run --release --example pida_6dof_audit [seeds] [random]`.
//!
//! The general scene of `crates/core/tests/compensators.rs` (`oblique-6dof` with both bodies
//! spinning about every axis and the target drifting) at 20 ms robot delay, over `seeds`
//! noise seeds (default 8), with one cause removed at a time: the sensor delay, the noise, the
//! moment noise, the identification (k̂, ĉ pinned at the truth), the energy controller
//! (`pic`). Prints the worst CoF and the worst rebound velocity error (a vector error ε of a
//! rebound of the right speed is a direction error of about ε rad) of each case, as medians
//! and ranges over the seeds.

use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_core::Scenario;

fn preset(name: &str) -> Scenario {
    let path = format!(
        "{}/../../python/hilcontact/scenarios/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    toml::from_str(&std::fs::read_to_string(path).expect("preset")).expect("parse")
}

/// The general 6-DOF scene of the tests at `robot_delay` (s).
fn general(robot_delay: f64) -> Scenario {
    let mut s = preset("oblique-6dof");
    s.target.angular_velocity = [0.01, 0.02, -0.015];
    s.servicer.angular_velocity = [0.005, -0.01, 0.02];
    s.target.velocity = [0.001, -0.002, 0.0005];
    s.facility.robot_delay = robot_delay;
    s
}

/// A random general scene as `crates/core/tests/common` builds them (spins within ±0.02
/// rad/s, target drift within ±2 mm/s, wall tilts within ±0.45 rad, rod offsets within
/// ±0.2 m), number `n` of a fixed sequence.
fn random(n: u64, robot_delay: f64) -> Scenario {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0x6d0f + n);
    let mut u = |a: f64| rng.random_range(-a..a);
    let mut s = preset("oblique-6dof");
    s.target.angular_velocity = [u(0.02), u(0.02), u(0.02)];
    s.servicer.angular_velocity = [u(0.02), u(0.02), u(0.02)];
    s.target.velocity = [u(0.002), u(0.002), u(0.002)];
    let tilt = [u(0.45), u(0.45)];
    let offset = [u(0.2), u(0.2)];
    s.walls[0].normal = [
        -tilt[0].cos() * tilt[1].cos(),
        -tilt[0].sin(),
        tilt[1].sin(),
    ];
    s.rod.tip = [1.0, offset[0], offset[1]];
    s.walls[0].point = [0.010, offset[0] - 0.05, offset[1]];
    s.facility.robot_delay = robot_delay;
    s
}

/// Median, smallest and largest.
fn spread(mut v: Vec<f64>) -> String {
    v.sort_by(f64::total_cmp);
    format!("{:.3} ({:.3}-{:.3})", v[v.len() / 2], v[0], v[v.len() - 1])
}

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .map_or(8, |s| s.parse().expect("seeds"));
    // `random`: a random scene per seed (the noise seed too) instead of the general scene
    let random_scenes = std::env::args().nth(2).is_some_and(|a| a == "random");
    let truth = |s: &Scenario| ModelParams {
        stiffness_initial: s.contact.stiffness,
        stiffness_std: 1.0,
        stiffness_walk: 0.0,
        damping_initial: s.contact.damping,
        damping_std: 1e-3,
        damping_walk: 0.0,
        ..ModelParams::default()
    };
    type Case = (&'static str, f64, f64, f64, bool, bool);
    // (label, force noise N, moment noise N·m (NaN: the preset's), sensor delay s, identification pinned, pic)
    let cases: [Case; 9] = [
        ("clean", 0.0, 0.0, 0.0, false, false),
        ("3 ms sensor delay", 0.0, 0.0, 0.003, false, false),
        ("0.2 N", 0.2, f64::NAN, 0.0, false, false),
        ("0.2 N, 3 ms", 0.2, f64::NAN, 0.003, false, false),
        ("0.2 N, 3 ms, k c pinned", 0.2, f64::NAN, 0.003, true, false),
        ("0.2 N, 3 ms, pic", 0.2, f64::NAN, 0.003, false, true),
        ("1 N, 3 ms", 1.0, f64::NAN, 0.003, false, false),
        ("1 N, 3 ms, no moment noise", 1.0, 0.0, 0.003, false, false),
        ("1 N, 3 ms, k c pinned", 1.0, f64::NAN, 0.003, true, false),
    ];
    if random_scenes {
        per_scene(seeds);
        noise_paths(seeds);
    }
    println!(
        "{} 6-DOF scene, 20 ms robot delay, seeds 1..={seeds}: median (min-max)",
        if random_scenes {
            "a random"
        } else {
            "the general"
        }
    );
    for (label, noise, moment_noise, sensor_delay, pinned, pic) in cases {
        let (mut cofs, mut errors, mut k_errors) = (Vec::new(), Vec::new(), Vec::new());
        for seed in 1..=seeds {
            let mut s = if random_scenes {
                random(seed, 0.02)
            } else {
                general(0.02)
            };
            s.facility.sensor_noise = noise;
            if !moment_noise.is_nan() {
                s.facility.torque_noise = moment_noise;
            }
            s.facility.sensor_delay = sensor_delay;
            s.facility.seed = seed;
            let p = if pinned {
                truth(&s)
            } else {
                ModelParams::default()
            };
            s.compensator = if pic {
                CompensatorConfig::Pic(p)
            } else {
                CompensatorConfig::Pida(p)
            };
            let m = hilcontact_core::simulate_metrics(&s).expect("run");
            let worst = |f: fn(&hilcontact_core::metrics::ComparedCollision) -> Option<f64>| {
                m.collisions.iter().filter_map(f).fold(f64::NAN, f64::max)
            };
            cofs.push(worst(|c| c.cof));
            errors.push(worst(|c| c.velocity_error));
            k_errors.push(m.identification.map_or(f64::NAN, |i| i.stiffness_error));
        }
        println!(
            "{label:>28}: worst CoF {}, worst velocity error {}, k error {}",
            spread(cofs),
            spread(errors),
            spread(k_errors)
        );
    }
}

/// The onset bound of each random scene: a contact whose force shows `τ` late lets the
/// virtual tip in by `v0·τ` unopposed, so the peak force is `√(1 + (ω τ)²)` times the ideal,
/// `ω = √(k / m_eff)` with `m_eff = 1 / (nᵀ K n)` the mass the wall's normal `n` sees at the
/// rod tip (`K` the tip mobility). Largest over the walls, at the start pose; against the
/// measured worst CoF, clean and with 3 ms of sensor delay (τ = 20 and 23 ms).
fn per_scene(seeds: u64) {
    println!(
        "scene: m_eff per wall (kg); predicted CoF at 20 / 23 ms; measured worst CoF clean / 3 ms"
    );
    for n in 1..=seeds {
        let s = random(n, 0.02);
        let plan = s.resolve().expect("plan");
        let mobility = plan.system.tip_mobility(&plan.initial);
        let masses: Vec<f64> = s
            .walls
            .iter()
            .map(|w| {
                let normal = nalgebra::Vector3::from(w.normal).normalize();
                1.0 / normal.dot(&(mobility * normal))
            })
            .collect();
        let lightest = masses.iter().cloned().fold(f64::INFINITY, f64::min);
        let omega = (s.contact.stiffness / lightest).sqrt();
        let bound = |tau: f64| (1.0 + (omega * tau).powi(2)).sqrt();
        let worst = |sensor_delay: f64| {
            let mut s = s.clone();
            s.facility.sensor_delay = sensor_delay;
            s.compensator = CompensatorConfig::Pida(ModelParams::default());
            let m = hilcontact_core::simulate_metrics(&s).expect("run");
            m.collisions
                .iter()
                .filter_map(|c| c.cof)
                .fold(f64::NAN, f64::max)
        };
        println!(
            "{n}: {}; {:.3} / {:.3}; {:.3} / {:.3}",
            masses
                .iter()
                .map(|m| format!("{m:.0}"))
                .collect::<Vec<_>>()
                .join(", "),
            bound(0.020),
            bound(0.023),
            worst(0.0),
            worst(0.003)
        );
    }
}

/// The rebound direction under 1 N of noise (3 ms sensor delay, 20 ms robot delay) with one
/// part of the compensator changed at a time: which part carries the noise into the
/// direction.
fn noise_paths(seeds: u64) {
    let base = ModelParams::default();
    let variants: [(&str, ModelParams, f64); 6] = [
        ("pida", base.clone(), 1.0),
        ("pida, no noise", base.clone(), 0.0),
        (
            "contact_force 10 N",
            ModelParams {
                contact_force: 10.0,
                ..base.clone()
            },
            1.0,
        ),
        (
            "observer paper",
            ModelParams {
                observer: hilcontact_core::compensator::ObserverMode::Paper,
                ..base.clone()
            },
            1.0,
        ),
        (
            "force_ratio_max 0.5",
            ModelParams {
                force_ratio_max: 0.5,
                ..base.clone()
            },
            1.0,
        ),
        (
            "alpha_max 1",
            ModelParams {
                alpha_max: 1.0,
                ..base.clone()
            },
            1.0,
        ),
    ];
    println!("per collision (scenes 6-8): reference peak force N: CoF clean / CoF 1 N, velocity error clean / 1 N");
    for n in 6..=seeds.min(8) {
        let run = |noise: f64| {
            let mut s = random(n, 0.02);
            s.facility.sensor_noise = noise;
            s.facility.sensor_delay = 0.003;
            s.facility.seed = n;
            s.compensator = CompensatorConfig::Pida(base.clone());
            hilcontact_core::simulate_metrics(&s).expect("run")
        };
        let (clean, noisy) = (run(0.0), run(1.0));
        let line: Vec<String> = clean
            .collisions
            .iter()
            .zip(&noisy.collisions)
            .map(|(a, b)| {
                let peak = a
                    .reference
                    .and_then(|r| clean.reference_collisions.iter().find(|c| c.index == r))
                    .map_or(f64::NAN, |c| c.peak_force);
                format!(
                    "{peak:.0}: {:.2}/{:.2}, {:.1}%/{:.1}%",
                    a.cof.unwrap_or(f64::NAN),
                    b.cof.unwrap_or(f64::NAN),
                    a.velocity_error.unwrap_or(f64::NAN) * 100.0,
                    b.velocity_error.unwrap_or(f64::NAN) * 100.0
                )
            })
            .collect();
        println!("scene {n}: {}", line.join("; "));
    }
    println!("1 N noise, 3 ms sensor delay, random scenes: worst velocity error per scene");
    for (label, p, noise) in variants {
        let errors: Vec<String> = (1..=seeds)
            .map(|n| {
                let mut s = random(n, 0.02);
                s.facility.sensor_noise = noise;
                s.facility.sensor_delay = 0.003;
                s.facility.seed = n;
                s.compensator = CompensatorConfig::Pida(p.clone());
                let m = hilcontact_core::simulate_metrics(&s).expect("run");
                let e = m
                    .collisions
                    .iter()
                    .filter_map(|c| c.velocity_error)
                    .fold(f64::NAN, f64::max);
                let cof = m
                    .collisions
                    .iter()
                    .filter_map(|c| c.cof)
                    .fold(f64::NAN, f64::max);
                format!("{:.1}%/{cof:.2}", e * 100.0)
            })
            .collect();
        println!("{label:>22}: {}", errors.join(" "));
    }
}
