//! `pida` on the frictional presets, per collision (issue 22):
//! `cargo +stable run --profile fast -p hilcontact-core --example pida_presets [preset|all] [delay_s ...] [trace=N]`
//! (`trace=N`: every other tick of collision N, pida's view and wrench).
//!
//! `rod-in-frame` and `probe-drogue` with 0.2 N sensor noise, 5 ms sensor delay and `pida` at
//! 10 and 20 ms robot delay (the target rows). For each collision matched to a
//! reference collision, one row:
//! - `v%`, `CoV`, `CoF`, `Jt%`, `Jn%`: the metrics' own rebound velocity vector error, CoV, CoF,
//!   tangential and normal impulse errors;
//! - `E%`: the energy after the collision (at its rebound time) against the reference's after
//!   its collision at the same time, % (target ≤ 5); `ms`, `msref`: the collision's duration
//!   and the reference's; `Jn app%`: the normal impulse error of the wrench the virtual
//!   dynamics felt (the metrics' `Jn%` is the robot's physical contact's);
//! - `surf`: the surfaces the facility's true geometry has at the robot's tip over the
//!   collision (most at once), `corner%` the share of contact ticks pida took as a corner;
//! - `n°`: the mean angle (weighted by the true normal force) between the normal pida used and
//!   the facility's true contact normal (the direction of its contact force less its friction),
//!   `n°max` the largest at a tick with more than 20 N;
//! - `μ̂`: pida's friction coefficient at the collision's end (true μ: the scenario's), `μapp`
//!   the ratio Σ|F_t|/ΣF_n of the wrench the virtual dynamics felt (about the true normal),
//!   `μref` the reference's;
//! - `k̂`, `ĉ` at the collision's end against the facility's law along the true normal, fitted
//!   over the collision from the robot's tip and the true normal force (`k`, `c`: no noise,
//!   no delay);
//! - `Wα`: the energy the controller's F_α dissipated over the collision, J; `Wf`, `Wfref`: the
//!   friction work of the applied wrench on the virtual tip's sliding and the reference's, J;
//!   `Fα/Fn`: the most negative F_α·n over F_comp·n in the contact (−1: F_α cancels the normal
//!   force).

#[path = "../tests/common/mod.rs"]
mod common;

use std::sync::{Arc, Mutex};

use hilcontact_core::compensator::{
    Compensator, CompensatorConfig, CompensatorInput, CompensatorOutput, ContactView, Pida,
};
use hilcontact_core::frames::FrameWrench;
use hilcontact_core::hil::compensator_context;
use hilcontact_core::sim::simulate_plan_with_compensator;
use hilcontact_core::world::{GeometryPrior, PRIOR_SURFACES};
use hilcontact_core::Scenario;
use nalgebra::{Matrix3, Vector3};

/// One tick of `pida`: its input, output, view and F_α.
#[derive(Clone, Copy)]
struct Tick {
    input: CompensatorInput,
    output: CompensatorOutput,
    view: Option<(ContactView, FrameWrench)>,
}

/// `pida` recording every tick.
struct Recorder {
    inner: Pida,
    log: Arc<Mutex<Vec<Tick>>>,
}

impl Compensator for Recorder {
    fn step(&mut self, input: &CompensatorInput) -> CompensatorOutput {
        let output = self.inner.step(input);
        self.log.lock().expect("log").push(Tick {
            input: *input,
            output,
            view: self.inner.last_tick(),
        });
        output
    }
    fn reset(&mut self) {
        self.inner.reset();
    }
    fn estimates_contact(&self) -> bool {
        true
    }
    fn observes_energy(&self) -> bool {
        true
    }
}

fn preset(name: &str) -> Scenario {
    let dir = format!(
        "{}/../../python/hilcontact/scenarios",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(format!("{dir}/{name}.toml")).expect("preset");
    let mut s: Scenario = toml::from_str(&text).expect("parse");
    for shape in s
        .target
        .shapes
        .iter_mut()
        .chain(s.servicer.shapes.iter_mut())
    {
        if shape.file.is_empty() {
            continue;
        }
        let file = std::mem::take(&mut shape.file);
        common::read_obj(&format!("{dir}/{file}"), shape);
    }
    s
}

fn column(table: &hilcontact_core::sim::Table, name: &str) -> Vec<f64> {
    table.column(name).expect(name).to_vec()
}

fn interp(t: f64, ts: &[f64], ys: &[f64]) -> f64 {
    let i = ts.partition_point(|x| *x < t).clamp(1, ts.len() - 1);
    let (t0, t1) = (ts[i - 1], ts[i]);
    let w = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
    ys[i - 1] + w.clamp(0.0, 1.0) * (ys[i] - ys[i - 1])
}

/// Least squares `F = k·d + c·ḋ + b`: (k, c).
fn law(rows: &[(f64, f64, f64)]) -> (f64, f64) {
    let mut a = Matrix3::zeros();
    let mut y = Vector3::zeros();
    for &(d, v, f) in rows {
        let h = Vector3::new(d, v, 1.0);
        a += h * h.transpose();
        y += h * f;
    }
    a.try_inverse().map_or((f64::NAN, f64::NAN), |i| {
        let x = i * y;
        (x[0], x[1])
    })
}

fn run(name: &str, delay: f64, trace: Option<usize>) {
    let mut s = preset(name);
    s.facility.sensor_noise = 0.2;
    s.facility.sensor_delay = 0.005;
    s.facility.robot_delay = delay;
    s.compensator = CompensatorConfig::from_kind("pida").expect("pida");
    let plan = s.resolve().expect("plan");
    let context = compensator_context(&plan);
    let CompensatorConfig::Pida(p) = &plan.compensator else {
        unreachable!()
    };
    let log = Arc::new(Mutex::new(Vec::new()));
    let recorder = Recorder {
        inner: Pida::new(p, &context),
        log: log.clone(),
    };
    let (out, rows) = simulate_plan_with_compensator(&plan, Box::new(recorder), true);
    let log = log.lock().expect("log");
    assert_eq!(log.len(), rows.len(), "one compensator tick per row");
    let m = &out.metrics;
    let truth = GeometryPrior {
        system: plan.system.clone(),
        ..(*context.geometry.clone().expect("a frictional preset")).clone()
    };
    let mu = s.contact.friction.kinetic_coefficient;
    let (t_r, e_r, w_r) = (
        column(&out.reference, "time"),
        column(&out.reference, "energy"),
        column(&out.reference, "friction_work"),
    );
    let f_r: Vec<Vector3<f64>> = (0..t_r.len())
        .map(|i| {
            let c = |a: &str| out.reference.column(a).expect(a)[i];
            Vector3::new(
                c("contact_force_x"),
                c("contact_force_y"),
                c("contact_force_z"),
            )
        })
        .collect();
    let ff_r: Vec<Vector3<f64>> = (0..t_r.len())
        .map(|i| {
            let c = |a: &str| out.reference.column(a).expect(a)[i];
            Vector3::new(
                c("friction_force_x"),
                c("friction_force_y"),
                c("friction_force_z"),
            )
        })
        .collect();
    println!(
        "### {name}, pida, {:.0} ms (0.2 N, 5 ms sensor delay; μ {mu}, k {:.0} N/m, c {:.0} N·s/m per point): status {:?}, lost {:?}, extra {:?}",
        delay * 1e3,
        s.contact.stiffness,
        s.contact.damping,
        m.status,
        m.lost_collisions,
        m.extra_collisions
    );
    println!("| # | t s | v% | CoV | CoF | Jt% | Jn% | E% | ms | msref | Jn app% | surf | corner% | n° | n°max | μ̂ | μapp | μref | k̂ | k | ĉ | c | Wα J | Wf J | Wfref J | Fα/Fn |");
    println!("|{}", "---|".repeat(26));
    let period = plan.period;
    for (i, c) in m.collisions.iter().enumerate() {
        let Some(r) = c.reference.and_then(|r| m.reference_collisions.get(r - 1)) else {
            continue;
        };
        let (t0, t1) = (c.collision.start - 0.005, c.collision.end + 0.005);
        let ticks: Vec<usize> = (0..rows.len())
            .filter(|&k| rows[k].time >= t0 && rows[k].time <= t1)
            .collect();
        if trace == Some(i + 1) {
            print_trace(&ticks, &rows, &log);
        }
        let (mut surfaces, mut corner, mut in_contact) = (0usize, 0usize, 0usize);
        let (mut angle_w, mut weight, mut angle_max) = (0.0, 0.0, 0.0f64);
        let (mut f_t, mut f_n) = (0.0, 0.0);
        let (mut w_alpha, mut w_f, mut ratio) = (0.0, 0.0, 0.0f64);
        let mut samples = Vec::new();
        let (mut mu_hat, mut k_hat, mut c_hat) = (f64::NAN, f64::NAN, f64::NAN);
        for &k in &ticks {
            let row = &rows[k];
            let tick = &log[k];
            let normal_force = row.contact_force - row.friction_force; // on the rod
            let n_true = -normal_force.try_normalize(1e-9).unwrap_or_default(); // into the wall
            let mut normals = [Vector3::zeros(); PRIOR_SURFACES];
            surfaces = surfaces.max(truth.normals_at(
                &row.actual_tip_position,
                &row.actual_orientation,
                &mut normals,
            ));
            let applied = tick.output.applied.force; // on the frame, t
            let v = tick.input.tip_velocity_desired;
            if let Some((view, alpha)) = tick.view {
                w_alpha += alpha.force.dot(&v) * period;
                if view.in_contact {
                    in_contact += 1;
                    corner += view.corner as usize;
                    mu_hat = view.friction;
                    k_hat = view.stiffness;
                    c_hat = view.damping;
                    let fn_true = normal_force.norm();
                    if fn_true > 1.0 {
                        let a = view
                            .normal
                            .dot(&n_true)
                            .clamp(-1.0, 1.0)
                            .acos()
                            .to_degrees();
                        angle_w += a * fn_true;
                        weight += fn_true;
                        if fn_true > 20.0 {
                            angle_max = angle_max.max(a);
                        }
                    }
                    let f_comp_n = (applied - alpha.force).dot(&view.normal);
                    if f_comp_n > 1.0 {
                        ratio = ratio.min(alpha.force.dot(&view.normal) / f_comp_n);
                    }
                }
            }
            if n_true != Vector3::zeros() {
                let fa_n = applied.dot(&n_true);
                f_n += fa_n.max(0.0);
                f_t += (applied - n_true * fa_n).norm();
                w_f += (applied - n_true * fa_n).dot(&(v - n_true * v.dot(&n_true))) * period;
                let fn_true = normal_force.norm();
                if fn_true > 5.0 {
                    samples.push((
                        row.actual_tip_position.dot(&n_true),
                        row.actual_tip_velocity.dot(&n_true),
                        fn_true,
                    ));
                }
            }
        }
        // the true law along each tick's normal: positions along a fixed direction (the
        // collision's mean normal) would mix in the sliding
        let (k_true, c_true) = law(&samples);
        let (mut fr_t, mut fr_n) = (0.0, 0.0);
        let q: Vec<usize> = (0..t_r.len())
            .filter(|&k| t_r[k] >= r.start - 0.005 && t_r[k] <= r.end + 0.005)
            .collect();
        for &k in &q {
            let n = f_r[k] - ff_r[k];
            fr_n += n.norm();
            fr_t += ff_r[k].norm();
        }
        // the normal impulses about the reference's mean normal: the wrench the virtual
        // dynamics felt (on the rod) against the reference's
        let j_ref: Vector3<f64> = q.iter().map(|&k| f_r[k]).sum::<Vector3<f64>>() * period;
        let n_mean = q
            .iter()
            .map(|&k| f_r[k] - ff_r[k])
            .sum::<Vector3<f64>>()
            .normalize();
        let j_app: Vector3<f64> = -ticks
            .iter()
            .map(|&k| log[k].output.applied.force)
            .sum::<Vector3<f64>>()
            * period;
        let w_fref = q.last().map_or(0.0, |&l| w_r[l] - w_r[q[0]]);
        let energy = c.rebound_time.map_or(f64::NAN, |after| {
            let t_h: Vec<f64> = rows.iter().map(|r| r.time).collect();
            let e_h: Vec<f64> = rows.iter().map(|r| r.energy).collect();
            let e_ref = interp(after, &t_r, &e_r);
            100.0 * (interp(after, &t_h, &e_h) - e_ref) / e_ref
        });
        let pct = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{:.1}", 100.0 * x));
        let num = |x: Option<f64>| x.map_or("-".to_string(), |x| format!("{x:.3}"));
        println!(
            "| {} | {:.2} | {} | {} | {} | {} | {} | {:.1} | {:.0} | {:.0} | {:.1} | {} | {:.0} | {:.1} | {:.1} | {:.3} | {:.3} | {:.3} | {:.0} | {:.0} | {:.0} | {:.0} | {:.4} | {:.4} | {:.4} | {:.2} |",
            i + 1,
            c.collision.start,
            pct(c.velocity_error),
            num(c.cov),
            num(c.cof),
            pct(c.tangential_impulse_error),
            pct(c.normal_impulse_error),
            energy,
            1e3 * (c.collision.end - c.collision.start),
            1e3 * (r.end - r.start),
            100.0 * (j_app.dot(&n_mean) - j_ref.dot(&n_mean)) / j_ref.dot(&n_mean),
            surfaces,
            100.0 * corner as f64 / in_contact.max(1) as f64,
            angle_w / weight,
            angle_max,
            mu_hat,
            f_t / f_n,
            fr_t / fr_n,
            k_hat,
            k_true,
            c_hat,
            c_true,
            w_alpha,
            w_f,
            w_fref,
            ratio
        );
    }
    println!();
}

/// Every other tick of a collision: pida's view and wrench against the facility's contact.
fn print_trace(ticks: &[usize], rows: &[hilcontact_core::hil::HilRecord], log: &[Tick]) {
    for &k in ticks.iter().step_by(2) {
        let (row, tick) = (&rows[k], &log[k]);
        let Some((view, alpha)) = tick.view else {
            continue;
        };
        let n = view.normal;
        let a = tick.output.applied.force;
        let v = tick.input.tip_velocity_desired;
        let v_t = v - n * v.dot(&n);
        let a_t = a - n * a.dot(&n);
        let phys = row.contact_force - row.friction_force;
        println!(
            "{:.3} in {} fr {} cor {} μ̂ {:.3} n·n_true {:.4} A·n {:7.1} |A_t| {:5.1} A_t·v̂_t {:6.1} |v_t| {:5.2}mm/s Fα·n {:7.1} Fphys {:6.1} Ffric {:5.1} M {:6.2} {:6.2} {:6.2}",
            row.time,
            view.in_contact as u8,
            view.frictional as u8,
            view.corner as u8,
            view.friction,
            -n.dot(&phys.try_normalize(1e-9).unwrap_or_default()),
            a.dot(&n),
            a_t.norm(),
            a_t.dot(&v_t.try_normalize(1e-9).unwrap_or_default()),
            1e3 * v_t.norm(),
            alpha.force.dot(&n),
            phys.norm(),
            row.friction_force.norm(),
            tick.output.applied.moment.x,
            tick.output.applied.moment.y,
            tick.output.applied.moment.z,
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let names: Vec<&str> = match args.first().map(String::as_str) {
        None | Some("all") => vec!["rod-in-frame", "probe-drogue"],
        Some(name) => vec![name],
    };
    let trace = args
        .iter()
        .find_map(|a| a.strip_prefix("trace="))
        .map(|n| n.parse().expect("trace=collision number"));
    let delays: Vec<f64> = if args.len() > 1 {
        args[1..]
            .iter()
            .filter(|a| !a.starts_with("trace="))
            .map(|d| d.parse().expect("delay, s"))
            .collect()
    } else {
        vec![0.01, 0.02]
    };
    for name in names {
        for &delay in &delays {
            run(name, delay, trace);
        }
    }
}
