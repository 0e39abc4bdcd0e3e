//! Passivity that holds (issue 10, item 5): the energy-based compensators never end a
//! collision with more energy than the ideal reference, in 6-DOF, and do not creep over long
//! runs.

mod common;

use common::{preset, table1};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams, TdpaParams};
use hilcontact_core::stop::StopKind;
use hilcontact_core::{simulate, Scenario, SimulationOutput};

fn run(mut s: Scenario, kind: CompensatorConfig) -> SimulationOutput {
    s.compensator = kind;
    simulate(&s).expect("valid scenario")
}

/// The virtual kinetic energy over the reference's, in the middle of the free flight after
/// each complete collision.
fn energy_ratios(out: &SimulationOutput) -> Vec<f64> {
    let time = out.timeseries.column("time").unwrap();
    let energy = out.timeseries.column("energy").unwrap();
    let reference = out.reference.column("energy").unwrap();
    let collisions = &out.metrics.collisions;
    collisions
        .iter()
        .enumerate()
        .filter(|(_, c)| c.collision.complete)
        .map(|(j, c)| {
            let next = collisions
                .get(j + 1)
                .map_or(*time.last().unwrap(), |n| n.collision.start);
            let k = time
                .iter()
                .position(|t| *t >= 0.5 * (c.collision.end + next))
                .unwrap_or(time.len() - 1);
            energy[k] / reference[k]
        })
        .collect()
}

/// `tdpa-admittance` on `oblique-6dof` (tilted wall, offset rod, spinning bodies): at 10, 20
/// and 40 ms no collision ends with more than 1.05 times the reference's energy. Its velocity
/// correction is an impulse at the rod tip sized with the tip's mobility (inertias included),
/// and its observer books what the impulse really removes. (When the correction changed the
/// centres of mass' velocity and was sized with the reduced mass, the energy after the first
/// collision was 1.51, 2.46 and 6.33 times the reference's.)
#[test]
fn tdpa_admittance_never_ends_an_oblique_collision_above_the_reference_energy() {
    for delay in [0.010, 0.020, 0.040] {
        let mut s = preset("oblique-6dof");
        s.facility.robot_delay = delay;
        let out = run(s, CompensatorConfig::TdpaAdmittance(TdpaParams::default()));
        assert_eq!(out.metrics.stop.kind, StopKind::Completed, "{delay}");
        let ratios = energy_ratios(&out);
        assert!(ratios.len() >= 2, "{delay}: {ratios:?}");
        for (n, r) in ratios.iter().enumerate() {
            assert!(
                *r <= 1.05,
                "{} ms, collision {}: energy {r:.3} times the reference's",
                delay * 1e3,
                n + 1
            );
        }
    }
}

/// Mean CoV of the last 20 collisions.
fn late_cov(out: &SimulationOutput) -> f64 {
    let covs: Vec<f64> = out
        .metrics
        .collisions
        .iter()
        .filter_map(|c| c.cov)
        .collect();
    assert!(covs.len() >= 40, "{} collisions", covs.len());
    covs[covs.len() - 20..].iter().sum::<f64>() / 20.0
}

/// The long-run creep: `paper-table1` at 20 ms robot delay, 5 ms sensor delay and 0.2 N of
/// noise for 60 s (53 collisions): the mean CoV of the last 20 collisions is within 3 % of 1.
/// Before the observers covered the whole exchange (the sub-threshold force of a contact's
/// first and last ticks included), carried a deficit left at its end into the next one, and
/// the compensators stopped feeding the sensor's noise to the dynamics in free flight, it was
/// 1.05 for `dac` and the TDPAs here, and 1.18 after 180 s (docs/energy.md, Limits).
#[test]
fn no_creep_over_a_minute_of_collisions() {
    let mut s = table1(0.020, 0.005);
    s.facility.sensor_noise = 0.2;
    s.simulation.duration = 60.0;
    for kind in [
        CompensatorConfig::Dac(ModelParams::default()),
        CompensatorConfig::Pida(ModelParams::default()),
        CompensatorConfig::TdpaImpedance(TdpaParams::default()),
        CompensatorConfig::TdpaAdmittance(TdpaParams::default()),
    ] {
        let name = kind.kind();
        let out = run(s.clone(), kind);
        let cov = late_cov(&out);
        eprintln!("{name}: mean CoV of the last 20 collisions {cov:.4}");
        assert!((cov - 1.0).abs() <= 0.03, "{name}: {cov:.4}");
        let energy = out.timeseries.column("energy").unwrap();
        let reference = out.reference.column("energy").unwrap();
        let ratio = energy.last().unwrap() / reference.last().unwrap();
        assert!(
            (ratio - 1.0).abs() <= 0.06,
            "{name}: final energy {ratio:.4}"
        );
    }
}
