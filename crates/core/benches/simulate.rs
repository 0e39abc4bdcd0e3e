//! `cargo bench -p hilcontact-core --bench simulate`: one whole `paper-table1` run with `pida`
//! at 20 ms robot delay (5.5 s simulated, 1 kHz control, 10 kHz plant, reference included),
//! as a sweep runs it (metrics only; and with its reference computed once for the batch's runs
//! that share it) and with its time series, and its two halves; and the
//! shapes' cost: `rod-in-frame` (6 s, 1 kHz, a cylinder rod against four boxes with friction)
//! against `paper-table1` as they are (`none`, 10 ms), the bound being 3×.

use criterion::{criterion_group, criterion_main, Criterion};
use hilcontact_core::compensator::{CompensatorConfig, ModelMediatedParams, ModelParams};
use hilcontact_core::sim::{run_hil, run_reference, simulate_plan_metrics_with_reference};
use hilcontact_core::{simulate, simulate_metrics, Scenario};
use std::hint::black_box;

fn preset(name: &str) -> Scenario {
    let path = format!(
        "{}/../../python/hilcontact/scenarios/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    toml::from_str(&std::fs::read_to_string(path).expect("preset")).expect("parse")
}

fn bench(c: &mut Criterion) {
    let mut s = preset("paper-table1");
    s.facility.robot_delay = 0.02;
    s.compensator = CompensatorConfig::Pida(ModelParams::default());
    let plan = s.resolve().expect("plan");
    c.bench_function(
        "paper-table1 pida 20 ms: metrics only (a sweep's run)",
        |b| b.iter(|| simulate_metrics(black_box(&s)).expect("run")),
    );
    let mut m = s.clone();
    m.compensator = CompensatorConfig::ModelMediated(ModelMediatedParams::default());
    c.bench_function(
        "paper-table1 model-mediated 20 ms: metrics only (a sweep's run)",
        |b| b.iter(|| simulate_metrics(black_box(&m)).expect("run")),
    );
    c.bench_function("paper-table1 pida 20 ms: with time series", |b| {
        b.iter(|| simulate(black_box(&s)).expect("run"))
    });
    c.bench_function("paper-table1: reference only", |b| {
        b.iter(|| run_reference(black_box(&plan), false))
    });
    c.bench_function("paper-table1 pida 20 ms: HIL loop only", |b| {
        b.iter(|| run_hil(black_box(&plan), f64::INFINITY, false))
    });
    // a sweep's run whose reference the batch computed once for every run that shares it
    let reference = run_reference(&plan, false).0;
    c.bench_function(
        "paper-table1 pida 20 ms: metrics only, the reference shared (a sweep's run)",
        |b| b.iter(|| simulate_plan_metrics_with_reference(black_box(&plan), &reference)),
    );
    let table1 = preset("paper-table1");
    c.bench_function("paper-table1 as it is: metrics only", |b| {
        b.iter(|| simulate_metrics(black_box(&table1)).expect("run"))
    });
    let rod = preset("rod-in-frame");
    c.bench_function("rod-in-frame as it is: metrics only", |b| {
        b.iter(|| simulate_metrics(black_box(&rod)).expect("run"))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = bench
}
criterion_main!(benches);
