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
use hilcontact_core::hil::compensator_context;
use hilcontact_core::sim::compensator_inputs;
use hilcontact_core::Scenario;

fn preset(name: &str) -> Scenario {
    let path = format!(
        "{}/../../python/hilcontact/scenarios/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    toml::from_str(&std::fs::read_to_string(path).expect("preset")).expect("parse")
}

/// The compensator inputs of every tick of a run of `s` (its own compensator), and the
/// context of its compensators.
fn recorded_inputs(s: &Scenario) -> (Vec<CompensatorInput>, CompensatorContext) {
    let plan = s.resolve().expect("plan");
    (compensator_inputs(&plan), compensator_context(&plan))
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

/// The contact-end fit of `model-mediated` on one contact's samples (linear and
/// Hunt-Crossley, `law = "auto"`): the longest single step of that compensator.
fn bench_fit(c: &mut Criterion) {
    use hilcontact_core::compensator::{fit_contact, LawForm, Sample};
    use nalgebra::Vector3;
    let n = Vector3::new(-1.0, 0.0, 0.0);
    let (k, omega, depth) = (176275.0, 25.1, 0.0008);
    // one 125 ms contact at 1 kHz: a half sine of penetration
    let samples: Vec<Sample> = (0..125)
        .map(|i| {
            let s = omega * i as f64 * 1e-3;
            let (d, rate) = (depth * s.sin(), depth * omega * s.cos());
            Sample {
                force: -n * (k * d), // on the frame, into the wall
                position: Vector3::new(0.01 + d, 0.0, 0.0),
                velocity: Vector3::new(rate, 0.0, 0.0),
            }
        })
        .collect();
    let sum: Vector3<f64> = samples.iter().map(|s| s.force).sum();
    for form in [LawForm::Linear, LawForm::Auto] {
        c.bench_function(
            &format!("model-mediated fit of one contact ({form:?})"),
            |b| b.iter(|| fit_contact(black_box(&samples), &sum, form)),
        );
    }
}

criterion_group! {
    name = fits;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(2));
    targets = bench_fit
}
criterion_main!(benches, fits);
