//! The scene in a recording of a shape scenario: every contact point of the shapes drawn with
//! its own normal and friction arrows where the core puts the contact points, the arrows adding
//! up to the contact force the simulated facility recorded; a walls scenario drawn as before.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use hilcontact_core::frames::RelativeMotion;
use hilcontact_core::hil::HilRecord;
use hilcontact_core::shapes::{BodyShape, ShapeGeometry};
use hilcontact_core::Plan;
use hilcontact_rt::output::mcap::{McapOptions, McapRecorder};
use hilcontact_rt::output::scene::{FORCE_ARROW_SCALE, MAX_SCENE_POINTS, SHAPES};
use hilcontact_rt::output::RunInfo;

fn plan(preset: &str) -> Plan {
    scenario(preset, |_| {}).resolve().expect("plan")
}

/// The preset's scenario, its raw table changed by `edit` first.
fn scenario(preset: &str, edit: impl FnOnce(&mut toml::Table)) -> hilcontact_core::Scenario {
    let path = format!(
        "{}/../../python/hilcontact/scenarios/{preset}.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let mut raw: toml::Table =
        toml::from_str(&std::fs::read_to_string(&path).expect("preset")).expect("toml");
    // a mesh's `file` (an OBJ beside the preset) read into its `vertices` and `triangles`, as
    // hilcontact.load_scenario does
    for body in ["servicer", "target"] {
        let shapes = raw
            .get_mut(body)
            .and_then(|b| b.get_mut("shapes"))
            .and_then(|s| s.as_array_mut());
        for shape in shapes.into_iter().flatten() {
            let Some(file) = shape.get("file").and_then(|f| f.as_str()).map(String::from) else {
                continue;
            };
            let obj = std::path::Path::new(&path).with_file_name(file);
            let (mut vertices, mut triangles) = (Vec::new(), Vec::new());
            for line in std::fs::read_to_string(obj).expect("mesh").lines() {
                let mut words = line.split_whitespace();
                let numbers = |w: std::str::SplitWhitespace| -> Vec<f64> {
                    w.map(|x| x.split('/').next().unwrap().parse().unwrap())
                        .collect()
                };
                match words.next() {
                    Some("v") => vertices.push(toml::Value::try_from(numbers(words)).unwrap()),
                    Some("f") => {
                        let f: Vec<i64> = numbers(words).iter().map(|i| *i as i64 - 1).collect();
                        triangles.push(toml::Value::try_from(f).unwrap());
                    }
                    _ => {}
                }
            }
            let shape = shape.as_table_mut().unwrap();
            shape.remove("file");
            shape.insert("vertices".into(), toml::Value::Array(vertices));
            shape.insert("triangles".into(), toml::Value::Array(triangles));
        }
    }
    edit(&mut raw);
    raw.try_into().expect("scenario")
}

/// A reader of the CDR layout (alignment relative to the 4-byte header).
struct Reader<'a>(&'a [u8], usize);

impl Reader<'_> {
    fn take(&mut self, n: usize) -> &[u8] {
        while !(self.1 - 4).is_multiple_of(n.min(8)) {
            self.1 += 1;
        }
        self.1 += n;
        &self.0[self.1 - n..self.1]
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take(4).try_into().unwrap())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take(8).try_into().unwrap())
    }
    fn v3(&mut self) -> Vector3<f64> {
        Vector3::new(self.f64(), self.f64(), self.f64())
    }
    fn string(&mut self) -> String {
        let n = self.u32() as usize;
        self.1 += n;
        String::from_utf8(self.0[self.1 - n..self.1 - 1].to_vec()).unwrap()
    }
}

/// One decoded marker: id, type, pose, scale, colour, points.
#[derive(Debug)]
struct Marker {
    kind: i32,
    position: Vector3<f64>,
    attitude: [f64; 4],
    scale: Vector3<f64>,
    rgba: [f32; 4],
    alpha: f32,
    points: Vec<Vector3<f64>>,
}

/// A `/hil/scene` message: its stamp (ns) and markers by id.
fn decode(bytes: &[u8]) -> (u64, BTreeMap<i32, Marker>) {
    let mut r = Reader(bytes, 4);
    let n = r.u32();
    let mut markers = BTreeMap::new();
    let mut stamp = 0;
    for _ in 0..n {
        let (sec, nsec) = (r.u32() as u64, r.u32() as u64);
        stamp = sec * 1_000_000_000 + nsec;
        r.string();
        assert_eq!(r.string(), "hilcontact");
        let (id, kind, _action) = (r.u32() as i32, r.u32() as i32, r.u32());
        let position = r.v3();
        let attitude = [r.f64(), r.f64(), r.f64(), r.f64()];
        let scale = r.v3();
        let rgba = [r.f32(), r.f32(), r.f32(), r.f32()];
        r.u32();
        r.u32();
        r.take(1);
        let points = (0..r.u32()).map(|_| r.v3()).collect();
        assert_eq!(r.u32(), 0);
        r.string();
        r.string();
        r.take(1);
        let old = markers.insert(
            id,
            Marker {
                kind,
                position,
                attitude,
                scale,
                rgba,
                alpha: rgba[3],
                points,
            },
        );
        assert!(old.is_none(), "marker id {id} twice");
    }
    assert_eq!(r.1, bytes.len(), "every marker read");
    (stamp, markers)
}

/// Records `plan`'s simulation as MCAP with the scene; returns the records, the scene
/// messages and the recording's report.
fn record(plan: &Plan, name: &str) -> (Vec<HilRecord>, Vec<Vec<u8>>, serde_json::Value) {
    let (out, records) = hilcontact_core::sim::simulate_plan_with_records(plan);
    let path = std::env::temp_dir().join(format!(
        "hilcontact-live-scene-{name}-{}.mcap",
        std::process::id()
    ));
    let info = RunInfo::new(plan, false);
    let stats = McapRecorder::create_with_scene(&McapOptions::new(&path), &info, plan)
        .expect("create")
        .record_run(&records, &out.metrics);
    let bytes = std::fs::read(&path).expect("recorded");
    let _ = std::fs::remove_file(&path);
    let scenes = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == "/hil/scene")
        .map(|m| m.data.to_vec())
        .collect();
    (records, scenes, serde_json::to_value(stats).unwrap())
}

/// The servicer's relative motion a record's actual tip, attitude and rates give.
fn actual(plan: &Plan, r: &HilRecord) -> RelativeMotion {
    let q: UnitQuaternion<f64> = r.actual_orientation;
    let arm = q * plan.system.rod_tip;
    RelativeMotion {
        position: r.actual_tip_position - arm,
        orientation: q,
        velocity: r.actual_tip_velocity - r.actual_angular_velocity.cross(&arm),
        angular_velocity: r.actual_angular_velocity,
    }
}

#[test]
fn a_shape_scene_draws_every_contact_point_with_its_own_normal_and_friction_arrows() {
    let plan = plan("rod-in-frame");
    let walls = plan.system.contact.walls.len() as i32;
    let (records, scenes, stats) = record(&plan, "rod-in-frame");
    assert_eq!(stats["scene_points_dropped"], 0, "{stats}");
    assert!(scenes.len() > 50, "{} scene messages", scenes.len());
    let (mut touching, mut most, mut with_friction) = (0, 0, 0);
    for bytes in &scenes {
        let (stamp, markers) = decode(bytes);
        // (the shapes' own markers after them: the next test)
        assert_eq!(
            markers.keys().filter(|id| **id < SHAPES).count() as i32,
            4 + walls + 3 * MAX_SCENE_POINTS as i32
        );
        let k = (stamp as f64 * 1e-9 / plan.period).round() as usize;
        let r = &records[k];
        // the core's contact points of the hardware at the record's actual motion
        let mut expected = Vec::new();
        plan.system
            .for_each_shape_contact(&actual(&plan, r), |p| expected.push(*p));
        let shown: Vec<i32> = (0..MAX_SCENE_POINTS as i32)
            .filter(|i| markers[&(1000 + 3 * i)].alpha == 1.0)
            .collect();
        assert_eq!(shown.len(), expected.len(), "t = {}", r.time);
        let mut total = markers[&3].points[1] - markers[&3].points[0];
        for (i, p) in shown.iter().zip(&expected) {
            let id = 1000 + 3 * i;
            let (point, normal, friction) =
                (&markers[&id], &markers[&(id + 1)], &markers[&(id + 2)]);
            assert_eq!(point.kind, 2, "a sphere");
            assert_eq!((normal.kind, friction.kind), (0, 0), "arrows");
            assert!((point.position - p.point).norm() < 1e-9, "t = {}", r.time);
            for arrow in [normal, friction] {
                assert!(
                    (arrow.points[0] - p.point).norm() < 1e-9,
                    "arrows start there"
                );
            }
            let f_n = (normal.points[1] - normal.points[0]) / FORCE_ARROW_SCALE;
            let f_t = (friction.points[1] - friction.points[0]) / FORCE_ARROW_SCALE;
            // the normal part along the point's normal, pushing; the friction part across it
            assert!(f_n.dot(&p.normal) >= 0.0);
            assert!((f_n - p.normal * f_n.dot(&p.normal)).norm() <= 1e-6 * (1.0 + f_n.norm()));
            assert!(f_t.dot(&p.normal).abs() <= 1e-6 * (1.0 + f_t.norm()));
            with_friction += usize::from(f_t.norm() > 1e-3);
            total +=
                (normal.points[1] - normal.points[0]) + (friction.points[1] - friction.points[0]);
        }
        // the arrows add up to the contact force the facility recorded
        let total = total / FORCE_ARROW_SCALE;
        assert!(
            (total - r.contact_force).norm() <= 1e-6 * (1.0 + r.contact_force.norm()),
            "t = {}: arrows {total:?}, recorded {:?}",
            r.time,
            r.contact_force
        );
        // unused slots are transparent
        for i in shown.len()..MAX_SCENE_POINTS {
            assert_eq!(markers[&(1000 + 3 * i as i32)].alpha, 0.0);
        }
        touching += usize::from(!expected.is_empty());
        most = most.max(expected.len());
    }
    // the run touches (the edge, then the corner on two bars) and slides
    assert!(touching > 10, "{touching} scene messages in contact");
    assert!(most >= 2, "at most {most} points at once");
    assert!(with_friction > 0);
}

#[test]
fn a_walls_scene_draws_the_contact_force_at_the_actual_tip_as_before() {
    let plan = plan("paper-table1");
    let walls = plan.system.contact.walls.len();
    let (records, scenes, stats) = record(&plan, "paper-table1");
    assert_eq!(stats["scene_points_dropped"], 0, "{stats}");
    let mut touching = 0;
    for bytes in &scenes {
        let (stamp, markers) = decode(bytes);
        // rods, contact point, force arrow and the walls: no point slots
        assert_eq!(markers.len(), 4 + walls);
        assert!(markers.keys().all(|id| *id < 1000));
        let r = &records[(stamp as f64 * 1e-9 / plan.period).round() as usize];
        let tip = r.actual_tip_position;
        assert_eq!(markers[&2].position, tip);
        assert_eq!(
            markers[&3].points,
            vec![tip, tip + r.contact_force * FORCE_ARROW_SCALE]
        );
        let in_contact = r.contact_force.norm() > plan.contact_threshold;
        assert_eq!(markers[&3].alpha, if in_contact { 1.0 } else { 0.0 });
        touching += usize::from(in_contact);
    }
    assert!(touching > 0);
}

#[test]
fn the_shipped_shape_presets_touch_at_fewer_points_than_a_scene_draws() {
    for preset in ["rod-in-frame", "probe-drogue"] {
        let plan = plan(preset);
        let (records, scenes, stats) = record(&plan, preset);
        assert_eq!(stats["scene_points_dropped"], 0, "{preset}: {stats}");
        assert!(!scenes.is_empty());
        // the most points at once over every tick of the run, not only the scene's
        let most = records
            .iter()
            .map(|r| {
                let mut n = 0;
                plan.system
                    .for_each_shape_contact(&actual(&plan, r), |_| n += 1);
                n
            })
            .max()
            .unwrap();
        println!("{preset}: at most {most} contact points at once");
        assert!(most >= 1 && most <= MAX_SCENE_POINTS, "{preset}: {most}");
    }
}

/// Whether a marker's pose is `pose` (the quaternion up to its sign) within 1e-9.
fn posed_at(m: &Marker, pose: &Isometry3<f64>) -> bool {
    let q = pose.rotation;
    let [x, y, z, w] = m.attitude;
    let dot = x * q.i + y * q.j + z * q.k + w * q.w;
    (m.position - pose.translation.vector).norm() < 1e-9 && (dot.abs() - 1.0).abs() < 1e-9
}

/// Checks every scene message of `scenario`'s run: one marker (a capsule three) per shape of
/// both bodies at body pose ∘ shape pose (the servicer's at the record's actual motion, the
/// target's at the hardware's mounting) with the shape's dimensions; returns the messages.
fn check_shapes(scenario: &hilcontact_core::Scenario, name: &str) -> usize {
    let plan = scenario.resolve().expect("plan");
    let mount = hilcontact_core::plan::mount_pose(&plan.nominal.contact, &scenario.facility);
    let walls = plan.system.contact.walls.len();
    // its own file name: the other tests record the same presets at once
    let (records, scenes, stats) = record(&plan, &format!("{name}-shapes"));
    assert_eq!(stats["scene_meshes_boxed"], 0, "{stats}");
    let shapes = &plan.nominal.contact.shapes;
    let all: Vec<(bool, &BodyShape)> = (shapes.servicer.iter().map(|s| (true, s)))
        .chain(shapes.target.iter().map(|s| (false, s)))
        .collect();
    let capsules = all
        .iter()
        .filter(|(_, s)| matches!(s.geometry, ShapeGeometry::Capsule { .. }))
        .count();
    for bytes in &scenes {
        let (stamp, markers) = decode(bytes);
        let r = &records[(stamp as f64 * 1e-9 / plan.period).round() as usize];
        assert_eq!(
            markers.len(),
            4 + walls + 3 * MAX_SCENE_POINTS + all.len() + 2 * capsules
        );
        let rel = actual(&plan, r);
        let body = Isometry3::from_parts(Translation3::from(rel.position), rel.orientation);
        let mut colours = [None, None];
        for (j, (servicer, shape)) in all.iter().enumerate() {
            let id = SHAPES + 3 * j as i32;
            let pose = if *servicer { body } else { mount } * shape.pose;
            let m = &markers[&id];
            assert!(
                posed_at(m, &pose),
                "{name} {}: {m:?} at {pose:?}",
                shape.name
            );
            // semi-transparent, one colour per body
            assert!(m.alpha > 0.0 && m.alpha < 1.0);
            let colour = colours[usize::from(*servicer)].get_or_insert(m.rgba);
            assert_eq!(*colour, m.rgba);
            match &shape.geometry {
                ShapeGeometry::Box { size, .. } => {
                    assert_eq!((m.kind, m.scale), (1, Vector3::from(*size)))
                }
                ShapeGeometry::Cylinder { radius, length, .. } => {
                    assert_eq!(m.kind, 3);
                    assert_eq!(m.scale, Vector3::new(2.0 * radius, 2.0 * radius, *length));
                }
                ShapeGeometry::Capsule { radius, length } => {
                    assert_eq!(m.kind, 3);
                    assert_eq!(m.scale, Vector3::new(2.0 * radius, 2.0 * radius, *length));
                    for (k, z) in [(1, -0.5 * length), (2, 0.5 * length)] {
                        let end = &markers[&(id + k)];
                        let at = pose * Translation3::new(0.0, 0.0, z);
                        assert!(posed_at(end, &at), "{name}: the capsule's end {k}");
                        assert_eq!((end.kind, end.scale), (2, Vector3::repeat(2.0 * radius)));
                        assert_eq!(end.rgba, m.rgba);
                    }
                }
                ShapeGeometry::Mesh {
                    vertices,
                    triangles,
                } => {
                    assert_eq!((m.kind, m.scale), (11, Vector3::repeat(1.0)));
                    let expected: Vec<Vector3<f64>> = triangles
                        .iter()
                        .flat_map(|t| t.map(|i| Vector3::from(vertices[i as usize])))
                        .collect();
                    assert_eq!(m.points, expected, "{name}: the mesh's triangles");
                }
                other => panic!("{name}: a {other:?} in a shipped preset"),
            }
        }
        assert_ne!(colours[0], colours[1], "the bodies' colours differ");
    }
    scenes.len()
}

#[test]
fn a_shape_scene_draws_every_shape_at_body_pose_times_shape_pose() {
    for preset in ["rod-in-frame", "probe-drogue"] {
        let n = check_shapes(&scenario(preset, |_| {}), preset);
        assert!(n > 50, "{preset}: {n} scene messages");
    }
    // the target's shapes where the hardware is mounted, not where the scenario puts them
    let mounted = scenario("rod-in-frame", |raw| {
        let f = raw
            .entry("facility")
            .or_insert(toml::Value::Table(Default::default()))
            .as_table_mut()
            .unwrap();
        f.insert(
            "mount_offset".into(),
            toml::Value::try_from([0.002, -0.001, 0.0]).unwrap(),
        );
        f.insert(
            "mount_rotation".into(),
            toml::Value::try_from([0.0, 0.5, 1.0]).unwrap(),
        );
    });
    assert!(check_shapes(&mounted, "rod-in-frame-mounted") > 50);
}
