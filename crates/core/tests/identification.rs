//! Offline identification (`identify.rs`): do the stated uncertainties cover the errors?
//!
//! Over many noisy simulated runs (seeds), the fraction of collisions whose true stiffness and
//! damping lie within the stated ±1σ and ±2σ must be about the Gaussian 68.3 % and 95.4 %.

mod common;

use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_core::hil::compensator_context;
use hilcontact_core::identify::{identify, model_params, OFFLINE_FORGETTING};
use hilcontact_core::replay::Recording;
use hilcontact_core::sim::simulate_plan;

/// Seeds per case.
const SEEDS: u64 = 50;

/// Per collision over `SEEDS` runs of `preset` (pida, the given noise, N): the normalised
/// errors `(k̂ − k)/σ_k` and `(ĉ − c)/σ_c`.
fn normalised_errors(preset: &str, noise: f64) -> (Vec<f64>, Vec<f64>) {
    let (mut zk, mut zc) = (Vec::new(), Vec::new());
    for seed in 1..=SEEDS {
        let mut scenario = common::preset(preset);
        scenario.compensator = CompensatorConfig::from_kind("pida").expect("pida");
        scenario.facility.sensor_noise = noise;
        scenario.facility.seed = seed;
        let (k, c) = (scenario.contact.stiffness, scenario.contact.damping);
        let plan = scenario.resolve().expect("plan");
        let table = simulate_plan(&plan).timeseries;
        let recording = Recording::from_table(&table, false).expect("recording");
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
                    "seed {seed} #{} n {} k {:.1} ± {:.1} ({:+.2}σ) c {:.1} ± {:.1} ({:+.2}σ)",
                    col.index,
                    col.updates,
                    col.stiffness,
                    col.stiffness_std,
                    (col.stiffness - k) / col.stiffness_std,
                    col.damping,
                    col.damping_std,
                    (col.damping - c) / col.damping_std
                );
            }
            zk.push((col.stiffness - k) / col.stiffness_std);
            zc.push((col.damping - c) / col.damping_std);
        }
    }
    (zk, zc)
}

fn within(z: &[f64], n: f64) -> f64 {
    z.iter().filter(|z| z.abs() <= n).count() as f64 / z.len() as f64
}

#[test]
fn stated_uncertainties_cover_the_errors_over_50_noisy_runs() {
    // measured (this test's output): k within 1σ / 2σ: 0.656 / 0.928 at 0.2 N, 0.576 / 0.892
    // at 0.5 N (Gaussian: 0.683 / 0.954); the filter's own √P had every collision within 1σ.
    // 250 collisions: a binomial fraction's σ is about 0.03, the bounds allow 3-4 of them.
    for noise in [0.2, 0.5] {
        let (zk, zc) = normalised_errors("paper-exp-2.64hz", noise);
        for (name, z) in [("k", &zk), ("c", &zc)] {
            let (one, two) = (within(z, 1.0), within(z, 2.0));
            println!(
                "paper-exp-2.64hz noise {noise} N, {name}: {} collisions, within 1σ {one:.3}, 2σ {two:.3}",
                z.len()
            );
        }
        assert!(zk.len() >= 200, "{}", zk.len());
        let (one, two) = (within(&zk, 1.0), within(&zk, 2.0));
        assert!((0.55..=0.82).contains(&one), "k within 1σ: {one}");
        assert!((0.86..=0.995).contains(&two), "k within 2σ: {two}");
    }
    // the damping: the projection on the noisy direction F/|F| biased ĉ low (about −15 N·s/m
    // at 0.2 N and −60 at 0.5 N); `identify` now removes that bias (`direction_bias`) and the
    // levels the detector truncates: c within 2σ 0.872 at 0.2 N and 0.896 at 0.5 N (before:
    // 0.824 and 0.672)
    for noise in [0.2, 0.5] {
        let (_, zc) = normalised_errors("paper-exp-2.64hz", noise);
        let two = within(&zc, 2.0);
        assert!(two >= 0.85, "c within 2σ at {noise} N: {two}");
    }
}
