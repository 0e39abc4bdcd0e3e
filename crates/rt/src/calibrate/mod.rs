//! `hilcontact calibrate`: the facility's hardware measured with its own robot before a run
//! (docs/calibration.md): each wall's plane, the contact law and the robot's delay, written as
//! a calibration file ([`hilcontact_core::calibration::CalibrationFile`]) that `model-mediated`
//! takes as its prior geometry and law.
//!
//! - [`procedure`]: the procedure as a tick-by-tick state machine (no device, no clock);
//! - [`options`]: its options;
//! - [`simulate`]: the procedure against the plan's simulated facility (the facility model of
//!   the true hardware: `facility.mount_*`, `robot_repeatability`, `stiffness_error`), as fast
//!   as it computes;
//! - [`realtime`]: the procedure in real time over the device links, as `hil`'s loop's driver.

pub mod options;
pub mod procedure;
pub mod realtime;

use hilcontact_core::calibration::{
    CalibratedLaw, CalibratedRobot, CalibratedWall, CalibrationFile, CalibrationInfo, FitForm,
    SurfaceFit,
};
use hilcontact_core::contact::{ContactModel, ContactModelKind};
use hilcontact_core::facility::FacilityLoop;
use hilcontact_core::Plan;

pub use options::CalibrateOptions;
pub use procedure::{FitDone, FitJob, Procedure, Progress, Step, StopReason, WallSummary};
pub use realtime::{CalibrationHandle, RealtimeCalibration};

/// Longest a calibration may take per wall, s, beyond the excitation (a bound of the
/// simulation's loop; the procedure itself ends far earlier).
const MAX_SECONDS_PER_WALL: f64 = 600.0;

/// What a calibration gives: the file, or the reason it stopped (with the contact released
/// and the robot holding).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationOutcome {
    /// The calibration, when every wall was measured.
    pub file: Option<CalibrationFile>,
    /// Why it stopped early.
    pub error: Option<String>,
    /// The progress lines, surface by surface.
    pub progress: Vec<String>,
    /// Simulated (or real) time the procedure took, s.
    pub duration: f64,
    /// Time spent on each wall measured, s.
    pub wall_seconds: Vec<f64>,
    /// Largest physical contact force the hardware felt, N (simulation only).
    pub peak_force: f64,
    /// The physical contact force at the end, N (0: released).
    pub final_force: f64,
}

/// Runs the procedure against the plan's simulated facility (its true hardware), tick by
/// tick, and builds the calibration file. `on_progress` gets each progress line as it comes.
pub fn simulate(
    plan: &Plan,
    options: &CalibrateOptions,
    force_limit: f64,
    measured_at: &str,
    mut on_progress: impl FnMut(&str),
) -> Result<CalibrationOutcome, String> {
    let mut procedure = Procedure::new(plan, options, force_limit)?;
    let mut facility = FacilityLoop::new(plan);
    let mut command = plan.nominal.relative_motion(&plan.initial);
    let max_ticks = ((options.excitation_duration
        + 10.0
        + MAX_SECONDS_PER_WALL * plan.nominal.contact.walls.len() as f64)
        / plan.period) as u64;
    let mut progress = Vec::new();
    let mut wall_seconds = Vec::new();
    let mut peak_force: f64 = 0.0;
    let mut ticks = 0u64;
    let names = procedure.wall_names();
    loop {
        let m = facility.tick(&command);
        peak_force = peak_force.max(facility.contact_force().norm());
        ticks += 1;
        let step = procedure.step(&m);
        procedure.fit_inline();
        procedure.drain_events(|event| {
            if let Progress::Wall { spent, .. } = event {
                wall_seconds.push(spent);
            }
            let line = describe(&event, &names);
            on_progress(&line);
            progress.push(line);
        });
        match step {
            Step::Command(c) => command = c,
            Step::Done => break,
        }
        if ticks > max_ticks {
            return Err(format!(
                "the calibration did not finish in its time bound ({})",
                procedure.whereabouts()
            ));
        }
    }
    let duration = ticks as f64 * plan.period;
    let final_force = facility.contact_force().norm();
    let file = match procedure.error() {
        Some(_) => None,
        None => Some(calibration_file(
            plan,
            &procedure,
            options,
            force_limit,
            "simulated",
            measured_at,
            duration,
        )?),
    };
    Ok(CalibrationOutcome {
        file,
        error: procedure.error(),
        progress,
        duration,
        wall_seconds,
        peak_force,
        final_force,
    })
}

/// One progress line; `names`: the walls' names, in the scenario's order.
pub fn describe(event: &Progress, names: &[String]) -> String {
    match event {
        Progress::Robot {
            response: r,
            noise,
            detect_force: detect,
        } => {
            let servo = if r.servo_frequency > 0.0 {
                format!(
                    ", servo lag {:.1} Hz (ζ {:.2})",
                    r.servo_frequency, r.servo_damping
                )
            } else {
                String::new()
            };
            format!(
                "robot: delay {:.1} ms{servo}; sensor noise {:.3} N, contact detected above {:.2} N",
                r.delay * 1e3,
                noise,
                detect
            )
        }
        Progress::Wall {
            index: i,
            fit,
            spent,
        } => {
            let name = names.get(*i).map_or("?", String::as_str);
            let (k, c) = law_numbers(&fit.law.law);
            format!(
                "wall {} '{name}': {} probes in {:.1} s; point [{:.4}, {:.4}, {:.4}] mm, normal [{:.5}, {:.5}, {:.5}] (±{:.4} mm, ±{:.3}°); k {:.5e} ± {:.2e}, c {:.4} ± {:.2}",
                i + 1,
                fit.probes,
                spent,
                fit.point.x * 1e3,
                fit.point.y * 1e3,
                fit.point.z * 1e3,
                fit.normal.x,
                fit.normal.y,
                fit.normal.z,
                fit.offset_sigma * 1e3,
                fit.angle_sigma.to_degrees(),
                k,
                fit.law.stiffness_sigma,
                c,
                fit.law.damping_sigma
            )
        }
    }
}

fn law_numbers(law: &ContactModel) -> (f64, f64) {
    match law {
        ContactModel::Linear(l) => (l.stiffness, l.damping),
        ContactModel::HuntCrossley(h) => (h.stiffness, h.damping),
    }
}

/// The calibration file of a finished procedure: each wall's plane, the law (the
/// inverse-variance mean of the walls' fits), the robot's response.
pub fn calibration_file(
    plan: &Plan,
    procedure: &Procedure,
    options: &CalibrateOptions,
    force_limit: f64,
    facility: &str,
    measured_at: &str,
    duration: f64,
) -> Result<CalibrationFile, String> {
    let fits: &[SurfaceFit] = &procedure.fits;
    let names = procedure.wall_names();
    if fits.len() != names.len() {
        return Err("not every wall was measured".into());
    }
    let robot = procedure
        .robot()
        .ok_or("the robot's response was not measured")?;
    let radius =
        options.probe_spacing * ((options.points_per_side as f64 - 1.0) / 2.0) * 2f64.sqrt();
    let walls = fits
        .iter()
        .zip(&names)
        .map(|(f, name)| CalibratedWall {
            name: name.clone(),
            point: f.point.into(),
            normal: f.normal.into(),
            offset_sigma: f.offset_sigma,
            angle_sigma: f.angle_sigma.to_degrees().min(90.0),
            radius,
            probes: f.contact_points.len() as u32,
            rms: f.rms,
        })
        .collect();
    // inverse-variance means of the walls' law parameters
    let mean = |value: &dyn Fn(&SurfaceFit) -> (f64, f64)| {
        let (mut sum, mut weights) = (0.0, 0.0);
        for f in fits {
            let (x, sigma) = value(f);
            let w = 1.0 / sigma.max(1e-12 * x.abs().max(1e-300)).powi(2);
            sum += w * x;
            weights += w;
        }
        (sum / weights, (1.0 / weights).sqrt())
    };
    let (k, k_sigma) = mean(&|f| (law_numbers(&f.law.law).0, f.law.stiffness_sigma));
    let (c, c_sigma) = mean(&|f| (law_numbers(&f.law.law).1, f.law.damping_sigma.max(1e-9)));
    let (n, n_sigma) = match procedure.form() {
        FitForm::Linear => (1.0, 0.0),
        FitForm::HuntCrossley => mean(&|f| match f.law.law {
            ContactModel::HuntCrossley(h) => (h.exponent, f.law.exponent_sigma.max(1e-9)),
            ContactModel::Linear(_) => (1.0, 1.0),
        }),
    };
    Ok(CalibrationFile {
        measured: CalibrationInfo {
            scenario: plan.name().to_string(),
            at: measured_at.to_string(),
            facility: facility.to_string(),
            version: env!("CARGO_PKG_VERSION").to_string(),
            probes_per_wall: procedure.probes_per_wall(),
            press_force: options.press_force(force_limit),
            duration,
        },
        walls,
        law: CalibratedLaw {
            model: match procedure.form() {
                FitForm::Linear => ContactModelKind::Linear,
                FitForm::HuntCrossley => ContactModelKind::HuntCrossley,
            },
            stiffness: k,
            damping: c.max(0.0),
            exponent: n,
            stiffness_sigma: k_sigma,
            damping_sigma: c_sigma,
            exponent_sigma: n_sigma,
        },
        robot: CalibratedRobot {
            delay: robot.delay.max(0.0),
            delay_sigma: robot.delay_sigma,
            servo_frequency: robot.servo_frequency,
            servo_damping: robot.servo_damping,
            sensor_delay: plan.sensor_delay(),
        },
    })
}

/// The JSON Schema of the calibration file and of the procedure's options:
/// `{"file": <CalibrationFile>, "options": <CalibrateOptions>}`.
pub fn schema() -> serde_json::Value {
    serde_json::json!({
        "file": schemars::schema_for!(CalibrationFile),
        "options": schemars::schema_for!(CalibrateOptions),
    })
}
