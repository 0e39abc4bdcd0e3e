//! The real-time threads never allocate once running, with the robot on KUKA RSI (robot-paced
//! loop, XML codec): as `no_alloc.rs`, a counting global allocator armed from the loop's first
//! tick while the loop, the writer and the emulator run must count zero allocations.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use common::{preset, rsi_loopback_options};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_rt::{FacilityHandle, HilHandle};

struct Counting;

static ARMED: AtomicBool = AtomicBool::new(false);
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if ARMED.load(Ordering::Relaxed) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.alloc(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if ARMED.load(Ordering::Relaxed) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn rsi_loop_writer_and_emulator_do_not_allocate() {
    let mut s = preset("paper-table1");
    s.facility.robot_delay = 0.02;
    s.simulation.period = 0.004; // the RSI cycle: the robot paces the loop
    s.simulation.duration = 2.5;
    s.compensator = CompensatorConfig::Pida(ModelParams::default());
    let (emu, rt) = rsi_loopback_options();
    let facility = FacilityHandle::start(&s, &emu).unwrap();
    let hil = HilHandle::start(&s, &rt).unwrap();
    // count from the loop's first tick over a window that spans the first collision
    while hil.status().phase != "running" {
        std::thread::sleep(Duration::from_micros(20));
    }
    ARMED.store(true, Ordering::SeqCst);
    let first = hil.status().tick;
    std::thread::sleep(Duration::from_millis(1600));
    ARMED.store(false, Ordering::SeqCst);
    let counted = ALLOCATIONS.load(Ordering::SeqCst);
    let ticks = hil.status().tick;
    assert!(hil.wait(Duration::from_secs(10)));
    let out = hil.finish().unwrap();
    drop(facility);
    // ran to its end (a busy machine's late ticks may make it `unfaithful`; not this test's subject)
    assert_eq!(
        out.metrics["stop"]["kind"], "completed",
        "{}",
        out.metrics["reason"]
    );
    assert!(ticks > 375, "the loop ran only {ticks} ticks");
    // armed as soon as this thread saw the loop running: within a few ticks on an idle
    // machine; a busy one may wake this thread late, and 25 ticks (0.1 s) still arm it well before
    // the first collision (0.27 s) — a bound that cannot flake
    assert!(first <= 25, "armed only after tick {first}");
    assert!(!out.metrics["collisions"].as_array().unwrap().is_empty());
    assert_eq!(counted, 0, "{counted} allocations while running");
}
