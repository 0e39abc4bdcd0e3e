//! Metrics (spec hil-loop.md §5, docs/model.md "Metrics"), defined once for simulations,
//! sweeps, reports and the real-time loop.
//!
//! - **Collision**: a maximal interval of samples where the physical contact force magnitude
//!   exceeds `metrics.contact_threshold`. Start: first sample above; end: first sample below.
//!   A collision still under way at the last sample is *incomplete*: it is listed, but has no
//!   rebound and counts in no ratio, no worst value and no verdict.
//! - **Matching**: HIL collisions are matched to reference collisions in order, by the
//!   alignment of least cost: leaving a collision unmatched costs 1, matching two costs
//!   `2 (1 − cos θ)` for the angle θ between their contact forces at the peak (collisions on
//!   different walls never match) plus at most 0.5 for the difference of their starts (the
//!   HIL's less the facility's lag, robot delay and servo lag, in units of the reference's
//!   median time between collisions), which only chooses among collisions on the same wall. A complete reference collision without a match that
//!   ended at least the loop's lag before the HIL run's last sample is *lost*; a complete HIL
//!   collision without a match is *extra*.
//! - **Rebound sample** of a matched pair: the middle of the common part of the two free
//!   flights that follow (each from its collision's end to the next collision's start or the
//!   end of the run), so both are read at the same time, where the sensor-delayed tail of the
//!   force has ended; each trace's own middle if the free flights do not overlap.
//! - Per matched pair of complete collisions:
//!   - `CoV = |v| / |v_ref|` (rebound speed of the rod tip relative to the target);
//!   - `velocity_error = |v − v_ref| / |v_ref|` (the rebound velocity as a vector: a rebound
//!     in the wrong direction has an error near 2 whatever its speed);
//!   - `angular_velocity_error = |ω − ω_ref| / |ω_ref|` of the servicer's angular velocity
//!     relative to the target (none when `|ω_ref|` < 1e-6 rad/s);
//!   - `CoF = F_peak / F_peak,ref` (physical contact force);
//!   - `impulse_ratio = |∫F dt| / |∫F_ref dt|` and `angular_impulse_ratio = |∫M dt| /
//!     |∫M_ref dt|`, the wrench the virtual dynamics felt (on the frame, moment about the
//!     sensor origin), from the collision's start to its rebound sample.
//! - **Contact episode**: a collision is an episode that may press several points. Each
//!   collision reports the normal and tangential impulse of the physical contact force
//!   (`J_n = ∫(F − F_t) dt`, `J_t = ∫F_t dt`, `F_t` its friction part; trapezoids from the
//!   sample before its start to its end), its peak moment about the sensor origin and its
//!   rebound velocity and angular velocity vectors. A matched pair adds the rebound direction
//!   error (degrees), the normal impulse error `|J_n − J_n,ref| / |J_n,ref|`, the tangential
//!   impulse error `|J_t − J_t,ref| / max(|J_t,ref|, 0.01 |J_n,ref|)`
//!   ([`TANGENTIAL_IMPULSE_FLOOR`]: 0, not NaN, without friction) and the peak moment ratio.
//! - **Local reference** ([`local_comparison`]): each complete HIL collision is also compared,
//!   by the same per-pair metrics, with the first collision of the ideal reference restarted
//!   from the virtual state just before it (`local_*` fields; a contact read from the state it
//!   began in). Read, never judged: the verdict stays the global comparison's.
//! - **Verdict**: a run that ran to its end is `unfaithful` when any matched collision breaks
//!   the tolerances ([`Tolerances`], `[metrics]` in the scenario: `|CoV − 1|`, CoF, velocity
//!   error, tangential impulse error) or more collisions are lost or extra than allowed; else `ok`.
//! - Identification error: mean of `|k̂/k − 1|` and of `|ĉ − c|` over contact samples after
//!   the first collision.
//! - Energy: kinetic energy of the virtual relative motion; a run whose energy passes a bound
//!   is `diverged` (a status, never a NaN or a crash).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::compensator::Rendering;
use crate::frames::FrameWrench;
use crate::stop::{Status, Stop};

/// What the metrics read of a run, one value per tick (the compact record a sweep keeps).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    /// Time, s.
    pub time: Vec<f64>,
    /// Magnitude of the physical contact force on the rod, N.
    pub force: Vec<f64>,
    /// The physical contact force on the rod, `t` frame, N.
    pub contact_force: Vec<Vector3<f64>>,
    /// Its tangential (friction) part, `t` frame, N (the normal part is `contact_force −
    /// friction_force`).
    pub friction_force: Vec<Vector3<f64>>,
    /// Moment of the physical contact force on the frame about the sensor origin, `t`, N·m.
    pub contact_moment: Vec<Vector3<f64>>,
    /// Velocity of the (virtual) rod tip relative to the target, `t` frame, m/s.
    pub velocity: Vec<Vector3<f64>>,
    /// Angular velocity of the (virtual) servicer relative to the target, `t` frame, rad/s.
    pub angular_velocity: Vec<Vector3<f64>>,
    /// Force the (virtual) dynamics felt, on the frame (the sensor's convention), `t`, N.
    pub wrench_force: Vec<Vector3<f64>>,
    /// Its moment about the sensor origin, `t`, N·m.
    pub wrench_moment: Vec<Vector3<f64>>,
    /// Kinetic energy of the (virtual) relative motion, J.
    pub energy: Vec<f64>,
    /// Identified stiffness, N/m (NaN when not identified; empty when nothing is identified).
    pub stiffness_estimate: Vec<f64>,
    /// Identified damping, N·s/m (NaN when not identified; empty when nothing is identified).
    pub damping_estimate: Vec<f64>,
    /// How many contact laws acted in parallel along the physical contact's normal
    /// ([`crate::world::Contact::law_factor`]; NaN where unknown; empty when nothing is
    /// identified).
    pub law_factor: Vec<f64>,
    /// Energy friction dissipated over the whole run, J (the ideal reference's; 0 otherwise).
    pub friction_work: f64,
    /// How the compensator handled each tick's contact (empty for the ideal reference).
    pub rendering: Vec<Rendering>,
}

/// One tick of a [`Trace`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceSample {
    /// Time, s.
    pub time: f64,
    /// Physical contact force on the rod, `t`, N.
    pub contact_force: Vector3<f64>,
    /// Its tangential (friction) part, `t`, N.
    pub friction_force: Vector3<f64>,
    /// Moment of the physical contact force on the frame about the sensor origin, `t`, N·m.
    pub contact_moment: Vector3<f64>,
    /// Rod tip velocity relative to the target, `t`, m/s.
    pub velocity: Vector3<f64>,
    /// Servicer angular velocity relative to the target, `t`, rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Wrench the dynamics felt, on the frame, `t` (moment about the sensor origin).
    pub wrench: FrameWrench,
    /// Kinetic energy of the relative motion, J.
    pub energy: f64,
}

impl Trace {
    /// An empty trace with room for `n` ticks (and estimates if `estimates`).
    pub fn with_capacity(n: usize, estimates: bool) -> Self {
        let e = if estimates { n } else { 0 };
        Trace {
            time: Vec::with_capacity(n),
            force: Vec::with_capacity(n),
            contact_force: Vec::with_capacity(n),
            friction_force: Vec::with_capacity(n),
            contact_moment: Vec::with_capacity(n),
            velocity: Vec::with_capacity(n),
            angular_velocity: Vec::with_capacity(n),
            wrench_force: Vec::with_capacity(n),
            wrench_moment: Vec::with_capacity(n),
            energy: Vec::with_capacity(n),
            stiffness_estimate: Vec::with_capacity(e),
            damping_estimate: Vec::with_capacity(e),
            law_factor: Vec::with_capacity(e),
            friction_work: 0.0,
            rendering: Vec::with_capacity(n),
        }
    }

    /// Appends one tick.
    pub fn push(&mut self, s: &TraceSample) {
        self.time.push(s.time);
        self.force.push(s.contact_force.norm());
        self.contact_force.push(s.contact_force);
        self.friction_force.push(s.friction_force);
        self.contact_moment.push(s.contact_moment);
        self.velocity.push(s.velocity);
        self.angular_velocity.push(s.angular_velocity);
        self.wrench_force.push(s.wrench.force);
        self.wrench_moment.push(s.wrench.moment);
        self.energy.push(s.energy);
    }

    /// Appends one tick's contact estimates (N/m, N·s/m) and the physical contact's
    /// [`Trace::law_factor`] (NaN where unknown).
    pub fn push_estimates(&mut self, stiffness: f64, damping: f64, law_factor: f64) {
        self.stiffness_estimate.push(stiffness);
        self.damping_estimate.push(damping);
        self.law_factor.push(law_factor);
    }

    /// Number of ticks.
    pub fn len(&self) -> usize {
        self.time.len()
    }

    /// Whether the trace has no tick.
    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    /// The sample nearest to time `t` (s); 0 for an empty trace.
    fn index_at(&self, t: f64) -> usize {
        let i = self.time.partition_point(|&x| x < t);
        if i == 0 {
            return 0;
        }
        if i >= self.time.len() {
            return self.time.len().saturating_sub(1);
        }
        if t - self.time[i - 1] <= self.time[i] - t {
            i - 1
        } else {
            i
        }
    }

    /// `∫ v dt` over samples `from..to` with each sample held until the next (ZOH).
    fn integral(&self, v: &[Vector3<f64>], from: usize, to: usize) -> Vector3<f64> {
        (from..to.min(self.len().saturating_sub(1)))
            .map(|i| v[i] * (self.time[i + 1] - self.time[i]))
            .sum()
    }
}

/// Where a collision lies in its trace, by sample index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Span {
    /// First sample above the threshold.
    start: usize,
    /// First sample below (the last sample of an incomplete collision).
    end: usize,
    /// Start of the next collision, or the last sample.
    next: usize,
    /// Whether the force fell below the threshold before the last sample.
    complete: bool,
}

fn spans(trace: &Trace, threshold: f64) -> Vec<Span> {
    let n = trace.len();
    let mut out: Vec<Span> = Vec::new();
    let mut start: Option<usize> = None;
    for i in 0..n {
        let in_contact = trace.force[i] > threshold;
        match (start, in_contact) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                out.push(Span {
                    start: s,
                    end: i,
                    next: n - 1,
                    complete: true,
                });
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push(Span {
            start: s,
            end: n - 1,
            next: n - 1,
            complete: false,
        });
    }
    for j in 1..out.len() {
        out[j - 1].next = out[j].start;
    }
    out
}

/// One collision of a run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Collision {
    /// 1-based index among the run's collisions.
    pub index: usize,
    /// Start time, s.
    pub start: f64,
    /// End time, s (the last sample's time for an incomplete collision).
    pub end: f64,
    /// Peak physical contact force, N.
    pub peak_force: f64,
    /// Whether the collision ended before the run did.
    pub complete: bool,
    /// Rebound speed, m/s, in the middle of the free flight that follows (none for an
    /// incomplete collision).
    pub rebound_speed: Option<f64>,
    /// Normal impulse `|J_n| = |∫ (F − F_t) dt|` of the physical contact force over the
    /// episode, N·s (trapezoidal, from the sample before its start to its end).
    pub normal_impulse: f64,
    /// Tangential (friction) impulse `|J_t| = |∫ F_t dt|` over the episode, N·s (0 without
    /// friction).
    pub tangential_impulse: f64,
    /// Peak moment of the physical contact force on the frame about the sensor origin, N·m.
    pub peak_moment: f64,
    /// Rebound velocity of the rod tip relative to the target, `t`, m/s, at the sample of
    /// `rebound_speed` (none for an incomplete collision).
    pub rebound_velocity: Option<[f64; 3]>,
    /// Angular velocity of the servicer relative to the target at the same sample, `t`,
    /// rad/s (none for an incomplete collision).
    pub rebound_angular_velocity: Option<[f64; 3]>,
    /// How the compensator handled the collision ([`collision_rendering`]); none for a
    /// compensator without a model and for the ideal reference.
    pub rendering: Option<Rendering>,
}

impl Collision {
    fn of(trace: &Trace, j: usize, s: &Span) -> Self {
        let (j_n, j_t) = impulses(trace, s);
        let rebound = (s.end + s.next) / 2;
        Collision {
            index: j + 1,
            start: trace.time[s.start],
            end: trace.time[s.end],
            peak_force: trace.force[s.start..=s.end]
                .iter()
                .cloned()
                .fold(0.0, f64::max),
            complete: s.complete,
            rebound_speed: s.complete.then(|| trace.velocity[rebound].norm()),
            normal_impulse: j_n.norm(),
            tangential_impulse: j_t.norm(),
            peak_moment: peak_norm(&trace.contact_moment[s.start..=s.end]),
            rebound_velocity: s.complete.then(|| trace.velocity[rebound].into()),
            rebound_angular_velocity: s.complete.then(|| trace.angular_velocity[rebound].into()),
            rendering: collision_rendering(&trace.rendering, s.start, s.next),
        }
    }
}

/// How a collision was handled, from the compensator's report of the ticks from its start
/// (`start`) up to the next collision's (`next`, excluded; or the end): `pida`'s (with its reason, the first reported) if
/// `pida` handled any of them, the model's if the model rendered any, else none. A contact
/// the compensator starts late (the measured force is the sensor delay behind the physical
/// one) or hands to `pida` midway is counted so.
pub fn collision_rendering(
    rendering: &[Rendering],
    start: usize,
    next: usize,
) -> Option<Rendering> {
    let ticks = rendering.get(start..next.max(start + 1).min(rendering.len()))?;
    ticks
        .iter()
        .find(|r| !matches!(r, Rendering::Unreported | Rendering::Model))
        .or_else(|| ticks.iter().find(|r| **r == Rendering::Model))
        .copied()
}

/// The largest norm of `v` (0 if empty).
fn peak_norm(v: &[Vector3<f64>]) -> f64 {
    v.iter().map(|x| x.norm()).fold(0.0, f64::max)
}

/// `∫ v dt` over a collision, trapezoidal, from the sample before its start (below the
/// threshold, or the first sample) to its end (the first sample below).
fn episode_integral(trace: &Trace, v: &[Vector3<f64>], s: &Span) -> Vector3<f64> {
    (s.start.saturating_sub(1)..s.end)
        .map(|i| (v[i] + v[i + 1]) * (0.5 * (trace.time[i + 1] - trace.time[i])))
        .sum()
}

/// Normal and tangential (friction) impulse vectors of the physical contact force over a
/// collision, `t`, N·s: `J_n = ∫ (F − F_t) dt`, `J_t = ∫ F_t dt`.
fn impulses(trace: &Trace, s: &Span) -> (Vector3<f64>, Vector3<f64>) {
    let total = episode_integral(trace, &trace.contact_force, s);
    let tangential = episode_integral(trace, &trace.friction_force, s);
    (total - tangential, tangential)
}

/// The floor of the tangential impulse error's denominator, as a fraction of the reference's
/// normal impulse: `|J_t − J_t,ref| / max(|J_t,ref|, TANGENTIAL_IMPULSE_FLOOR · |J_n,ref|)`.
/// A frictionless contact (both `J_t` zero) has error 0, never NaN; one with a friction
/// coefficient below 0.01 is judged against this floor, a tangential impulse of 1 % of the
/// normal one.
pub const TANGENTIAL_IMPULSE_FLOOR: f64 = 0.01;

/// The angle between two vectors, degrees (none if either is shorter than 1e-12).
fn angle_deg(a: &Vector3<f64>, b: &Vector3<f64>) -> Option<f64> {
    (a.norm() >= 1e-12 && b.norm() >= 1e-12).then(|| a.cross(b).norm().atan2(a.dot(b)).to_degrees())
}

/// Finds the collisions of a trace (see the module doc).
pub fn collisions(trace: &Trace, threshold: f64) -> Vec<Collision> {
    spans(trace, threshold)
        .iter()
        .enumerate()
        .map(|(j, s)| Collision::of(trace, j, s))
        .collect()
}

/// A HIL collision compared with the reference collision it is matched to.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ComparedCollision {
    /// The collision itself.
    #[serde(flatten)]
    pub collision: Collision,
    /// Index of the matched reference collision (none for an extra collision).
    pub reference: Option<usize>,
    /// Time of the rebound sample, s (none unless both collisions are complete).
    pub rebound_time: Option<f64>,
    /// CoV = |v| / |v_ref|.
    pub cov: Option<f64>,
    /// CoF = F_peak / F_peak,ref.
    pub cof: Option<f64>,
    /// |v − v_ref| / |v_ref| of the rebound velocity (fraction).
    pub velocity_error: Option<f64>,
    /// |ω − ω_ref| / |ω_ref| of the relative angular velocity after the collision (fraction;
    /// none when the reference hardly turns).
    pub angular_velocity_error: Option<f64>,
    /// |∫F dt| / |∫F_ref dt| of the wrench the virtual dynamics felt.
    pub impulse_ratio: Option<f64>,
    /// |∫M dt| / |∫M_ref dt| (moments about the sensor origin).
    pub angular_impulse_ratio: Option<f64>,
    /// Rebound direction error: the angle between `v` and `v_ref` at the rebound sample,
    /// degrees (none when either is zero).
    pub direction_error: Option<f64>,
    /// Normal impulse error `|J_n − J_n,ref| / |J_n,ref|` of the physical contact force
    /// (impulse vectors; fraction).
    pub normal_impulse_error: Option<f64>,
    /// Tangential impulse error `|J_t − J_t,ref| / max(|J_t,ref|, 0.01 |J_n,ref|)` (impulse
    /// vectors, [`TANGENTIAL_IMPULSE_FLOOR`]; fraction; 0 for two frictionless contacts).
    pub tangential_impulse_error: Option<f64>,
    /// Peak moment of the physical contact about the sensor origin / the reference's (none
    /// when the reference's lever arm is below 1 µm).
    pub peak_moment_ratio: Option<f64>,
    /// Time of the local reference's restart, s: the virtual state there, with the bodies
    /// apart, is where the ideal reference was run again for this collision alone
    /// ([`local_comparison`]; none without the virtual states, e.g. real-time runs and
    /// replays, or when no tick with the bodies apart was found).
    pub local_start: Option<f64>,
    /// `|v − v_loc| / |v_loc|`: the rebound velocity error against the local reference's
    /// first collision ([`local_comparison`]; fraction). Read, never judged.
    pub local_velocity_error: Option<f64>,
    /// `F_peak / F_peak,loc` against the local reference's first collision. Read, never judged.
    pub local_cof: Option<f64>,
    /// `|J_t − J_t,loc| / max(|J_t,loc|, 0.01 |J_n,loc|)` against the local reference's
    /// first collision (fraction). Read, never judged.
    pub local_tangential_impulse_error: Option<f64>,
    /// `|J_n − J_n,loc| / |J_n,loc|` against the local reference's first collision
    /// (fraction). Read, never judged.
    pub local_normal_impulse_error: Option<f64>,
}

/// When a run is faithful (`[metrics]` in the scenario; docs/model.md "Metrics").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Tolerances {
    /// Largest `|CoV − 1|` of a collision (fraction).
    pub cov: f64,
    /// Largest CoF of a collision.
    pub cof: f64,
    /// Largest rebound velocity error `|v − v_ref| / |v_ref|` (fraction).
    pub velocity_error: f64,
    /// Largest tangential impulse error `|J_t − J_t,ref| / max(|J_t,ref|, 0.01 |J_n,ref|)`
    /// (fraction).
    #[serde(default = "default_tangential_impulse_error")]
    pub tangential_impulse_error: f64,
    /// How many reference collisions may be lost.
    pub lost_collisions: usize,
    /// How many HIL collisions may have no reference collision.
    pub extra_collisions: usize,
    /// The first collision judged (1-based): earlier ones are reported, not judged.
    pub judge_from: usize,
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            cov: 0.05,
            cof: 1.2,
            velocity_error: 0.05,
            tangential_impulse_error: default_tangential_impulse_error(),
            lost_collisions: 0,
            extra_collisions: 0,
            judge_from: 1,
        }
    }
}

fn default_tangential_impulse_error() -> f64 {
    0.10
}

/// The collisions of a HIL run against the reference's, and the verdict on them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    /// The HIL run's collisions, compared.
    pub collisions: Vec<ComparedCollision>,
    /// The reference's collisions.
    pub reference_collisions: Vec<Collision>,
    /// Indices of the lost reference collisions.
    pub lost_collisions: Vec<usize>,
    /// Indices of the extra HIL collisions.
    pub extra_collisions: Vec<usize>,
    /// Every tolerance the run breaks, one line each (empty for a faithful run).
    pub violations: Vec<String>,
}

/// Compares a HIL trace with the reference's (see the module doc). `lag`: the loop's lag, s
/// (robot delay plus servo lag: HIL collisions start that much after the reference's);
/// `settle`: how long after a reference collision's end its HIL collision must have ended,
/// s (the lag plus the sensor delay and a few ticks), before it can be called lost.
pub fn compare(
    hil: &Trace,
    reference: &Trace,
    threshold: f64,
    tolerances: &Tolerances,
    lag: f64,
    settle: f64,
) -> Comparison {
    let hs = spans(hil, threshold);
    let rs = spans(reference, threshold);
    let matched = align(hil, &hs, reference, &rs, lag);
    let mut partner: Vec<Option<usize>> = vec![None; hs.len()];
    for (i, m) in matched.iter().enumerate() {
        if let Some(j) = *m {
            partner[j] = Some(i);
        }
    }
    let collisions: Vec<ComparedCollision> = hs
        .iter()
        .enumerate()
        .map(|(j, h)| {
            let collision = Collision::of(hil, j, h);
            let mut c = ComparedCollision {
                collision,
                reference: partner[j].map(|i| i + 1),
                rebound_time: None,
                cov: None,
                cof: None,
                velocity_error: None,
                angular_velocity_error: None,
                impulse_ratio: None,
                angular_impulse_ratio: None,
                direction_error: None,
                normal_impulse_error: None,
                tangential_impulse_error: None,
                peak_moment_ratio: None,
                local_start: None,
                local_velocity_error: None,
                local_cof: None,
                local_tangential_impulse_error: None,
                local_normal_impulse_error: None,
            };
            if let Some(i) = partner[j] {
                compare_pair(&mut c, hil, &hs, j, reference, &rs, i);
            }
            c
        })
        .collect();
    let last = hil.time.last().copied().unwrap_or(f64::NEG_INFINITY);
    let lost_collisions: Vec<usize> = rs
        .iter()
        .enumerate()
        .filter(|(i, r)| {
            matched[*i].is_none() && r.complete && reference.time[r.end] + settle <= last
        })
        .map(|(i, _)| i + 1)
        .collect();
    let extra_collisions: Vec<usize> = hs
        .iter()
        .enumerate()
        .filter(|(j, h)| partner[*j].is_none() && h.complete)
        .map(|(j, _)| j + 1)
        .collect();
    let violations = verdict(&collisions, &lost_collisions, &extra_collisions, tolerances);
    Comparison {
        collisions,
        reference_collisions: rs
            .iter()
            .enumerate()
            .map(|(i, s)| Collision::of(reference, i, s))
            .collect(),
        lost_collisions,
        extra_collisions,
        violations,
    }
}

/// The per-pair metrics of HIL collision `j` (spans `hs` of `hil`) against reference
/// collision `i` (spans `rs` of `reference`), written into `c` (see the module doc; nothing
/// unless both are complete). The reference may be a local one ([`local_comparison`]): the
/// two traces are read by time, so they need not start at the same sample.
fn compare_pair(
    c: &mut ComparedCollision,
    hil: &Trace,
    hs: &[Span],
    j: usize,
    reference: &Trace,
    rs: &[Span],
    i: usize,
) {
    let ratio = |a: f64, b: f64| (b > 0.0 && a.is_finite()).then(|| a / b);
    let (h, r) = (&hs[j], &rs[i]);
    if !(h.complete && r.complete) {
        return;
    }
    // the rebound sample: the middle of the common free flight
    let lo = hil.time[h.end].max(reference.time[r.end]);
    let hi = hil.time[h.next].min(reference.time[r.next]);
    let (hi_i, ri) = if hi > lo {
        let t = 0.5 * (lo + hi);
        (hil.index_at(t), reference.index_at(t))
    } else {
        ((h.end + h.next) / 2, (r.end + r.next) / 2)
    };
    let (v, v_ref) = (hil.velocity[hi_i], reference.velocity[ri]);
    let (w, w_ref) = (hil.angular_velocity[hi_i], reference.angular_velocity[ri]);
    let peak = |t: &Trace, s: &Span| t.force[s.start..=s.end].iter().cloned().fold(0.0, f64::max);
    // from the middle of the free flight before the collision: a compensator may make
    // the virtual dynamics feel the contact before the robot does (model-mediated)
    let from = |spans: &[Span], j: usize| match j {
        0 => 0,
        _ => (spans[j - 1].end + spans[j].start) / 2,
    };
    let impulse = |t: &Trace, from: usize, to: usize| {
        (
            t.integral(&t.wrench_force, from, to),
            t.integral(&t.wrench_moment, from, to),
        )
    };
    let (j_h, m_h) = impulse(hil, from(hs, j), hi_i);
    let (j_r, m_r) = impulse(reference, from(rs, i), ri);
    c.rebound_time = Some(hil.time[hi_i]);
    c.cov = ratio(v.norm(), v_ref.norm());
    c.velocity_error = ratio((v - v_ref).norm(), v_ref.norm());
    c.angular_velocity_error = (w_ref.norm() >= 1e-6).then(|| (w - w_ref).norm() / w_ref.norm());
    c.cof = ratio(peak(hil, h), peak(reference, r));
    c.impulse_ratio = ratio(j_h.norm(), j_r.norm());
    c.angular_impulse_ratio = ratio(m_h.norm(), m_r.norm());
    c.direction_error = angle_deg(&v, &v_ref);
    let ((jn_h, jt_h), (jn_r, jt_r)) = (impulses(hil, h), impulses(reference, r));
    c.normal_impulse_error = ratio((jn_h - jn_r).norm(), jn_r.norm());
    c.tangential_impulse_error = ratio(
        (jt_h - jt_r).norm(),
        jt_r.norm().max(TANGENTIAL_IMPULSE_FLOOR * jn_r.norm()),
    );
    let (m_peak, m_peak_ref) = (
        peak_norm(&hil.contact_moment[h.start..=h.end]),
        peak_norm(&reference.contact_moment[r.start..=r.end]),
    );
    c.peak_moment_ratio = (m_peak_ref > 1e-6 * peak(reference, r))
        .then(|| m_peak / m_peak_ref)
        .filter(|x| x.is_finite());
}

/// Where a HIL collision lies in its trace, by sample index (= tick): what a local reference
/// is restarted from ([`local_comparison`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CollisionSpan {
    /// First sample above the threshold.
    pub start: usize,
    /// First sample below it.
    pub end: usize,
    /// Start of the next collision, or the last sample.
    pub next: usize,
    /// End of the previous collision (0 for the first).
    pub previous_end: usize,
}

/// The local (restarted) reference of each complete HIL collision, and the errors against it
/// (docs/model.md "Metrics"): `restart` runs the ideal reference again from the virtual state
/// at a tick before the collision where the bodies are apart and hands back its trace (samples
/// at the HIL trace's times from that tick on) and the restart's time, or none; the
/// collision is then compared with the local reference's first collision by
/// the same per-pair metrics as with the global reference's ([`compare`]), into the
/// `local_*` fields. A local reference whose first sample is in contact, or whose first
/// collision does not end, gives none. The global metrics and the verdict are untouched:
/// the local errors read each contact on its own, from the state the run was in.
pub fn local_comparison(
    hil: &Trace,
    threshold: f64,
    collisions: &mut [ComparedCollision],
    mut restart: impl FnMut(&CollisionSpan) -> Option<(f64, Trace)>,
) {
    let hs = spans(hil, threshold);
    for (j, h) in hs.iter().enumerate() {
        let Some(c) = collisions.get_mut(j) else {
            break;
        };
        if !h.complete {
            continue;
        }
        let span = CollisionSpan {
            start: h.start,
            end: h.end,
            next: h.next,
            previous_end: if j == 0 { 0 } else { hs[j - 1].end },
        };
        let Some((start, local)) = restart(&span) else {
            continue;
        };
        let ls = spans(&local, threshold);
        let apart = local.force.first().is_some_and(|&f| f <= threshold);
        if !apart || !ls.first().is_some_and(|l| l.complete) {
            continue;
        }
        let mut pair = c.clone();
        compare_pair(&mut pair, hil, &hs, j, &local, &ls, 0);
        c.local_start = Some(start);
        c.local_velocity_error = pair.velocity_error;
        c.local_cof = pair.cof;
        c.local_tangential_impulse_error = pair.tangential_impulse_error;
        c.local_normal_impulse_error = pair.normal_impulse_error;
    }
}

/// Matches HIL collisions to reference collisions: the order-keeping alignment of least
/// cost (Needleman–Wunsch), where leaving a collision unmatched costs 1 and matching two costs
/// `0.5 min(|Δt| / gap, 1) + 2 (1 − cos θ)`: `Δt` the difference of their starts after the
/// lag, `gap` the reference's median time between collision starts, `θ` the angle between
/// their contact forces at the peak. Collisions on different walls (θ large) do not match;
/// on the same wall the k-th matches the k-th, however far a diverging run has drifted in
/// time, unless another one is nearer in time (a collision split in two by a rebound within
/// it). Returns, for each reference collision, the index of its HIL collision.
fn align(hil: &Trace, hs: &[Span], reference: &Trace, rs: &[Span], lag: f64) -> Vec<Option<usize>> {
    let (n, m) = (rs.len(), hs.len());
    let mut gaps: Vec<f64> = rs
        .windows(2)
        .map(|w| reference.time[w[1].start] - reference.time[w[0].start])
        .collect();
    gaps.sort_by(f64::total_cmp);
    let span =
        |t: &Trace| t.time.last().copied().unwrap_or(0.0) - t.time.first().copied().unwrap_or(0.0);
    let gap = gaps
        .get(gaps.len() / 2)
        .copied()
        .unwrap_or_else(|| span(reference))
        .max(1e-9);
    let direction = |t: &Trace, s: &Span| {
        let peak = (s.start..=s.end)
            .max_by(|&a, &b| t.force[a].total_cmp(&t.force[b]))
            .unwrap_or(s.start);
        t.contact_force[peak]
            .try_normalize(1e-12)
            .unwrap_or_else(Vector3::zeros)
    };
    let (dr, dh): (Vec<_>, Vec<_>) = (
        rs.iter().map(|s| direction(reference, s)).collect(),
        hs.iter().map(|s| direction(hil, s)).collect(),
    );
    let cost = |i: usize, j: usize| {
        let dt = (hil.time[hs[j].start] - lag - reference.time[rs[i].start]).abs();
        0.5 * (dt / gap).min(1.0) + 2.0 * (1.0 - dr[i].dot(&dh[j]))
    };
    // d[i][j]: least cost of aligning the first i reference and the first j HIL collisions
    let mut d = vec![vec![0.0f64; m + 1]; n + 1];
    for i in 0..=n {
        for j in 0..=m {
            d[i][j] = match (i, j) {
                (0, _) => j as f64,
                (_, 0) => i as f64,
                _ => (d[i - 1][j - 1] + cost(i - 1, j - 1))
                    .min(d[i - 1][j] + 1.0)
                    .min(d[i][j - 1] + 1.0),
            };
        }
    }
    let mut matched = vec![None; n];
    let (mut i, mut j) = (n, m);
    while i > 0 && j > 0 {
        if d[i][j] == d[i - 1][j - 1] + cost(i - 1, j - 1) {
            matched[i - 1] = Some(j - 1);
            i -= 1;
            j -= 1;
        } else if d[i][j] == d[i - 1][j] + 1.0 {
            i -= 1;
        } else {
            j -= 1;
        }
    }
    matched
}

/// Every tolerance broken, one line each (formats: not for a real-time tick).
fn verdict(
    collisions: &[ComparedCollision],
    lost: &[usize],
    extra: &[usize],
    tol: &Tolerances,
) -> Vec<String> {
    let mut out = Vec::new();
    for c in collisions {
        let n = c.collision.index;
        if n < tol.judge_from {
            continue; // reported, not judged
        }
        if let Some(cov) = c.cov.filter(|v| (v - 1.0).abs() > tol.cov) {
            out.push(format!(
                "collision {n}: |CoV - 1| = {:.3} > {}",
                (cov - 1.0).abs(),
                tol.cov
            ));
        }
        if let Some(cof) = c.cof.filter(|v| *v > tol.cof) {
            out.push(format!("collision {n}: CoF = {cof:.3} > {}", tol.cof));
        }
        if let Some(e) = c.velocity_error.filter(|v| *v > tol.velocity_error) {
            out.push(format!(
                "collision {n}: rebound velocity error {e:.3} > {}",
                tol.velocity_error
            ));
        }
        if let Some(e) = c
            .tangential_impulse_error
            .filter(|v| *v > tol.tangential_impulse_error)
        {
            out.push(format!(
                "collision {n}: tangential impulse error {e:.3} > {}",
                tol.tangential_impulse_error
            ));
        }
    }
    if lost.len() > tol.lost_collisions {
        out.push(format!(
            "{} reference collision(s) lost ({}) > {} allowed",
            lost.len(),
            list(lost),
            tol.lost_collisions
        ));
    }
    if extra.len() > tol.extra_collisions {
        out.push(format!(
            "{} extra collision(s) ({}) > {} allowed",
            extra.len(),
            list(extra),
            tol.extra_collisions
        ));
    }
    out
}

fn list(indices: &[usize]) -> String {
    indices
        .iter()
        .map(|i| format!("#{i}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Identification error of the contact estimates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IdentificationError {
    /// Mean `|k̂/k − 1|` (fraction).
    pub stiffness_error: f64,
    /// Mean `|ĉ − c|`, N·s/m.
    pub damping_error: f64,
    /// Number of samples averaged.
    pub samples: usize,
    /// The units of the two errors, written with them into `metrics.json`
    /// ([`IDENTIFICATION_UNITS`]).
    pub units: IdentificationUnits,
}

/// The units of [`IdentificationError`]'s errors, as `metrics.json` states them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct IdentificationUnits {
    /// Unit of `stiffness_error`.
    pub stiffness_error: &'static str,
    /// Unit of `damping_error`.
    pub damping_error: &'static str,
}

/// `stiffness_error` is a fraction (0.01 = 1 %), `damping_error` is in N·s/m.
pub const IDENTIFICATION_UNITS: IdentificationUnits = IdentificationUnits {
    stiffness_error: "fraction (0.01 = 1 %)",
    damping_error: "N·s/m",
};

/// Identification error over samples in contact (`force > threshold`) after the first
/// collision's end; `None` if there is no such sample or the trace has no estimates.
/// `stiffness` and `damping` are the law at one contact point; a sample where the contact
/// pressed several points at once is compared with the law along its normal, `λ·k` and `λ·c`
/// (`λ` the sample's [`Trace::law_factor`], `Σᵢ (nᵢ·n̂)²`: a probe in the crease of two facets
/// is twice as stiff as one facet), the law an identification along one normal finds; a sample
/// without a known factor with the point's law.
pub fn identification_error(
    trace: &Trace,
    threshold: f64,
    first_collision_end: f64,
    stiffness: f64,
    damping: f64,
) -> Option<IdentificationError> {
    let (mut sk, mut sc, mut n) = (0.0, 0.0, 0usize);
    let estimates = trace.stiffness_estimate.iter().zip(&trace.damping_estimate);
    for (i, (&k, &c)) in estimates.enumerate() {
        if trace.time[i] > first_collision_end
            && trace.force[i] > threshold
            && k.is_finite()
            && c.is_finite()
        {
            // `λ` (1 where unknown or exactly one point)
            let factor = trace
                .law_factor
                .get(i)
                .copied()
                .filter(|f| f.is_finite() && *f > 0.0)
                .unwrap_or(1.0);
            sk += (k / (factor * stiffness) - 1.0).abs();
            sc += (c - factor * damping).abs();
            n += 1;
        }
    }
    (n > 0).then(|| IdentificationError {
        stiffness_error: sk / n as f64,
        damping_error: sc / n as f64,
        samples: n,
        units: IDENTIFICATION_UNITS,
    })
}

/// The value farthest from `target` of the finite values, and their mean (NaN, NaN if none).
fn mean_and_worst(values: impl Iterator<Item = f64>, target: f64) -> (f64, f64) {
    let (mut sum, mut n, mut worst) = (0.0, 0usize, f64::NAN);
    for v in values.filter(|v| v.is_finite()) {
        sum += v;
        n += 1;
        if worst.is_nan() || (v - target).abs() > (worst - target).abs() {
            worst = v;
        }
    }
    (if n > 0 { sum / n as f64 } else { f64::NAN }, worst)
}

/// A run's collisions in a few numbers (complete, matched collisions only).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    /// Number of HIL collisions (complete or not).
    pub collisions: usize,
    /// Number of collisions compared with the reference (both complete).
    pub compared: usize,
    /// Mean CoV (NaN if none).
    pub mean_cov: f64,
    /// The CoV farthest from 1 (NaN if none).
    pub worst_cov: f64,
    /// Mean CoF (NaN if none).
    pub mean_cof: f64,
    /// The CoF farthest from 1 (NaN if none).
    pub worst_cof: f64,
    /// The largest rebound velocity error (fraction, NaN if none).
    pub worst_velocity_error: f64,
    /// The largest angular velocity error (fraction, NaN if none).
    pub worst_angular_velocity_error: f64,
    /// The impulse ratio farthest from 1 (NaN if none).
    pub worst_impulse_ratio: f64,
    /// The angular impulse ratio farthest from 1 (NaN if none).
    pub worst_angular_impulse_ratio: f64,
    /// The largest rebound direction error, degrees (NaN if none).
    pub worst_direction_error: f64,
    /// The largest normal impulse error (fraction, NaN if none).
    pub worst_normal_impulse_error: f64,
    /// The largest tangential impulse error (fraction, NaN if none).
    pub worst_tangential_impulse_error: f64,
    /// The peak moment ratio farthest from 1 (NaN if none).
    pub worst_peak_moment_ratio: f64,
    /// The largest local rebound velocity error from `judge_from` on (fraction, NaN if none;
    /// [`local_comparison`], read, never judged).
    pub worst_local_velocity_error: f64,
    /// The local CoF farthest from 1 from `judge_from` on (NaN if none).
    pub worst_local_cof: f64,
    /// The largest local tangential impulse error from `judge_from` on (fraction, NaN if none).
    pub worst_local_tangential_impulse_error: f64,
    /// The largest local normal impulse error from `judge_from` on (fraction, NaN if none).
    pub worst_local_normal_impulse_error: f64,
}

impl Summary {
    /// The summary of compared collisions (the local errors' worst over all of them).
    pub fn of(collisions: &[ComparedCollision]) -> Self {
        Self::judged_from(collisions, 1)
    }

    /// The summary of compared collisions, the local errors' worst over those from the
    /// `judge_from`-th on (1-based, [`Tolerances::judge_from`]).
    pub fn judged_from(collisions: &[ComparedCollision], judge_from: usize) -> Self {
        let pick = |f: fn(&ComparedCollision) -> Option<f64>, target: f64| {
            mean_and_worst(collisions.iter().filter_map(f), target)
        };
        let local = |f: fn(&ComparedCollision) -> Option<f64>, target: f64| {
            let judged = collisions
                .iter()
                .filter(|c| c.collision.index >= judge_from);
            mean_and_worst(judged.filter_map(f), target).1
        };
        let (mean_cov, worst_cov) = pick(|c| c.cov, 1.0);
        let (mean_cof, worst_cof) = pick(|c| c.cof, 1.0);
        Summary {
            collisions: collisions.len(),
            compared: collisions.iter().filter(|c| c.cov.is_some()).count(),
            mean_cov,
            worst_cov,
            mean_cof,
            worst_cof,
            worst_velocity_error: pick(|c| c.velocity_error, 0.0).1,
            worst_angular_velocity_error: pick(|c| c.angular_velocity_error, 0.0).1,
            worst_impulse_ratio: pick(|c| c.impulse_ratio, 1.0).1,
            worst_angular_impulse_ratio: pick(|c| c.angular_impulse_ratio, 1.0).1,
            worst_direction_error: pick(|c| c.direction_error, 0.0).1,
            worst_normal_impulse_error: pick(|c| c.normal_impulse_error, 0.0).1,
            worst_tangential_impulse_error: pick(|c| c.tangential_impulse_error, 0.0).1,
            worst_peak_moment_ratio: pick(|c| c.peak_moment_ratio, 1.0).1,
            worst_local_velocity_error: local(|c| c.local_velocity_error, 0.0),
            worst_local_cof: local(|c| c.local_cof, 1.0),
            worst_local_tangential_impulse_error: local(|c| c.local_tangential_impulse_error, 0.0),
            worst_local_normal_impulse_error: local(|c| c.local_normal_impulse_error, 0.0),
        }
    }
}

/// Energy summary, J.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EnergySummary {
    /// Energy at t = 0.
    pub initial: f64,
    /// Energy at the last sample.
    pub r#final: f64,
    /// The reference's energy at its last sample.
    pub reference_final: f64,
    /// Energy friction dissipated in the reference, J (0 without friction); the rest of the
    /// reference's loss, `initial − reference_final − reference_friction_work` out of contact,
    /// is the damping's.
    pub reference_friction_work: f64,
    /// Largest energy of the run.
    pub max: f64,
}

/// Everything `metrics.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Metrics {
    /// Scenario name.
    pub scenario: String,
    /// Compensator kind.
    pub compensator: String,
    /// `ok`, `unfaithful`, `interrupted`, `diverged` or `stopped` (from `stop` and, for a run
    /// that ran to its end, `violations`).
    pub status: Status,
    /// Time at which divergence was detected, s.
    pub diverged_at: Option<f64>,
    /// Why the run stopped early (from `stop`), or why it is unfaithful (the first
    /// violation and how many more).
    pub reason: Option<String>,
    /// How the run stopped.
    pub stop: Stop,
    /// The HIL run's collisions, compared with the reference's.
    pub collisions: Vec<ComparedCollision>,
    /// Mean and worst values of `collisions`.
    pub summary: Summary,
    /// The ideal reference's collisions.
    pub reference_collisions: Vec<Collision>,
    /// Indices of the reference collisions the HIL run lost.
    pub lost_collisions: Vec<usize>,
    /// Indices of the HIL collisions that have no reference collision.
    pub extra_collisions: Vec<usize>,
    /// Every tolerance the run breaks, one line each.
    pub violations: Vec<String>,
    /// The tolerances of the verdict.
    pub tolerances: Tolerances,
    /// Identification error, when the compensator identifies the contact.
    pub identification: Option<IdentificationError>,
    /// Energy summary.
    pub energy: EnergySummary,
}

impl Metrics {
    /// The status of a run that stopped with `stop` and broke `violations`: `unfaithful`
    /// instead of `ok` when it broke any.
    pub fn verdict(stop: &Stop, violations: &[String]) -> Status {
        match stop.kind.status() {
            Status::Ok if !violations.is_empty() => Status::Unfaithful,
            status => status,
        }
    }
}

/// Energy bound past which a run is `diverged`, J: `ratio × max(initial, reference peak)`.
pub fn divergence_bound(ratio: f64, initial_energy: f64, reference_energy: &[f64]) -> f64 {
    ratio
        * reference_energy
            .iter()
            .cloned()
            .fold(initial_energy, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stop::StopKind;

    /// A trace sampled every 0.1 s: contact force magnitude (along −x on the rod, so the
    /// frame feels +x) and rod tip velocity per sample.
    fn trace(force: &[f64], velocity: &[Vector3<f64>]) -> Trace {
        let mut t = Trace::with_capacity(force.len(), false);
        for (i, (&f, v)) in force.iter().zip(velocity).enumerate() {
            t.push(&TraceSample {
                time: i as f64 * 0.1,
                contact_force: Vector3::new(-f, 0.0, 0.0),
                friction_force: Vector3::zeros(),
                contact_moment: Vector3::new(0.0, 0.0, 0.1 * f),
                velocity: *v,
                angular_velocity: Vector3::new(0.0, 0.0, 0.01),
                wrench: FrameWrench {
                    force: Vector3::new(f, 0.0, 0.0),
                    moment: Vector3::new(0.0, 0.0, 0.1 * f),
                },
                energy: 1.0,
            });
        }
        t
    }

    /// Contact `peak` N on the sample ranges given, 0 elsewhere, over `n` samples.
    fn pulses(n: usize, spans: &[(usize, usize, f64)]) -> Vec<f64> {
        (0..n)
            .map(|i| {
                spans
                    .iter()
                    .find(|s| (s.0..s.1).contains(&i))
                    .map_or(0.0, |s| s.2)
            })
            .collect()
    }

    /// Velocity +x before sample `a`, `after` from then on.
    fn velocities(n: usize, a: usize, after: Vector3<f64>) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|i| if i < a { Vector3::x() } else { after })
            .collect()
    }

    fn tol() -> Tolerances {
        Tolerances::default()
    }

    #[test]
    fn finds_collisions_and_rebounds() {
        // 0..10: free, 10..20 contact, 20..40 free, 40..50 contact, 50..60 free
        let speed: Vec<Vector3<f64>> = (0..60).map(|i| Vector3::new(i as f64, 0.0, 0.0)).collect();
        let t = trace(&pulses(60, &[(10, 20, 5.0), (40, 50, 7.0)]), &speed);
        let c = collisions(&t, 0.5);
        assert_eq!(c.len(), 2);
        assert!((c[0].start - 1.0).abs() < 1e-12 && (c[0].end - 2.0).abs() < 1e-12);
        assert_eq!(c[0].rebound_speed, Some(30.0)); // midway between 20 and 40
        assert_eq!(c[1].rebound_speed, Some(54.0)); // midway between 50 and 59
        assert_eq!(c[1].peak_force, 7.0);
        assert!(c[0].complete && c[1].complete);
    }

    #[test]
    fn identical_runs_are_faithful_with_unit_ratios() {
        let v = velocities(60, 20, Vector3::new(-0.9, 0.1, 0.0));
        let t = trace(&pulses(60, &[(10, 20, 5.0)]), &v);
        let c = compare(&t, &t, 0.5, &tol(), 0.0, 0.0);
        assert!(c.violations.is_empty(), "{:?}", c.violations);
        let x = &c.collisions[0];
        assert_eq!(x.reference, Some(1));
        for r in [x.cov, x.cof, x.impulse_ratio, x.angular_impulse_ratio] {
            assert!((r.unwrap() - 1.0).abs() < 1e-12);
        }
        assert_eq!(x.velocity_error, Some(0.0));
        assert_eq!(x.angular_velocity_error, Some(0.0));
    }

    #[test]
    fn ratios_against_the_reference_and_the_impulse_over_the_collision() {
        let r = trace(
            &pulses(60, &[(10, 20, 100.0)]),
            &velocities(60, 20, -0.02 * Vector3::x()),
        );
        let h = trace(
            &pulses(60, &[(10, 20, 120.0)]),
            &velocities(60, 20, -0.03 * Vector3::x()),
        );
        let c = compare(&h, &r, 0.5, &tol(), 0.0, 0.0);
        let x = &c.collisions[0];
        assert!((x.cov.unwrap() - 1.5).abs() < 1e-12);
        assert!((x.cof.unwrap() - 1.2).abs() < 1e-12);
        assert!((x.velocity_error.unwrap() - 0.5).abs() < 1e-12);
        assert!((x.impulse_ratio.unwrap() - 1.2).abs() < 1e-12);
        assert!((x.angular_impulse_ratio.unwrap() - 1.2).abs() < 1e-12);
        // CoV 1.5 and velocity error 0.5 break their tolerances; CoF 1.2 is at its limit
        assert_eq!(c.violations.len(), 2, "{:?}", c.violations);
        assert!(c.violations[0].contains("CoV"));
    }

    #[test]
    fn judge_from_reports_earlier_collisions_without_judging_them() {
        let r = trace(
            &pulses(100, &[(10, 20, 100.0), (50, 60, 100.0)]),
            &velocities(100, 20, -0.02 * Vector3::x()),
        );
        // the first collision 1.5 times as strong, the second exact
        let h = trace(
            &pulses(100, &[(10, 20, 150.0), (50, 60, 100.0)]),
            &velocities(100, 20, -0.02 * Vector3::x()),
        );
        let judged = compare(&h, &r, 0.5, &tol(), 0.0, 0.0);
        assert!(!judged.violations.is_empty());
        let from_2 = Tolerances {
            judge_from: 2,
            ..tol()
        };
        let c = compare(&h, &r, 0.5, &from_2, 0.0, 0.0);
        assert!(c.violations.is_empty(), "{:?}", c.violations);
        // still reported
        assert!((c.collisions[0].cof.unwrap() - 1.5).abs() < 1e-12);
        // a lost collision counts whatever judge_from says
        let one = trace(
            &pulses(100, &[(10, 20, 100.0)]),
            &velocities(100, 20, -0.02 * Vector3::x()),
        );
        let lost = compare(&one, &r, 0.5, &from_2, 0.0, 0.0);
        assert!(
            lost.violations.iter().any(|v| v.contains("lost")),
            "{:?}",
            lost.violations
        );
    }

    #[test]
    fn a_rebound_in_the_wrong_direction_is_unfaithful_though_its_speed_is_right() {
        let r = trace(
            &pulses(60, &[(10, 20, 5.0)]),
            &velocities(60, 20, Vector3::new(-0.6, 0.8, 0.0)),
        );
        let h = trace(
            &pulses(60, &[(10, 20, 5.0)]),
            &velocities(60, 20, Vector3::new(0.6, 0.8, 0.0)),
        );
        let c = compare(&h, &r, 0.5, &tol(), 0.0, 0.0);
        let x = &c.collisions[0];
        assert!((x.cov.unwrap() - 1.0).abs() < 1e-12);
        assert!((x.velocity_error.unwrap() - 1.2).abs() < 1e-12);
        assert_eq!(c.violations.len(), 1);
        assert!(
            c.violations[0].contains("velocity error"),
            "{:?}",
            c.violations
        );
        let stop = Stop::plain(StopKind::Completed, 6.0);
        assert_eq!(Metrics::verdict(&stop, &c.violations), Status::Unfaithful);
        assert_eq!(Metrics::verdict(&stop, &[]), Status::Ok);
        let diverged = Stop::plain(StopKind::Diverged, 3.0);
        assert_eq!(Metrics::verdict(&diverged, &c.violations), Status::Diverged);
    }

    #[test]
    fn a_truncated_collision_counts_in_no_ratio_and_no_verdict() {
        // the HIL's second collision is cut off by the end of the run: a small peak, no ratio
        let v = velocities(60, 20, -Vector3::x());
        let r = trace(&pulses(60, &[(10, 20, 100.0), (40, 50, 100.0)]), &v);
        let h = trace(&pulses(60, &[(10, 20, 100.0), (57, 60, 16.6)]), &v);
        let c = compare(&h, &r, 0.5, &tol(), 0.0, 0.0);
        assert_eq!(c.collisions.len(), 2);
        let cut = &c.collisions[1];
        assert!(!cut.collision.complete && cut.collision.rebound_speed.is_none());
        assert!(cut.cof.is_none() && cut.cov.is_none());
        let s = Summary::of(&c.collisions);
        assert_eq!(s.worst_cof, 1.0); // not 0.166
        assert_eq!(s.compared, 1);
    }

    #[test]
    fn a_lost_collision_is_reported_and_unfaithful() {
        let v = velocities(80, 20, -Vector3::x());
        let r = trace(&pulses(80, &[(10, 20, 100.0), (40, 50, 100.0)]), &v);
        let h = trace(&pulses(80, &[(10, 20, 100.0)]), &v);
        let c = compare(&h, &r, 0.5, &tol(), 0.0, 0.5);
        assert_eq!(c.lost_collisions, vec![2]);
        assert!(
            c.violations.iter().any(|v| v.contains("lost (#2)")),
            "{:?}",
            c.violations
        );
        // allowed by the tolerances, it is not a violation
        let lenient = Tolerances {
            lost_collisions: 1,
            ..tol()
        };
        assert!(compare(&h, &r, 0.5, &lenient, 0.0, 0.5)
            .violations
            .is_empty());
        // one that ended too close to the end of the run to be judged is not lost
        let late = trace(&pulses(80, &[(10, 20, 100.0), (70, 75, 100.0)]), &v);
        assert!(compare(&h, &late, 0.5, &tol(), 0.0, 0.6)
            .lost_collisions
            .is_empty());
    }

    #[test]
    fn an_extra_collision_is_reported_and_collisions_are_matched_after_the_lag() {
        let v = velocities(100, 20, -Vector3::x());
        let r = trace(&pulses(100, &[(10, 20, 100.0), (50, 60, 100.0)]), &v);
        // the HIL's collisions start 0.3 s later (the lag), and there is one more at the end
        let h = trace(
            &pulses(100, &[(13, 23, 100.0), (53, 63, 100.0), (85, 90, 10.0)]),
            &v,
        );
        let c = compare(&h, &r, 0.5, &tol(), 0.3, 0.5);
        assert_eq!(c.collisions[0].reference, Some(1));
        assert_eq!(c.collisions[1].reference, Some(2));
        assert_eq!(c.collisions[2].reference, None);
        assert_eq!(c.extra_collisions, vec![3]);
        assert!(c.lost_collisions.is_empty());
        assert!(
            c.violations.iter().any(|v| v.contains("extra")),
            "{:?}",
            c.violations
        );
    }

    /// `trace` with a friction part: the contact force on the rod is `(−f, μf, 0)`, its
    /// normal part `(−f, 0, 0)` and its friction part `(0, μf, 0)` (a sliding contact).
    fn sliding(force: &[f64], velocity: &[Vector3<f64>], mu: f64) -> Trace {
        let mut t = trace(force, velocity);
        for (i, &f) in force.iter().enumerate() {
            t.friction_force[i] = Vector3::new(0.0, mu * f, 0.0);
            t.contact_force[i] += t.friction_force[i];
            t.force[i] = t.contact_force[i].norm();
        }
        t
    }

    #[test]
    fn in_sliding_the_tangential_impulse_is_mu_times_the_normal_one() {
        let v = velocities(60, 20, Vector3::new(-0.9, 0.1, 0.0));
        for mu in [0.0, 0.1, 0.2, 0.3] {
            let c = &collisions(&sliding(&pulses(60, &[(10, 20, 5.0)]), &v, mu), 0.5)[0];
            // trapezoids from sample 9 (0 N) to 20 (0 N): 10 samples of 5 N, 0.1 s apart
            assert!(
                (c.normal_impulse - 5.0).abs() < 1e-12,
                "{}",
                c.normal_impulse
            );
            assert!((c.tangential_impulse - mu * 5.0).abs() < 1e-12);
            assert!((c.peak_moment - 0.5).abs() < 1e-12);
            assert_eq!(c.rebound_velocity, Some([-0.9, 0.1, 0.0]));
            assert_eq!(c.rebound_angular_velocity, Some([0.0, 0.0, 0.01]));
        }
    }

    #[test]
    fn frictionless_contacts_have_a_tangential_impulse_error_of_zero_not_nan() {
        let v = velocities(60, 20, Vector3::new(-0.9, 0.1, 0.0));
        let r = trace(&pulses(60, &[(10, 20, 100.0)]), &v);
        let h = trace(&pulses(60, &[(10, 20, 120.0)]), &v);
        let c = compare(&h, &r, 0.5, &tol(), 0.0, 0.0);
        let x = &c.collisions[0];
        assert_eq!(x.tangential_impulse_error, Some(0.0));
        assert!((x.normal_impulse_error.unwrap() - 0.2).abs() < 1e-12);
        assert!((x.peak_moment_ratio.unwrap() - 1.2).abs() < 1e-12);
        assert_eq!(x.direction_error, Some(0.0));
        let s = Summary::of(&c.collisions);
        assert_eq!(s.worst_tangential_impulse_error, 0.0);
        assert!((s.worst_normal_impulse_error - 0.2).abs() < 1e-12);
    }

    #[test]
    fn a_tangential_impulse_off_by_more_than_its_tolerance_is_unfaithful() {
        let v = velocities(60, 20, Vector3::new(-0.9, 0.1, 0.0));
        let pulse = pulses(60, &[(10, 20, 100.0)]);
        let r = sliding(&pulse, &v, 0.2);
        // 20 % more friction, the same normal impulse and rebound
        let c = compare(&sliding(&pulse, &v, 0.24), &r, 0.5, &tol(), 0.0, 0.0);
        let x = &c.collisions[0];
        assert!((x.tangential_impulse_error.unwrap() - 0.2).abs() < 1e-9);
        assert!(x.normal_impulse_error.unwrap() < 1e-12);
        assert_eq!(c.violations.len(), 1, "{:?}", c.violations);
        assert!(c.violations[0].contains("tangential impulse error 0.200 > 0.1"));
        // 8 % more is within the default 10 %
        let close = compare(&sliding(&pulse, &v, 0.216), &r, 0.5, &tol(), 0.0, 0.0);
        assert!(close.violations.is_empty(), "{:?}", close.violations);
        // the error is a vector's: friction of the right size in the opposite direction
        let opposite = compare(&sliding(&pulse, &v, -0.2), &r, 0.5, &tol(), 0.0, 0.0);
        assert!((opposite.collisions[0].tangential_impulse_error.unwrap() - 2.0).abs() < 1e-9);
        // below the floor (μ < 0.01) the error is measured against 1 % of the normal impulse
        let tiny = sliding(&pulse, &v, 0.001);
        let c = compare(&sliding(&pulse, &v, 0.003), &tiny, 0.5, &tol(), 0.0, 0.0);
        assert!((c.collisions[0].tangential_impulse_error.unwrap() - 0.2).abs() < 1e-6);
    }

    #[test]
    fn the_rebound_direction_error_is_the_angle_between_the_rebounds() {
        let pulse = pulses(60, &[(10, 20, 5.0)]);
        let r = trace(&pulse, &velocities(60, 20, Vector3::new(-0.6, 0.8, 0.0)));
        for (after, angle) in [
            (Vector3::new(0.6, 0.8, 0.0), 0.28f64.acos().to_degrees()),
            (Vector3::new(-1.2, 1.6, 0.0), 0.0),
            (Vector3::new(0.6, -0.8, 0.0), 180.0),
            (Vector3::new(0.0, 0.0, 0.3), 90.0),
        ] {
            let h = trace(&pulse, &velocities(60, 20, after));
            let e = compare(&h, &r, 0.5, &tol(), 0.0, 0.0).collisions[0]
                .direction_error
                .unwrap();
            assert!((e - angle).abs() < 1e-9, "{after:?}: {e} vs {angle}");
        }
    }

    #[test]
    fn a_collision_is_pidas_if_pida_handled_any_of_its_ticks_else_the_models() {
        use crate::compensator::Rendering::{
            Model, PidaLawUnknown, PidaPriorContradicted, Unreported,
        };
        let r = [
            Unreported,
            Model,
            Model,
            PidaPriorContradicted,
            PidaLawUnknown,
            Unreported,
            Model,
        ];
        // handed over midway: pida's, with the first reason reported
        assert_eq!(collision_rendering(&r, 0, 6), Some(PidaPriorContradicted));
        assert_eq!(collision_rendering(&r, 0, 3), Some(Model));
        assert_eq!(collision_rendering(&r, 4, 7), Some(PidaLawUnknown));
        assert_eq!(collision_rendering(&r, 5, 6), None);
        // no report at all (the reference, a compensator without a model)
        assert_eq!(collision_rendering(&[], 0, 3), None);
        assert_eq!(collision_rendering(&r, 9, 12), None);
    }

    #[test]
    fn summary_takes_the_values_farthest_from_one() {
        let mk = |cov: Option<f64>, cof: Option<f64>, ve: Option<f64>| ComparedCollision {
            collision: Collision {
                index: 1,
                start: 0.0,
                end: 1.0,
                peak_force: 1.0,
                complete: true,
                rebound_speed: None,
                normal_impulse: 1.0,
                tangential_impulse: 0.0,
                peak_moment: 0.0,
                rebound_velocity: None,
                rebound_angular_velocity: None,
                rendering: None,
            },
            reference: Some(1),
            rebound_time: None,
            cov,
            cof,
            velocity_error: ve,
            angular_velocity_error: None,
            impulse_ratio: cof,
            angular_impulse_ratio: None,
            direction_error: None,
            normal_impulse_error: None,
            tangential_impulse_error: None,
            peak_moment_ratio: None,
            local_start: None,
            local_velocity_error: None,
            local_cof: None,
            local_tangential_impulse_error: None,
            local_normal_impulse_error: None,
        };
        let s = Summary::of(&[
            mk(Some(1.02), Some(1.1), Some(0.03)),
            mk(Some(0.9), Some(1.3), Some(0.01)),
            mk(None, Some(0.6), None),
        ]);
        assert_eq!(s.collisions, 3);
        assert_eq!(s.compared, 2);
        assert_eq!(s.worst_cov, 0.9);
        assert_eq!(s.worst_cof, 0.6);
        assert_eq!(s.worst_velocity_error, 0.03);
        assert_eq!(s.worst_impulse_ratio, 0.6);
        assert!(s.worst_angular_impulse_ratio.is_nan());
        assert!((s.mean_cov - 0.96).abs() < 1e-12);
        assert!((s.mean_cof - 1.0).abs() < 1e-12);
        let empty = Summary::of(&[]);
        assert!(empty.worst_cov.is_nan() && empty.mean_cof.is_nan() && empty.collisions == 0);
    }
}
