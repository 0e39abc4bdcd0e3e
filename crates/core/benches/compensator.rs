//! `cargo bench -p hilcontact-core --bench compensator`: one compensator step (`pida`, then
//! `dac` and `tdpa-impedance` for scale, and `model-mediated`, whose contact-end fits are
//! spread over the steps) on the inputs of a real run: `paper-table1` at 20 ms
//! robot delay with 0.2 N sensor noise, 5.5 s, recorded once from the HIL loop and replayed
//! tick after tick (one criterion iteration = one step; a fresh compensator per sample); and
//! the same over the ticks in contact only, where identification and the energy work run.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use hilcontact_core::compensator::{
    CompensatorConfig, CompensatorContext, CompensatorInput, ModelMediatedParams, ModelParams,
    TdpaParams,
};
use hilcontact_core::facility::FacilityModel;
use hilcontact_core::hil::VirtualDynamics;
use hilcontact_core::Scenario;

fn preset(name: &str) -> Scenario {
    let path = format!(
        "{}/../../python/hilcontact/scenarios/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    toml::from_str(&std::fs::read_to_string(path).expect("preset")).expect("parse")
}

/// The compensator inputs of every tick of a `pida` run, and its context.
fn recorded_inputs(s: &Scenario) -> (Vec<CompensatorInput>, CompensatorContext) {
    let plan = s.resolve().expect("plan");
    let system = &plan.system;
    let mut virt = VirtualDynamics::new(&plan);
    let mut facility = FacilityModel::new(&plan, &virt.command());
    let mut inputs = Vec::with_capacity(plan.ticks);
    for _ in 0..plan.ticks {
        let m = facility.measure();
        inputs.push(virt.input(&m));
        let out = virt.compensate(&m);
        virt.integrate(&out);
        facility.advance(&virt.command());
    }
    let context = CompensatorContext {
        period: s.simulation.period,
        sensor_delay_ticks: plan.facility.sensor_delay_ticks,
        sensor_origin: system.sensor_origin,
        reduced_mass: system.reduced_mass(),
    };
    (inputs, context)
}

fn bench(c: &mut Criterion) {
    let mut s = preset("paper-table1");
    s.facility.robot_delay = 0.02;
    s.facility.sensor_noise = 0.2;
    s.compensator = CompensatorConfig::Pida(ModelParams::default());
    let (inputs, context) = recorded_inputs(&s);
    let kinds = [
        ("pida", CompensatorConfig::Pida(ModelParams::default())),
        ("dac", CompensatorConfig::Dac(ModelParams::default())),
        (
            "tdpa-impedance",
            CompensatorConfig::TdpaImpedance(TdpaParams::default()),
        ),
        (
            "model-mediated",
            CompensatorConfig::ModelMediated(ModelMediatedParams::default()),
        ),
    ];
    // the ticks in contact only (measured force above 3 N): identification and energy work
    let first_contact = inputs
        .iter()
        .position(|i| i.measured.force.norm() > 3.0)
        .expect("a contact");
    let contact: Vec<usize> = (first_contact..inputs.len())
        .filter(|&i| inputs[i].measured.force.norm() > 3.0)
        .collect();
    for (name, config) in kinds {
        c.bench_function(
            &format!("{name} step (paper-table1, 20 ms, noisy inputs)"),
            |b| {
                b.iter_custom(|iters| {
                    let mut compensator = config.build(&context);
                    let start = Instant::now();
                    for i in 0..iters as usize {
                        black_box(compensator.step(black_box(&inputs[i % inputs.len()])));
                    }
                    start.elapsed()
                })
            },
        );
        c.bench_function(&format!("{name} step in contact"), |b| {
            b.iter_custom(|iters| {
                let mut compensator = config.build(&context);
                for input in &inputs[..first_contact] {
                    compensator.step(input); // reach the first contact as the loop does
                }
                let start = Instant::now();
                for i in 0..iters as usize {
                    black_box(compensator.step(black_box(&inputs[contact[i % contact.len()]])));
                }
                start.elapsed()
            })
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(50).measurement_time(Duration::from_secs(3));
    targets = bench
}
criterion_main!(benches);
