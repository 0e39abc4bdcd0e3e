//! The real-time calibration's loop thread (`hil-rt`, `hilcontact calibrate` over the device
//! links) never allocates once running: a counting global allocator counts the allocations of
//! that one thread (found by its name in `/proc/self/task`, compared by kernel thread id, so
//! the allocator itself calls nothing that allocates), armed once the loop runs (after the
//! links connected) until the wall's progress line arrives: the excitation, the robot's
//! response handed to the fitting thread, then a whole wall (moves, approaches, presses,
//! dwells with their oscillation, retreats, the wall's fit handed off and its result taken
//! back), against the emulated facility on loopback in this process; the fitting and the
//! progress threads (which allocate) run beside it. And a procedure that stops itself (a wall
//! not where the scenario says) allocates nothing either, from its stop through backing out
//! until the loop holds: its reason is kept as numbers and formatted after the loop ended.
#![cfg(target_os = "linux")]

mod common;
mod thread_alloc;

use thread_alloc::{threads_named, ALLOCATIONS, ARMED, WATCHED_TID};

use std::sync::atomic::Ordering;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use common::{loopback_options, preset};
use hilcontact_core::Scenario;
use hilcontact_rt::calibrate::{CalibrateOptions, CalibrationHandle, RealtimeCalibration};
use hilcontact_rt::FacilityHandle;

/// The counter and the watched thread are the process's: one test at a time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// paper-table1's front wall alone, mounted off nominal, a noisy and delayed sensor, a robot
/// of finite repeatability (as tests/calibrate_realtime.rs).
fn one_wall() -> Scenario {
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
    s
}

/// Starts the facility and the calibration; once the loop runs, watches its thread and arms
/// the counter. Returns both handles, the start instant and the loop's tick when armed.
fn start_armed(
    s: &Scenario,
    options: &CalibrateOptions,
) -> (FacilityHandle, CalibrationHandle, Instant, u64) {
    ALLOCATIONS.store(0, Ordering::SeqCst);
    let (emu, rt) = loopback_options();
    let facility = FacilityHandle::start(s, &emu).unwrap();
    let handle = CalibrationHandle::start(s, &rt, options, "now").unwrap();
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
    (facility, handle, begun, first)
}

/// Disarms the counter, then waits for the loop's end and stops the facility. Returns the
/// allocations counted, the ticks armed (from `first`) and the calibration's result.
fn disarm_and_finish(
    facility: FacilityHandle,
    handle: CalibrationHandle,
    first: u64,
) -> (u64, u64, RealtimeCalibration) {
    ARMED.store(false, Ordering::SeqCst);
    let counted = ALLOCATIONS.load(Ordering::SeqCst);
    let ticks = handle.status().tick - first;
    assert!(
        handle.wait(Duration::from_secs(120)),
        "the loop did not end"
    );
    let out = handle.finish().unwrap();
    drop(facility);
    (counted, ticks, out)
}

/// The procedure's options: a 2 × 2 grid and its centre, a 2 s excitation.
fn short() -> CalibrateOptions {
    CalibrateOptions {
        points_per_side: 2,
        excitation_duration: 2.0,
        ..CalibrateOptions::default()
    }
}

#[test]
fn the_real_time_calibration_s_loop_does_not_allocate_over_a_wall() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let s = one_wall();
    let (facility, handle, begun, first) = start_armed(&s, &short());
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
    let (counted, ticks, out) = disarm_and_finish(facility, handle, first);
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

#[test]
fn the_real_time_calibration_s_loop_does_not_allocate_as_the_procedure_stops_itself() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    // the front wall 4 mm farther than the scenario says: the first probe searches 2 mm past
    // the nominal plane, finds nothing, and the procedure stops itself, backs out and ends
    let mut s = one_wall();
    s.facility.mount_offset = [0.004, 0.0, 0.0];
    let (facility, handle, begun, first) = start_armed(&s, &short());
    // armed until the loop leaves `running`: the procedure stopped, backed out of the search,
    // waited out a loop delay and ended; the loop then holds the robot
    while handle.status().phase == "running" && !handle.is_finished() {
        assert!(
            begun.elapsed() < Duration::from_secs(240),
            "the procedure did not stop in 240 s"
        );
        std::thread::sleep(Duration::from_micros(500));
    }
    let (counted, ticks, out) = disarm_and_finish(facility, handle, first);
    println!("{ticks} ticks armed: {:?}", out.outcome.error);
    // the procedure stopped itself (not the loop's safety) with its reason, released
    let error = out.outcome.error.clone().expect("stopped");
    assert!(error.contains("'front' was not found"), "{error}");
    assert!(error.contains("probe 1 of 5"), "{error}");
    assert_eq!(out.exit_code, 1);
    assert_eq!(
        out.stop.kind.exit_code(),
        0,
        "the loop ran to the procedure's end"
    );
    assert!(out.outcome.final_force < 5.0, "{}", out.outcome.final_force);
    // the window spanned the excitation and the search (2 mm standoff, 2 mm past the plane)
    let period = s.resolve().unwrap().period;
    assert!(
        ticks as f64 * period > short().excitation_duration,
        "armed {ticks} ticks"
    );
    assert_eq!(
        counted, 0,
        "{counted} allocations on the calibration's loop thread in {ticks} ticks, up to its self-stop's hold"
    );
}
