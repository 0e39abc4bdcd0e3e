//! Runs a preset scenario file and prints its collisions:
//! `cargo run --release --example run_preset -- python/hilcontact/scenarios/paper-table1.toml [key=value ...]`
//! with keys `robot_delay`, `sensor_delay`, `round_delays` (true|false), `noise` (N), `seed`, `kind` (compensator), `mode` (align|lead),
//! `observer` (work|paper), `controller` (normal|paper), `ratio` (force_ratio_max), `duration` (s), `servo` (Hz), `law` (linear|hunt-crossley), `stiffness`, `damping`, `exponent`, `repeat` (more runs, metrics only as a sweep runs them, for profiling: `perf record -g`
//! on this example), `tables` (true: the repeated runs keep their time series, as `hc.simulate`).

use hilcontact_core::compensator::{
    CompensatorConfig, ControllerMode, DelayMode, ModelParams, ObserverMode,
};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .map(String::as_str)
        .unwrap_or("python/hilcontact/scenarios/paper-table1.toml");
    let text = std::fs::read_to_string(path).expect("read scenario");
    let mut s: hilcontact_core::Scenario = toml::from_str(&text).expect("parse scenario");
    let (mut kind, mut mode, mut observer) =
        ("none".to_string(), DelayMode::Align, ObserverMode::Work);
    let mut repeat = 1usize;
    let mut tables = false;
    let mut ratio = ModelParams::default().force_ratio_max;
    let mut controller = ControllerMode::Normal;
    for arg in &args[2.min(args.len())..] {
        let (key, value) = arg.split_once('=').expect("key=value");
        match key {
            "robot_delay" => s.facility.robot_delay = value.parse().expect("s"),
            "sensor_delay" => s.facility.sensor_delay = value.parse().expect("s"),
            "noise" => s.facility.sensor_noise = value.parse().expect("N"),
            "seed" => s.facility.seed = value.parse().expect("integer"),
            "round_delays" => s.facility.round_delays = value.parse().expect("true or false"),
            "kind" => kind = value.to_string(),
            "repeat" => repeat = value.parse().expect("integer"),
            "tables" => tables = value.parse().expect("true or false"),
            "ratio" => ratio = value.parse().expect("force_ratio_max"),
            "duration" => s.simulation.duration = value.parse().expect("s"),
            "servo" => s.facility.servo_frequency = value.parse().expect("Hz"),
            "stiffness" => s.contact.stiffness = value.parse().expect("N/m or N/m^n"),
            "damping" => s.contact.damping = value.parse().expect("N s/m"),
            "exponent" => s.contact.exponent = value.parse().expect("n"),
            "law" => {
                s.contact.model = match value {
                    "hunt-crossley" => hilcontact_core::config::ContactModelKind::HuntCrossley,
                    _ => hilcontact_core::config::ContactModelKind::Linear,
                }
            }
            "controller" => {
                controller = if value == "paper" {
                    ControllerMode::Paper
                } else {
                    ControllerMode::Normal
                }
            }
            "mode" => {
                mode = if value == "lead" {
                    DelayMode::Lead
                } else {
                    DelayMode::Align
                }
            }
            "observer" => {
                observer = if value == "paper" {
                    ObserverMode::Paper
                } else {
                    ObserverMode::Work
                }
            }
            _ => panic!("unknown key {key}"),
        }
    }
    let model = ModelParams {
        delay_mode: mode,
        observer,
        controller,
        force_ratio_max: ratio,
        ..ModelParams::default()
    };
    s.compensator = match CompensatorConfig::from_kind(&kind) {
        Some(CompensatorConfig::Pic(_)) => CompensatorConfig::Pic(model),
        Some(CompensatorConfig::Dac(_)) => CompensatorConfig::Dac(model),
        Some(CompensatorConfig::Pida(_)) => CompensatorConfig::Pida(model),
        // the file's own table when it is of this kind (e.g. model-mediated prior walls)
        Some(other) if other.kind() == s.compensator.kind() => s.compensator.clone(),
        Some(other) => other,
        None => panic!("unknown compensator {kind}"),
    };
    let start = std::time::Instant::now();
    let out = hilcontact_core::simulate(&s).expect("simulate");
    for _ in 1..repeat {
        if tables {
            // as `hc.simulate` runs it: with the time series
            std::hint::black_box(hilcontact_core::simulate(&s).expect("simulate"));
        } else {
            // as a sweep runs it: summary only, no time series
            std::hint::black_box(hilcontact_core::simulate_metrics(&s).expect("simulate"));
        }
    }
    let elapsed = start.elapsed() / repeat as u32;
    let m = &out.metrics;
    let fmt = |x: Option<f64>| x.map_or("-".to_string(), |v| format!("{v:.3}"));
    println!(
        "{} [{}] status {:?} in {:.1} ms; CoV {}; CoF {}; id {:?}",
        m.scenario,
        m.compensator,
        m.status,
        elapsed.as_secs_f64() * 1e3,
        m.collisions
            .iter()
            .map(|c| fmt(c.cov))
            .collect::<Vec<_>>()
            .join(" "),
        m.collisions
            .iter()
            .map(|c| fmt(c.cof))
            .collect::<Vec<_>>()
            .join(" "),
        m.identification.as_ref().map(|i| (
            format!("k {:.3}%", i.stiffness_error * 100.0),
            format!("c {:.1} N s/m", i.damping_error)
        ))
    );
    println!(
        "  velocity error {}; impulse {}; angular impulse {}; lost {:?}; extra {:?}",
        m.collisions
            .iter()
            .map(|c| fmt(c.velocity_error))
            .collect::<Vec<_>>()
            .join(" "),
        m.collisions
            .iter()
            .map(|c| fmt(c.impulse_ratio))
            .collect::<Vec<_>>()
            .join(" "),
        m.collisions
            .iter()
            .map(|c| fmt(c.angular_impulse_ratio))
            .collect::<Vec<_>>()
            .join(" "),
        m.lost_collisions,
        m.extra_collisions,
    );
    let covs: Vec<f64> = m.collisions.iter().filter_map(|c| c.cov).collect();
    if covs.len() > 20 {
        let last = &covs[covs.len() - 20..];
        println!(
            "  {} collisions; mean CoV of the last 20: {:.4}; energy final / reference final {:.4}",
            covs.len(),
            last.iter().sum::<f64>() / 20.0,
            m.energy.r#final / m.energy.reference_final
        );
    }
    if let Some(reason) = &m.reason {
        println!("  {reason}");
    }
    // every bit of both tables and of the metrics, to tell a pure optimisation (same digest)
    let mut digest = 0xcbf2_9ce4_8422_2325u64; // FNV-1a
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            digest = (digest ^ u64::from(*b)).wrapping_mul(0x0100_0000_01b3);
        }
    };
    for table in [&out.timeseries, &out.reference] {
        for (name, values) in &table.columns {
            eat(name.as_bytes());
            for v in values {
                eat(&v.to_bits().to_le_bytes());
            }
        }
    }
    eat(serde_json::to_string(m).expect("metrics").as_bytes());
    println!("  digest of the tables and metrics: {digest:016x}");
}
