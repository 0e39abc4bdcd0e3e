//! `hilcontact calibrate` in real time over the device links, against the emulated facility on
//! loopback (its own threads, real sockets, the wall clock): a single wall mounted off its
//! nominal pose, a noisy and delayed sensor, a robot of finite repeatability; the procedure
//! shortened (a 2 × 2 grid and its centre). The fitted plane, law and delay against the truth;
//! a wall that is not there stops it with the contact released and the robot holding; a safety
//! stop of the loop (the force limit) applies to the procedure's commands as to `hil`'s.

mod common;

use std::time::Duration;

use common::{loopback_options, preset};
use hilcontact_core::contact::ContactModel;
use hilcontact_core::Scenario;
use hilcontact_rt::calibrate::{CalibrateOptions, CalibrationHandle, RealtimeCalibration};
use hilcontact_rt::{EmulatorOptions, FacilityHandle, RuntimeOptions};
use nalgebra::Vector3;

/// paper-table1's front wall alone, on a facility as the target states it: 0.2 N
/// noise, 5 ms sensor delay, repeatability 0.03 mm, hardware 0.5 mm and 0.5° off nominal,
/// k 7 % high; a 20 ms robot delay.
fn one_wall_off_nominal(seed: u64) -> Scenario {
    let mut s = preset("paper-table1");
    s.walls.truncate(1);
    let f = &mut s.facility;
    f.robot_delay = 0.02;
    f.sensor_delay = 0.005;
    f.sensor_noise = 0.2;
    f.robot_repeatability = 3e-5;
    f.mount_offset = [0.0005 * 0.6, -0.0005 * 0.8, 0.0];
    f.mount_rotation = [0.0, 0.3, 0.4]; // 0.5°
    f.stiffness_error = 1.07;
    f.seed = seed;
    s
}

/// The shortened procedure: a 2 × 2 grid and its centre (5 probes), the default elsewhere.
fn short() -> CalibrateOptions {
    CalibrateOptions {
        points_per_side: 2,
        ..CalibrateOptions::default()
    }
}

/// Runs the calibration of `s` with `options` against the emulator on loopback; waits at most
/// `bound` (a generous wall-clock bound: a loaded machine runs the same procedure, only later).
fn calibrate(
    s: &Scenario,
    options: &CalibrateOptions,
    tune: impl FnOnce(&mut EmulatorOptions, &mut RuntimeOptions),
    bound: Duration,
) -> RealtimeCalibration {
    let (mut emu, mut rt) = loopback_options();
    tune(&mut emu, &mut rt);
    let facility = FacilityHandle::start(s, &emu).unwrap();
    let handle = CalibrationHandle::start(s, &rt, options, "now").unwrap();
    let mut lines = Vec::new();
    let start = std::time::Instant::now();
    while !handle.wait(Duration::from_millis(200)) {
        lines.extend(handle.progress());
        assert!(
            start.elapsed() < bound,
            "the calibration took longer than {bound:?}: {lines:?}"
        );
    }
    lines.extend(handle.progress());
    let out = handle.finish().unwrap();
    drop(facility);
    for line in &out.outcome.progress {
        println!("{}: {line}", s.name);
    }
    // every line reached the handle as it came, in order
    assert_eq!(lines, out.outcome.progress);
    out
}

#[test]
fn a_real_time_calibration_over_the_device_links_finds_the_mounted_wall() {
    let s = one_wall_off_nominal(11);
    let out = calibrate(&s, &short(), |_, _| {}, Duration::from_secs(240));
    println!("{}", serde_json::to_string(&out.realtime).unwrap());
    assert_eq!(out.exit_code, 0, "{:?}", out.outcome.error);
    let file = out.outcome.file.clone().expect("a calibration");
    file.check().unwrap();
    assert!(
        file.measured.facility.contains("EGM"),
        "{}",
        file.measured.facility
    );
    // progress: the robot, then the wall
    assert_eq!(out.outcome.progress.len(), 2, "{:?}", out.outcome.progress);
    assert!(out.outcome.progress[1].contains("'front'"));

    let plan = s.resolve().unwrap();
    let truth = &plan.system.contact;
    let (w, true_wall) = (&file.walls[0], &truth.walls[0]);
    let offset = (Vector3::from(w.point) - true_wall.point).dot(&true_wall.normal);
    let angle = Vector3::from(w.normal)
        .dot(&true_wall.normal)
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees();
    let nominal = &plan.nominal.contact.walls[0];
    let nominal_offset = (nominal.point - true_wall.point).dot(&true_wall.normal);
    let k = match truth.law {
        ContactModel::Linear(l) => l.stiffness,
        ContactModel::HuntCrossley(h) => h.stiffness,
    };
    let k_error = file.law.stiffness / k - 1.0;
    println!(
        "plane {:+.4} mm (nominal {:+.4} mm, σ {:.4}), normal {angle:.3}°, k {:+.2} %, c {:.1} N·s/m, delay {:.2} ms (truth {} ms), wall {:?} s",
        offset * 1e3,
        nominal_offset * 1e3,
        w.offset_sigma * 1e3,
        k_error * 1e2,
        file.law.damping,
        file.robot.delay * 1e3,
        plan.robot_delay() * 1e3,
        out.outcome.wall_seconds
    );
    // the bounds where 5 probes meet them: the plane along its normal (0.02 mm), c
    // (20 N·s/m of an undamped contact), the delay (2 ms); the normal from 5 probes 20 mm
    // apart under 0.03 mm repeatability: 0.2° (twice the 0.1°, which the full 17-probe
    // grid meets); k within 5 %, not the 2 %: five probes, one run (over the links k
    // comes out 0.5-1.4 % low on this wall since the fit takes new robot feedback only; it
    // was 1.6-2.6 % low on the poses extrapolated between EGM's 4 ms reports:
    // docs/calibration.md, "Measured, real time")
    assert!(offset.abs() <= 2e-5, "plane off by {} mm", offset * 1e3);
    assert!(angle <= 0.2, "normal off by {angle}°");
    assert!(k_error.abs() <= 0.05, "k off by {} %", k_error * 1e2);
    assert!(file.law.damping <= 20.0, "c {}", file.law.damping);
    assert!((file.robot.delay - plan.robot_delay()).abs() <= 0.002);
    // the loop's units check read the first contact at the robot's reported pose: the
    // measured peak against the law's, the hardware 7 % stiffer than the scenario says (at
    // the pose extrapolated between EGM's reports it read 0.43-0.97 in 17 runs, and a spike
    // of the extrapolation early in a press could stop the calibration for its units, below
    // 1/3: docs/calibration.md, "On a real cell")
    let units = out.realtime["safety"]["units_ratio"]
        .as_f64()
        .expect("decided");
    assert!((0.8..=1.5).contains(&units), "units ratio {units}");
    // the law's samples: a new robot pose each, those with a held force left out
    let pairing = &out.realtime["pairing"];
    let with_pose = pairing["samples_with_new_pose"].as_u64().unwrap();
    let held = pairing["held_forces_left_out"].as_u64().unwrap();
    println!("pairing: {held} of {with_pose} samples with a new pose had a held force");
    assert!(with_pose > 1000 && held < with_pose, "{pairing}");
    // at most 60 s of the loop's time per wall
    assert!(out.outcome.wall_seconds.iter().all(|&t| t <= 60.0));
    // never pressed past the procedure's bound, released at the end
    assert!(out.outcome.peak_force <= short().abort_force(500.0));
    assert!(out.outcome.final_force < 5.0, "{}", out.outcome.final_force);
}

#[test]
fn a_wall_that_is_not_there_stops_the_real_time_calibration_released() {
    let mut s = one_wall_off_nominal(12);
    s.facility.mount_offset = [0.004, 0.0, 0.0]; // the front wall 4 mm farther
    let options = CalibrateOptions {
        excitation_duration: 2.0,
        ..short()
    };
    let out = calibrate(&s, &options, |_, _| {}, Duration::from_secs(120));
    let error = out.outcome.error.clone().expect("stopped");
    assert!(error.contains("'front' was not found"), "{error}");
    assert!(out.outcome.file.is_none());
    assert_eq!(out.exit_code, 1);
    assert_eq!(
        out.stop.kind.exit_code(),
        0,
        "the loop ran to the procedure's end"
    );
    assert!(out.outcome.final_force < 5.0, "{}", out.outcome.final_force);
}

#[test]
fn the_loops_workspace_stops_the_real_time_calibration_as_it_stops_hil() {
    // the loop's workspace 8 mm around the start tip (the procedure's own is 0.3 m): the first
    // probe (5 mm away) runs, the move to the second (15 mm away) is stopped by the loop
    let s = one_wall_off_nominal(13);
    let options = CalibrateOptions {
        excitation_duration: 2.0,
        ..short()
    };
    let out = calibrate(
        &s,
        &options,
        |_, rt| rt.limits.workspace = 0.008,
        Duration::from_secs(120),
    );
    assert_eq!(out.exit_code, 3, "{:?}", out.outcome.error);
    assert_eq!(out.stop.kind, hilcontact_rt::safety::StopKind::Workspace);
    assert!(out.realtime["stop"]["safety_stop"].as_bool().unwrap());
    assert!(out.outcome.file.is_none());
    let error = out.outcome.error.clone().unwrap();
    assert!(error.contains("workspace"), "{error}");
    // the first probe was done and released before the move that was stopped
    assert!(out.outcome.final_force < 5.0, "{}", out.outcome.final_force);
}
