//! The compensators against the numbers (paper Table 1, the noisy case, the damped
//! experiments, long delays) and a property test over random scenarios.

mod common;

use common::{cofs, col, covs, oblique_6dof_cases, preset, table1};
use hilcontact_core::compensator::{CompensatorConfig, DelayMode, ModelParams, TdpaParams};
use hilcontact_core::stop::StopKind;
use hilcontact_core::{simulate, Scenario, SimulationOutput};
use proptest::prelude::*;

fn kinds() -> Vec<CompensatorConfig> {
    let m = ModelParams::default();
    let t = TdpaParams::default();
    vec![
        CompensatorConfig::Pic(m.clone()),
        CompensatorConfig::Dac(m.clone()),
        CompensatorConfig::Pida(m),
        CompensatorConfig::TdpaImpedance(t.clone()),
        CompensatorConfig::TdpaAdmittance(t),
    ]
}

fn run(mut s: Scenario, kind: CompensatorConfig) -> SimulationOutput {
    s.compensator = kind;
    simulate(&s).expect("valid scenario")
}

fn stiffness_error(out: &SimulationOutput) -> f64 {
    out.metrics
        .identification
        .as_ref()
        .expect("identified")
        .stiffness_error
}

#[test]
fn without_delay_every_compensator_is_the_identity() {
    for kind in kinds() {
        let name = kind.kind();
        let out = run(table1(0.0, 0.0), kind);
        let (measured, applied) = (col(&out, "measured_force_x"), col(&out, "applied_force_x"));
        let worst = measured
            .iter()
            .zip(applied)
            .map(|(m, a)| (m - a).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 0.01 * 140.28,
            "{name}: applied differs from measured by {worst} N"
        );
        for (cov, cof) in covs(&out).iter().zip(cofs(&out)) {
            assert!(
                (cov - 1.0).abs() < 0.005 && (cof - 1.0).abs() < 0.005,
                "{name}: CoV {cov} CoF {cof}"
            );
        }
    }
}

#[test]
fn pida_reaches_the_paper_numbers_on_table1() {
    for (delay, cof_max) in [(0.010, 1.10), (0.020, 1.20)] {
        let out = run(
            table1(delay, 0.0),
            CompensatorConfig::Pida(ModelParams::default()),
        );
        let (cov, cof) = (covs(&out), cofs(&out));
        assert_eq!(cov.len(), 5, "{delay}: five collisions with a rebound");
        assert!(
            cov.iter().all(|c| (0.97..=1.05).contains(c)),
            "{delay}: CoV {cov:?}"
        );
        assert!(cof.iter().all(|c| *c <= cof_max), "{delay}: CoF {cof:?}");
        // paper: 0.43 % at 10 ms
        assert!(
            stiffness_error(&out) < 0.005,
            "{delay}: stiffness error {}",
            stiffness_error(&out)
        );
    }
}

#[test]
fn pic_and_dac_show_the_paper_trade_offs() {
    let pic = run(
        table1(0.020, 0.0),
        CompensatorConfig::Pic(ModelParams::default()),
    );
    let dac = run(
        table1(0.010, 0.0),
        CompensatorConfig::Dac(ModelParams::default()),
    );
    // PIC cannot remove the energy of the contact's onset: rebounds grow
    let c = covs(&pic);
    assert!(
        c.windows(2).all(|w| w[1] > w[0]) && c[0] > 1.05,
        "PIC CoV {c:?}"
    );
    // DAC: velocity right, force too high (paper: CoV ≈ 1, CoF ≈ 1.28 at 10 ms)
    assert!(
        covs(&dac).iter().all(|c| (c - 1.0).abs() < 0.02),
        "DAC CoV {:?}",
        covs(&dac)
    );
    assert!(
        cofs(&dac).iter().all(|c| *c > 1.15),
        "DAC CoF {:?}",
        cofs(&dac)
    );
}

fn noisy(mode: DelayMode) -> SimulationOutput {
    let mut s = table1(0.020, 0.005);
    s.facility.sensor_noise = 0.2;
    run(
        s,
        CompensatorConfig::Pida(ModelParams {
            delay_mode: mode,
            ..ModelParams::default()
        }),
    )
}

#[test]
fn pida_with_noise_and_sensor_delay_aligns_instead_of_differentiating() {
    let out = noisy(DelayMode::Align);
    assert_eq!(out.metrics.stop.kind, StopKind::Completed); // ran to its end
    assert!(
        stiffness_error(&out) < 0.01,
        "stiffness error {}",
        stiffness_error(&out)
    );
    let (cov, cof) = (covs(&out), cofs(&out));
    assert_eq!(cov.len(), 5);
    assert!(cov.iter().all(|c| (0.95..=1.05).contains(c)), "CoV {cov:?}");
    assert!(cof.iter().all(|c| *c <= 1.30), "CoF {cof:?}");
    // the paper's lead filter differentiates the noise: identification is far off (9x with
    // the noise-aware contact detection, which keeps the noisiest samples out)
    let lead = noisy(DelayMode::Lead);
    assert!(
        stiffness_error(&lead) > 5.0 * stiffness_error(&out),
        "lead {} vs align {}",
        stiffness_error(&lead),
        stiffness_error(&out)
    );
}

#[test]
fn pida_reproduces_the_damped_experiments_and_tdpa_does_not() {
    for name in ["paper-exp-2.64hz", "paper-exp-1.93hz"] {
        let out = run(
            preset(name),
            CompensatorConfig::Pida(ModelParams::default()),
        );
        let cov = covs(&out);
        assert!(
            cov.len() >= 4 && cov.iter().all(|c| (0.95..=1.05).contains(c)),
            "{name}: PIDA CoV {cov:?}"
        );
        // TDPA spends the contact's real dissipation on the delay's energy: too fast rebounds
        let tdpa = run(
            preset(name),
            CompensatorConfig::TdpaImpedance(TdpaParams::default()),
        );
        let worst = covs(&tdpa).into_iter().fold(0.0, f64::max);
        assert!(worst > 1.10, "{name}: TDPA worst CoV {worst}");
    }
}

#[test]
fn nothing_diverges_up_to_60_ms() {
    for kind in [
        CompensatorConfig::Pida(ModelParams::default()),
        CompensatorConfig::TdpaImpedance(TdpaParams::default()),
        CompensatorConfig::TdpaAdmittance(TdpaParams::default()),
    ] {
        for delay in [0.030, 0.045, 0.060] {
            let name = kind.kind();
            let out = run(table1(delay, 0.0), kind.clone());
            assert_eq!(
                out.metrics.stop.kind,
                StopKind::Completed,
                "{name} at {delay}"
            );
            assert!(
                covs(&out).iter().all(|c| (c - 1.0).abs() < 0.05),
                "{name} at {delay}: CoV {:?}",
                covs(&out)
            );
        }
    }
    // and the admittance type really acts on the velocity
    let out = run(
        table1(0.020, 0.0),
        CompensatorConfig::TdpaAdmittance(TdpaParams::default()),
    );
    let none = run(table1(0.020, 0.0), CompensatorConfig::default());
    assert!(covs(&out)[0] < 0.6 * covs(&none)[0]);
}

/// Energy of a run in the middle of the free flight after collision n (1-based).
fn energy_after(out: &SimulationOutput, reference: bool, n: usize) -> f64 {
    let (collisions, table) = if reference {
        (out.metrics.reference_collisions.clone(), &out.reference)
    } else {
        (
            out.metrics
                .collisions
                .iter()
                .map(|c| c.collision.clone())
                .collect(),
            &out.timeseries,
        )
    };
    let time = table.column("time").unwrap();
    let energy = table.column("energy").unwrap();
    let end = collisions[n - 1].end;
    let next = collisions.get(n).map_or(*time.last().unwrap(), |c| c.start);
    let k = time
        .iter()
        .position(|t| *t >= 0.5 * (end + next))
        .unwrap_or(time.len() - 1);
    energy[k]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// With the energy controller on, the virtual system never ends up with more than 10 %
    /// more energy than the ideal after five collisions, and nothing is NaN, over random
    /// delays, noise, stiffness, masses and seeds (the ranges; undamped contact: with
    /// noise the damping is poorly identified, see docs/compensators/pida.md, and the damped
    /// presets have their own test above).
    #[test]
    fn energy_controller_bounds_the_energy(
        robot_ticks in 0usize..=60,
        sensor_ticks in 0usize..=5,
        noise in 0.0f64..0.5,
        stiffness in 75_000.0f64..180_000.0,
        servicer_mass in 300.0f64..600.0,
        seed in 0u64..1000,
        pida in any::<bool>(),
    ) {
        let mut s = table1(robot_ticks as f64 * 1e-3, sensor_ticks as f64 * 1e-3);
        s.simulation.duration = 7.0;
        s.facility.sensor_noise = noise;
        s.facility.seed = seed;
        s.contact.stiffness = stiffness;
        s.servicer.mass = servicer_mass;
        let kind = if pida { CompensatorConfig::Pida(ModelParams::default()) } else { CompensatorConfig::Dac(ModelParams::default()) };
        let out = run(s, kind);
        prop_assert_eq!(out.metrics.stop.kind, StopKind::Completed);
        for (name, values) in &out.timeseries.columns {
            prop_assert!(values.iter().all(|v| v.is_finite()) || name.ends_with("_estimate") || name == "observed_energy", "{} has NaN", name);
        }
        let n = out.metrics.collisions.iter().filter(|c| c.cov.is_some()).count().min(5);
        prop_assert!(n >= 3, "only {} collisions", n);
        let (hil, ideal) = (energy_after(&out, false, n), energy_after(&out, true, n));
        prop_assert!(hil <= 1.10 * ideal, "energy after {} collisions {} vs ideal {}", n, hil, ideal);
    }
}

/// Sensor noise up to 1 N per axis: contact detection set by the noise level (hysteresis,
/// `compensator::detect`) keeps pida at 20 ms faithful (before: single noisy ticks above the
/// 3 N threshold were taken as contact, CoV 0.70–0.95 and a collision lost), and in free
/// flight nothing beyond the noise is applied.
#[test]
fn pida_at_20ms_with_up_to_1n_of_noise_keeps_every_collision_and_applies_only_the_noise() {
    for (noise, seed) in [(0.5, 3), (0.9, 1), (1.0, 1), (1.0, 2), (1.0, 5)] {
        let mut s = table1(0.020, 0.0);
        s.facility.sensor_noise = noise;
        s.facility.seed = seed;
        let out = run(s, CompensatorConfig::Pida(ModelParams::default()));
        let m = &out.metrics;
        assert!(
            m.lost_collisions.is_empty() && m.extra_collisions.is_empty(),
            "σ {noise} seed {seed}: {:?}",
            m.violations
        );
        assert!(m.summary.compared >= 4, "σ {noise} seed {seed}");
        for c in m.collisions.iter().filter_map(|c| c.cov) {
            assert!((c - 1.0).abs() <= 0.05, "σ {noise} seed {seed}: CoV {c}");
        }
        // free flight: no physical contact over the last 60 ms (robot delay and a margin)
        let col = |name: &str| out.timeseries.column(name).unwrap();
        let norm = |p: &str, k: usize| {
            (col(&format!("{p}_x"))[k].powi(2)
                + col(&format!("{p}_y"))[k].powi(2)
                + col(&format!("{p}_z"))[k].powi(2))
            .sqrt()
        };
        let mut free_ticks = 0usize;
        for k in 60..col("time").len() {
            if (k - 60..=k).all(|j| norm("contact_force", j) == 0.0) {
                free_ticks += 1;
                let applied = norm("applied_force", k);
                assert!(
                    applied <= 6.0 * noise,
                    "σ {noise} seed {seed}: {applied} N applied in free flight at tick {k}"
                );
            }
        }
        assert!(free_ticks > 1000);
    }
}

/// `oblique-6dof` or a general 6-DOF case (both bodies moving and spinning about every axis)
/// with a robot delay, clean or with 0.2 N noise and 3 ms sensor delay.
fn six_dof(general: bool, robot_delay: f64, noisy: bool) -> Scenario {
    let mut s = preset("oblique-6dof");
    if general {
        s.target.angular_velocity = [0.01, 0.02, -0.015];
        s.servicer.angular_velocity = [0.005, -0.01, 0.02];
        s.target.velocity = [0.001, -0.002, 0.0005];
    }
    s.facility.robot_delay = robot_delay;
    if noisy {
        s.facility.sensor_noise = 0.2;
        s.facility.sensor_delay = 0.003;
        s.facility.seed = 4;
    }
    s
}

/// pida in 6-DOF (issue 10's targets): every reference collision present, rebound velocity
/// error ≤ 5 % (8 % at 40 ms), |CoV − 1| ≤ 0.03, and CoF ≤ 1.25 at 20 ms (1.28 with the
/// 3 ms sensor delay, which adds to the robot's: measured 1.249–1.256). (Before the
/// normal energy controller, pida rebounded the wrong way on `oblique-6dof` at 20 ms and lost
/// its second collision.)
#[test]
fn pida_is_faithful_in_6dof_at_10_20_and_40_ms() {
    for general in [false, true] {
        for noisy in [false, true] {
            for delay in [0.010, 0.020, 0.040] {
                let label = format!("general {general}, noisy {noisy}, {} ms", delay * 1e3);
                let out = run(
                    six_dof(general, delay, noisy),
                    CompensatorConfig::Pida(ModelParams::default()),
                );
                let m = &out.metrics;
                assert_eq!(m.stop.kind, StopKind::Completed, "{label}");
                assert!(
                    m.lost_collisions.is_empty() && m.extra_collisions.is_empty(),
                    "{label}: {:?}",
                    m.violations
                );
                assert!(m.summary.compared >= 2, "{label}");
                let max_error = if delay > 0.03 { 0.08 } else { 0.05 };
                for c in &m.collisions {
                    let (v, cov, cof) = (c.velocity_error.unwrap(), c.cov.unwrap(), c.cof.unwrap());
                    assert!(v <= max_error, "{label}: velocity error {v}");
                    assert!((cov - 1.0).abs() <= 0.03, "{label}: CoV {cov}");
                    eprintln!("{label}: CoV {cov:.4} CoF {cof:.3} velocity error {v:.4}");
                    if delay <= 0.02 {
                        let max_cof = if noisy { 1.28 } else { 1.25 };
                        assert!(cof <= max_cof, "{label}: CoF {cof}");
                    }
                }
            }
        }
    }
}

proptest! {
    // a fixed seed: the same 32 cases on every machine (a test that must not flake)
    #![proptest_config(ProptestConfig {
        cases: 32,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x6d0f),
        ..ProptestConfig::default()
    })]
    /// Random 6-DOF geometry (wall tilt, rod offset, spins, target motion), robot delays
    /// 0–40 ms, noise 0–0.5 N: pida keeps every reference collision and the rebound velocity
    /// within 5 % (8 % above 30 ms). Cases with a grazing reference collision (a peak below a
    /// quarter of the largest) are left out: whether a touch of a few newtons happens at all
    /// depends on sub-millimetre differences of the path, for any loop (a 1.4 % rebound error
    /// from 0.3 N of noise lost one 5 s later).
    #[test]
    fn pida_keeps_every_collision_over_random_6dof_cases(
        case in oblique_6dof_cases(0.02, 0.002, 0.45, 0.2),
        robot_ticks in 0usize..=40,
        noise in 0.0f64..0.5,
        seed in 0u64..1000,
    ) {
        let mut s = case;
        s.facility.robot_delay = robot_ticks as f64 * 1e-3;
        s.facility.sensor_noise = noise;
        s.facility.seed = seed;
        let out = run(s, CompensatorConfig::Pida(ModelParams::default()));
        let m = &out.metrics;
        let peaks: Vec<f64> = m.reference_collisions.iter().map(|c| c.peak_force).collect();
        let largest = peaks.iter().cloned().fold(0.0, f64::max);
        prop_assume!(peaks.iter().all(|p| *p >= 0.25 * largest));
        prop_assert_eq!(m.stop.kind, StopKind::Completed);
        prop_assert!(m.lost_collisions.is_empty(), "lost {:?}: {:?}", m.lost_collisions, m.violations);
        let max_error = if robot_ticks > 30 { 0.08 } else { 0.05 };
        for c in &m.collisions {
            if let Some(v) = c.velocity_error {
                prop_assert!(v <= max_error, "collision {}: velocity error {}", c.collision.index, v);
            }
        }
    }
}
