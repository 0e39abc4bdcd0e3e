//! Debug trace of a pida run around the first collision (not part of the product).
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
fn main() {
    let text = std::fs::read_to_string("python/hilcontact/scenarios/paper-table1.toml").unwrap();
    let mut s: hilcontact_core::Scenario = toml::from_str(&text).unwrap();
    s.facility.robot_delay = 0.02;
    s.compensator = CompensatorConfig::Pida(ModelParams::default());
    let out = hilcontact_core::simulate(&s).unwrap();
    let c = |n: &str| out.timeseries.column(n).unwrap().to_vec();
    let (t, e, eo, fa, fc, x, xa, v) = (c("time"), c("energy"), c("observed_energy"), c("applied_force_x"), c("contact_force_x"), c("tip_position_x"), c("actual_tip_position_x"), c("tip_velocity_x"));
    for k in (240..460).step_by(4) {
        println!("{:.3} E {:.5} Eobs {:8.5} applied {:8.2} contact {:8.2} x {:.5} xa {:.5} v {:.4}", t[k], e[k], eo[k], fa[k], -fc[k], x[k]*1e3, xa[k]*1e3, v[k]*1e3);
    }
}
