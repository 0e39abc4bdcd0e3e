//! Offline identification of a recording's contacts: per collision, the stiffness k and
//! damping c, and the contact surface (a plane: a point and its normal), each with an
//! uncertainty.
//!
//! k and c come from the compensators' own front end ([`ContactEstimator`]: the noise-aware
//! detector, the sensor-delay handling of `delay_mode`, the Sage-Husa filter of eqs. (8)-(13)),
//! run over the whole recording; its filter is restarted (back to `k̂₀`, `ĉ₀`, `P₀`) at the
//! start of each collision, so that each collision is identified on its own. Their
//! uncertainties are the filter's `√P₀₀`, `√P₁₁` at the collision's last tick.
//!
//! The surface, from where the force begins and its direction. The force on the frame points
//! into the wall (`e = F/|F|`, eq. 7), so the wall normal (into free space) is `n = −ē`, `ē`
//! the direction of the collision's summed force; its uncertainty is the standard error of the
//! samples' angles to `ē`. With the sample's tip position `p` and velocity `v` (those that
//! produced the force: `τ_p` earlier for `align`), the linear law `F·ē = k·d + c·ḋ` with
//! `d = (p − p_w)·ē`, `ḋ = v·ē` gives the plane's offset of each sample,
//! `p_w·ē = p·ē − (F·ē − ĉ·v·ē)/k̂`; the offset is their mean, its uncertainty the standard
//! error combined with that of `k̂` and `ĉ`. The point is the tip at the first contact sample
//! projected on the plane.

use nalgebra::{UnitQuaternion, Vector3};

use crate::compensator::{
    CompensatorConfig, CompensatorContext, ContactEstimator, DelayMode, ModelParams,
};
use crate::error::RecordingError;
use crate::hil::compensator_context;
use crate::plan::Plan;
use crate::replay::Recording;
use crate::sim::Table;

/// The forgetting factor b of the noise estimate (eq. 13) that offline identification uses
/// by default (`hilcontact identify --forgetting`). The compensators' 0.98 averages the noise
/// over about 50 updates, so the large `H·P⁻·Hᵀ` of the first updates (P₀ is wide) keeps R,
/// and so the gain on ĉ, high for a whole collision: measured on a damped oblique-6dof run
/// without noise, ĉ = 116 ± 101 N·s/m for c = 130 at 0.98, 129.5 ± 18.8 at 0.9, 130.00 ± 0.7
/// at 0.5. 0.9 keeps about 10 updates, still averaging a noisy sensor's increments.
pub const OFFLINE_FORGETTING: f64 = 0.9;

/// One collision's identified contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CollisionIdentification {
    /// Number of the collision, from 1.
    pub index: usize,
    /// Time of its first contact sample, s.
    pub start: f64,
    /// Time of its last contact sample, s.
    pub end: f64,
    /// Number of contact samples.
    pub samples: usize,
    /// Filter updates made on it (eqs. 11-13).
    pub updates: u32,
    /// Identified stiffness k̂, N/m.
    pub stiffness: f64,
    /// Its standard deviation √P₀₀, N/m.
    pub stiffness_std: f64,
    /// Identified damping ĉ, N·s/m.
    pub damping: f64,
    /// Its standard deviation √P₁₁, N·s/m.
    pub damping_std: f64,
    /// Wall normal n (into free space, unit), `t`.
    pub normal: Vector3<f64>,
    /// Angular uncertainty of n, rad.
    pub normal_std: f64,
    /// A point of the wall (the first contact, on the plane), `t`, m.
    pub point: Vector3<f64>,
    /// Uncertainty of the plane's position along n, m.
    pub offset_std: f64,
    /// Peak measured force magnitude, N.
    pub peak_force: f64,
}

/// What [`identify`] gives: per tick and per collision.
#[derive(Debug, Clone, PartialEq)]
pub struct Identification {
    /// Per tick: `time` (s), `in_contact` (1 or 0), `stiffness_estimate` (N/m),
    /// `stiffness_std` (N/m), `damping_estimate` (N·s/m), `damping_std` (N·s/m).
    pub timeseries: Table,
    /// Per collision.
    pub collisions: Vec<CollisionIdentification>,
}

/// The identification parameters of a compensator config: its own for `pic`, `dac`, `pida`,
/// the defaults for the others.
pub fn model_params(config: &CompensatorConfig) -> ModelParams {
    match config {
        CompensatorConfig::Pic(p) | CompensatorConfig::Dac(p) | CompensatorConfig::Pida(p) => {
            p.clone()
        }
        _ => ModelParams::default(),
    }
}

/// Identifies the contacts of `recording` (the desired tip is not used) with the front end of
/// `params` built with `context`; `sensor_to_t` is the sensor's attitude in `t`.
pub fn identify(
    params: &ModelParams,
    context: &CompensatorContext,
    sensor_to_t: &UnitQuaternion<f64>,
    recording: &Recording<'_>,
) -> Result<Identification, RecordingError> {
    recording.check()?;
    let n = recording.len();
    let mut estimator = ContactEstimator::new(params, context);
    let lag = match params.delay_mode {
        DelayMode::Align => context.sensor_delay_ticks,
        DelayMode::Lead => 0,
    };
    let mut contact = vec![0.0; n];
    let mut k_hat = vec![0.0; n];
    let mut k_std = vec![0.0; n];
    let mut c_hat = vec![0.0; n];
    let mut c_std = vec![0.0; n];
    // (first, last) contact tick of each collision
    let mut spans: Vec<(usize, usize)> = Vec::new();
    let mut updates: Vec<u32> = Vec::new();
    let mut previous = false;
    for k in 0..n {
        let view = estimator.step(&recording.input(k, sensor_to_t));
        if view.in_contact && !previous {
            // a new collision: identified on its own from its second sample on
            estimator.filter.reset();
            spans.push((k, k));
            updates.push(0);
        }
        if view.in_contact {
            if let (Some(span), Some(u)) = (spans.last_mut(), updates.last_mut()) {
                span.1 = k;
                *u = estimator.filter.t;
            }
        }
        previous = view.in_contact;
        let f = &estimator.filter;
        contact[k] = f64::from(u8::from(view.in_contact));
        k_hat[k] = f.x[0];
        c_hat[k] = f.x[1];
        k_std[k] = f.p[(0, 0)].max(0.0).sqrt();
        c_std[k] = f.p[(1, 1)].max(0.0).sqrt();
    }

    let force = |k: usize| {
        let c = &recording.measured_force;
        sensor_to_t * Vector3::new(c[0][k], c[1][k], c[2][k])
    };
    let kinematics = |k: usize| {
        let j = k.saturating_sub(lag);
        let (p, v) = (
            &recording.actual_tip_position,
            &recording.actual_tip_velocity,
        );
        (
            Vector3::new(p[0][j], p[1][j], p[2][j]),
            Vector3::new(v[0][j], v[1][j], v[2][j]),
        )
    };
    let collisions = spans
        .iter()
        .zip(&updates)
        .enumerate()
        .map(|(i, (&(first, last), &u))| {
            let (stiffness, damping) = (k_hat[last], c_hat[last]);
            let (sk, sc) = (k_std[last], c_std[last]);
            let count = (last - first + 1) as f64;
            let total: Vector3<f64> = (first..=last).map(force).sum();
            let e = total.normalize();
            let peak_force = (first..=last).map(|k| force(k).norm()).fold(0.0, f64::max);
            // angles of the samples' force to ē
            let angle2: f64 = (first..=last)
                .map(|k| force(k).normalize().dot(&e).clamp(-1.0, 1.0).acos().powi(2))
                .sum();
            let normal_std = (angle2 / count).sqrt() / count.sqrt();
            // the plane's offset along ē from each sample
            let offset_of = |k: usize| {
                let (p, v) = kinematics(k);
                let penetration = (force(k).dot(&e) - damping * v.dot(&e)) / stiffness;
                (p.dot(&e) - penetration, penetration, v.dot(&e))
            };
            let (mut sum, mut sum2, mut pen, mut rate) = (0.0, 0.0, 0.0, 0.0);
            for k in first..=last {
                let (o, d, r) = offset_of(k);
                sum += o;
                sum2 += o * o;
                pen += d.abs();
                rate += r.abs();
            }
            let offset = sum / count;
            let spread = (sum2 / count - offset * offset).max(0.0).sqrt();
            let from_k = pen / count * sk / stiffness;
            let from_c = rate / count * sc / stiffness;
            let offset_std = ((spread * spread) / count + from_k * from_k + from_c * from_c).sqrt();
            let (p_first, _) = kinematics(first);
            CollisionIdentification {
                index: i + 1,
                start: recording.time[first],
                end: recording.time[last],
                samples: last - first + 1,
                updates: u,
                stiffness,
                stiffness_std: sk,
                damping,
                damping_std: sc,
                normal: -e,
                normal_std,
                point: p_first - e * (p_first.dot(&e) - offset),
                offset_std,
                peak_force,
            }
        })
        .collect();
    let names = [
        "time",
        "in_contact",
        "stiffness_estimate",
        "stiffness_std",
        "damping_estimate",
        "damping_std",
    ];
    let values = [recording.time.to_vec(), contact, k_hat, k_std, c_hat, c_std];
    Ok(Identification {
        timeseries: Table {
            columns: names.iter().map(|s| s.to_string()).zip(values).collect(),
        },
        collisions,
    })
}

/// [`identify`] with a plan's identification parameters ([`model_params`]), context and
/// sensor attitude.
pub fn identify_plan(
    plan: &Plan,
    recording: &Recording<'_>,
) -> Result<Identification, RecordingError> {
    identify(
        &model_params(&plan.compensator),
        &compensator_context(plan),
        &plan.sensor.orientation,
        recording,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::replay::tests::preset_plan;
    use crate::sim::simulate_plan;

    /// A damped oblique-6dof run with the given sensor delay (s), and the identification of
    /// its recording.
    fn identified(sensor_delay: f64) -> (Plan, Identification) {
        let mut plan = preset_plan("oblique-6dof", "pida", 0.01);
        let mut scenario = plan.scenario.clone();
        scenario.contact.damping = 130.0;
        scenario.facility.sensor_delay = sensor_delay;
        plan = scenario.resolve().expect("plan");
        let table = simulate_plan(&plan).timeseries;
        let recording = Recording::from_table(&table, false).expect("recording");
        let mut params = model_params(&plan.compensator);
        params.forgetting = OFFLINE_FORGETTING;
        let context = compensator_context(&plan);
        let q = plan.sensor.orientation;
        let id = identify(&params, &context, &q, &recording).expect("identify");
        (plan, id)
    }

    #[test]
    fn identifies_a_damped_oblique_wall_with_and_without_sensor_delay() {
        for delay in [0.0, 0.005] {
            let (plan, id) = identified(delay);
            assert!(!id.collisions.is_empty());
            for c in &id.collisions {
                let wall = plan
                    .system
                    .contact
                    .walls
                    .iter()
                    .max_by(|a, b| a.normal.dot(&c.normal).total_cmp(&b.normal.dot(&c.normal)))
                    .expect("wall");
                let angle = wall
                    .normal
                    .dot(&c.normal)
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees();
                let distance = (c.point - wall.point).dot(&wall.normal);
                println!(
                    "delay {delay} #{} k {:.1}±{:.1} c {:.2}±{:.2} angle {angle:.4}° ±{:.4} plane {:.4} mm ±{:.4}",
                    c.index, c.stiffness, c.stiffness_std, c.damping, c.damping_std,
                    c.normal_std.to_degrees(), distance * 1e3, c.offset_std * 1e3
                );
                assert!((c.stiffness / 176_275.0 - 1.0).abs() < 0.01, "{c:?}");
                assert!((c.damping / 130.0 - 1.0).abs() < 0.01, "{c:?}");
                assert!(angle < 0.5, "{angle}");
                assert!(distance.abs() < 0.5e-3, "{distance}");
            }
        }
    }
}
