//! `cargo run --release --example axial_torque_audit`: for every compensator and robot delay
//! (4–40 ms) on the presets, how close to rounding the torques of the applied wrenches about the
//! bodies' centres of mass come (`|F × τ|₁ / (ε |F|₁ (|M|₁ + |(s − c) × F|₁))`, for torques
//! below 1e4 such units: the ones `TwoBodySystem::body_wrenches` may take for rounding, up to
//! 128), and the first tick at which either body of the virtual dynamics turns (`None`: never).
use hilcontact_core::compensator::REGISTRY;
use hilcontact_core::facility::FacilityLoop;
use hilcontact_core::hil::VirtualDynamics;
use nalgebra::Vector3;

fn main() {
    for preset in [
        "paper-table1",
        "paper-exp-1.93hz",
        "paper-exp-2.64hz",
        "rod-in-frame",
        "oblique-6dof",
    ] {
        let path = format!(
            "{}/../../python/hilcontact/scenarios/{preset}.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let base: hilcontact_core::Scenario =
            toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        for info in REGISTRY {
            for delay in [0.004, 0.01, 0.02, 0.04] {
                let mut s = base.clone();
                s.facility.robot_delay = delay;
                s.compensator = (info.default)();
                let plan = s.resolve().unwrap();
                let mut virt = VirtualDynamics::new(&plan);
                let mut facility = FacilityLoop::new(&plan);
                let (mut worst, mut n, mut first_nonzero) = (0.0f64, 0, None);
                for k in 0..plan.ticks {
                    let m = facility.tick(&virt.command());
                    let out = virt.compensate(&m);
                    let x = *virt.state();
                    let sys = virt.system();
                    let t = &x.target;
                    let sv = &x.servicer;
                    let force = t.orientation * out.applied.force;
                    let moment = t.orientation * out.applied.moment;
                    let sensor_world = t.position + t.orientation * sys.sensor_origin;
                    let pairs = [
                        (moment, (sensor_world - t.position).cross(&force)),
                        (-moment, -(sensor_world - sv.position).cross(&force)),
                    ];
                    for (a, b) in pairs {
                        let tau = a + b;
                        if tau != Vector3::zeros() && force != Vector3::zeros() {
                            let r = force.cross(&tau).abs().sum()
                                / (f64::EPSILON
                                    * force.abs().sum()
                                    * (a.abs().sum() + b.abs().sum()));
                            if r < 1e4 {
                                worst = worst.max(r);
                                n += 1;
                            }
                        }
                    }
                    if first_nonzero.is_none()
                        && (x.servicer.angular_velocity != Vector3::zeros()
                            || x.target.angular_velocity != Vector3::zeros())
                    {
                        first_nonzero = Some(k);
                    }
                    virt.integrate(&out);
                }
                println!("{preset} {:16} {delay}: {n} near-through-centre torques, worst ratio {worst:.3}, first turning tick {first_nonzero:?}", info.kind);
            }
        }
    }
}
