//! The real-time calibration's loop thread (`hil-rt`, `hilcontact calibrate` over the device
//! links) never allocates once running: a counting global allocator counts the allocations of
//! that one thread (found by its name in `/proc/self/task`, compared by kernel thread id, so
//! the allocator itself calls nothing that allocates), armed once the loop runs (after the
//! links connected) until the wall's progress line arrives: the excitation, the robot's
//! response handed to the fitting thread, then a whole wall (moves, approaches, presses,
//! dwells with their oscillation, retreats, the wall's fit handed off and its result taken
//! back), against the emulated facility on loopback in this process; the fitting and the
//! progress threads (which allocate) run beside it.
#![cfg(target_os = "linux")]

mod common;
mod thread_alloc;

use thread_alloc::{threads_named, ALLOCATIONS, ARMED, WATCHED_TID};

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use common::{loopback_options, preset};
use hilcontact_rt::calibrate::{CalibrateOptions, CalibrationHandle};
use hilcontact_rt::FacilityHandle;

#[test]
fn the_real_time_calibration_s_loop_does_not_allocate_over_a_wall() {
    // paper-table1's front wall alone, mounted off nominal, a noisy and delayed sensor, a
    // robot of finite repeatability (as tests/calibrate_realtime.rs)
    let mut s = preset("paper-table1");
    s.walls.truncate(1);
    let f = &mut s.facility;
    f.robot_delay = 0.02;
    f.sensor_delay = 0.005;
    f.sensor_noise = 0.2;
    f.robot_repeatability = 3e-5;
    f.mount_offset = [0.0003, -0.0004, 0.0];
    f.mount_rotation = [0.0, 0.3, 0.4];
    f.stiffness_error = 1.07;
    f.seed = 21;
    let options = CalibrateOptions {
        points_per_side: 2,
        excitation_duration: 2.0,
        ..CalibrateOptions::default()
    };
    let (emu, rt) = loopback_options();
    let facility = FacilityHandle::start(&s, &emu).unwrap();
    let handle = CalibrationHandle::start(&s, &rt, &options, "now").unwrap();
    let begun = Instant::now();
    // the thread names itself as it starts
    let tids = loop {
        let tids = threads_named("hil-rt");
        if !tids.is_empty() || begun.elapsed() > Duration::from_secs(60) {
            break tids;
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    assert_eq!(tids.len(), 1, "one loop thread: {tids:?}");
    WATCHED_TID.store(tids[0], Ordering::SeqCst);
    while handle.status().phase != "running" {
        assert!(
            begun.elapsed() < Duration::from_secs(60),
            "the loop never ran"
        );
        assert!(!handle.is_finished(), "the loop ended before running");
        std::thread::sleep(Duration::from_micros(200));
    }
    ARMED.store(true, Ordering::SeqCst);
    let first = handle.status().tick;
    // armed until the wall's line (the robot's line comes first)
    let mut lines = Vec::new();
    while !lines.iter().any(|l: &String| l.contains("'front'")) {
        assert!(
            begun.elapsed() < Duration::from_secs(240),
            "no wall measured in 240 s: {lines:?}"
        );
        if handle.is_finished() {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
        lines.extend(handle.progress());
    }
    ARMED.store(false, Ordering::SeqCst);
    let counted = ALLOCATIONS.load(Ordering::SeqCst);
    let ticks = handle.status().tick - first;
    assert!(
        handle.wait(Duration::from_secs(120)),
        "the loop did not end"
    );
    let out = handle.finish().unwrap();
    drop(facility);
    println!("{ticks} ticks armed: {:?}", out.outcome.progress);
    // the window spanned the whole calibration of the wall, which was measured
    assert_eq!(out.exit_code, 0, "{:?}", out.outcome.error);
    assert_eq!(out.outcome.progress.len(), 2, "{:?}", out.outcome.progress);
    assert!(
        lines.iter().any(|l| l.contains("'front': 5 probes")),
        "{lines:?}"
    );
    let wall_ticks = (out.outcome.wall_seconds[0] / s.resolve().unwrap().period) as u64;
    assert!(
        ticks >= wall_ticks,
        "armed {ticks} ticks, the wall took {wall_ticks}"
    );
    assert_eq!(
        counted, 0,
        "{counted} allocations on the calibration's loop thread in {ticks} ticks"
    );
}
