//! Where a compensator's energy goes, collision by collision:
//! `cargo run --release --example energy_audit -- SCENARIO.toml kind=K [robot_delay=s]
//! [sensor_delay=s] [noise=N] [duration=s] [last=n]`.
//!
//! For every exchange with the wall (from the first tick a force acts on the virtual dynamics
//! or the compensator's observer is on, to the last), it prints the virtual kinetic energy
//! before and after (and after over the reference's), and splits its change into: before the
//! observer's window opens, inside the window (the observer's own account `−E` against the
//! real change), and after it closes. A sound observer has `inside − (−E) ≈ 0`; whatever the
//! `before` and `after` columns hold is energy no window counts.

use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_core::facility::{Facility, FacilityModel};
use hilcontact_core::hil::HilStep;
use hilcontact_core::sim::run_reference;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let text = std::fs::read_to_string(&args[1]).expect("read scenario");
    let mut s: hilcontact_core::Scenario = toml::from_str(&text).expect("parse scenario");
    let mut last = usize::MAX;
    for arg in &args[2..] {
        let (key, value) = arg.split_once('=').expect("key=value");
        match key {
            "robot_delay" => s.facility.robot_delay = value.parse().expect("s"),
            "sensor_delay" => s.facility.sensor_delay = value.parse().expect("s"),
            "noise" => s.facility.sensor_noise = value.parse().expect("N"),
            "duration" => s.simulation.duration = value.parse().expect("s"),
            "kind" => s.compensator = CompensatorConfig::from_kind(value).expect("kind"),
            "last" => last = value.parse().expect("n"),
            _ => panic!("unknown key {key}"),
        }
    }
    let plan = s.resolve().expect("resolve");
    let (reference, _) = run_reference(&plan, false);
    let reference_energy = reference.energy[0];
    let mut step = HilStep::new(&plan, f64::INFINITY);
    let mut facility = FacilityModel::new(&plan, &step.command());
    // per tick: kinetic energy, observed energy (NaN out of the window), |applied force|
    let mut ke = Vec::new();
    let mut obs = Vec::new();
    let mut applied = Vec::new();
    let mut rows = Vec::new();
    for k in 0..=plan.ticks {
        let m = facility.measure();
        let (row, stop) = step.observe(k, &m, Some(facility.physical_contact()));
        ke.push(row.energy);
        obs.push(row.observed_energy);
        applied.push(row.applied_force.norm());
        rows.push(row);
        if stop.is_some() {
            break;
        }
        match step.advance(k) {
            Ok(c) => facility.advance(&c),
            Err(_) => break,
        }
    }
    let n = ke.len();
    let active = |k: usize| applied[k] > 1.0 || (obs[k].is_finite() && obs[k] != 0.0);
    let mut episodes = Vec::new();
    let mut k = 0;
    while k < n {
        if !active(k) {
            k += 1;
            continue;
        }
        let start = k;
        // an exchange ends after 50 idle ticks (a noisy sensor's force is never zero)
        let mut idle = 0;
        while k < n && idle < 50 {
            idle = if active(k) { 0 } else { idle + 1 };
            k += 1;
        }
        k -= idle;
        episodes.push((start, k.min(n - 1))); // k: first tick after, its KE is the result
    }
    println!(
        "reference energy {reference_energy:.6} J; {} exchanges",
        episodes.len()
    );
    println!("   #   t(s)   KE before   KE after  after/ref |  before-win  in-win(real) in-win(-E)  mismatch  after-win | E_end");
    // over the run: what the exchanges and the free flights between them did to the energy
    let exchanges: f64 = episodes.iter().map(|&(a, b)| ke[b] - ke[a]).sum();
    let flights: f64 = episodes.windows(2).map(|w| ke[w[1].0] - ke[w[0].1]).sum();
    println!(
        "sum over exchanges {exchanges:+.6} J (mean {:+.3e}), over free flights {flights:+.6} J; final/ref {:.4}",
        exchanges / episodes.len().max(1) as f64,
        ke[n - 1] / reference_energy
    );
    // ticks with no physical contact and no force but the sensor's noise
    let noise: f64 = (0..n - 1)
        .filter(|&i| rows[i].contact_force.norm() == 0.0 && rows[i].measured_force.norm() < 1.5)
        .map(|i| ke[i + 1] - ke[i])
        .sum();
    println!("sum over ticks of noise alone {noise:+.6} J");
    let skip = episodes.len().saturating_sub(last);
    for (j, &(a, b)) in episodes.iter().enumerate().skip(skip) {
        // the window: ticks the observer runs (an observer that reports 0 out of contact
        // opens at the tick before its first non-zero energy)
        let mut window: Vec<usize> = (a..b)
            .filter(|&i| obs[i].is_finite() && obs[i] != 0.0)
            .collect();
        if let Some(&first) = window.first() {
            if first > 0 && obs[first - 1] == 0.0 {
                window.insert(0, first - 1);
            }
        }
        let (w0, w1) = match (window.first(), window.last()) {
            (Some(&x), Some(&y)) => (x, y),
            _ => (a, a),
        };
        let e_end = if window.is_empty() { 0.0 } else { obs[w1] };
        let before = ke[w0] - ke[a];
        let inside = ke[w1] - ke[w0];
        let after = ke[b] - ke[w1];
        println!(
            "{:4} {:6.3} {:10.6} {:10.6} {:9.4} | {:+10.6} {:+12.6} {:+10.6} {:+10.6} {:+10.6} | {:+.6}",
            j + 1,
            a as f64 * plan.period,
            ke[a],
            ke[b],
            ke[b] / reference_energy,
            before,
            inside,
            -e_end,
            inside + e_end,
            after,
            e_end,
        );
        if std::env::var("AUDIT_TICKS").is_ok() {
            for i in a..(b + 3).min(n - 1) {
                let r = &rows[i];
                println!(
                    "    {i} dKE {:+.3e} dE {:+.3e} miss {:+.3e} |F| {:.1} Fmea {:.2?} Fc {:.1} Fa {:.2?} v {:.4?} w {:.4?} E {:+.3e}",
                    ke[i + 1] - ke[i],
                    obs[i + 1] - obs[i],
                    ke[i + 1] - ke[i] + obs[i + 1] - obs[i],
                    applied[i],
                    r.measured_force,
                    r.contact_force.norm(),
                    r.applied_force,
                    r.tip_velocity,
                    r.angular_velocity,
                    obs[i]
                );
            }
        }
    }
}
