//! Runs a preset scenario file and prints its collisions: `cargo run --release --example
//! run_preset -- python/hilcontact/scenarios/paper-table1.toml [robot_delay_s]`.

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args.get(1).map(String::as_str).unwrap_or("python/hilcontact/scenarios/paper-table1.toml");
    let text = std::fs::read_to_string(path).expect("read scenario");
    let mut s: hilcontact_core::Scenario = toml::from_str(&text).expect("parse scenario");
    if let Some(d) = args.get(2) {
        s.facility.robot_delay = d.parse().expect("robot delay, s");
    }
    let start = std::time::Instant::now();
    let out = hilcontact_core::simulate(&s).expect("simulate");
    let elapsed = start.elapsed();
    let m = &out.metrics;
    println!("{} [{}] status {:?} {:?} in {:.2} ms", m.scenario, m.compensator, m.status, m.reason, elapsed.as_secs_f64() * 1e3);
    for c in &m.collisions {
        let r = m.reference_collisions.get(c.collision.index - 1);
        println!(
            "#{} {:.3}-{:.3} s peak {:8.2} N (ref {:8.2}) rebound {:7.3} mm/s (ref {:7.3}) CoV {:?} CoF {:?}",
            c.collision.index,
            c.collision.start,
            c.collision.end,
            c.collision.peak_force,
            r.map_or(f64::NAN, |r| r.peak_force),
            c.collision.rebound_speed.unwrap_or(f64::NAN) * 1e3,
            r.and_then(|r| r.rebound_speed).unwrap_or(f64::NAN) * 1e3,
            c.cov,
            c.cof
        );
    }
    println!("energy {:?}", m.energy);
}
