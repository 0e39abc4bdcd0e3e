//! The real-time threads never allocate once running, with every protocol (RDT and SRI
//! sensors, EGM and RSI robots): a counting global allocator is armed from the loop's first
//! tick while the loop, the writer and the emulator run (no HTTP server, the test's own thread
//! asleep), and must count zero allocations.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use common::{delayed, loopback_options, loopback_sri_options, rsi_loopback_options};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_rt::{EmulatorOptions, FacilityHandle, HilHandle, RuntimeOptions};

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

/// Runs pida at 20 ms on loopback with `options` (emulator, runtime) at `period` s, and
/// checks that nothing allocates from the loop's first tick over a window spanning the first
/// collision. One configuration at a time: the allocator counts the whole process.
fn assert_no_allocation(name: &str, period: f64, (emu, rt): (EmulatorOptions, RuntimeOptions)) {
    let mut s = delayed(CompensatorConfig::Pida(ModelParams::default()), 2.5);
    s.simulation.period = period;
    ALLOCATIONS.store(0, Ordering::SeqCst);
    let facility = FacilityHandle::start(&s, &emu).unwrap();
    let hil = HilHandle::start(&s, &rt).unwrap();
    while hil.status().phase != "running" {
        std::thread::sleep(Duration::from_micros(20));
    }
    ARMED.store(true, Ordering::SeqCst);
    let first = hil.status().tick;
    std::thread::sleep(Duration::from_millis(1600));
    ARMED.store(false, Ordering::SeqCst);
    let counted = ALLOCATIONS.load(Ordering::SeqCst);
    let ticks = hil.status().tick;
    assert!(hil.wait(Duration::from_secs(10)), "{name}");
    let out = hil.finish().unwrap();
    drop(facility);
    // ran to its end (a busy machine's late ticks may make it `unfaithful`; not this test's subject)
    assert_eq!(
        out.metrics["stop"]["kind"], "completed",
        "{name}: {}",
        out.metrics["reason"]
    );
    let expected = (1.5 / period) as u64;
    assert!(ticks > expected, "{name}: the loop ran only {ticks} ticks");
    // armed as soon as this thread saw the loop running: within a few ticks on an idle
    // machine; a busy one may wake this thread late, and 0.1 s still arms it well before the
    // first collision (0.27 s) — a bound that cannot flake
    assert!(
        first as f64 * period <= 0.1,
        "{name}: armed only after tick {first}"
    );
    assert!(!out.metrics["collisions"].as_array().unwrap().is_empty());
    assert_eq!(counted, 0, "{name}: {counted} allocations while running");
}

#[test]
fn loop_writer_and_emulator_do_not_allocate_with_any_device() {
    assert_no_allocation("RDT x EGM", 0.001, loopback_options());
    assert_no_allocation("SRI x EGM", 0.001, loopback_sri_options());
    // the RSI cycle paces the loop
    assert_no_allocation("RDT x RSI", 0.004, rsi_loopback_options());
}
