//! `pida` with the scenario's geometry as its prior normal (issue 22) allocates nothing while
//! stepping: the prior's query over the shapes' contact points (`rod-in-frame`: a cylinder in a
//! frame of boxes, its corner of two bars) and over walls (`oblique-6dof` with friction), the
//! robot's attitude delayed with the kinematics, the net friction. A counting allocator, armed
//! on this test's thread only, while the steps run on recorded inputs.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use common::preset;
use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_core::contact::FrictionConfig;
use hilcontact_core::hil::compensator_context;
use hilcontact_core::sim::compensator_inputs;

struct Counting;

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    if ARMED.with(Cell::get) {
        COUNT.with(|c| c.set(c.get() + 1));
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn pida_with_the_geometry_prior_steps_without_allocating() {
    let mut oblique = preset("oblique-6dof");
    oblique.contact.friction = FrictionConfig {
        kinetic_coefficient: 0.2,
        ..FrictionConfig::default()
    };
    for mut s in [preset("rod-in-frame"), oblique] {
        s.facility.sensor_noise = 0.2;
        s.facility.sensor_delay = 0.005;
        s.facility.robot_delay = 0.01;
        s.compensator = CompensatorConfig::from_kind("pida").expect("pida");
        let plan = s.resolve().expect("plan");
        let context = compensator_context(&plan);
        assert!(context.geometry.is_some(), "{}: no geometry prior", s.name);
        let inputs = compensator_inputs(&plan);
        assert!(
            inputs.iter().any(|i| i.measured.force.norm() > 50.0),
            "{}: no contact",
            s.name
        );
        let mut compensator = s.compensator.build(&context);
        COUNT.with(|c| c.set(0));
        ARMED.with(|a| a.set(true));
        for input in &inputs {
            std::hint::black_box(compensator.step(input));
        }
        ARMED.with(|a| a.set(false));
        assert_eq!(
            COUNT.with(Cell::get),
            0,
            "{}: allocated while stepping",
            s.name
        );
    }
}
