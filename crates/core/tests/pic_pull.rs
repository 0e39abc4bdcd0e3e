//! `pic`'s `pull` option: eq. (22) as written, `F_comp = F_act + F_err`, against the default
//! no-pull clamp (`compensator/force.rs`), over random contact views and robot lags.

use hilcontact_core::compensator::{
    compensate_force, compensate_force_pulling, CompensatorInput, ContactView,
};
use hilcontact_core::frames::FrameWrench;
use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;

fn vector(range: f64) -> impl Strategy<Value = Vector3<f64>> {
    prop::array::uniform3(-range..range).prop_map(Vector3::from)
}

fn view(force: Vector3<f64>, stiffness: f64, damping: f64) -> ContactView {
    let e = force.normalize();
    ContactView {
        in_contact: true,
        direction: e,
        force,
        moment: Vector3::new(0.1, -0.2, 0.3),
        stiffness,
        damping,
        normal: e,
        frictional: false,
        friction: 0.0,
        corner: false,
    }
}

fn input(
    p_act: Vector3<f64>,
    lag: Vector3<f64>,
    v_act: Vector3<f64>,
    dv: Vector3<f64>,
) -> CompensatorInput {
    CompensatorInput {
        measured: FrameWrench::default(),
        tip_position_actual: p_act,
        tip_velocity_actual: v_act,
        orientation_actual: None,
        tip_position_desired: p_act + lag,
        tip_velocity_desired: v_act + dv,
        motion_desired: None,
        tip_mobility: Matrix3::zeros(),
        fresh: true,
    }
}

proptest! {
    /// Unclamped, the force along e is exactly F_act·e + k̂·Δp_err + ĉ·Δv_err (eqs. 21-24) and
    /// stays along e; clamped, it is that value's positive part. Where the value is positive
    /// the two are identical, moment included.
    #[test]
    fn pulling_is_eq_22_unclamped_and_the_default_its_positive_part(
        f in vector(200.0).prop_filter("a force", |f| f.norm() > 1.0),
        k in 1e3..2e5f64,
        c in 0.0..500.0f64,
        p_act in vector(1.0),
        lag in vector(0.01),
        v_act in vector(0.1),
        dv in vector(0.1),
    ) {
        let view = view(f, k, c);
        let input = input(p_act, lag, v_act, dv);
        let origin = Vector3::new(0.0, 0.0, -0.15);
        let e = view.direction;
        let along = f.dot(&e) + k * lag.dot(&e) + c * dv.dot(&e);
        let pulled = compensate_force_pulling(&view, &input, &origin);
        let clamped = compensate_force(&view, &input, &origin);
        let scale = f.norm() + k * 0.02 + c * 0.2;
        prop_assert!((pulled.force - e * along).norm() <= 1e-9 * scale, "{:?} vs {along}", pulled.force);
        prop_assert!((clamped.force - e * along.max(0.0)).norm() <= 1e-9 * scale);
        if along >= 0.0 {
            prop_assert_eq!(pulled, clamped);
        } else {
            prop_assert!(pulled.force.dot(&e) < 0.0 && clamped.force == Vector3::zeros());
        }
        // eqs. (27), (28) with the force actually applied
        let moment = view.moment + lag.cross(&pulled.force) + (p_act - origin).cross(&pulled.error);
        prop_assert!((pulled.moment - moment).norm() <= 1e-9 * scale * 2.0);
    }
}

/// Out of contact both give F_act, M_act.
#[test]
fn out_of_contact_both_pass_the_measurement_through() {
    let mut v = view(Vector3::new(1.0, 0.0, 0.0), 8e4, 130.0);
    v.in_contact = false;
    let i = input(
        Vector3::zeros(),
        Vector3::new(-0.01, 0.0, 0.0),
        Vector3::zeros(),
        Vector3::zeros(),
    );
    let origin = Vector3::zeros();
    let pulled = compensate_force_pulling(&v, &i, &origin);
    assert_eq!(pulled, compensate_force(&v, &i, &origin));
    assert_eq!(pulled.force, v.force);
}
