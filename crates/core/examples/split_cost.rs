//! `cargo run --release --example split_cost -- [repeat]`: the wall time of `paper-table1` with
//! `pida` at 20 ms robot delay split into its reference and its HIL loop (median and minimum of
//! `repeat` runs, µs; the minimum is the measure on a busy machine), and how many ticks of each
//! have a turning relative motion, and how fast (docs/performance.md, issue 25's fourth round).
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_core::sim::{run_hil, run_reference};
use std::time::Instant;

fn median(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0])
}

fn main() {
    let repeat: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse().expect("integer"))
        .unwrap_or(200);
    let path = format!(
        "{}/../../python/hilcontact/scenarios/paper-table1.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let mut s: hilcontact_core::Scenario =
        toml::from_str(&std::fs::read_to_string(path).expect("preset")).expect("parse");
    s.facility.robot_delay = 0.02;
    s.compensator = CompensatorConfig::Pida(ModelParams::default());
    let plan = s.resolve().expect("plan");
    let (mut reference, mut hil) = (Vec::new(), Vec::new());
    for _ in 0..repeat {
        let t = Instant::now();
        std::hint::black_box(run_reference(&plan, false));
        reference.push(t.elapsed().as_secs_f64() * 1e6);
        let t = Instant::now();
        std::hint::black_box(run_hil(&plan, f64::INFINITY, false));
        hil.push(t.elapsed().as_secs_f64() * 1e6);
    }
    println!(
        "reference {:.0?} us, HIL loop {:.0?} us (median, minimum of {repeat})",
        median(reference),
        median(hil)
    );
    let (_, rows) = run_reference(&plan, true);
    let turning = rows
        .iter()
        .filter(|r| r.angular_velocity != nalgebra::Vector3::zeros())
        .count();
    println!(
        "reference ticks with relative angular velocity != 0: {turning} of {}",
        rows.len()
    );
    let run = run_hil(&plan, f64::INFINITY, true);
    let turning = run
        .rows
        .iter()
        .filter(|r| r.angular_velocity != nalgebra::Vector3::zeros())
        .count();
    let largest = run
        .rows
        .iter()
        .map(|r| r.angular_velocity.norm())
        .fold(0.0, f64::max);
    println!(
        "HIL ticks with relative angular velocity != 0: {turning} of {}, largest {largest:e} rad/s",
        run.rows.len()
    );
}
