//! Offline identification's stated uncertainties over random scenes: do the ±2σ intervals of
//! `identify` (crates/core/src/identify.rs) contain the true k and c?
//!
//! Each run draws a 6-DOF scene (the oblique-6dof preset with random spins, drift, wall tilt
//! and rod offset), a servicer mass, a contact stiffness and damping, a force-sensor noise, a
//! sensor delay and a robot delay, runs `pida` over it and identifies every collision of the
//! recording. The 95 % interval (2σ) must contain the truth for at least 90 % of the
//! collisions, for k and for c. The same runs check the live loop's own final estimate and
//! the σ that `online_identification` states for it (the one the `hil`/`demo-rt` summary
//! prints). Set `ID_DEBUG=1` to print every collision, `ID_RUNS=N` for another number of runs.

mod common;

use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_core::config::Scenario;
use hilcontact_core::hil::compensator_context;
use hilcontact_core::identify::{
    identify, model_params, online_identification_plan, OFFLINE_FORGETTING,
};
use hilcontact_core::replay::Recording;
use hilcontact_core::sim::simulate_plan;
use rand::{Rng, SeedableRng};

/// Random scenes drawn.
const RUNS: u64 = 200;

/// A random identification case: the scene and its true k (N/m), c (N·s/m).
fn random_scene(rng: &mut rand_pcg::Pcg64Mcg, seed: u64) -> Scenario {
    let mut u3 = |r: f64| {
        [
            rng.random_range(-r..r),
            rng.random_range(-r..r),
            rng.random_range(-r..r),
        ]
    };
    let spins = (u3(0.003), u3(0.003));
    let drift = u3(0.002);
    let tilt = [rng.random_range(-0.5..0.5), rng.random_range(-0.3..0.3)];
    let offset = [rng.random_range(-0.15..0.15), rng.random_range(-0.1..0.1)];
    let mut s = common::oblique_6dof(spins, drift, tilt, offset);
    s.servicer.mass = rng.random_range(100.0..1000.0);
    s.contact.stiffness = rng.random_range(20_000.0..200_000.0);
    s.contact.damping = rng.random_range(0.0..300.0);
    s.facility.sensor_noise = [0.0, 0.1, 0.3, 0.5, 1.0][rng.random_range(0..5)];
    s.facility.torque_noise = s.facility.sensor_noise * 0.1;
    s.facility.sensor_delay = 0.001 * rng.random_range(0..=10) as f64;
    s.facility.robot_delay = 0.001 * rng.random_range(5..=30) as f64;
    s.facility.seed = seed;
    s.compensator = CompensatorConfig::from_kind("pida").expect("pida");
    s
}

/// Per collision: (k, c, k̂, σ_k, ĉ, σ_c, noise, sensor delay).
type Row = (f64, f64, f64, f64, f64, f64, f64, f64);

/// Per collision, `identify`'s rows; per run (one random scene each), the live loop's own
/// final estimate with the σ `online_identification` states for it, as a row too.
fn rows() -> (Vec<Row>, Vec<Row>) {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(2026);
    let (mut rows, mut online_rows) = (Vec::new(), Vec::new());
    let runs = std::env::var("ID_RUNS").map_or(RUNS, |v| v.parse().expect("ID_RUNS"));
    for seed in 1..=runs {
        let scenario = random_scene(&mut rng, seed);
        let (k, c) = (scenario.contact.stiffness, scenario.contact.damping);
        let (noise, tau) = (
            scenario.facility.sensor_noise,
            scenario.facility.sensor_delay,
        );
        let plan = scenario.resolve().expect("plan");
        let out = simulate_plan(&plan);
        let recording = Recording::from_table(&out.timeseries, false).expect("recording");
        if let Some(online) = online_identification_plan(&plan, &recording).expect("online") {
            // the replayed front end is the loop's: its final estimate is the run's
            let series = common::col(&out, "stiffness_estimate");
            let last = series[series.len() - 1];
            assert!(
                (online.stiffness - last).abs() <= 1e-9 * last.abs(),
                "{online:?} against {last}"
            );
            online_rows.push((
                k,
                c,
                online.stiffness,
                online.stiffness_std,
                online.damping,
                online.damping_std,
                noise,
                tau,
            ));
        }
        let mut params = model_params(&plan.compensator);
        params.forgetting = OFFLINE_FORGETTING;
        let id = identify(
            &params,
            &compensator_context(&plan),
            &plan.sensor.orientation,
            &recording,
        )
        .expect("identify");
        for col in &id.collisions {
            if std::env::var("ID_DEBUG").is_ok() {
                println!(
                    "run {seed} #{} n {} fr {} noise {noise} τs {:.0} ms k {:.0} {:+.2}σ ({:.0}) c {:.0} ĉ {:.1} ± {:.1} ({:+.2}σ)",
                    col.index,
                    col.updates,
                    col.frictional,
                    tau * 1e3,
                    k,
                    (col.stiffness - k) / col.stiffness_std,
                    col.stiffness_std,
                    c,
                    col.damping,
                    col.damping_std,
                    (col.damping - c) / col.damping_std
                );
            }
            rows.push((
                k,
                c,
                col.stiffness,
                col.stiffness_std,
                col.damping,
                col.damping_std,
                noise,
                tau,
            ));
        }
    }
    (rows, online_rows)
}

/// The fraction of `errors` (error, σ) within `n` σ.
fn within(errors: &[(f64, f64)], n: f64) -> f64 {
    errors.iter().filter(|(e, s)| e.abs() <= n * s).count() as f64 / errors.len() as f64
}

#[test]
fn two_sigma_covers_the_truth_in_90_percent_of_random_collisions() {
    let (rows, online) = rows();
    let k: Vec<(f64, f64)> = rows.iter().map(|r| (r.2 - r.0, r.3)).collect();
    let c: Vec<(f64, f64)> = rows.iter().map(|r| (r.4 - r.1, r.5)).collect();
    for (name, e) in [("k", &k), ("c", &c)] {
        println!(
            "{RUNS} random scenes, {} collisions, {name}: within 1σ {:.3}, within 2σ {:.3}",
            e.len(),
            within(e, 1.0),
            within(e, 2.0)
        );
    }
    for (name, e) in [("k", &k), ("c", &c)] {
        let z: Vec<f64> = e
            .iter()
            .zip(&rows)
            .filter(|(_, r)| r.6 > 0.0)
            .map(|((e, s), _)| e / s)
            .collect();
        let mean = z.iter().sum::<f64>() / z.len() as f64;
        let rms = (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt();
        println!("{name}: normalised error mean {mean:+.2}, RMS {rms:.2}");
    }
    // per noise level, for the docs' table
    for noise in [0.0, 0.1, 0.3, 0.5, 1.0] {
        let pick = |f: &dyn Fn(&Row) -> (f64, f64)| -> Vec<(f64, f64)> {
            rows.iter().filter(|r| r.6 == noise).map(f).collect()
        };
        let (k, c) = (pick(&|r| (r.2 - r.0, r.3)), pick(&|r| (r.4 - r.1, r.5)));
        if !k.is_empty() {
            println!(
                "noise {noise} N: {} collisions, k within 2σ {:.3}, c within 2σ {:.3}",
                k.len(),
                within(&k, 2.0),
                within(&c, 2.0)
            );
        }
    }
    let k_online: Vec<(f64, f64)> = online.iter().map(|r| (r.2 - r.0, r.3)).collect();
    let c_online: Vec<(f64, f64)> = online.iter().map(|r| (r.4 - r.1, r.5)).collect();
    for (name, e) in [("k", &k_online), ("c", &c_online)] {
        println!(
            "online (the loop's final estimate), {} runs, {name}: within 1σ {:.3}, within 2σ {:.3}",
            e.len(),
            within(e, 1.0),
            within(e, 2.0)
        );
    }
    for noise in [0.0, 0.1, 0.3, 0.5, 1.0] {
        let pick: Vec<&Row> = online.iter().filter(|r| r.6 == noise).collect();
        let k: Vec<(f64, f64)> = pick.iter().map(|r| (r.2 - r.0, r.3)).collect();
        let c: Vec<(f64, f64)> = pick.iter().map(|r| (r.4 - r.1, r.5)).collect();
        if !k.is_empty() {
            println!(
                "online, noise {noise} N: {} runs, k within 2σ {:.3}, c within 2σ {:.3}",
                k.len(),
                within(&k, 2.0),
                within(&c, 2.0)
            );
        }
    }
    assert!(rows.len() >= 100, "{} collisions", rows.len());
    assert!(within(&k, 2.0) >= 0.90, "k within 2σ: {}", within(&k, 2.0));
    assert!(within(&c, 2.0) >= 0.90, "c within 2σ: {}", within(&c, 2.0));
    // the loop's own final estimate (one per run): measured 0.915 for k and 0.930 for c
    // within 2σ (0.745 and 0.910 with the noise part and the direction bias alone)
    assert!(online.len() >= 150, "{} runs", online.len());
    let (k2, c2) = (within(&k_online, 2.0), within(&c_online, 2.0));
    assert!(k2 >= 0.90, "online k within 2σ: {k2}");
    assert!(c2 >= 0.90, "online c within 2σ: {c2}");
}
