//! Every compensator's `step` allocates nothing, over whole contacts (identification, energy
//! work, `model-mediated`'s contact-end fits and model updates): a counting allocator, armed on
//! this test's thread only, while the steps run on recorded inputs. And `reset` forgets a run.
//! The facility's side of a tick (`FacilityLoop::tick`: advance, measure) allocates nothing
//! either, over a whole run with noise, quantisation and servo lag. `pida` with the scenario's
//! geometry as its prior normal (shapes, a corner of two bars, walls with friction) neither,
//! nor `model-mediated` with the scenario's shapes as its prior geometry (`prior_shapes`).

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use common::{preset, table1};
use hilcontact_core::compensator::{CompensatorConfig, ModelMediatedParams, PriorShapes, REGISTRY};
use hilcontact_core::contact::FrictionConfig;
use hilcontact_core::facility::FacilityLoop;
use hilcontact_core::hil::compensator_context;
use hilcontact_core::hil::HilStep;
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

/// The allocations `f` makes on this thread.
fn allocations(f: impl FnOnce()) -> u64 {
    COUNT.with(|c| c.set(0));
    ARMED.with(|a| a.set(true));
    f();
    ARMED.with(|a| a.set(false));
    COUNT.with(Cell::get)
}

#[test]
fn no_compensator_step_allocates() {
    // a model-mediated run with priors (so every mode, fit and update happens), with noise
    let mut s = table1(0.04, 0.005);
    s.facility.sensor_noise = 0.2;
    s.compensator = CompensatorConfig::ModelMediated(ModelMediatedParams {
        prior_walls: s.walls.clone(),
        ..ModelMediatedParams::default()
    });
    let plan = s.resolve().unwrap();
    let inputs = compensator_inputs(&plan);
    let context = compensator_context(&plan);
    for info in REGISTRY {
        let config = match (info.default)() {
            CompensatorConfig::ModelMediated(_) => s.compensator.clone(),
            other => other,
        };
        let mut compensator = config.build(&context);
        let allocated = allocations(|| {
            for input in &inputs {
                std::hint::black_box(compensator.step(input));
            }
        });
        assert_eq!(allocated, 0, "{}: allocated while stepping", info.kind);
        // reset forgets the run: the same inputs give the same outputs as a fresh compensator
        // (compared as text: NaN, "not observed", equals itself there)
        compensator.reset();
        let mut fresh = config.build(&context);
        for (k, input) in inputs.iter().enumerate() {
            let (a, b) = (compensator.step(input), fresh.step(input));
            assert_eq!(
                format!("{a:?}"),
                format!("{b:?}"),
                "{} after reset, tick {k}",
                info.kind
            );
        }
    }
}

#[test]
fn no_facility_tick_allocates() {
    // the commands of a whole run with contact, then the same ticks again, armed
    let mut s = table1(0.02, 0.005);
    s.facility.sensor_noise = 0.2;
    s.facility.torque_noise = 0.02;
    s.facility.force_resolution = 0.01;
    s.facility.servo_frequency = 10.0;
    // with friction, and a tangential velocity for it to act on
    s.contact.friction.kinetic_coefficient = 0.2;
    s.contact.friction.static_coefficient = 0.3;
    s.servicer.velocity[1] = 0.005;
    let plan = s.resolve().unwrap();
    let mut step = HilStep::new(&plan, f64::INFINITY);
    let mut facility = FacilityLoop::new(&plan);
    let mut commands = Vec::with_capacity(plan.ticks + 1);
    let mut command = step.command();
    for k in 0..=plan.ticks {
        commands.push(command);
        let m = facility.tick(&command);
        let _ = step.observe(k, &m, Some(facility.physical_contact()));
        command = step.advance(k).unwrap();
    }
    assert!(commands.iter().any(|c| c.position.norm() > 0.0));
    let mut facility = FacilityLoop::new(&plan);
    let mut contact = 0.0_f64;
    let allocated = allocations(|| {
        for command in &commands {
            let m = facility.tick(command);
            contact = contact.max(facility.contact_force().norm());
            std::hint::black_box(m);
        }
    });
    assert_eq!(allocated, 0, "allocated while ticking");
    assert!(contact > 0.0, "the run touches a wall");
}

#[test]
fn no_compensator_step_allocates_on_a_frictional_oblique_contact() {
    // oblique-6dof with friction and noise: the surface fit, the friction sums and the
    // friction booked by the energy observers all run
    let mut s = common::preset("oblique-6dof");
    s.contact.friction.kinetic_coefficient = 0.2;
    s.facility.sensor_noise = 0.2;
    s.facility.sensor_delay = 0.005;
    s.compensator = CompensatorConfig::from_kind("pida").unwrap();
    let plan = s.resolve().unwrap();
    let inputs = compensator_inputs(&plan);
    let context = compensator_context(&plan);
    for info in REGISTRY {
        let mut compensator = (info.default)().build(&context);
        let allocated = allocations(|| {
            for input in &inputs {
                std::hint::black_box(compensator.step(input));
            }
        });
        assert_eq!(
            allocated, 0,
            "{}: allocated while stepping a frictional contact",
            info.kind
        );
    }
}

#[test]
fn contacts_of_shapes_allocate_nothing_in_the_facility_nor_the_reference() {
    // the shape presets: a cylinder rod against four boxes (an edge, a corner), a capsule
    // against a triangle mesh (the mesh from the preset's OBJ file, read here as the loader
    // would); the facility's ticks and the reference's steps of whole runs, armed
    for name in ["rod-in-frame", "probe-drogue"] {
        let mut s = common::preset(name);
        if name == "probe-drogue" {
            common::load_drogue_mesh(&mut s);
        }
        s.facility.robot_delay = 0.0;
        let plan = s.resolve().unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut step = HilStep::new(&plan, f64::INFINITY);
        let mut facility = FacilityLoop::new(&plan);
        let mut commands = Vec::with_capacity(plan.ticks + 1);
        let mut command = step.command();
        for k in 0..=plan.ticks {
            commands.push(command);
            let m = facility.tick(&command);
            let _ = step.observe(k, &m, Some(facility.physical_contact()));
            command = step.advance(k).unwrap();
        }
        let mut facility = FacilityLoop::new(&plan);
        let mut contact = 0.0_f64;
        let mut x = plan.initial;
        let allocated = allocations(|| {
            for command in &commands {
                let m = facility.tick(command);
                contact = contact.max(facility.contact_force().norm());
                std::hint::black_box(m);
                plan.system
                    .step_reference(&mut x, plan.period, plan.reference_substeps);
            }
        });
        assert_eq!(allocated, 0, "{name}: allocated while ticking");
        assert!(contact > 0.0, "{name}: the run touches");
    }
}

/// `pida` with the geometry prior: the prior's query over the shapes' contact points
/// (`rod-in-frame`: a cylinder in a frame of boxes, its corner of two bars) and over walls
/// (`oblique-6dof` with friction), the robot's attitude delayed with the kinematics, the net
/// friction.
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
        let allocated = allocations(|| {
            for input in &inputs {
                std::hint::black_box(compensator.step(input));
            }
        });
        assert_eq!(allocated, 0, "{}: allocated while stepping", s.name);
    }
}

/// `model-mediated` with the scenario's shapes as its prior geometry: the shapes' wrench at the
/// virtual pose (the engine's query), the robot's attitude delayed, the shapes' fit at each
/// contact's end and its adoption; `geometry` (the law fitted from `pida`'s first contact) and
/// `geometry-and-law`, on `rod-in-frame` (a cylinder in four boxes) and `probe-drogue` (a
/// capsule in a cone mesh).
#[test]
fn model_mediated_with_the_shapes_prior_steps_without_allocating() {
    for name in ["rod-in-frame", "probe-drogue"] {
        for prior in [PriorShapes::Geometry, PriorShapes::GeometryAndLaw] {
            let mut s = preset(name);
            if name == "probe-drogue" {
                common::load_drogue_mesh(&mut s);
            }
            s.facility.sensor_noise = 0.2;
            s.facility.sensor_delay = 0.005;
            s.facility.robot_delay = 0.08;
            s.compensator = CompensatorConfig::ModelMediated(ModelMediatedParams {
                prior_shapes: prior,
                ..ModelMediatedParams::default()
            });
            let plan = s.resolve().expect("plan");
            let context = compensator_context(&plan);
            let inputs = compensator_inputs(&plan);
            assert!(
                inputs.iter().any(|i| i.measured.force.norm() > 50.0),
                "{name}: no contact"
            );
            let mut compensator = s.compensator.build(&context);
            let mut modelled = 0;
            let allocated = allocations(|| {
                for input in &inputs {
                    std::hint::black_box(compensator.step(input));
                    if compensator.rendering() == hilcontact_core::compensator::Rendering::Model {
                        modelled += 1;
                    }
                }
            });
            assert_eq!(allocated, 0, "{name} {prior:?}: allocated while stepping");
            assert!(
                modelled > 0,
                "{name} {prior:?}: nothing rendered by the model"
            );
        }
    }
}
