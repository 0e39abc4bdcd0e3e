//! pida's force fidelity on general 6-DOF scenes is its onset bound (docs/compensators/pida.md,
//! "6-DOF with noise"): a contact whose force shows `τ` late (robot and sensor delay) lets the
//! virtual rod tip in by `v0·τ` before any force opposes it, so the peak force is about
//! `√(1 + (ω τ)²)` times the ideal, with `ω = √(k / m_eff)` and `m_eff = 1 / (nᵀ K n)` the
//! mass a wall of normal `n` sees at the rod tip (`K` the tip mobility). Oblique walls and
//! offset rods make `m_eff` smaller than the reduced mass, hence the higher CoF than on
//! `paper-table1`; the delay compensation and the identification add little to it.

mod common;

use common::oblique_6dof;
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_core::Scenario;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};

/// Random general scenes (spins ±0.02 rad/s, drift ±2 mm/s, tilts ±0.45 rad, offsets ±0.2 m)
/// from a fixed sequence: the same scenes on every machine.
fn scene(n: u64) -> Scenario {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0x6d0f + n);
    let mut u = |a: f64| rng.random_range(-a..a);
    let spins = ([u(0.02), u(0.02), u(0.02)], [u(0.02), u(0.02), u(0.02)]);
    let drift = [u(0.002), u(0.002), u(0.002)];
    let tilt = [u(0.45), u(0.45)];
    let offset = [u(0.2), u(0.2)];
    let mut s = oblique_6dof(spins, drift, tilt, offset);
    s.facility.robot_delay = 0.02;
    s.compensator = CompensatorConfig::Pida(ModelParams::default());
    s
}

/// `√(1 + (ω τ)²)` for the lightest wall at the start pose.
fn onset_bound(s: &Scenario, tau: f64) -> f64 {
    let plan = s.resolve().expect("plan");
    let k = plan.system.tip_mobility(&plan.initial);
    let lightest = s
        .walls
        .iter()
        .map(|w| {
            let n = Vector3::from(w.normal).normalize();
            1.0 / n.dot(&(k * n))
        })
        .fold(f64::INFINITY, f64::min);
    let omega = (s.contact.stiffness / lightest).sqrt();
    (1.0 + (omega * tau).powi(2)).sqrt()
}

/// Worst CoF and worst rebound velocity error of a run.
fn worst(s: &Scenario) -> (f64, f64) {
    let m = hilcontact_core::simulate_metrics(s).expect("run");
    assert!(m.lost_collisions.is_empty(), "{:?}", m.violations);
    let cof = m
        .collisions
        .iter()
        .filter_map(|c| c.cof)
        .fold(0.0, f64::max);
    let error = m
        .collisions
        .iter()
        .filter_map(|c| c.velocity_error)
        .fold(0.0, f64::max);
    (cof, error)
}

/// Clean and with 0.2 N of noise and 3 ms of sensor delay, over eight random scenes, the CoF
/// lies between the onset bound of the loop's whole delay (20 ms, 23 ms with the sensor's) and
/// 8 % above it clean, 13 % noisy (measured: 1.026-1.065 times the bound clean, 1.027-1.101
/// noisy, the most on a collision of 38 N peak, where the noise-aware contact detector's 6σ
/// threshold delays the compensation); the rebound velocity error stays within 0.5 % clean
/// and 1.5 % noisy (measured: 0.22 % and 0.77 %).
#[test]
fn pida_cof_on_general_6dof_scenes_is_the_onset_bound() {
    for n in 1..=8 {
        let clean = scene(n);
        let (cof, error) = worst(&clean);
        let bound = onset_bound(&clean, 0.02);
        eprintln!(
            "scene {n}: CoF {cof:.3}, bound {bound:.3}, ratio {:.3}, velocity error {error:.4}",
            cof / bound
        );
        assert!(
            cof >= bound && cof <= 1.08 * bound,
            "scene {n}: CoF {cof:.3} against the onset bound {bound:.3}"
        );
        assert!(error <= 0.005, "scene {n}: velocity error {error}");

        let mut noisy = clean.clone();
        noisy.facility.sensor_noise = 0.2;
        noisy.facility.sensor_delay = 0.003;
        noisy.facility.seed = n;
        let (cof, error) = worst(&noisy);
        let bound = onset_bound(&noisy, 0.023);
        eprintln!("scene {n}, 0.2 N, 3 ms: CoF {cof:.3}, bound {bound:.3}, ratio {:.3}, velocity error {error:.4}", cof / bound);
        assert!(
            cof >= bound && cof <= 1.13 * bound,
            "scene {n}, 0.2 N, 3 ms: CoF {cof:.3} against the onset bound {bound:.3}"
        );
        assert!(
            error <= 0.015,
            "scene {n}, 0.2 N, 3 ms: velocity error {error}"
        );
    }
}
