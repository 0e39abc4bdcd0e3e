//! A counting global allocator for one thread (shared by the real-time no-allocation tests
//! that watch a thread other than the test's own): it counts the allocations of the thread whose
//! kernel id is in [`WATCHED_TID`] while [`ARMED`], comparing kernel thread ids so that the
//! allocator itself calls nothing that allocates. A test binary that declares `mod thread_alloc;`
//! gets it as its global allocator.
#![allow(dead_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU64, Ordering};

struct Counting;

/// Whether allocations are counted.
pub static ARMED: AtomicBool = AtomicBool::new(false);
/// Kernel thread id of the watched thread (0: not yet known).
pub static WATCHED_TID: AtomicI32 = AtomicI32::new(0);
/// Allocations (and reallocations) of the watched thread while armed.
pub static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

fn count() {
    if ARMED.load(Ordering::Relaxed)
        && unsafe { libc::gettid() } == WATCHED_TID.load(Ordering::Relaxed)
    {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
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

/// The kernel ids of this process's threads named `name`.
pub fn threads_named(name: &str) -> Vec<i32> {
    std::fs::read_dir("/proc/self/task")
        .unwrap()
        .filter_map(|e| {
            let path = e.ok()?.path();
            let comm = std::fs::read_to_string(path.join("comm")).ok()?;
            (comm.trim_end() == name).then(|| path.file_name()?.to_str()?.parse().ok())?
        })
        .collect()
}
