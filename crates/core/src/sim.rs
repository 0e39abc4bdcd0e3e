//! A whole simulation: the ideal reference, the HIL loop against the plan's facility (the
//! [`FacilityLoop`] the emulated facility runs too), the recorded time series and the metrics. Allocates its records up front; the per-tick code
//! (facility, compensator, dynamics) does not allocate.

use std::sync::atomic::{AtomicBool, Ordering};

use nalgebra::{UnitQuaternion, Vector3};

use crate::compensator::{Compensator, CompensatorInput};
use crate::config::{ContactModelKind, Scenario};
use crate::error::Result;
use crate::facility::FacilityLoop;
use crate::frames::FrameWrench;
pub use crate::hil::HilRecord;
use crate::hil::{HilStep, VirtualDynamics};
pub use crate::metrics::Trace;
use crate::metrics::{self, EnergySummary, Metrics, TraceSample};
use crate::plan::Plan;
use crate::stop::{Status, Stop, StopKind};
use crate::world::TwoBodyState;

/// Named columns of equal length.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    /// `(name, values)` in output order.
    pub columns: Vec<(String, Vec<f64>)>,
}

impl Table {
    /// This table with the columns of `other` appended.
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
}

/// The trace of HIL records (with estimates if `estimates_contact`), for the metrics.
pub fn hil_trace(plan: &Plan, rows: &[HilRecord], estimates_contact: bool) -> Trace {
    let mut trace = Trace::with_capacity(rows.len(), estimates_contact);
    for row in rows {
        push_record(&mut trace, plan, row, estimates_contact);
    }
    trace
}

/// Appends a HIL record to a trace (the sensor's attitude in `t` and its origin from `plan`).
/// The contact moment is the physical force's at the actual rod tip about the sensor origin.
fn push_record(trace: &mut Trace, plan: &Plan, row: &HilRecord, estimates_contact: bool) {
    let sensor_to_t: &UnitQuaternion<f64> = &plan.sensor.orientation;
    trace.push(&TraceSample {
        time: row.time,
        contact_force: row.contact_force,
        friction_force: row.friction_force,
        contact_moment: row.contact_moment,
        velocity: row.tip_velocity,
        angular_velocity: row.angular_velocity,
        wrench: FrameWrench {
            force: sensor_to_t * row.applied_force,
            moment: sensor_to_t * row.applied_moment,
        },
        energy: row.energy,
    });
    if estimates_contact {
        trace.push_estimates(row.stiffness_estimate, row.damping_estimate, row.law_factor);
    }
    trace.rendering.push(row.rendering);
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
    /// Its friction (tangential) part, `t` frame, N (the rest is the normal part).
    pub friction_force: Vector3<f64>,
    /// Moment of the contact force on the frame about the sensor origin, `t` frame, N·m.
    pub contact_moment: Vector3<f64>,
    /// Kinetic energy of the relative motion, J.
    pub energy: f64,
    /// Energy friction has dissipated since the start, J (0 without friction): reported apart
    /// from the damping's, which is the rest of the energy lost.
    pub friction_work: f64,
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
    run_reference_from(plan, &plan.initial, 0, plan.ticks, keep_rows, |_| false)
}

/// [`run_reference`] from the state `x0` at tick `k0` (time `k0 · period`) to tick `n`, or
/// to the first tick after which `done` (asked of the trace after each tick's sample) says
/// so: the same integration, step for step (a local reference, [`metrics::local_comparison`]).
pub fn run_reference_from(
    plan: &Plan,
    x0: &TwoBodyState,
    k0: usize,
    n: usize,
    keep_rows: bool,
    mut done: impl FnMut(&Trace) -> bool,
) -> (Trace, Vec<ReferenceRecord>) {
    let (period, system) = (plan.period, &plan.system);
    let mut x = *x0;
    let ticks = n.saturating_sub(k0) + 1;
    let mut trace = Trace::with_capacity(ticks, false);
    let mut rows = Vec::with_capacity(if keep_rows { ticks } else { 0 });
    let mut friction_work = 0.0;
    // the relative motion at `x` and its rod tip (kept from the step that computed them)
    let mut start = system.reference_start(&system.relative_motion(&x));
    for k in k0..=n {
        // (as the step that ended here computed it, if it did)
        let contact = system.reference_contact(&mut start);
        let rel = &start.rel;
        let (contact_force, wrench) = (contact.force, contact.wrench);
        let row = ReferenceRecord {
            time: k as f64 * period,
            tip_position: contact.tip,
            tip_velocity: start.tip_velocity,
            angular_velocity: rel.angular_velocity,
            contact_force,
            friction_force: contact.friction_force,
            contact_moment: wrench.moment,
            energy: system.energy(&x),
            friction_work,
        };
        trace.push(&TraceSample {
            time: row.time,
            contact_force,
            friction_force: contact.friction_force,
            contact_moment: wrench.moment,
            velocity: row.tip_velocity,
            angular_velocity: row.angular_velocity,
            wrench,
            energy: row.energy,
        });
        if keep_rows {
            rows.push(row);
        }
        if done(&trace) {
            break;
        }
        if k < n {
            let (work, end) =
                system.step_reference_at(&mut x, &start, period, plan.reference_substeps);
            friction_work += work;
            start = end.unwrap_or_else(|| system.reference_start(&system.relative_motion(&x)));
        }
    }
    trace.friction_work = friction_work;
    (trace, rows)
}

/// How a HIL run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct HilRun {
    /// What the metrics read of every tick run.
    pub trace: Trace,
    /// Every record, if asked for (up to divergence).
    pub rows: Vec<HilRecord>,
    /// The virtual dynamics' state of both bodies at every tick run (what the local
    /// references restart from, [`metrics::local_comparison`]).
    pub states: Vec<TwoBodyState>,
    /// Whether the compensator identified the contact.
    pub estimates_contact: bool,
    /// Whether the compensator observed the port energy.
    pub observes_energy: bool,
    /// How it stopped.
    pub stop: Stop,
}

/// The HIL loop of [`HilStep`] against the plan's facility ([`FacilityLoop`], the engine of
/// `[facility] kind`), stopped once the energy passes `energy_bound` (J); every record is kept
/// if `keep_rows`, the trace always.
pub fn run_hil(plan: &Plan, energy_bound: f64, keep_rows: bool) -> HilRun {
    run_hil_against(plan, FacilityLoop::new(plan), energy_bound, keep_rows)
}

/// [`run_hil`] against a facility built elsewhere (e.g. an external engine the core cannot
/// build by kind, wrapped with [`FacilityLoop::with`]); it must not have ticked yet.
pub fn run_hil_against(
    plan: &Plan,
    facility: FacilityLoop,
    energy_bound: f64,
    keep_rows: bool,
) -> HilRun {
    run_hil_step(plan, facility, HilStep::new(plan, energy_bound), keep_rows)
}

/// The HIL loop of a [`HilStep`] built elsewhere (e.g. with a compensator from outside the
/// core, [`VirtualDynamics::with_compensator`]) against `facility`, which must not have ticked.
pub fn run_hil_step(plan: &Plan, facility: FacilityLoop, step: HilStep, keep_rows: bool) -> HilRun {
    run_hil_step_until(plan, facility, step, keep_rows, &AtomicBool::new(false))
}

/// [`run_hil_step`] that the user can stop: `stop` is read once per tick (one relaxed load,
/// no allocation), after the tick's record; once it is set the run ends there as a
/// [`StopKind::User`] stop at that tick's time (status `interrupted`), with every record so
/// far. A stop of the step itself (divergence, a value no longer finite) at the same tick
/// comes first. The virtual states ([`HilRun::states`]) are kept where the scenario asks for
/// the local references (`metrics.local_references`).
pub fn run_hil_step_until(
    plan: &Plan,
    facility: FacilityLoop,
    step: HilStep,
    keep_rows: bool,
    stop: &AtomicBool,
) -> HilRun {
    let keep_states = plan.scenario.metrics.local_references;
    run_hil_loop(plan, facility, step, keep_rows, keep_states, stop)
}

/// [`run_hil_step_until`], keeping the virtual states ([`HilRun::states`]) only if
/// `keep_states` (a sweep's row does not read the local references they are for).
fn run_hil_loop(
    plan: &Plan,
    mut facility: FacilityLoop,
    mut step: HilStep,
    keep_rows: bool,
    keep_states: bool,
    stop: &AtomicBool,
) -> HilRun {
    let user_stop = stop;
    let n = plan.ticks;
    let estimates = step.dynamics().estimates_contact();
    // (the identification metric reads the law factor)
    facility.measure_law_factor(estimates);
    let mut rows = Vec::with_capacity(if keep_rows { n + 1 } else { 0 });
    let mut trace = Trace::with_capacity(n + 1, estimates);
    let mut states = Vec::with_capacity(if keep_states { n + 1 } else { 0 });
    // the command for the coming tick (the first tick does not read it)
    let mut command = step.command();
    let mut k = 0;
    let stop = loop {
        if keep_states {
            states.push(*step.dynamics().state());
        }
        let m = facility.tick(&command);
        let (row, stop) = step.observe(k, &m, Some(facility.physical_contact()));
        let time = row.time;
        push_record(&mut trace, plan, &row, estimates);
        if keep_rows {
            rows.push(row);
        }
        if let Some(stop) = stop {
            break stop;
        }
        if user_stop.load(Ordering::Relaxed) {
            break Stop::plain(StopKind::User, time);
        }
        match step.advance(k) {
            Ok(next) => command = next,
            Err(stop) => break stop,
        }
        k += 1;
    };
    HilRun {
        trace,
        rows,
        states,
        estimates_contact: estimates,
        observes_energy: step.dynamics().observes_energy(),
        stop,
    }
}

/// The compensator input of every tick of a plan's HIL run with its own compensator, run to
/// the end without its stops (no divergence check): what a benchmark or a test steps a
/// compensator alone on.
pub fn compensator_inputs(plan: &Plan) -> Vec<CompensatorInput> {
    let mut virt = VirtualDynamics::new(plan);
    let mut facility = FacilityLoop::new(plan);
    let mut inputs = Vec::with_capacity(plan.ticks);
    for _ in 0..plan.ticks {
        let m = facility.tick(&virt.command());
        inputs.push(virt.input(&m));
        let out = virt.compensate(&m);
        virt.integrate(&out);
    }
    inputs
}

/// Runs the reference and the HIL loop of a scenario and computes the metrics, without
/// keeping the records (what a sweep keeps of a run).
pub fn simulate_metrics(s: &Scenario) -> Result<Metrics> {
    let plan = s.resolve()?;
    crate::facility::buildable(&plan)?;
    Ok(simulate_plan_metrics(&plan))
}

/// Runs the reference and the HIL loop of a resolved plan and computes the metrics, without
/// keeping the records (what a sweep keeps of a run).
pub fn simulate_plan_metrics(plan: &Plan) -> Metrics {
    simulate_plan_metrics_with_reference(plan, &run_reference(plan, false).0)
}

/// What a plan's ideal reference depends on, as text that tells every bit apart: the true
/// system, the initial state, the period, the ticks and the reference's sub-steps (all
/// [`run_reference`] reads of a plan). Plans with the same key have the same reference, to the
/// bit (e.g. a sweep's runs that differ only in the facility's delays, noise, seed or the
/// compensator), so a batch of runs computes it once ([`simulate_plan_metrics_with_reference`]).
/// Exact: `f64`'s `Debug` writes the shortest text that reads back to the same bits, and tells
/// `-0.0` from `0.0`.
pub fn reference_key(plan: &Plan) -> String {
    format!(
        "{:?}|{:?}|{:?}|{}|{}",
        plan.system, plan.initial, plan.period, plan.ticks, plan.reference_substeps
    )
}

/// [`simulate_plan_metrics`] with the plan's reference trace already computed
/// (`run_reference(p, false).0` of a plan `p` with the same [`reference_key`]): the same
/// metrics, to the bit, without running the reference again. Neither keeps the virtual states,
/// so neither has the local references' errors ([`run_metrics`]; a sweep's row does not read
/// them).
pub fn simulate_plan_metrics_with_reference(plan: &Plan, reference: &Trace) -> Metrics {
    let step = HilStep::new(plan, divergence_bound_of(plan, reference));
    let (facility, stop) = (FacilityLoop::new(plan), &AtomicBool::new(false));
    let hil = run_hil_loop(plan, facility, step, false, false, stop);
    trace_metrics(plan, reference, &hil.trace, hil.estimates_contact, hil.stop)
}

/// The divergence bound of a plan's HIL run from its reference's trace, J
/// ([`metrics::divergence_bound`]).
fn divergence_bound_of(plan: &Plan, reference: &Trace) -> f64 {
    metrics::divergence_bound(
        plan.divergence_energy_ratio,
        reference.energy[0],
        &reference.energy,
    )
}

/// Runs the reference and the HIL loop of a scenario and computes the metrics.
pub fn simulate(s: &Scenario) -> Result<SimulationOutput> {
    let plan = s.resolve()?;
    crate::facility::buildable(&plan)?;
    Ok(simulate_plan(&plan))
}

/// Runs the reference and the HIL loop of a resolved plan and computes the metrics.
pub fn simulate_plan(plan: &Plan) -> SimulationOutput {
    simulate_plan_with_records(plan).0
}

/// As [`simulate_plan`], also handing back the HIL loop's records, one per tick (what a
/// recording such as an MCAP file is written from).
pub fn simulate_plan_with_records(plan: &Plan) -> (SimulationOutput, Vec<HilRecord>) {
    simulate_plan_until(plan, &AtomicBool::new(false))
}

/// [`simulate_plan_with_records`] that the user can stop (Ctrl-C): once `stop` is set, the HIL
/// loop ends at its next tick ([`run_hil_step_until`]) and the run is returned as it stands:
/// status `interrupted` (never `ok`), the records up to that tick, and the reference and the
/// metrics over the same span (`0..=k` ticks). A flag set while the reference runs stops the
/// loop at its first tick.
pub fn simulate_plan_until(plan: &Plan, stop: &AtomicBool) -> (SimulationOutput, Vec<HilRecord>) {
    let Runs {
        reference,
        hil,
        metrics,
    } = simulate_plan_records_until(plan, stop);
    let output = SimulationOutput {
        timeseries: hil_table(&hil.rows, hil.estimates_contact, hil.observes_energy),
        reference: reference_table(&reference),
        metrics,
    };
    (output, hil.rows)
}

/// [`simulate_plan_until`] without its tables: the records of both loops and the metrics, the
/// tables to be made from them only if they are read ([`Runs::timeseries`],
/// [`Runs::reference_table`]; the same tables, to the bit). Building them cost a `paper-table1`
/// run about 0.8 ms, an eighth of the run.
pub fn simulate_plan_records_until(plan: &Plan, stop: &AtomicBool) -> Runs {
    run_with(plan, true, None, stop)
}

/// How a table's field reads a record: one value, or a vector (three columns `_x`, `_y`, `_z`).
pub enum Get<R> {
    /// One column.
    Scalar(fn(&R) -> f64),
    /// Three columns, `t` frame (or the sensor frame, as the field says).
    Vector(fn(&R) -> Vector3<f64>),
}

/// Which runs have a field.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Only {
    /// Every run.
    Always,
    /// Runs whose compensator identifies the contact (`stiffness_estimate`, ...).
    Estimates,
    /// Runs whose compensator observes the port energy.
    ObservedEnergy,
}

/// A field of a table: its name, unit and how it reads a record (the one definition of the
/// tables' columns, exported to Python with their units).
pub struct Field<R> {
    /// Column name (a vector's columns add `_x`, `_y`, `_z`).
    pub name: &'static str,
    /// SI unit.
    pub unit: &'static str,
    /// How it reads a record.
    pub get: Get<R>,
    /// Which runs have it.
    pub only: Only,
}

/// A one-column field read by `get`, in every run.
pub const fn scalar<R>(name: &'static str, unit: &'static str, get: fn(&R) -> f64) -> Field<R> {
    Field {
        name,
        unit,
        get: Get::Scalar(get),
        only: Only::Always,
    }
}

/// A three-column field read by `get`, in every run.
pub const fn vector<R>(
    name: &'static str,
    unit: &'static str,
    get: fn(&R) -> Vector3<f64>,
) -> Field<R> {
    Field {
        name,
        unit,
        get: Get::Vector(get),
        only: Only::Always,
    }
}

/// The HIL loop's table (one definition for simulations and real-time runs): desired
/// (virtual) and actual (robot) rod tip in `t`, the physical contact force on the rod (`t`),
/// the sensor's wrench and the applied wrench (sensor frame and convention), the energy, and
/// the estimates of the compensators that make them.
pub const HIL_FIELDS: [Field<HilRecord>; 16] = [
    scalar("time", "s", |r| r.time),
    vector("tip_position", "m", |r| r.tip_position),
    vector("tip_velocity", "m/s", |r| r.tip_velocity),
    vector("angular_velocity", "rad/s", |r| r.angular_velocity),
    vector("actual_tip_position", "m", |r| r.actual_tip_position),
    vector("actual_tip_velocity", "m/s", |r| r.actual_tip_velocity),
    vector("contact_force", "N", |r| r.contact_force),
    vector("friction_force", "N", |r| r.friction_force),
    vector("measured_force", "N", |r| r.measured_force),
    vector("measured_moment", "N m", |r| r.measured_moment),
    vector("applied_force", "N", |r| r.applied_force),
    vector("applied_moment", "N m", |r| r.applied_moment),
    scalar("energy", "J", |r| r.energy),
    Field {
        only: Only::Estimates,
        ..scalar("stiffness_estimate", "N/m", |r| r.stiffness_estimate)
    },
    Field {
        only: Only::Estimates,
        ..scalar("damping_estimate", "N s/m", |r| r.damping_estimate)
    },
    Field {
        only: Only::ObservedEnergy,
        ..scalar("observed_energy", "J", |r| r.observed_energy)
    },
];

/// The reference's table: rod tip (`t`), the servicer's angular velocity relative to the
/// target (`t`), the contact force on the rod and its moment on the frame about the sensor
/// origin (`t`), the energy and the energy friction has dissipated so far.
pub const REFERENCE_FIELDS: [Field<ReferenceRecord>; 9] = [
    scalar("time", "s", |r| r.time),
    vector("tip_position", "m", |r| r.tip_position),
    vector("tip_velocity", "m/s", |r| r.tip_velocity),
    vector("angular_velocity", "rad/s", |r| r.angular_velocity),
    vector("contact_force", "N", |r| r.contact_force),
    vector("friction_force", "N", |r| r.friction_force),
    vector("contact_moment", "N m", |r| r.contact_moment),
    scalar("energy", "J", |r| r.energy),
    scalar("friction_work", "J", |r| r.friction_work),
];

/// The columns of a table's fields: `(name, unit, only)`, a vector's as three columns.
pub fn columns<R>(fields: &[Field<R>]) -> Vec<(String, &'static str, Only)> {
    let mut out = Vec::new();
    for f in fields {
        match f.get {
            Get::Scalar(_) => out.push((f.name.to_string(), f.unit, f.only)),
            Get::Vector(_) => {
                for axis in ["x", "y", "z"] {
                    out.push((format!("{}_{axis}", f.name), f.unit, f.only));
                }
            }
        }
    }
    out
}

/// The table of `rows` with the `fields` for which `has(field.only)`.
pub fn table<R>(rows: &[R], fields: &[Field<R>], has: impl Fn(Only) -> bool) -> Table {
    let used: Vec<&Field<R>> = fields.iter().filter(|f| has(f.only)).collect();
    let mut columns: Vec<(String, Vec<f64>)> = Vec::new();
    for f in &used {
        match f.get {
            Get::Scalar(_) => columns.push((f.name.to_string(), Vec::with_capacity(rows.len()))),
            Get::Vector(_) => {
                for label in ["x", "y", "z"] {
                    columns.push((
                        format!("{}_{label}", f.name),
                        Vec::with_capacity(rows.len()),
                    ));
                }
            }
        }
    }
    // one pass over the records (each read once, a vector field's getter called once per row)
    for r in rows {
        let mut column = columns.iter_mut().map(|(_, values)| values);
        for f in &used {
            match f.get {
                Get::Scalar(get) => column.next().expect("a column per field").push(get(r)),
                Get::Vector(get) => {
                    let v = get(r);
                    for x in v.iter() {
                        column.next().expect("three columns per field").push(*x);
                    }
                }
            }
        }
    }
    Table { columns }
}

/// The HIL loop's table ([`HIL_FIELDS`]), one row per record, with the estimates if
/// `estimates_contact` and the observed energy if `observes_energy`.
pub fn hil_table(rows: &[HilRecord], estimates_contact: bool, observes_energy: bool) -> Table {
    table(rows, &HIL_FIELDS, |only| match only {
        Only::Always => true,
        Only::Estimates => estimates_contact,
        Only::ObservedEnergy => observes_energy,
    })
}

/// The reference's table ([`REFERENCE_FIELDS`]), one row per record.
pub fn reference_table(reference: &[ReferenceRecord]) -> Table {
    table(reference, &REFERENCE_FIELDS, |_| true)
}

/// The records and metrics of a run.
#[derive(Debug, Clone)]
pub struct Runs {
    /// The ideal reference, one record per tick (empty when the records were not kept).
    pub reference: Vec<ReferenceRecord>,
    /// The HIL loop (its records when kept).
    pub hil: HilRun,
    /// The metrics.
    pub metrics: Metrics,
}

impl Runs {
    /// The HIL loop's table ([`hil_table`]).
    pub fn timeseries(&self) -> Table {
        let hil = &self.hil;
        hil_table(&hil.rows, hil.estimates_contact, hil.observes_energy)
    }

    /// The reference's table ([`reference_table`]).
    pub fn reference_table(&self) -> Table {
        reference_table(&self.reference)
    }
}

/// [`simulate_plan_with_records`] with a compensator built outside the core (e.g. one written
/// in Python, `crates/py`) in place of the plan's `[compensator]` (whose kind the metrics name;
/// the caller renames it).
pub fn simulate_plan_with_compensator(
    plan: &Plan,
    compensator: Box<dyn Compensator>,
    keep_rows: bool,
) -> (SimulationOutput, Vec<HilRecord>) {
    simulate_plan_with_compensator_until(plan, compensator, keep_rows, &AtomicBool::new(false))
}

/// [`simulate_plan_with_compensator`] that the user can stop, as [`simulate_plan_until`].
pub fn simulate_plan_with_compensator_until(
    plan: &Plan,
    compensator: Box<dyn Compensator>,
    keep_rows: bool,
    stop: &AtomicBool,
) -> (SimulationOutput, Vec<HilRecord>) {
    let Runs {
        reference,
        hil,
        metrics,
    } = run_with(plan, keep_rows, Some(compensator), stop);
    let output = SimulationOutput {
        timeseries: hil_table(&hil.rows, hil.estimates_contact, hil.observes_energy),
        reference: reference_table(&reference),
        metrics,
    };
    (output, hil.rows)
}

/// The reference and the HIL loop, with the plan's compensator or `compensator`; `stop`: the
/// user's stop ([`run_hil_step_until`]), after which the reference is run again over the HIL
/// loop's span, so that both tables and the metrics cover the same ticks.
fn run_with(
    plan: &Plan,
    keep_rows: bool,
    compensator: Option<Box<dyn Compensator>>,
    stop: &AtomicBool,
) -> Runs {
    let (mut reference_trace, mut reference) = run_reference(plan, keep_rows);
    let bound = divergence_bound_of(plan, &reference_trace);
    let step = match compensator {
        None => HilStep::new(plan, bound),
        Some(c) => HilStep::with_dynamics(plan, bound, VirtualDynamics::with_compensator(plan, c)),
    };
    let hil = run_hil_step_until(plan, FacilityLoop::new(plan), step, keep_rows, stop);
    if hil.stop.kind == StopKind::User {
        // the reference over the same span: ticks 0..=k of the interrupted loop
        let span = Plan {
            ticks: hil.trace.time.len().saturating_sub(1),
            ..plan.clone()
        };
        (reference_trace, reference) = run_reference(&span, keep_rows);
    }
    let metrics = run_metrics(plan, &reference_trace, &hil);
    Runs {
        reference,
        hil,
        metrics,
    }
}

/// The metrics of a simulated HIL run against the reference's trace: [`trace_metrics`]
/// with the local references restarted from the run's virtual states
/// ([`metrics::local_comparison`]).
pub fn run_metrics(plan: &Plan, reference: &Trace, hil: &HilRun) -> Metrics {
    trace_metrics_with_states(
        plan,
        reference,
        &hil.trace,
        hil.estimates_contact,
        hil.stop,
        &hil.states,
    )
}

/// The local reference of a HIL collision ([`metrics::local_comparison`]): the ideal
/// reference run again from the virtual state `states[k0]` (the restart's time and its trace),
/// `k0` the tick `lag + sensor delay + 3` periods before the collision's start, or the
/// latest tick before it down to the previous collision's end where the virtual bodies are
/// apart ([`crate::world::TwoBodySystem::clearance_at`] > 0); run until its first contact has
/// ended and settled (`2 (lag + sensor delay + 5 periods)` after both collisions' ends), or
/// until the next HIL collision or its own second contact starts, whichever comes first (its
/// rebound is read in the middle of that common free flight). None if no such tick is found.
pub fn local_reference(
    plan: &Plan,
    states: &[TwoBodyState],
    span: &metrics::CollisionSpan,
) -> Option<(f64, Trace)> {
    let (system, period, threshold) = (&plan.system, plan.period, plan.contact_threshold);
    let back = ((plan.facility_lag() + plan.sensor_delay()) / period).ceil() as usize + 3;
    let lo = span.previous_end;
    let hi = span
        .start
        .saturating_sub(back)
        .max(lo)
        .min(states.len().checked_sub(1)?);
    let k0 = (lo..=hi)
        .rev()
        .find(|&k| system.clearance_at(&system.relative_motion(&states[k])) > 0.0)?;
    // stop once the first contact has ended and either a second one starts or the HIL's
    // next collision does
    let (mut touched, mut ended) = (false, None);
    // settled: twice the loop's lag, the sensor delay and 5 periods after both collisions
    // ended, so that the rebound sample (the middle of the common free flight) lies after the
    // sensor-delayed tail of the HIL's force, as [`trace_metrics`]' `settle` does
    let settle = 2 * (back + 2);
    let done = |t: &Trace| {
        let (f, k) = (t.force.last().copied().unwrap_or(0.0), k0 + t.len() - 1);
        touched |= f > threshold;
        if touched && f <= threshold && ended.is_none() {
            ended = Some(k);
        }
        ended.is_some_and(|e| f > threshold || k >= span.next || k >= e.max(span.end) + settle)
    };
    let (trace, _) = run_reference_from(plan, &states[k0], k0, plan.ticks, false, done);
    Some((k0 as f64 * period, trace))
}

/// [`trace_metrics`] with the virtual dynamics' state at every tick of the trace (`states`,
/// [`HilRun::states`]): each complete collision also compared with its local reference
/// ([`local_reference`]); without states (real-time runs, replays, a sweep's rows) and for a
/// diverged run the local errors are none.
pub fn trace_metrics_with_states(
    plan: &Plan,
    reference: &Trace,
    hil: &Trace,
    estimates_contact: bool,
    stop: Stop,
    states: &[TwoBodyState],
) -> Metrics {
    let mut m = trace_metrics(plan, reference, hil, estimates_contact, stop);
    // a diverged run's collisions grow without bound (restarting each would cost more than
    // the run): no local references
    if states.is_empty() || m.status == Status::Diverged {
        return m;
    }
    metrics::local_comparison(hil, plan.contact_threshold, &mut m.collisions, |span| {
        local_reference(plan, states, span)
    });
    m.summary = metrics::Summary::judged_from(&m.collisions, plan.tolerances.judge_from);
    m
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
        (None, [first, rest @ ..]) => {
            Some(format!("unfaithful: {first} (and {} more)", rest.len()))
        }
    };
    let (t, r) = (hil, reference);
    Metrics {
        scenario: s.name.clone(),
        compensator: s.compensator.kind().to_string(),
        status,
        diverged_at: (status == Status::Diverged).then(|| t.time.last().copied().unwrap_or(0.0)),
        reason,
        stop,
        summary: metrics::Summary::judged_from(&comparison.collisions, plan.tolerances.judge_from),
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
            reference_friction_work: r.friction_work,
            max: t
                .energy
                .iter()
                .copied()
                .filter(|e| e.is_finite())
                .fold(0.0, f64::max),
        },
    }
}
