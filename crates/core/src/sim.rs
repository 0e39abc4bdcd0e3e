//! A whole simulation: the ideal reference, the HIL loop against the facility model, the
//! recorded time series and the metrics. Allocates its records up front; the per-tick code
//! (facility, compensator, dynamics) does not allocate.

use nalgebra::{UnitQuaternion, Vector3};

use crate::config::{ContactModelKind, Scenario};
use crate::error::Result;
use crate::facility::FacilityModel;
pub use crate::hil::HilRecord;
use crate::hil::HilStep;
use crate::frames::FrameWrench;
use crate::metrics::{self, EnergySummary, Metrics, Stop, TraceSample};
pub use crate::metrics::Trace;
use crate::plan::Plan;

/// Named columns of equal length.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    /// `(name, values)` in output order.
    pub columns: Vec<(String, Vec<f64>)>,
}

impl Table {
    /// This table with the columns of `other` appended.
    fn with(mut self, other: Table) -> Table {
        self.columns.extend(other.columns);
        self
    }

    /// The column called `name`.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.columns.first().map_or(0, |(_, v)| v.len())
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn from_rows<R>(
        rows: &[R],
        scalars: &[(&str, fn(&R) -> f64)],
        vectors: &[(&str, fn(&R) -> Vector3<f64>)],
    ) -> Table {
        let mut columns = Vec::new();
        for (name, get) in scalars {
            columns.push((name.to_string(), rows.iter().map(get).collect()));
        }
        for (name, get) in vectors {
            for (axis, label) in ["x", "y", "z"].iter().enumerate() {
                columns.push((
                    format!("{name}_{label}"),
                    rows.iter().map(|r| get(r)[axis]).collect(),
                ));
            }
        }
        Table { columns }
    }
}

/// The trace of HIL records (with estimates if `estimates_contact`), for the metrics.
pub fn hil_trace(plan: &Plan, rows: &[HilRecord], estimates_contact: bool) -> Trace {
    let mut trace = Trace::with_capacity(rows.len(), estimates_contact);
    let q = plan.facility.sensor_orientation;
    for row in rows {
        push_record(&mut trace, row, &q, estimates_contact);
    }
    trace
}

/// Appends a HIL record to a trace; `sensor_to_t`: the sensor's attitude in `t`.
fn push_record(
    trace: &mut Trace,
    row: &HilRecord,
    sensor_to_t: &UnitQuaternion<f64>,
    estimates_contact: bool,
) {
    trace.push(&TraceSample {
        time: row.time,
        contact_force: row.contact_force,
        velocity: row.tip_velocity,
        angular_velocity: row.angular_velocity,
        wrench: FrameWrench {
            force: sensor_to_t * row.applied_force,
            moment: sensor_to_t * row.applied_moment,
        },
        energy: row.energy,
    });
    if estimates_contact {
        trace.push_estimates(row.stiffness_estimate, row.damping_estimate);
    }
}

/// One tick of the ideal reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceRecord {
    /// Time, s.
    pub time: f64,
    /// Rod tip relative to the target, `t` frame, m.
    pub tip_position: Vector3<f64>,
    /// Rod tip velocity relative to the target, `t` frame, m/s.
    pub tip_velocity: Vector3<f64>,
    /// Servicer angular velocity relative to the target, `t` frame, rad/s.
    pub angular_velocity: Vector3<f64>,
    /// Contact force on the rod, `t` frame, N.
    pub contact_force: Vector3<f64>,
    /// Moment of the contact force on the frame about the sensor origin, `t` frame, N·m.
    pub contact_moment: Vector3<f64>,
    /// Kinetic energy of the relative motion, J.
    pub energy: f64,
}

/// Result of a simulation.
#[derive(Debug, Clone)]
pub struct SimulationOutput {
    /// The HIL loop, one row per control tick (up to divergence).
    pub timeseries: Table,
    /// The ideal reference, one row per control tick.
    pub reference: Table,
    /// The metrics.
    pub metrics: Metrics,
}

/// The ideal reference: the true contact law, no facility, sampled at every tick; integrated by
/// [`crate::world::TwoBodySystem::step_reference`] (one force-free step per period in free
/// flight; in contact RK4 with `simulation.reference_substeps` steps per period and the
/// contact's start and end located). Returns the trace and, if `keep_rows`, every record.
pub fn run_reference(plan: &Plan, keep_rows: bool) -> (Trace, Vec<ReferenceRecord>) {
    let (n, period, system) = (plan.ticks, plan.period, &plan.system);
    let mut x = plan.initial;
    let mut trace = Trace::with_capacity(n + 1, false);
    let mut rows = Vec::with_capacity(if keep_rows { n + 1 } else { 0 });
    for k in 0..=n {
        let rel = system.relative_motion(&x);
        let (contact_force, tip) = system.contact_force_at(&rel);
        let wrench = FrameWrench::from_rod_force(&contact_force, &tip, &system.sensor_origin);
        let row = ReferenceRecord {
            time: k as f64 * period,
            tip_position: tip,
            tip_velocity: rel.point_velocity(&system.rod_tip),
            angular_velocity: rel.angular_velocity,
            contact_force,
            contact_moment: wrench.moment,
            energy: system.energy(&x),
        };
        trace.push(&TraceSample {
            time: row.time,
            contact_force,
            velocity: row.tip_velocity,
            angular_velocity: row.angular_velocity,
            wrench,
            energy: row.energy,
        });
        if keep_rows {
            rows.push(row);
        }
        if k < n {
            system.step_reference(&mut x, period, plan.reference_substeps);
        }
    }
    (trace, rows)
}

/// How a HIL run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct HilRun {
    /// What the metrics read of every tick run.
    pub trace: Trace,
    /// Every record, if asked for (up to divergence).
    pub rows: Vec<HilRecord>,
    /// Whether the compensator identified the contact.
    pub estimates_contact: bool,
    /// Whether the compensator observed the port energy.
    pub observes_energy: bool,
    /// How it stopped.
    pub stop: Stop,
}

/// The HIL loop of [`HilStep`] against the facility model, stopped once the energy passes
/// `energy_bound` (J); every record is kept if `keep_rows`, the trace always.
pub fn run_hil(plan: &Plan, energy_bound: f64, keep_rows: bool) -> HilRun {
    let n = plan.ticks;
    let mut step = HilStep::new(plan, energy_bound);
    let mut facility = FacilityModel::new(plan, &step.command());
    let estimates = step.dynamics().estimates_contact();
    let mut rows = Vec::with_capacity(if keep_rows { n + 1 } else { 0 });
    let mut trace = Trace::with_capacity(n + 1, estimates);
    let mut k = 0;
    let stop = loop {
        let m = facility.measure();
        let (row, stop) = step.observe(k, &m, Some(facility.contact_force()));
        push_record(&mut trace, &row, &plan.facility.sensor_orientation, estimates);
        if keep_rows {
            rows.push(row);
        }
        if let Some(stop) = stop {
            break stop;
        }
        match step.advance(k) {
            Ok(command) => facility.advance(&command),
            Err(stop) => break stop,
        }
        k += 1;
    };
    HilRun {
        trace,
        rows,
        estimates_contact: estimates,
        observes_energy: step.dynamics().observes_energy(),
        stop,
    }
}

/// Runs the reference and the HIL loop of a scenario and computes the metrics, without
/// keeping the records (what a sweep keeps of a run).
pub fn simulate_metrics(s: &Scenario) -> Result<Metrics> {
    Ok(simulate_plan_metrics(&s.resolve()?))
}

/// Runs the reference and the HIL loop of a resolved plan and computes the metrics, without
/// keeping the records (what a sweep keeps of a run).
pub fn simulate_plan_metrics(plan: &Plan) -> Metrics {
    run(plan, false).metrics
}

/// Runs the reference and the HIL loop of a scenario and computes the metrics.
pub fn simulate(s: &Scenario) -> Result<SimulationOutput> {
    Ok(simulate_plan(&s.resolve()?))
}

/// Runs the reference and the HIL loop of a resolved plan and computes the metrics.
pub fn simulate_plan(plan: &Plan) -> SimulationOutput {
    let Runs {
        reference,
        hil,
        metrics,
    } = run(plan, true);
    SimulationOutput {
        timeseries: hil_table(&hil.rows, hil.estimates_contact, hil.observes_energy),
        reference: reference_table(&reference),
        metrics,
    }
}

/// The HIL loop's table, one row per record: `time`, the vectors `tip_position`,
/// `tip_velocity`, `actual_tip_position`, `actual_tip_velocity`, `contact_force`,
/// `measured_force`, `measured_moment`, `applied_force`, `applied_moment` (`_x`, `_y`, `_z`),
/// `energy`, and `stiffness_estimate`, `damping_estimate` if `estimates_contact`,
/// `observed_energy` if `observes_energy` (one definition for simulations and real-time runs).
pub fn hil_table(rows: &[HilRecord], estimates_contact: bool, observes_energy: bool) -> Table {
    type V = Vector3<f64>;
    let vectors: [(&str, fn(&HilRecord) -> V); 10] = [
        ("tip_position", |r| r.tip_position),
        ("tip_velocity", |r| r.tip_velocity),
        ("angular_velocity", |r| r.angular_velocity),
        ("actual_tip_position", |r| r.actual_tip_position),
        ("actual_tip_velocity", |r| r.actual_tip_velocity),
        ("contact_force", |r| r.contact_force),
        ("measured_force", |r| r.measured_force),
        ("measured_moment", |r| r.measured_moment),
        ("applied_force", |r| r.applied_force),
        ("applied_moment", |r| r.applied_moment),
    ];
    let mut scalars: Vec<(&str, fn(&HilRecord) -> f64)> = vec![("energy", |r| r.energy)];
    if estimates_contact {
        scalars.push(("stiffness_estimate", |r| r.stiffness_estimate));
        scalars.push(("damping_estimate", |r| r.damping_estimate));
    }
    if observes_energy {
        scalars.push(("observed_energy", |r| r.observed_energy));
    }
    Table::from_rows(rows, &[("time", |r: &HilRecord| r.time)], &vectors).with(Table::from_rows(
        rows,
        &scalars,
        &[],
    ))
}

/// The reference's table: `time`, `tip_position_*`, `tip_velocity_*`, `contact_force_*`,
/// `energy` (one definition for simulations and real-time runs).
pub fn reference_table(reference: &[ReferenceRecord]) -> Table {
    Table::from_rows(
        reference,
        &[("time", |r: &ReferenceRecord| r.time)],
        &[
            ("tip_position", |r| r.tip_position),
            ("tip_velocity", |r| r.tip_velocity),
            ("angular_velocity", |r| r.angular_velocity),
            ("contact_force", |r| r.contact_force),
            ("contact_moment", |r| r.contact_moment),
        ],
    )
    .with(Table::from_rows(
        reference,
        &[("energy", |r: &ReferenceRecord| r.energy)],
        &[],
    ))
}

/// The records and metrics of a run.
struct Runs {
    reference: Vec<ReferenceRecord>,
    hil: HilRun,
    metrics: Metrics,
}

fn run(plan: &Plan, keep_rows: bool) -> Runs {
    let (reference_trace, reference) = run_reference(plan, keep_rows);
    let reference_energy = &reference_trace.energy;
    let bound = metrics::divergence_bound(
        plan.divergence_energy_ratio,
        reference_energy[0],
        reference_energy,
    );
    let hil = run_hil(plan, bound, keep_rows);
    let metrics = trace_metrics(plan, &reference_trace, &hil.trace, hil.estimates_contact, hil.stop);
    Runs {
        reference,
        hil,
        metrics,
    }
}

/// The metrics of a HIL trace against the reference's trace: the one computation used by
/// simulations and by the real-time runtime. `estimates_contact`: whether the trace has
/// stiffness and damping estimates; `stop`: how the run ended (`diverged_at` is the trace's
/// last time for a diverged run).
pub fn trace_metrics(
    plan: &Plan,
    reference: &Trace,
    hil: &Trace,
    estimates_contact: bool,
    stop: Stop,
) -> Metrics {
    let s = &plan.scenario;
    let threshold = plan.contact_threshold;
    let comparison = metrics::compare(
        hil,
        reference,
        threshold,
        &plan.tolerances,
        plan.facility_lag(),
        plan.facility_lag() + plan.sensor_delay() + 5.0 * plan.period,
    );
    let first_end = comparison.collisions.first().map(|c| c.collision.end);
    let identification = match (estimates_contact, s.contact.model, first_end) {
        (true, ContactModelKind::Linear, Some(first_end)) => metrics::identification_error(
            hil,
            threshold,
            first_end,
            s.contact.stiffness,
            s.contact.damping,
        ),
        _ => None,
    };
    let status = Metrics::verdict(&stop, &comparison.violations);
    let reason = match (stop.reason(), comparison.violations.as_slice()) {
        (Some(reason), _) => Some(reason),
        (None, []) => None,
        (None, [first]) => Some(format!("unfaithful: {first}")),
        (None, [first, rest @ ..]) => Some(format!("unfaithful: {first} (and {} more)", rest.len())),
    };
    let (t, r) = (hil, reference);
    Metrics {
        scenario: s.name.clone(),
        compensator: s.compensator.kind().to_string(),
        status,
        diverged_at: (status == metrics::Status::Diverged)
            .then(|| t.time.last().copied().unwrap_or(0.0)),
        reason,
        stop,
        summary: metrics::Summary::of(&comparison.collisions),
        collisions: comparison.collisions,
        reference_collisions: comparison.reference_collisions,
        lost_collisions: comparison.lost_collisions,
        extra_collisions: comparison.extra_collisions,
        violations: comparison.violations,
        tolerances: plan.tolerances,
        identification,
        energy: EnergySummary {
            initial: t.energy.first().copied().unwrap_or(f64::NAN),
            r#final: t.energy.last().copied().unwrap_or(f64::NAN),
            reference_final: r.energy.last().copied().unwrap_or(f64::NAN),
            max: t
                .energy
                .iter()
                .copied()
                .filter(|e| e.is_finite())
                .fold(0.0, f64::max),
        },
    }
}
