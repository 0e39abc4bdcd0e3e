//! `cargo bench -p hilcontact-core --bench simulate`: one whole `paper-table1` run (5.5 s
//! simulated, 1 kHz control, 10 kHz plant, reference included), and its two halves.

use criterion::{criterion_group, criterion_main, Criterion};
use hilcontact_core::sim::{run_hil, run_reference};
use hilcontact_core::world::TwoBodySystem;
use hilcontact_core::{simulate, Scenario};
use std::hint::black_box;

fn preset(name: &str) -> Scenario {
    let path = format!("{}/../../python/hilcontact/scenarios/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    toml::from_str(&std::fs::read_to_string(path).expect("preset")).expect("parse")
}

fn bench(c: &mut Criterion) {
    let s = preset("paper-table1");
    let system = TwoBodySystem::from_scenario(&s).expect("system");
    c.bench_function("paper-table1 simulate (HIL + reference + metrics)", |b| b.iter(|| simulate(black_box(&s)).expect("run")));
    c.bench_function("paper-table1 reference only", |b| b.iter(|| run_reference(black_box(&s), &system).expect("run")));
    c.bench_function("paper-table1 HIL loop only", |b| b.iter(|| run_hil(black_box(&s), &system, f64::INFINITY).expect("run")));
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
