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
//! The window ([`ExchangeWindow`]). With `work`, the observer covers the whole exchange with
//! the wall: it is open while in contact or while the force is above the quiet level
//! ([`ContactDetector::quiet_threshold`], the sensor's noise), so the first and last ticks of a
//! contact, whose force is below the contact threshold, are counted too; outside it the
//! compensator applies nothing (the force is noise, whose random work would otherwise move the
//! energy by several per cent over minutes); a deficit (`E < 0`) left when the window closes
//! is carried into the next exchange, a surplus is forgotten, so energy banked in one
//! collision never pays for the next. With `paper` the window is the contact itself, `E(0) = 0`
//! at each contact's start, and the force is applied outside it as it comes (the paper's
//! form). Outside the window the damping term would accumulate during free flight. The
//! controller only ever dissipates: α ≥ 0 and `F_α·v_des ≥ 0`; α is capped at `alpha_max` and a
//! deficit that the cap leaves is carried to the next tick by the observer.

use nalgebra::Vector3;

use super::delay::ContactView;
use super::detect::ContactDetector;
use super::params::{ControllerMode, ModelParams, ObserverMode};
use super::{CompensatorContext, CompensatorInput, CompensatorOutput, ContactEstimate};
use crate::frames::FrameWrench;

/// The window of an energy observer over one exchange with a wall, and the carried deficit.
///
/// The window is open while the tick is in contact or its force is above the quiet level
/// ([`ContactDetector::quiet_threshold`]): that covers the first and last ticks of a contact,
/// whose force is below the contact threshold but does work. Outside it the force is the
/// sensor's noise, and the compensator applies nothing (so every force that reaches the
/// virtual dynamics is inside a window, and counted):
/// ```text
/// opens:   E ← D                  (D ≤ 0, the deficit carried from the exchanges before)
/// open:    E ← E + W(k)           (W(k) the work the dynamics gave the port over the last step)
/// closes:  D ← max(min(E, 0), −CARRY_SHARE·max E)
/// ```
/// A surplus is forgotten at the close (energy banked in one exchange must not pay for the
/// next); a deficit is kept until a later exchange has dissipated it. Allocation-free.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ExchangeWindow {
    open: bool,
    energy: f64,
    carried: f64,
    /// Largest energy of the open window, J (the exchange's scale).
    peak: f64,
}

/// Largest deficit carried out of an exchange, as a share of the exchange's peak energy: a
/// window's accounting error (a law identified wrong, e.g. linear on a Hunt-Crossley or
/// heavily damped contact) must not be dissipated from the next contact whole.
pub const CARRY_SHARE: f64 = 0.02;

impl ExchangeWindow {
    /// Forgets everything, the carried deficit too.
    pub fn reset(&mut self) {
        *self = ExchangeWindow::default();
    }

    /// The energy of the open window (J; 0 when closed).
    pub fn energy(&self) -> f64 {
        self.energy
    }

    /// The deficit carried into the next exchange (J, ≤ 0).
    pub fn carried(&self) -> f64 {
        self.carried
    }

    /// Whether the window is open.
    pub fn is_open(&self) -> bool {
        self.open
    }

    /// Restates the open window's energy (J) and its peak so far (J), after the exchange was
    /// re-observed ([`EnergyObserver::rebook`]).
    pub fn restate(&mut self, energy: f64, peak: f64) {
        if self.open {
            self.energy = energy;
            self.peak = peak;
        }
    }

    /// One tick: `work` (J) over the step that ends now (by the force held since the last
    /// tick: zero if the window was closed, since nothing was applied), and whether this tick
    /// is in the exchange (in contact, or its force above the quiet level). Returns whether the
    /// window is open.
    pub fn step(&mut self, work: f64, in_exchange: bool) -> bool {
        if self.open {
            self.energy += work;
            self.peak = self.peak.max(self.energy);
        }
        match (self.open, in_exchange) {
            (false, true) => {
                self.energy = self.carried;
                self.carried = 0.0;
                self.peak = 0.0;
            }
            (true, false) => {
                self.carried = self.energy.min(0.0).max(-CARRY_SHARE * self.peak);
                self.energy = 0.0;
            }
            _ => {}
        }
        self.open = in_exchange;
        self.open
    }
}

/// One tick of the observer's history.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Tick {
    force: Vector3<f64>,
    direction: Vector3<f64>,
    damping: f64,
    /// Identified friction coefficient μ̂ (0: frictionless; `direction` is then the normal).
    friction: f64,
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
    /// The exchange window (`work`).
    window: ExchangeWindow,
    /// The open window's ticks and the velocity that closed each one's step (capacity
    /// [`HISTORY`], allocated once: a window longer than that is not re-observed).
    history: Vec<(Tick, Vector3<f64>)>,
    /// The window's energy when it opened (the carried deficit), J.
    opening: f64,
    /// Whether the open window's friction was booked ([`EnergyObserver::rebook`]).
    booked: bool,
}

/// Ticks of an exchange the observer keeps to re-observe it (2 s at 1 kHz).
pub const HISTORY: usize = 2048;

/// Damping force `ĉ·(v·e)·e` of the identified contact, N. A negative estimate (noise can
/// produce one) counts as zero here: it would let the observer credit energy the contact never
/// gives, and the controller would then allow the energy to grow.
fn damping_force(damping: f64, velocity: &Vector3<f64>, direction: &Vector3<f64>) -> Vector3<f64> {
    direction * (damping.max(0.0) * velocity.dot(direction))
}

/// Speed below which the booked friction fades (regularised like the Coulomb law), m/s.
pub const FRICTION_SPEED: f64 = 1e-3;

/// The friction a contact of coefficient `friction` should exert on the frame, N:
/// `μ̂·F_n·v_t/√(|v_t|² + v_ε²)` with `F_n = max(F·n, 0)` and `v_t` the tangential part of
/// the virtual tip's velocity (the frame feels friction along the rod's sliding). Its power
/// `μ̂·F_n·|v_t|²/√(…) ≥ 0` is the energy the contact dissipates by friction: booked as real.
pub fn friction_force(
    friction: f64,
    force: &Vector3<f64>,
    velocity: &Vector3<f64>,
    normal: &Vector3<f64>,
) -> Vector3<f64> {
    let f_n = force.dot(normal).max(0.0);
    let v_t = velocity - normal * velocity.dot(normal);
    let speed2 = v_t.norm_squared();
    v_t * (friction.max(0.0) * f_n / (speed2 + FRICTION_SPEED * FRICTION_SPEED).sqrt())
}

/// The elastic force of a tick: its force less the booked damping and friction, N.
fn elastic_force(t: &Tick) -> Vector3<f64> {
    let f = t.force - damping_force(t.damping, &t.velocity, &t.direction);
    if t.friction > 0.0 {
        f - friction_force(t.friction, &t.force, &t.velocity, &t.direction)
    } else {
        f
    }
}

impl EnergyObserver {
    /// An observer for control period `period` (s).
    pub fn new(period: f64, mode: ObserverMode) -> Self {
        EnergyObserver {
            period,
            mode,
            energy: 0.0,
            previous: None,
            window: ExchangeWindow::default(),
            history: Vec::with_capacity(HISTORY),
            opening: 0.0,
            booked: false,
        }
    }

    /// Whether the open window's friction is already booked.
    pub fn is_booked(&self) -> bool {
        self.booked
    }

    /// Re-observes the open window with the surface identified during it: the friction
    /// coefficient `friction` and normal `normal` (into the wall) are booked at every tick
    /// of the window so far (before the contact's normal was determined the friction could
    /// not be told from the elastic force, and its dissipation hid the delay's energy). The
    /// window's energy is summed again from its opening; the controller's forces stay as they
    /// were. Once per window; allocation-free.
    pub fn rebook(&mut self, friction: f64, normal: &Vector3<f64>) {
        if self.booked || self.mode != ObserverMode::Work || !self.window.is_open() {
            return;
        }
        self.booked = true;
        if self.history.len() >= HISTORY {
            return; // too long to re-observe: booked from now on only
        }
        let book = |t: &mut Tick| {
            if t.force != Vector3::zeros() {
                t.friction = friction;
                t.direction = *normal;
            }
        };
        let (mut energy, mut peak) = (self.opening, 0.0f64);
        for (tick, next) in self.history.iter_mut() {
            book(tick);
            energy += 0.5
                * self.period
                * (elastic_force(tick) + tick.alpha_force).dot(&(tick.velocity + *next));
            peak = peak.max(energy);
        }
        if let Some(p) = self.previous.as_mut() {
            book(p);
        }
        self.window.restate(energy, peak);
        self.energy = energy;
    }

    /// Forgets the contact, and the deficit carried from the ones before.
    pub fn reset(&mut self) {
        self.energy = 0.0;
        self.previous = None;
        self.window.reset();
        self.history.clear();
        self.opening = 0.0;
        self.booked = false;
    }

    /// The deficit carried into the next exchange (J, ≤ 0; always 0 with `paper`).
    pub fn carried(&self) -> f64 {
        self.window.carried()
    }

    /// Observed energy E_obs, J.
    pub fn energy(&self) -> f64 {
        self.energy
    }

    /// One tick with the compensated force (N), whether the tick is in contact and whether its
    /// force is above the quiet level (`active`), the contact direction (the normal; zero out
    /// of contact: then the force's own direction), identified damping (N·s/m), identified
    /// friction coefficient μ̂ (0: frictionless) and desired velocity (m/s). The damping force
    /// `ĉ·(v·n)·n` and the friction force [`friction_force`] are booked as real: the elastic
    /// force is the rest.
    /// Returns the elastic force F_ek of this tick (N), zero outside the window, and whether
    /// the window is open (with `paper`: whether the tick is in contact).
    pub fn step(
        &mut self,
        in_contact: bool,
        active: bool,
        force: &Vector3<f64>,
        direction: &Vector3<f64>,
        damping: f64,
        friction: f64,
        velocity: &Vector3<f64>,
    ) -> (Vector3<f64>, bool) {
        let elastic = elastic_force;
        if self.mode == ObserverMode::Paper {
            if !in_contact {
                self.energy = 0.0;
                self.previous = None;
                return (Vector3::zeros(), false);
            }
            let current = Tick {
                force: *force,
                direction: *direction,
                damping,
                friction,
                velocity: *velocity,
                alpha_force: Vector3::zeros(),
            };
            let f_ek_now = elastic(&current);
            if let Some(p) = self.previous {
                // (15), (16) as printed
                let f_ek = if velocity.dot(force) > 0.0 {
                    elastic(&p)
                } else {
                    f_ek_now
                };
                self.energy += self.period * (f_ek.dot(velocity) + p.alpha_force.dot(&p.velocity));
            }
            self.previous = Some(current);
            return (f_ek_now, true);
        }
        // out of contact the force's own direction (for the damping part of the first and
        // last ticks of a contact, whose force is below the contact threshold)
        let magnitude = force.norm();
        let direction = if direction.norm_squared() > 0.5 || magnitude == 0.0 {
            *direction
        } else {
            force / magnitude
        };
        let current = Tick {
            force: *force,
            direction,
            damping,
            friction,
            velocity: *velocity,
            alpha_force: Vector3::zeros(),
        };
        // the wrench held over the last step: its work on the virtual kinetic energy is
        // exactly T·F(k−1)·(v(k−1) + v(k))/2 under symplectic Euler
        let work = self.previous.map_or(0.0, |p| {
            0.5 * self.period * (elastic(&p) + p.alpha_force).dot(&(p.velocity + velocity))
        });
        let was_open = self.window.is_open();
        if let (true, Some(p)) = (was_open, self.previous) {
            if self.history.len() < HISTORY {
                self.history.push((p, *velocity));
            }
        }
        let open = self.window.step(work, in_contact || active);
        if open && !was_open {
            self.history.clear();
            self.opening = self.window.energy();
            self.booked = false;
        }
        self.energy = self.window.energy();
        if open {
            self.previous = Some(current);
            (elastic(&current), true)
        } else {
            // nothing is applied outside the window
            self.previous = Some(Tick {
                force: Vector3::zeros(),
                damping: 0.0,
                friction: 0.0,
                ..current
            });
            (Vector3::zeros(), false)
        }
    }

    /// Whether the compensator applies its force at this tick: inside the window with
    /// `work`, always with `paper` (which applies the force outside contact too, as the
    /// paper does).
    pub fn applies(&self) -> bool {
        self.mode == ObserverMode::Paper || self.window.is_open()
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

/// The identified damping where the virtual rod tip is in the wall, else 0 (N·s/m): the
/// contact dissipates only there. Its penetration from the identified model,
/// `d_des = (F_act·e − ĉ·v_act·e)/k̂ + (p_des − p_act)·e`, e the direction of `F_act`. While
/// the delayed robot still presses after the virtual tip has left the wall, `ĉ·(v·e)²` is no
/// dissipation of the virtual contact, and booking it would let the controller remove energy
/// the contact never took.
fn virtual_damping(view: &ContactView, input: &CompensatorInput) -> f64 {
    let (e, magnitude) = if view.frictional {
        (view.normal, view.force.dot(&view.normal))
    } else {
        let magnitude = view.force.norm();
        (view.force / magnitude, magnitude)
    };
    if view.damping <= 0.0 || view.stiffness <= 0.0 || magnitude <= 0.0 {
        return view.damping;
    }
    let actual = (magnitude - view.damping * input.tip_velocity_actual.dot(&e)) / view.stiffness;
    let desired = actual + (input.tip_position_desired - input.tip_position_actual).dot(&e);
    if desired > 0.0 {
        view.damping
    } else {
        0.0
    }
}

/// Observer and controller together: the damping amendment that DAC and PIDA add to the
/// force they feed the dynamics.
#[derive(Debug, Clone, PartialEq)]
pub struct DampingAmendment {
    observer: EnergyObserver,
    controller: EnergyController,
    /// The quiet level of the force (the noise estimate), for the observer's window.
    detector: ContactDetector,
    sensor_origin: Vector3<f64>,
    /// Whether the damping is booked only where the virtual tip is in the wall.
    virtual_damping: bool,
}

impl DampingAmendment {
    /// An amendment with the compensator's parameters.
    pub fn new(p: &ModelParams, context: &CompensatorContext) -> Self {
        DampingAmendment {
            observer: EnergyObserver::new(context.period, p.observer),
            controller: EnergyController::new(p, context.period),
            detector: ContactDetector::new(p.contact_force, context.period),
            sensor_origin: context.sensor_origin,
            virtual_damping: false,
        }
    }

    /// An amendment for a force that is the robot's (`F_act`, `dac`): with the `work` observer,
    /// the identified damping counts as dissipated only while the virtual tip is in the wall
    /// ([`virtual_damping`]). The robot's force keeps pressing after the virtual tip has left,
    /// and booking `ĉ·(v·e)²` there would let the controller remove energy the contact never
    /// took (`dac`'s damped rebounds then slowed collision after collision). `F_comp` (`pida`)
    /// is the model's force at the virtual tip, zero once it has left.
    pub fn for_robot_force(p: &ModelParams, context: &CompensatorContext) -> Self {
        DampingAmendment {
            virtual_damping: true,
            ..DampingAmendment::new(p, context)
        }
    }

    /// Forgets the contact and the deficit carried.
    pub fn reset(&mut self) {
        self.observer.reset();
        self.detector.reset();
    }

    /// Observed energy E_obs, J.
    pub fn energy(&self) -> f64 {
        self.observer.energy()
    }

    /// Whether the compensator applies its force at this tick (see [`EnergyObserver::applies`]):
    /// outside the `work` observer's window the force is the sensor's noise.
    pub fn applies(&self) -> bool {
        self.observer.applies()
    }

    /// The output of an amended compensator: `F̂ = F + F_α` (29), `M̂ = M + M_α` (30) with
    /// `force` F (N) and `moment` M (N·m, about the sensor origin) the wrench fed to the
    /// dynamics before amendment (`F_comp` for `pida`, `F_act` for `dac`) and `alpha` = (F_α, M_α) of [`DampingAmendment::step`]; nothing
    /// outside the observer's window (the force there is the sensor's noise). It reports the
    /// identified contact of `view` and the observed energy.
    pub fn output(
        &self,
        force: &Vector3<f64>,
        moment: &Vector3<f64>,
        alpha: &FrameWrench,
        view: &ContactView,
    ) -> CompensatorOutput {
        let applied = if self.applies() {
            FrameWrench {
                force: force + alpha.force,
                moment: moment + alpha.moment,
            }
        } else {
            FrameWrench::default()
        };
        CompensatorOutput {
            applied,
            velocity_correction: Vector3::zeros(),
            estimate: Some(ContactEstimate {
                stiffness: view.stiffness,
                damping: view.damping,
            }),
            observed_energy: self.energy(),
        }
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
        self.detector.update(&view.force);
        let active = force.norm() > self.detector.quiet_threshold();
        let damping = if self.virtual_damping && self.observer.mode == ObserverMode::Work {
            virtual_damping(view, input)
        } else {
            view.damping
        };
        if view.frictional && view.friction > 0.0 && !self.observer.is_booked() {
            self.observer.rebook(view.friction, &view.normal);
        }
        let (f_ek, open) = self.observer.step(
            view.in_contact,
            active,
            force,
            &view.normal,
            damping,
            view.friction,
            &v,
        );
        let f_alpha = if open {
            // after the contact (the window's tail) the force's own direction
            let direction = if view.in_contact || force.norm() == 0.0 {
                view.normal
            } else {
                force.normalize()
            };
            self.controller
                .step(self.observer.energy(), &f_ek, &direction, &v, force)
                .1
        } else {
            Vector3::zeros()
        };
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
                obs.step(true, true, &force, &e, 0.0, 0.0, &(e * v));
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

    /// The window counts every step of an exchange, closes with a deficit carried into the
    /// next exchange and a surplus forgotten, and counts nothing between exchanges.
    #[test]
    fn exchange_window_carries_a_deficit_and_forgets_a_surplus() {
        let mut w = ExchangeWindow::default();
        assert!(!w.step(0.0, false));
        assert!(w.step(0.0, true));
        w.step(0.1, true);
        w.step(-0.1005, true);
        assert!((w.energy() + 0.5e-3).abs() < 1e-15);
        // the step that ends at the closing tick still belongs to the exchange
        assert!(!w.step(-0.1e-3, false));
        assert!((w.carried() + 0.6e-3).abs() < 1e-15);
        assert_eq!(w.energy(), 0.0);
        // free flight: nothing is counted
        assert!(!w.step(5.0, false));
        // the next exchange opens with the deficit, ends with a surplus: forgotten
        assert!(w.step(0.0, true));
        assert!((w.energy() + 0.6e-3).abs() < 1e-15);
        w.step(1e-3, true);
        assert!(!w.step(0.0, false));
        assert_eq!(w.carried(), 0.0);
        // a deficit larger than CARRY_SHARE of the exchange's peak is carried only up to it
        assert!(w.step(0.0, true));
        w.step(1e-3, true);
        w.step(-1.5e-3, true);
        assert!(!w.step(0.0, false));
        assert!((w.carried() + CARRY_SHARE * 1e-3).abs() < 1e-15);
        w.reset();
        assert_eq!(w, ExchangeWindow::default());
    }

    /// With `work`, nothing is applied outside the window, and the force of the ticks just
    /// below the contact threshold opens it (their work is counted); with `paper` the window
    /// is the contact and the force is applied throughout.
    #[test]
    fn the_work_observer_covers_the_sub_threshold_ticks_and_the_paper_one_does_not() {
        let e = Vector3::new(1.0, 0.0, 0.0);
        let v = e * 0.02;
        for (mode, expected) in [(ObserverMode::Work, true), (ObserverMode::Paper, false)] {
            let mut obs = EnergyObserver::new(1e-3, mode);
            // a force of 1 N, below the 3 N threshold (not in contact) but above the noise
            let (_, open) = obs.step(false, true, &(e * 1.0), &Vector3::zeros(), 0.0, 0.0, &v);
            assert_eq!(open, expected, "{mode:?}");
            let (_, open) = obs.step(true, true, &(e * 5.0), &e, 0.0, 0.0, &v);
            assert!(open);
            // the 1 N held over the first step is in the energy with `work` only
            let first = 1e-3 * 1.0 * 0.02;
            if expected {
                assert!((obs.energy() - first).abs() < 1e-15, "{}", obs.energy());
            }
            assert!(obs.applies());
            obs.step(
                false,
                false,
                &Vector3::zeros(),
                &Vector3::zeros(),
                0.0,
                0.0,
                &v,
            );
            assert_eq!(obs.applies(), mode == ObserverMode::Paper);
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
