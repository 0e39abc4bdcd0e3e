//! What the local (restarted) references cost a run (docs/model.md "Metrics"): medians of 15
//! rounds of the reference, the HIL loop, the metrics without and with the local references.
//!
//!     cargo run --release --example local_reference_cost            # the presets as they are
//!     cargo run --release --example local_reference_cost -- comp    # pida 20 ms; rod-in-frame:
//!                                                                   # model-mediated 80 ms, shapes prior
//!
//! (0.2 N noise and 5 ms sensor delay with `comp`.)

use hilcontact_core::compensator::{CompensatorConfig, PriorShapes};
use hilcontact_core::sim::{run_hil, run_metrics, run_reference, trace_metrics};
use hilcontact_core::Scenario;
use std::time::Instant;

fn main() {
    let comp = std::env::args().nth(1).as_deref() == Some("comp");
    for name in ["paper-table1", "rod-in-frame", "oblique-6dof"] {
        let path = format!(
            "{}/../../python/hilcontact/scenarios/{name}.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let text = std::fs::read_to_string(&path).expect("preset");
        let mut s: Scenario = toml::from_str(&text).expect("scenario");
        if comp {
            let mm = name == "rod-in-frame";
            s.facility.robot_delay = if mm { 0.08 } else { 0.02 };
            s.facility.sensor_delay = 0.005;
            s.facility.sensor_noise = 0.2;
            let kind = if mm { "model-mediated" } else { "pida" };
            s.compensator = CompensatorConfig::from_kind(kind).expect("kind");
            if let CompensatorConfig::ModelMediated(p) = &mut s.compensator {
                p.prior_shapes = PriorShapes::Geometry;
            }
        }
        let plan = s.resolve().expect("plan");
        let (mut tr, mut th, mut tg, mut tl) = (vec![], vec![], vec![], vec![]);
        let mut status = None;
        for _ in 0..15 {
            let t = Instant::now();
            let (reference, _) = run_reference(&plan, false);
            tr.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let bound = hilcontact_core::metrics::divergence_bound(
                plan.divergence_energy_ratio,
                reference.energy[0],
                &reference.energy,
            );
            let hil = run_hil(&plan, bound, false);
            th.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let global = trace_metrics(
                &plan,
                &reference,
                &hil.trace,
                hil.estimates_contact,
                hil.stop,
            );
            tg.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let local = run_metrics(&plan, &reference, &hil);
            tl.push(t.elapsed().as_secs_f64());
            assert_eq!(global.status, local.status);
            status = Some(local.status);
        }
        let med = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2] * 1e3
        };
        let (r, h, g, l) = (med(&mut tr), med(&mut th), med(&mut tg), med(&mut tl));
        println!(
            "{name} ({:?}): reference {r:.2} ms, HIL loop {h:.2} ms, metrics {g:.3} ms, with the local \
             references {l:.3} ms: +{:.3} ms = {:.1} % of the run",
            status,
            l - g,
            100.0 * (l - g) / (r + h + g)
        );
    }
}
