//! The user's stop (Ctrl-C) of a simulation: the HIL loop ends at the tick where its flag is
//! first seen set, the run is `interrupted` (never `ok`), its records are exactly the first
//! ticks of the uninterrupted run, and the reference and the metrics cover the same span.

mod common;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use common::preset;
use hilcontact_core::compensator::{Compensator, CompensatorInput, CompensatorOutput};
use hilcontact_core::hil::compensator_context;
use hilcontact_core::sim::{
    simulate_plan_until, simulate_plan_with_compensator_until, simulate_plan_with_records,
};
use hilcontact_core::stop::{Status, StopKind};
use hilcontact_core::Plan;
use proptest::prelude::*;

/// The plan's own compensator, which sets the user's stop flag at its step of tick `at`
/// (a Ctrl-C landing there, deterministically).
struct StopAt {
    inner: Box<dyn Compensator>,
    flag: Arc<AtomicBool>,
    tick: usize,
    at: usize,
}

impl Compensator for StopAt {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        if self.tick == self.at {
            self.flag.store(true, Ordering::Relaxed);
        }
        self.tick += 1;
        self.inner.step(input)
    }
    fn reset(&mut self) {
        self.inner.reset();
        self.tick = 0;
    }
    fn estimates_contact(&self) -> bool {
        self.inner.estimates_contact()
    }
    fn observes_energy(&self) -> bool {
        self.inner.observes_energy()
    }
    fn uses_tip_mobility(&self) -> bool {
        self.inner.uses_tip_mobility()
    }
}

/// Bit-for-bit equality of two columns (NaN where a compensator has no estimate yet).
fn bits(values: &[f64]) -> Vec<u64> {
    values.iter().map(|v| v.to_bits()).collect()
}

/// Bit-for-bit equality of two tables.
fn same_table(a: &hilcontact_core::Table, b: &hilcontact_core::Table) -> bool {
    a.columns.len() == b.columns.len()
        && a.columns
            .iter()
            .zip(&b.columns)
            .all(|((na, va), (nb, vb))| na == nb && bits(va) == bits(vb))
}

fn plan(kind: &str, duration: f64) -> Plan {
    let mut s = preset("paper-table1");
    s.simulation.duration = duration;
    s.compensator = hilcontact_core::compensator::CompensatorConfig::from_kind(kind).unwrap();
    s.resolve().unwrap()
}

fn interrupted_at(plan: &Plan, at: usize) -> (hilcontact_core::SimulationOutput, usize) {
    let flag = Arc::new(AtomicBool::new(false));
    let c = StopAt {
        inner: plan.compensator.build(&compensator_context(plan)),
        flag: Arc::clone(&flag),
        tick: 0,
        at,
    };
    let (out, rows) = simulate_plan_with_compensator_until(plan, Box::new(c), true, &flag);
    (out, rows.len())
}

#[test]
fn a_stop_before_the_loop_keeps_the_first_tick() {
    let plan = plan("pida", 2.0);
    let (out, rows) = simulate_plan_until(&plan, &AtomicBool::new(true));
    assert_eq!(rows.len(), 1);
    assert_eq!(out.timeseries.len(), 1);
    assert_eq!(out.reference.len(), 1);
    let m = &out.metrics;
    assert_eq!(m.status, Status::Interrupted);
    assert_eq!(m.stop.kind, StopKind::User);
    assert_eq!(m.stop.time, 0.0);
    assert_eq!(m.reason.as_deref(), Some("stopped by the user at 0.000 s"));
}

#[test]
fn an_unset_flag_changes_nothing() {
    let plan = plan("pida", 2.0);
    let (full, rows) = simulate_plan_with_records(&plan);
    let (same, same_rows) = simulate_plan_until(&plan, &AtomicBool::new(false));
    assert_eq!(rows.len(), same_rows.len());
    assert!(same_table(&full.timeseries, &same.timeseries));
    assert!(same_table(&full.reference, &same.reference));
    assert_eq!(full.metrics.status, same.metrics.status);
    assert_eq!(full.metrics.stop.kind, same.metrics.stop.kind);
    assert_eq!(full.metrics.stop.time, same.metrics.stop.time);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// Interrupted at any tick of a run with collisions: the records and both tables are
    /// the uninterrupted run's first `at + 1` ticks, the stop is the user's at that tick's
    /// time, and the status is `interrupted` whatever the collisions so far say.
    #[test]
    fn an_interrupted_run_is_the_first_ticks_of_the_whole_run(
        at in 0usize..2500,
        kind in prop::sample::select(vec!["none", "pida", "pic"]),
    ) {
        let plan = plan(kind, 2.5);
        let (full, _) = simulate_plan_with_records(&plan);
        let (out, rows) = interrupted_at(&plan, at);
        let n = at + 1;
        prop_assert_eq!(rows, n);
        prop_assert_eq!(out.timeseries.len(), n);
        prop_assert_eq!(out.reference.len(), n);
        for (name, values) in &out.timeseries.columns {
            let whole = full.timeseries.column(name).unwrap();
            prop_assert_eq!(bits(values), bits(&whole[..n]), "timeseries {}", name);
        }
        for (name, values) in &out.reference.columns {
            let whole = full.reference.column(name).unwrap();
            prop_assert_eq!(bits(values), bits(&whole[..n]), "reference {}", name);
        }
        let m = &out.metrics;
        prop_assert_eq!(m.status, Status::Interrupted);
        prop_assert_eq!(m.stop.kind, StopKind::User);
        prop_assert!((m.stop.time - at as f64 * plan.period).abs() < 1e-12);
        let last = *out.timeseries.column("time").unwrap().last().unwrap();
        prop_assert!((last - m.stop.time).abs() < 1e-12);
        // the collisions compared are those of the span: none ends after it
        for c in &m.collisions {
            prop_assert!(c.collision.end <= last + 1e-12);
        }
    }
}
