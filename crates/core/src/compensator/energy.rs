//! Energy observer (14)-(16), (18) and energy controller (17), (19), (20).
//!
//! Sensor convention (force on the frame), so the power flowing into the environment port is
//! `F·v_des`: positive while the rod compresses the contact, negative while it is pushed back.
//! ```text
//! E_obs(k) = E(0) + Σ T·[F_ek(i)·v_des(i) + F_α(i−1)·v_des(i−1)]          (14), (15)
//! F_ek = F_comp − ĉ·(v_des·e)·e, of the previous tick while compressing     (16)
//! E_obs,i = E_obs·|F_ek,i|/|F_ek|                                           (18)
//! α_ii = −E_obs,i / (proj·F_ek,i·v_des,i·T) when E_obs,i < 0,
//!        proj = v_desᵀF_ek/|F_ek|²                                          (19)
//! F_α,i = α_ii·proj·F_ek,i                                                   (17)
//! M_α = (p_des − p_s) × F_α                                                  (20)
//! ```
//! Two readings of the sum ([`ObserverMode`]):
//! - `work` (default): the virtual dynamics hold the wrench of tick k−1 over the step to k
//!   (symplectic Euler), which changes their kinetic energy by exactly
//!   `−T·F(k−1)·(v_des(k−1) + v_des(k))/2`. So the observer adds
//!   `T·(F_ek(k−1) + F_α(k−1))·(v_des(k−1) + v_des(k))/2`, and its energy is the virtual system's
//!   real elastic exchange (tested to 1e-12 J). Eq. (16) uses the previous tick's force for
//!   the same reason, but only while compressing.
//! - `paper`: (15), (16) as printed. On `paper-table1` it gives PIDA the same CoV as `work`
//!   within 0.1 % at 10 and 20 ms, but lets DAC's rebounds creep up: CoV 1.019 and 1.032 at
//!   the fifth collision, against 1.005 and 1.003 with `work`.
//!
//! The observer runs only in contact (`E(0) = 0` at each contact's start): outside contact
//! the damping term would otherwise accumulate during free flight. The controller only ever
//! dissipates: α ≥ 0 and `F_α·v_des ≥ 0`; α is capped at `alpha_max` and a deficit that the
//! cap leaves is carried to the next tick by the observer.

use nalgebra::Vector3;

use super::delay::ContactView;
use super::params::{ControllerMode, ModelParams, ObserverMode};
use super::{CompensatorContext, CompensatorInput};
use crate::frames::FrameWrench;

/// One tick of the observer's history.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tick {
    force: Vector3<f64>,
    direction: Vector3<f64>,
    damping: f64,
    velocity: Vector3<f64>,
    alpha_force: Vector3<f64>,
}

/// The energy observer.
#[derive(Debug, Clone, PartialEq)]
pub struct EnergyObserver {
    period: f64,
    mode: ObserverMode,
    energy: f64,
    previous: Option<Tick>,
}

/// Damping force `ĉ·(v·e)·e` of the identified contact, N. A negative estimate (noise can
/// produce one) counts as zero here: it would let the observer credit energy the contact never
/// gives, and the controller would then allow the energy to grow.
fn damping_force(damping: f64, velocity: &Vector3<f64>, direction: &Vector3<f64>) -> Vector3<f64> {
    direction * (damping.max(0.0) * velocity.dot(direction))
}

impl EnergyObserver {
    /// An observer for control period `period` (s).
    pub fn new(period: f64, mode: ObserverMode) -> Self {
        EnergyObserver {
            period,
            mode,
            energy: 0.0,
            previous: None,
        }
    }

    /// Forgets the contact.
    pub fn reset(&mut self) {
        self.energy = 0.0;
        self.previous = None;
    }

    /// Observed energy E_obs, J.
    pub fn energy(&self) -> f64 {
        self.energy
    }

    /// One tick with the compensated force (N), contact direction, identified damping (N·s/m)
    /// and desired velocity (m/s). Returns the elastic force F_ek of this tick (N); zero out of
    /// contact.
    pub fn step(
        &mut self,
        in_contact: bool,
        force: &Vector3<f64>,
        direction: &Vector3<f64>,
        damping: f64,
        velocity: &Vector3<f64>,
    ) -> Vector3<f64> {
        if !in_contact {
            self.reset();
            return Vector3::zeros();
        }
        let elastic = |t: &Tick| t.force - damping_force(t.damping, &t.velocity, &t.direction);
        let current = Tick {
            force: *force,
            direction: *direction,
            damping,
            velocity: *velocity,
            alpha_force: Vector3::zeros(),
        };
        let f_ek_now = elastic(&current);
        self.energy += match (self.mode, self.previous) {
            (_, None) => 0.0,
            // the wrench held over the last step: its work on the virtual kinetic energy is
            // exactly T·F(k−1)·(v(k−1) + v(k))/2 under symplectic Euler
            (ObserverMode::Work, Some(p)) => {
                0.5 * self.period * (elastic(&p) + p.alpha_force).dot(&(p.velocity + velocity))
            }
            // (15), (16) as printed
            (ObserverMode::Paper, Some(p)) => {
                let f_ek = if velocity.dot(force) > 0.0 {
                    elastic(&p)
                } else {
                    f_ek_now
                };
                self.period * (f_ek.dot(velocity) + p.alpha_force.dot(&p.velocity))
            }
        };
        self.previous = Some(current);
        f_ek_now
    }

    /// Records the controller's force of this tick (enters the next tick's sum).
    pub fn record_alpha_force(&mut self, alpha_force: &Vector3<f64>) {
        if let Some(p) = self.previous.as_mut() {
            p.alpha_force = *alpha_force;
        }
    }
}

/// The energy controller: a variable damping that dissipates what the observer finds created.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnergyController {
    period: f64,
    alpha_max: f64,
    mode: ControllerMode,
    force_ratio_max: f64,
    contact_force: f64,
}

impl EnergyController {
    /// A controller for period `period` (s) with α capped at `alpha_max` (N·s/m), in `mode`;
    /// the `normal` mode's force is capped at `force_ratio_max · max(|F_comp|, contact_force)`.
    pub fn new(p: &ModelParams, period: f64) -> Self {
        EnergyController {
            period,
            alpha_max: p.alpha_max,
            mode: p.controller,
            force_ratio_max: p.force_ratio_max,
            contact_force: p.contact_force,
        }
    }

    /// The amendment damping α (diagonal, N·s/m) and force F_α (N) for observed energy
    /// `energy` (J), elastic force `f_ek` (N), contact direction `direction`, desired
    /// velocity (m/s) and the compensated contact force `f_comp` (N).
    ///
    /// Both modes act along ê = F_ek/|F_ek| (where F_ek vanishes, the virtual tip has left
    /// the wall while the robot has not, the contact direction stands in, so that a deficit
    /// found late in the rebound can still be dissipated) and only ever dissipate.
    /// - `normal`: one damping α along ê, `F_α = α (v·ê) ê`, whose power `α (v·ê)²` is the
    ///   deficit `−E/T`, so `α = −E / (T (v·ê)²)`, capped at `alpha_max` and the force at
    ///   `force_ratio_max · max(|F_comp|, contact_force)`. The same in every direction: on
    ///   a contact along an axis it is the paper's controller exactly.
    /// - `paper`: eqs. (17)-(19) as printed, one α per axis (see [`ControllerMode::Paper`]).
    pub fn step(
        &self,
        energy: f64,
        f_ek: &Vector3<f64>,
        direction: &Vector3<f64>,
        velocity: &Vector3<f64>,
        f_comp: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let norm = f_ek.norm();
        let e_hat = if norm > 1e-9 { f_ek / norm } else { *direction };
        if energy >= 0.0 || e_hat.norm_squared() < 0.5 {
            return (Vector3::zeros(), Vector3::zeros());
        }
        let v_along = velocity.dot(&e_hat);
        match self.mode {
            ControllerMode::Normal => {
                if v_along == 0.0 {
                    return (Vector3::zeros(), Vector3::zeros());
                }
                let alpha = (-energy / (self.period * v_along * v_along)).min(self.alpha_max);
                let bound = self.force_ratio_max * f_comp.norm().max(self.contact_force);
                let magnitude = (alpha * v_along.abs()).min(bound);
                let f_alpha = e_hat * (magnitude * v_along.signum()); // F_α·v = magnitude |v·ê| ≥ 0
                let alpha = magnitude / v_along.abs();
                (Vector3::repeat(alpha), f_alpha)
            }
            ControllerMode::Paper => {
                // proj·F_ek,i = (v·ê)·ê_i with proj = vᵀF_ek/|F_ek|²
                let mut alpha = Vector3::zeros();
                for i in 0..3 {
                    let e_i = energy * e_hat[i].abs(); // (18)
                    let denominator = v_along * e_hat[i] * velocity[i] * self.period;
                    // (19), guarded: only where this axis can dissipate, never negative, capped
                    if e_i < 0.0 && denominator > 0.0 {
                        alpha[i] = (-e_i / denominator).min(self.alpha_max);
                    }
                }
                let f_alpha = alpha.component_mul(&e_hat) * v_along; // (17)
                (alpha, f_alpha)
            }
        }
    }
}

/// Observer and controller together: the damping amendment that DAC and PIDA add to the
/// force they feed the dynamics.
#[derive(Debug, Clone, PartialEq)]
pub struct DampingAmendment {
    observer: EnergyObserver,
    controller: EnergyController,
    sensor_origin: Vector3<f64>,
}

impl DampingAmendment {
    /// An amendment with the compensator's parameters.
    pub fn new(p: &ModelParams, context: &CompensatorContext) -> Self {
        DampingAmendment {
            observer: EnergyObserver::new(context.period, p.observer),
            controller: EnergyController::new(p, context.period),
            sensor_origin: context.sensor_origin,
        }
    }

    /// Forgets the contact.
    pub fn reset(&mut self) {
        self.observer.reset();
    }

    /// Observed energy E_obs, J.
    pub fn energy(&self) -> f64 {
        self.observer.energy()
    }

    /// One tick: observes `force` (the force fed to the dynamics before amendment, N) and
    /// returns `F_α` (17) and `M_α = (p_des − p_s) × F_α` (20).
    pub fn step(
        &mut self,
        view: &ContactView,
        force: &Vector3<f64>,
        input: &CompensatorInput,
    ) -> FrameWrench {
        let v = input.tip_velocity_desired;
        let f_ek = self
            .observer
            .step(view.in_contact, force, &view.direction, view.damping, &v);
        let (_, f_alpha) =
            self.controller
                .step(self.observer.energy(), &f_ek, &view.direction, &v, force);
        self.observer.record_alpha_force(&f_alpha);
        FrameWrench {
            force: f_alpha,
            moment: (input.tip_position_desired - self.sensor_origin).cross(&f_alpha),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lossless contact integrated like the virtual dynamics (symplectic Euler, force held
    /// over the step): the observer's energy is, at every tick, the kinetic energy the body
    /// has handed to the environment, and it returns to zero when the contact is over.
    #[test]
    fn observer_energy_is_zero_over_a_lossless_cycle() {
        let (k, m, t) = (176_275.0, 279.07, 1e-3);
        let e = Vector3::new(1.0, 0.0, 0.0); // into the wall
        for mode in [ObserverMode::Work, ObserverMode::Paper] {
            let mut obs = EnergyObserver::new(t, mode);
            let (mut x, mut v) = (0.0f64, 0.02f64); // penetration, its rate
            let ke0 = 0.5 * m * v * v;
            let (mut peak, mut worst) = (0.0f64, 0.0f64);
            loop {
                let force = e * (k * x).max(0.0); // on the frame
                obs.step(true, &force, &e, 0.0, &(e * v));
                if mode == ObserverMode::Work {
                    worst = worst.max((obs.energy() - (ke0 - 0.5 * m * v * v)).abs());
                }
                peak = peak.max(obs.energy());
                if x < 0.0 {
                    break;
                }
                v -= force.x / m * t;
                x += v * t;
            }
            assert!(
                (peak / ke0 - 1.0).abs() < 0.02,
                "{mode:?}: peak {peak} vs {ke0}"
            );
            if mode == ObserverMode::Work {
                assert!(
                    worst < 1e-12,
                    "the observer must track the kinetic energy exchanged: {worst}"
                );
                assert!(
                    obs.energy().abs() < 1e-5 * ke0,
                    "after the cycle {}",
                    obs.energy()
                );
            }
        }
    }

    #[test]
    fn controller_only_dissipates_and_alpha_is_never_negative() {
        for mode in [ControllerMode::Normal, ControllerMode::Paper] {
            let p = ModelParams {
                controller: mode,
                ..ModelParams::default()
            };
            let ctl = EnergyController::new(&p, 1e-3);
            let cases = [
                (
                    Vector3::new(50.0, 3.0, -1.0),
                    Vector3::new(-0.02, 0.001, 0.0),
                ),
                (
                    Vector3::new(50.0, -30.0, 5.0),
                    Vector3::new(-0.01, 0.02, 0.003),
                ),
                (Vector3::new(1e-3, 0.0, 0.0), Vector3::new(-0.02, 0.0, 0.0)),
                (Vector3::new(80.0, 0.0, 0.0), Vector3::new(-1e-7, 0.0, 0.0)),
            ];
            for (f, v) in cases {
                for energy in [-1e-2, -1e-5, 0.0, 1e-3] {
                    let (alpha, f_alpha) = ctl.step(energy, &f, &f.normalize(), &v, &f);
                    assert!(alpha.iter().all(|a| *a >= 0.0 && *a <= 1e5), "{alpha:?}");
                    assert!(
                        f_alpha.dot(&v) >= -1e-15,
                        "F_α must dissipate: {}",
                        f_alpha.dot(&v)
                    );
                    if energy >= 0.0 {
                        assert_eq!(f_alpha, Vector3::zeros());
                    }
                }
            }
            // a small deficit on a clean 1-D rebound is removed in exactly one tick
            let (f, v) = (Vector3::new(50.0, 0.0, 0.0), Vector3::new(-0.02, 0.0, 0.0));
            let (_, f_alpha) = ctl.step(-1e-7, &f, &f.normalize(), &v, &f);
            assert!((f_alpha.dot(&v) * 1e-3 - 1e-7).abs() < 1e-15);
        }
    }

    #[test]
    fn normal_controller_dissipates_exactly_the_deficit_in_any_direction_and_bounds_its_force() {
        let p = ModelParams::default();
        let ctl = EnergyController::new(&p, 1e-3);
        // an oblique contact, rebounding: the paper's split dissipates Σ|ê_i| ≈ 1.48 times
        // the deficit; the normal controller exactly the deficit
        let e = Vector3::new(0.8924, 0.4161, -0.1736).normalize();
        let f = e * 50.0;
        let v = Vector3::new(-0.02, -0.004, 0.003);
        let deficit = -1e-6;
        let (_, f_alpha) = ctl.step(deficit, &f, &e, &v, &f);
        assert!(
            (f_alpha.dot(&v) * 1e-3 + deficit).abs() < 1e-15,
            "{}",
            f_alpha.dot(&v) * 1e-3
        );
        let paper = EnergyController::new(
            &ModelParams {
                controller: ControllerMode::Paper,
                ..p.clone()
            },
            1e-3,
        );
        let (_, f_paper) = paper.step(deficit, &f, &e, &v, &f);
        assert!(
            f_paper.dot(&v) * 1e-3 > 1.2 * -deficit,
            "{}",
            f_paper.dot(&v) * 1e-3
        );
        // a large deficit: the force stays within force_ratio_max·|F_comp|, the rest is left
        let (_, f_big) = ctl.step(-10.0, &f, &e, &v, &f);
        assert!(
            (f_big.norm() - p.force_ratio_max * 50.0).abs() < 1e-9,
            "{}",
            f_big.norm()
        );
        assert!(f_big.dot(&v) > 0.0);
    }
}
