//! Compensated force and moment for the robot's response delay, eqs. (21)-(24), (27), (28).
//!
//! With e the contact direction (into the wall) and penetrations along e:
//! ```text
//! Δp_err = (p_des − p_act)·e                  (23)
//! Δv_err = (v_des − v_act)·e                  (24)
//! F_err  = (k̂·Δp_err + ĉ·Δv_err)·e           (21)
//! F_comp = F_act + F_err, never pulling (22; `pic`'s `pull` option: unclamped)
//! M_comp = M_act + (p_des − p_act) × F_comp + (p_act − p_s) × F_err   (27), (28)
//! ```
//! On a frictional surface ([`ContactView::frictional`]) the increments are taken along the
//! identified normal n̂ instead of e, and the whole force is scaled (Coulomb friction follows
//! the normal force, in the direction of the robot's sliding):
//! ```text
//! F_n    = F_act·n̂
//! F_comp = F_act·max(0, F_n + k̂·Δp·n̂ + ĉ·Δv·n̂)/F_n
//! ```

use nalgebra::Vector3;

use super::delay::ContactView;
use super::CompensatorInput;

/// The compensated wrench.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompensatedWrench {
    /// F_comp, N.
    pub force: Vector3<f64>,
    /// M_comp about the sensor origin, N·m.
    pub moment: Vector3<f64>,
    /// F_err actually added (after the no-pull clamp), N.
    pub error: Vector3<f64>,
}

/// Eqs. (21)-(24), (27), (28); out of contact F_comp = F_act, M_comp = M_act.
pub fn compensate_force(
    view: &ContactView,
    input: &CompensatorInput,
    sensor_origin: &Vector3<f64>,
) -> CompensatedWrench {
    compensate(view, input, sensor_origin, false)
}

/// [`compensate_force`] without the no-pull clamp: `F_comp = F_act + F_err` as eq. (22) writes
/// it, negative (pulling) when `F_err` outweighs `F_act` (`pic`'s `pull` option).
pub fn compensate_force_pulling(
    view: &ContactView,
    input: &CompensatorInput,
    sensor_origin: &Vector3<f64>,
) -> CompensatedWrench {
    compensate(view, input, sensor_origin, true)
}

/// Eqs. (21)-(24), (27), (28), clamped at zero along the contact direction unless `pull`.
fn compensate(
    view: &ContactView,
    input: &CompensatorInput,
    sensor_origin: &Vector3<f64>,
    pull: bool,
) -> CompensatedWrench {
    if !view.in_contact {
        return CompensatedWrench {
            force: view.force,
            moment: view.moment,
            error: Vector3::zeros(),
        };
    }
    if view.frictional {
        return compensate_frictional(view, input, sensor_origin, pull);
    }
    let e = view.direction;
    let dp = input.tip_position_desired - input.tip_position_actual;
    let dp_err = dp.dot(&e); // (23)
    let dv_err = (input.tip_velocity_desired - input.tip_velocity_actual).dot(&e); // (24)
    let along = view.force.dot(&e) + view.stiffness * dp_err + view.damping * dv_err; // (21), (22)
    let force = e * if pull { along } else { along.max(0.0) };
    let error = force - view.force;
    let moment =
        view.moment + dp.cross(&force) + (input.tip_position_actual - sensor_origin).cross(&error); // (27), (28)
    CompensatedWrench {
        force,
        moment,
        error,
    }
}

/// [`compensate_force`] on a frictional surface: along the identified normal, the whole force
/// scaled.
fn compensate_frictional(
    view: &ContactView,
    input: &CompensatorInput,
    sensor_origin: &Vector3<f64>,
    pull: bool,
) -> CompensatedWrench {
    let n = view.normal;
    let dp = input.tip_position_desired - input.tip_position_actual;
    let dv = input.tip_velocity_desired - input.tip_velocity_actual;
    let f_n = view.force.dot(&n);
    let force = if f_n > 0.0 {
        let along = f_n + view.stiffness * dp.dot(&n) + view.damping * dv.dot(&n);
        view.force * (if pull { along } else { along.max(0.0) } / f_n)
    } else {
        view.force
    };
    let error = force - view.force;
    let moment =
        view.moment + dp.cross(&force) + (input.tip_position_actual - sensor_origin).cross(&error);
    CompensatedWrench {
        force,
        moment,
        error,
    }
}
