//! Metrics (spec hil-loop.md §5), defined once for simulations, reports and the real-time loop.
//!
//! - Collision n: a maximal interval of samples where the physical contact force magnitude
//!   exceeds `metrics.contact_threshold`. Start: first sample above; end: first sample below
//!   (or the last sample, for a collision still under way, which then has no rebound).
//! - Rebound speed of collision n: speed of the virtual relative motion of the rod tip in the
//!   middle of the free flight that follows (halfway to the next collision's start, or to the
//!   end of the run), where the sensor-delayed tail of the force has long ended.
//! - `CoV_n` = rebound speed / the reference's rebound speed of collision n;
//!   `CoF_n` = peak force / the reference's peak force of collision n.
//! - Identification error: mean of `|k̂/k − 1|` and of `|ĉ − c|` over contact samples after
//!   the first collision.
//! - Energy: kinetic energy of the virtual relative motion; a run whose energy passes a bound
//!   is `diverged` (a status, never a NaN or a crash).

use serde::Serialize;

/// One collision.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Collision {
    /// 1-based index.
    pub index: usize,
    /// Start time, s.
    pub start: f64,
    /// End time, s.
    pub end: f64,
    /// Peak physical contact force, N.
    pub peak_force: f64,
    /// Rebound speed, m/s (none for a collision still under way at the end).
    pub rebound_speed: Option<f64>,
}

/// A HIL collision compared with the reference's collision of the same index.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ComparedCollision {
    /// The collision itself.
    #[serde(flatten)]
    pub collision: Collision,
    /// CoV: rebound speed / the reference's (none without a matching reference rebound).
    pub cov: Option<f64>,
    /// CoF: peak force / the reference's (none without a matching reference collision).
    pub cof: Option<f64>,
}

/// Finds the collisions in a record: `time` (s), contact force magnitude (N) and the virtual
/// tip speed (m/s), sample by sample.
pub fn collisions(time: &[f64], force: &[f64], speed: &[f64], threshold: f64) -> Vec<Collision> {
    let n = time.len().min(force.len()).min(speed.len());
    let mut spans: Vec<(usize, usize, bool)> = Vec::new(); // (start, end, complete)
    let mut start: Option<usize> = None;
    for i in 0..n {
        let in_contact = force[i] > threshold;
        match (start, in_contact) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                spans.push((s, i, true));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        spans.push((s, n - 1, false));
    }
    spans
        .iter()
        .enumerate()
        .map(|(j, &(s, e, complete))| {
            let next = spans.get(j + 1).map_or(n - 1, |next| next.0);
            Collision {
                index: j + 1,
                start: time[s],
                end: time[e],
                peak_force: force[s..=e].iter().cloned().fold(0.0, f64::max),
                rebound_speed: complete.then(|| speed[(e + next) / 2]),
            }
        })
        .collect()
}

/// CoV and CoF of each collision against the reference's collision of the same index.
pub fn compare_with_reference(
    collisions: &[Collision],
    reference: &[Collision],
) -> Vec<ComparedCollision> {
    let ratio = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        _ => None,
    };
    collisions
        .iter()
        .map(|c| {
            let r = reference.get(c.index - 1);
            ComparedCollision {
                collision: c.clone(),
                cov: ratio(c.rebound_speed, r.and_then(|r| r.rebound_speed)),
                cof: ratio(Some(c.peak_force), r.map(|r| r.peak_force)),
            }
        })
        .collect()
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
}

/// Identification error over samples in contact (`force > threshold`) after the first
/// collision's end; `None` if there is no such sample.
pub fn identification_error(
    time: &[f64],
    force: &[f64],
    threshold: f64,
    first_collision_end: f64,
    stiffness_estimate: &[f64],
    damping_estimate: &[f64],
    stiffness: f64,
    damping: f64,
) -> Option<IdentificationError> {
    let (mut sk, mut sc, mut n) = (0.0, 0.0, 0usize);
    for i in 0..time.len() {
        let (k, c) = (stiffness_estimate[i], damping_estimate[i]);
        if time[i] > first_collision_end && force[i] > threshold && k.is_finite() && c.is_finite() {
            sk += (k / stiffness - 1.0).abs();
            sc += (c - damping).abs();
            n += 1;
        }
    }
    (n > 0).then(|| IdentificationError {
        stiffness_error: sk / n as f64,
        damping_error: sc / n as f64,
        samples: n,
    })
}

/// A run in a few numbers: what a comparison table or a sweep row shows.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    /// Number of HIL collisions.
    pub collisions: usize,
    /// Mean CoV over the collisions that have one (NaN if none).
    pub mean_cov: f64,
    /// The CoV farthest from 1 (NaN if none).
    pub worst_cov: f64,
    /// Mean CoF over the collisions that have one (NaN if none).
    pub mean_cof: f64,
    /// The CoF farthest from 1 (NaN if none).
    pub worst_cof: f64,
}

impl Summary {
    /// The summary of compared collisions.
    pub fn of(collisions: &[ComparedCollision]) -> Self {
        let stats = |values: &mut dyn Iterator<Item = f64>| {
            let (mut sum, mut n, mut worst) = (0.0, 0usize, f64::NAN);
            for v in values.filter(|v| v.is_finite()) {
                sum += v;
                n += 1;
                if worst.is_nan() || (v - 1.0).abs() > (worst - 1.0).abs() {
                    worst = v;
                }
            }
            (if n > 0 { sum / n as f64 } else { f64::NAN }, worst)
        };
        let (mean_cov, worst_cov) = stats(&mut collisions.iter().filter_map(|c| c.cov));
        let (mean_cof, worst_cof) = stats(&mut collisions.iter().filter_map(|c| c.cof));
        Summary {
            collisions: collisions.len(),
            mean_cov,
            worst_cov,
            mean_cof,
            worst_cof,
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
    /// Largest energy of the run.
    pub max: f64,
}

/// Outcome of a run, as `metrics.json` states it (one vocabulary for simulated and
/// real-time runs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Ran to the end.
    Ok,
    /// Stopped by the user (Ctrl-C).
    Interrupted,
    /// Stopped when the energy passed its bound or a value stopped being finite.
    Diverged,
    /// Stopped by a safety function of the real-time runtime.
    Stopped,
}

/// Why a run stopped: the one list for simulations and the real-time runtime.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopKind {
    /// Ran for the whole duration.
    Completed,
    /// Stopped by the user (Ctrl-C).
    User,
    /// Measured force magnitude above the limit.
    ForceLimit,
    /// Measured moment magnitude above the limit.
    MomentLimit,
    /// No valid sensor record for longer than the watchdog.
    SensorWatchdog,
    /// No valid robot feedback for longer than the watchdog.
    RobotWatchdog,
    /// Commanded rod tip outside the workspace.
    Workspace,
    /// A state, force or command stopped being finite.
    NonFinite,
    /// The virtual energy passed the scenario's divergence bound.
    Diverged,
}

impl StopKind {
    /// Every kind, in the order of [`StopKind::code`].
    pub const ALL: [StopKind; 9] = [
        StopKind::Completed,
        StopKind::User,
        StopKind::ForceLimit,
        StopKind::MomentLimit,
        StopKind::SensorWatchdog,
        StopKind::RobotWatchdog,
        StopKind::Workspace,
        StopKind::NonFinite,
        StopKind::Diverged,
    ];

    /// The run's status for this stop.
    pub fn status(self) -> Status {
        match self {
            StopKind::Completed => Status::Ok,
            StopKind::User => Status::Interrupted,
            StopKind::Diverged | StopKind::NonFinite => Status::Diverged,
            _ => Status::Stopped,
        }
    }

    /// Whether a safety function stopped the run.
    pub fn is_safety_stop(self) -> bool {
        !matches!(self, StopKind::Completed | StopKind::User)
    }

    /// Exit code of the command that ran it: 0 completed (or a simulation that ran its
    /// course), 130 user stop (Ctrl-C), 3 any safety stop.
    pub fn exit_code(self) -> i32 {
        match self {
            StopKind::Completed => 0,
            StopKind::User => 130,
            _ => 3,
        }
    }

    /// Small integer for atomics (0 = still running).
    pub fn code(self) -> u8 {
        self as u8 + 1
    }

    /// The kind of a [`StopKind::code`].
    pub fn from_code(code: u8) -> Option<Self> {
        StopKind::ALL
            .get((code as usize).checked_sub(1)?)
            .copied()
    }
}

/// How a run stopped: kind, tick time (s), and the value that tripped against its limit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stop {
    /// Why.
    pub kind: StopKind,
    /// Time of the tick, s.
    pub time: f64,
    /// The offending value (N, N·m, ms, m or J), NaN when there is none.
    #[serde(serialize_with = "finite_or_null")]
    pub value: f64,
    /// The limit it passed, same unit, NaN when there is none.
    #[serde(serialize_with = "finite_or_null")]
    pub limit: f64,
}

fn finite_or_null<S: serde::Serializer>(v: &f64, s: S) -> std::result::Result<S::Ok, S::Error> {
    if v.is_finite() {
        s.serialize_f64(*v)
    } else {
        s.serialize_none()
    }
}

impl Stop {
    /// A stop without a value.
    pub fn plain(kind: StopKind, time: f64) -> Self {
        Stop {
            kind,
            time,
            value: f64::NAN,
            limit: f64::NAN,
        }
    }

    /// One line for humans, `None` for a completed run (formats: call it outside a loop).
    pub fn reason(&self) -> Option<String> {
        self.reason_naming("sensor", "robot")
    }

    /// [`Stop::reason`] naming the devices' protocols, e.g. `reason_naming("RDT", "EGM")`:
    /// "no valid RDT record", "no valid EGM feedback".
    pub fn reason_naming(&self, sensor: &str, robot: &str) -> Option<String> {
        let (v, l, t) = (self.value, self.limit, self.time);
        Some(match self.kind {
            StopKind::Completed => return None,
            StopKind::User => format!("stopped by the user at {t:.3} s"),
            StopKind::ForceLimit => format!("force limit: |F| = {v:.1} N > {l:.1} N (force_limit) at {t:.3} s"),
            StopKind::MomentLimit => format!("moment limit: |M| = {v:.2} N·m > {l:.2} N·m (moment_limit) at {t:.3} s"),
            StopKind::SensorWatchdog => format!("sensor watchdog: no valid {sensor} record for {v:.1} ms > {l:.1} ms (watchdog_ms) at {t:.3} s"),
            StopKind::RobotWatchdog => format!("robot watchdog: no valid {robot} feedback for {v:.1} ms > {l:.1} ms (watchdog_ms) at {t:.3} s"),
            StopKind::Workspace => format!("workspace limit: commanded rod tip {:.1} mm from its start > {:.1} mm (workspace) at {t:.3} s", v * 1e3, l * 1e3),
            StopKind::NonFinite => format!("a state, force or command stopped being finite at {t:.3} s"),
            StopKind::Diverged => format!("diverged: energy {v:.4} J passed the divergence bound {l:.4} J at {t:.3} s"),
        })
    }
}

/// Everything `metrics.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Metrics {
    /// Scenario name.
    pub scenario: String,
    /// Compensator kind.
    pub compensator: String,
    /// `ok`, `interrupted`, `diverged` or `stopped` (from `stop`).
    pub status: Status,
    /// Time at which divergence was detected, s.
    pub diverged_at: Option<f64>,
    /// Why the run stopped early (from `stop`).
    pub reason: Option<String>,
    /// How the run stopped.
    pub stop: Stop,
    /// The HIL run's collisions, with CoV and CoF.
    pub collisions: Vec<ComparedCollision>,
    /// Mean and worst CoV and CoF of `collisions`.
    pub summary: Summary,
    /// The ideal reference's collisions.
    pub reference_collisions: Vec<Collision>,
    /// Identification error, when the compensator identifies the contact.
    pub identification: Option<IdentificationError>,
    /// Energy summary.
    pub energy: EnergySummary,
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

    #[test]
    fn finds_collisions_and_rebounds() {
        // 0..10: free, 10..20 contact, 20..40 free, 40..50 contact, 50..60 free
        let time: Vec<f64> = (0..60).map(|i| i as f64 * 0.1).collect();
        let force: Vec<f64> = (0..60)
            .map(|i| {
                if (10..20).contains(&i) {
                    5.0
                } else if (40..50).contains(&i) {
                    7.0
                } else {
                    0.0
                }
            })
            .collect();
        let speed: Vec<f64> = (0..60).map(|i| i as f64).collect();
        let c = collisions(&time, &force, &speed, 0.5);
        assert_eq!(c.len(), 2);
        assert!((c[0].start - 1.0).abs() < 1e-12 && (c[0].end - 2.0).abs() < 1e-12);
        assert_eq!(c[0].rebound_speed, Some(30.0)); // midway between 20 and 40
        assert_eq!(c[1].rebound_speed, Some(54.0)); // midway between 50 and 59
        assert_eq!(c[1].peak_force, 7.0);
    }

    #[test]
    fn unfinished_collision_has_no_rebound() {
        let time = [0.0, 1.0, 2.0];
        let c = collisions(&time, &[0.0, 3.0, 3.0], &[1.0, 1.0, 1.0], 0.5);
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].rebound_speed, None);
    }

    #[test]
    fn cov_and_cof_are_ratios_to_the_reference() {
        let mk = |speed, peak| Collision {
            index: 1,
            start: 0.0,
            end: 1.0,
            peak_force: peak,
            rebound_speed: Some(speed),
        };
        let hil = compare_with_reference(&[mk(0.03, 120.0)], &[mk(0.02, 100.0)]);
        assert!((hil[0].cov.unwrap() - 1.5).abs() < 1e-12);
        assert!((hil[0].cof.unwrap() - 1.2).abs() < 1e-12);
    }

    #[test]
    fn summary_takes_the_values_farthest_from_one() {
        let mk = |cov: Option<f64>, cof: Option<f64>| ComparedCollision {
            collision: Collision {
                index: 1,
                start: 0.0,
                end: 1.0,
                peak_force: 1.0,
                rebound_speed: None,
            },
            cov,
            cof,
        };
        let s = Summary::of(&[
            mk(Some(1.02), Some(1.1)),
            mk(Some(0.9), Some(1.3)),
            mk(None, Some(0.6)),
        ]);
        assert_eq!(s.collisions, 3);
        assert_eq!(s.worst_cov, 0.9);
        assert_eq!(s.worst_cof, 0.6);
        assert!((s.mean_cov - 0.96).abs() < 1e-12);
        assert!((s.mean_cof - 1.0).abs() < 1e-12);
        let empty = Summary::of(&[]);
        assert!(empty.worst_cov.is_nan() && empty.mean_cof.is_nan() && empty.collisions == 0);
    }
}
