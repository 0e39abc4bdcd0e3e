//! The facility in 3-D, as the live view ([`super::live`]) draws it: the walls, the virtual
//! (commanded) and the actual rod, the contact point and the contact force as an arrow
//! (`/hil/scene`, `visualization_msgs/msg/MarkerArray`), and the frames of both servicers in
//! the target frame `t` (`/tf`, `tf2_msgs/msg/TFMessage`), encoded as CDR with
//! [`Cdr`] like every channel of the MCAP recording, at [`SCENE_RATE`] of run time.
//!
//! **Shapes' contact points.** A scenario with shapes touches at several points at once, which
//! a record does not carry (it has the total force). The scene computes them itself, off the
//! loop's thread, at each scene message only: every contact point of the shapes at the record's
//! *actual* servicer motion ([`TwoBodySystem::for_each_shape_contact_force`]), each drawn as a
//! point with its own normal-force arrow and friction arrow; the rod-tip arrow then carries the
//! rod tip's part against the walls only (zero without walls), so the arrows add up to the
//! contact. Which system ([`ContactSource`]): a simulation's and an emulated facility's scene
//! uses the hardware as it really is ([`Plan::system`], with `facility.dissipation`), so its
//! arrows sum to the recorded contact force; a real-time run's (`hil`, `demo-rt`) uses what the
//! loop knows, the scenario's shapes and law ([`Plan::nominal`], no added damping): the points
//! and forces the model predicts at the robot's measured pose, not measured ones. At most
//! [`MAX_SCENE_POINTS`] points per message (the slots are preallocated); more are counted in
//! [`Scene::points_dropped`]. A scenario without shapes draws exactly as before.
//!
//! **The shapes themselves.** Every collision shape of both bodies (`[[servicer.shapes]]`,
//! `[[target.shapes]]`) is drawn, semi-transparent, one colour per body: the target's where
//! the facility's hardware is ([`Plan::system`]'s, its mounting applied), the servicer's at
//! the record's *actual* servicer motion (the motion the contact points use), each at body
//! pose ∘ shape pose. A box is a cube, a sphere a sphere, a cylinder a cylinder, a capsule a
//! cylinder and two spheres, a half-space a plate like a wall, a cone and a mesh a triangle
//! list built once in [`Scene::new`] (a mesh of at most [`MAX_MESH_TRIANGLES`] triangles;
//! a larger one is drawn as its bounding box and counted, [`Scene::meshes_boxed`]).
//!
//! Frames: `t` the target (mockup) frame; `servicer` the commanded servicer body (its origin
//! `p_tip − R·r_tip`, `R` its attitude relative to `t`, `r_tip` the rod tip in its frame);
//! `servicer_actual` the robot's actual one.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use hilcontact_core::frames::RelativeMotion;
use hilcontact_core::shapes::{BodyShape, ShapeGeometry};
use hilcontact_core::world::TwoBodySystem;
use hilcontact_core::Plan;

use super::mcap::{schema_text, Cdr, ChannelScope, ChannelSpec, FRAME_TARGET};
use super::RunInfo;
use crate::report::Sample;

/// Scene messages per second of run time (at most one per tick), Hz.
pub const SCENE_RATE: f64 = 30.0;

/// Frame id of the commanded servicer body.
pub const FRAME_SERVICER: &str = "servicer";

/// Frame id of the robot's actual servicer body.
pub const FRAME_SERVICER_ACTUAL: &str = "servicer_actual";

/// Length of the force arrow per newton of contact force, m/N.
pub const FORCE_ARROW_SCALE: f64 = 0.001;

/// The scene's channels (the one list; docs/realtime.md shows it).
pub const SCENE_CHANNELS: [ChannelSpec; 2] = [
    ChannelSpec {
        topic: "/hil/scene",
        schema: "visualization_msgs/msg/MarkerArray",
        frame: FRAME_TARGET,
        scope: ChannelScope::Always,
        doc: "walls (grey), the virtual rod (blue) and the actual rod (orange), the contact point and the contact force arrow (red, 1 mm/N); with shapes, the shapes of the servicer (orange) and the target (purple), semi-transparent, and each contact point (red) with its normal force (red) and friction (green) arrows, at 30 Hz of run time",
    },
    ChannelSpec {
        topic: "/tf",
        schema: "tf2_msgs/msg/TFMessage",
        frame: FRAME_TARGET,
        scope: ChannelScope::Always,
        doc: "the commanded and the actual servicer frames (servicer, servicer_actual) in t, at 30 Hz of run time",
    },
];

/// Marker ids of the scene (walls after them, `WALLS + i`).
const ROD: i32 = 0;
const ROD_ACTUAL: i32 = 1;
const CONTACT: i32 = 2;
const FORCE: i32 = 3;
const WALLS: i32 = 10;
/// Shapes' contact point `i`: its point `POINTS + 3i`, normal arrow `+ 1`, friction arrow `+ 2`.
const POINTS: i32 = 1000;
/// Shape `j` (the servicer's shapes first, then the target's): its markers `SHAPES + 3j + m`
/// (`m` = 0, and a capsule's end spheres 1 and 2).
pub const SHAPES: i32 = 2000;

/// Most triangles of a mesh the scene draws as a triangle list (each message carries its
/// `3 × 24` bytes per triangle: 74 kB at the bound); a larger mesh is drawn as its bounding
/// box and counted ([`Scene::meshes_boxed`]).
pub const MAX_MESH_TRIANGLES: usize = 1024;

/// Sides of the triangle list a cone is drawn with (its mantle and its base, `2 ×` as many
/// triangles).
pub const CONE_SIDES: usize = 32;

/// Most shapes' contact points one scene message draws (each a point and two arrows, always
/// sent: unused ones transparent); more are counted ([`Scene::points_dropped`]). The shipped
/// shape presets touch at 2 points at most (`tests/live_scene.rs`); a box flat on a face at 4.
pub const MAX_SCENE_POINTS: usize = 16;

/// `visualization_msgs/Marker` types used.
const ARROW: i32 = 0;
const CUBE: i32 = 1;
const SPHERE: i32 = 2;
const CYLINDER: i32 = 3;
const LINE_STRIP: i32 = 4;
const TRIANGLE_LIST: i32 = 11;

/// RGBA colours.
const GREY: [f32; 4] = [0.6, 0.6, 0.6, 0.5];
const BLUE: [f32; 4] = [0.12, 0.47, 0.71, 1.0];
const ORANGE: [f32; 4] = [1.0, 0.5, 0.05, 1.0];
const RED: [f32; 4] = [0.84, 0.15, 0.16, 1.0];
const GREEN: [f32; 4] = [0.17, 0.63, 0.17, 1.0];
/// The servicer's shapes (the actual rod's orange) and the target's (purple).
const SERVICER_SHAPES: [f32; 4] = [1.0, 0.5, 0.05, 0.35];
const TARGET_SHAPES: [f32; 4] = [0.58, 0.4, 0.74, 0.35];

/// How one shape is drawn, in its own frame (m).
#[derive(Debug, Clone)]
enum Look {
    /// A cube of these full edge lengths (a box; a mesh's bounding box: the shape frame's
    /// `centre` offset).
    Cube {
        size: Vector3<f64>,
        centre: Vector3<f64>,
    },
    /// A sphere of this diameter.
    Sphere(f64),
    /// A cylinder along z: diameter, length.
    Cylinder(f64, f64),
    /// A capsule along z: diameter, distance between its end caps' centres.
    Capsule(f64, f64),
    /// A plate in the shape's xy plane (a half-space's boundary), side m.
    Plate(f64),
    /// Triangles (three points each) in the shape frame, built once.
    Triangles(Vec<Vector3<f64>>),
}

impl Look {
    /// Markers it takes.
    fn markers(&self) -> usize {
        match self {
            Look::Capsule(..) => 3,
            _ => 1,
        }
    }
}

/// One shape as drawn: which body, its pose in its body frame, its look.
#[derive(Debug, Clone)]
struct Drawn {
    servicer: bool,
    pose: Isometry3<f64>,
    look: Look,
}

/// The look of `shape` (a plate of side `plate` for a half-space), and whether it is a mesh
/// over [`MAX_MESH_TRIANGLES`] triangles drawn as its bounding box.
fn look(shape: &BodyShape, plate: f64) -> (Look, bool) {
    match &shape.geometry {
        ShapeGeometry::Sphere { radius } => (Look::Sphere(2.0 * radius), false),
        ShapeGeometry::Box { size, .. } => (
            Look::Cube {
                size: Vector3::from(*size),
                centre: Vector3::zeros(),
            },
            false,
        ),
        ShapeGeometry::Cylinder { radius, length, .. } => {
            (Look::Cylinder(2.0 * radius, *length), false)
        }
        ShapeGeometry::Capsule { radius, length } => (Look::Capsule(2.0 * radius, *length), false),
        ShapeGeometry::HalfSpace => (Look::Plate(plate), false),
        ShapeGeometry::Cone { radius, length, .. } => {
            let h = 0.5 * length;
            let apex = Vector3::new(0.0, 0.0, h);
            let centre = Vector3::new(0.0, 0.0, -h);
            let rim = |i: usize| {
                let a = std::f64::consts::TAU * i as f64 / CONE_SIDES as f64;
                Vector3::new(radius * a.cos(), radius * a.sin(), -h)
            };
            let mut points = Vec::with_capacity(6 * CONE_SIDES);
            for i in 0..CONE_SIDES {
                points.extend([apex, rim(i), rim(i + 1)]);
                points.extend([centre, rim(i + 1), rim(i)]);
            }
            (Look::Triangles(points), false)
        }
        ShapeGeometry::Mesh {
            vertices,
            triangles,
        } => {
            if triangles.len() <= MAX_MESH_TRIANGLES {
                let points = triangles
                    .iter()
                    .flat_map(|t| t.map(|i| Vector3::from(vertices[i as usize])))
                    .collect();
                return (Look::Triangles(points), false);
            }
            let first = Point3::from(vertices[0]);
            let (lo, hi) = vertices.iter().fold((first, first), |(lo, hi), v| {
                let v = Point3::from(*v);
                (lo.inf(&v), hi.sup(&v))
            });
            let look = Look::Cube {
                size: hi - lo,
                centre: nalgebra::center(&lo, &hi).coords,
            };
            (look, true)
        }
    }
}

/// Which system the shapes' contact points are drawn from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactSource {
    /// The hardware as it really is ([`Plan::system`], with `facility.dissipation`): a
    /// simulation's and an emulated facility's scene.
    Truth,
    /// What the loop knows ([`Plan::nominal`], no added damping): a real-time run's scene.
    Model,
}

impl ContactSource {
    /// A real-time run's ([`RunInfo::realtime`]): the model; a simulation's and a facility's:
    /// the truth.
    pub fn of(info: &RunInfo) -> Self {
        if info.realtime() {
            ContactSource::Model
        } else {
            ContactSource::Truth
        }
    }
}

/// One shapes' contact point as drawn: where, and the normal and friction parts of the force
/// on the servicer there (`t` frame, m and N).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ScenePoint {
    /// The contact point, m.
    pub point: Vector3<f64>,
    /// The normal part of the force, N.
    pub normal_force: Vector3<f64>,
    /// The friction part of the force, N.
    pub friction_force: Vector3<f64>,
}

/// The shapes' contact, for a scenario with shapes.
struct Shapes {
    system: TwoBodySystem,
    added_damping: f64,
    points: [ScenePoint; MAX_SCENE_POINTS],
    n: usize,
}

/// What the scene is drawn from: the plan's walls and rod, and the encoder.
pub struct Scene {
    walls: Vec<(Vector3<f64>, UnitQuaternion<f64>)>,
    wall_size: f64,
    rod_tip: Vector3<f64>,
    contact_threshold: f64,
    /// Ticks between two scene messages (>= 1).
    pub every: u64,
    cdr: Cdr,
    /// The shapes' contact (None: no shapes, the rod tip only).
    shapes: Option<Box<Shapes>>,
    /// Shapes' contact points beyond [`MAX_SCENE_POINTS`] in a message, not drawn (summed
    /// over messages).
    pub points_dropped: u64,
    /// Every shape of both bodies as drawn (servicer's first).
    drawn: Vec<Drawn>,
    /// Markers the shapes take.
    shape_markers: usize,
    /// Meshes over [`MAX_MESH_TRIANGLES`] triangles, drawn as their bounding box.
    pub meshes_boxed: u64,
}

impl Scene {
    /// The scene of `plan`: each wall a thin square plate (side 4 × the rod's length, at least
    /// 0.2 m) centred on its point, normal to its normal; with shapes, their contact points
    /// from `source`.
    pub fn new(plan: &Plan, source: ContactSource) -> Self {
        let rod_tip = plan.system.rod_tip;
        let wall_size = (4.0 * rod_tip.norm()).max(0.2);
        // the target's shapes where the hardware is (mounted), the servicer's in its frame
        let bodies = &plan.system.contact.shapes;
        let mut meshes_boxed = 0;
        let drawn: Vec<Drawn> = (bodies.servicer.iter().map(|s| (true, s)))
            .chain(bodies.target.iter().map(|s| (false, s)))
            .map(|(servicer, shape)| {
                let (look, boxed) = look(shape, wall_size);
                meshes_boxed += u64::from(boxed);
                Drawn {
                    servicer,
                    pose: shape.pose,
                    look,
                }
            })
            .collect();
        let shape_markers = drawn.iter().map(|d| d.look.markers()).sum();
        let walls = plan
            .system
            .contact
            .walls
            .iter()
            .map(|w| {
                let q = UnitQuaternion::rotation_between(&Vector3::z(), &w.normal).unwrap_or_else(
                    || UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
                );
                (w.point, q)
            })
            .collect();
        Scene {
            walls,
            wall_size,
            rod_tip,
            contact_threshold: plan.contact_threshold,
            every: ((1.0 / (SCENE_RATE * plan.period)).round() as u64).max(1),
            cdr: Cdr::new(),
            shapes: (!plan.system.contact.shapes.servicer.is_empty()).then(|| {
                let (system, added_damping) = match source {
                    ContactSource::Truth => (plan.system.clone(), plan.facility.dissipation),
                    ContactSource::Model => (plan.nominal.clone(), 0.0),
                };
                Box::new(Shapes {
                    system,
                    added_damping,
                    points: [ScenePoint::default(); MAX_SCENE_POINTS],
                    n: 0,
                })
            }),
            points_dropped: 0,
            drawn,
            shape_markers,
            meshes_boxed,
        }
    }

    /// The shapes' contact points of the newest [`Scene::markers`] message (empty without
    /// shapes).
    pub fn points(&self) -> &[ScenePoint] {
        self.shapes.as_ref().map_or(&[], |s| &s.points[..s.n])
    }

    /// The servicer's relative motion that a record's actual tip, attitude and rates give.
    fn actual_motion(&self, s: &Sample) -> RelativeMotion {
        let r = &s.record;
        let arm = r.actual_orientation * self.rod_tip;
        RelativeMotion {
            position: r.actual_tip_position - arm,
            orientation: r.actual_orientation,
            velocity: r.actual_tip_velocity - r.actual_angular_velocity.cross(&arm),
            angular_velocity: r.actual_angular_velocity,
        }
    }

    /// With shapes: their contact points at the sample's actual motion into the slots (beyond
    /// them counted), and the rod tip's force against the walls, N. Without: the record's
    /// contact force.
    fn contact(&mut self, s: &Sample) -> Vector3<f64> {
        let rel = self.actual_motion(s);
        let Some(shapes) = self.shapes.as_deref_mut() else {
            return s.record.contact_force;
        };
        let Shapes {
            system,
            added_damping,
            points,
            n,
        } = shapes;
        *n = 0;
        let mut dropped = 0;
        system.for_each_shape_contact_force(&rel, *added_damping, |p, f| {
            if *n < MAX_SCENE_POINTS {
                points[*n] = ScenePoint {
                    point: p.point,
                    normal_force: f.force - f.friction_force,
                    friction_force: f.friction_force,
                };
                *n += 1;
            } else {
                dropped += 1;
            }
        });
        self.points_dropped += dropped;
        system
            .contact
            .force_with_added_damping(
                &rel.point(&self.rod_tip),
                &rel.point_velocity(&self.rod_tip),
                *added_damping,
            )
            .force
    }

    /// Whether tick `k` carries a scene message.
    pub fn due(&self, k: u64) -> bool {
        k.is_multiple_of(self.every)
    }

    /// The servicer's origin in `t` from its rod tip and attitude, m.
    pub fn origin(&self, tip: &Vector3<f64>, attitude: &UnitQuaternion<f64>) -> Vector3<f64> {
        tip - attitude * self.rod_tip
    }

    /// The `/hil/scene` message of one sample at run time `t_ns` (ns).
    pub fn markers(&mut self, t_ns: u64, s: &Sample) -> &[u8] {
        let r = &s.record;
        let base = self.origin(&r.tip_position, &r.orientation);
        let base_actual = self.origin(&r.actual_tip_position, &r.actual_orientation);
        let force = self.contact(s);
        let actual = self.actual_motion(s);
        let servicer =
            Isometry3::from_parts(Translation3::from(actual.position), actual.orientation);
        let in_contact = force.norm() > self.contact_threshold;
        let walls = std::mem::take(&mut self.walls);
        let size = self.wall_size;
        let shapes = self.shapes.take();
        let slots = if shapes.is_some() {
            MAX_SCENE_POINTS
        } else {
            0
        };
        let c = self.cdr.begin();
        c.u32((4 + walls.len() + 3 * slots + self.shape_markers) as u32);
        let none = UnitQuaternion::identity();
        let zero = Vector3::zeros();
        marker(
            c,
            t_ns,
            ROD,
            LINE_STRIP,
            &zero,
            &none,
            [0.01, 0.0, 0.0],
            BLUE,
            &[base, r.tip_position],
        );
        let tip_actual = r.actual_tip_position;
        marker(
            c,
            t_ns,
            ROD_ACTUAL,
            LINE_STRIP,
            &zero,
            &none,
            [0.01, 0.0, 0.0],
            ORANGE,
            &[base_actual, tip_actual],
        );
        let mut contact_colour = RED;
        contact_colour[3] = if in_contact { 1.0 } else { 0.0 };
        marker(
            c,
            t_ns,
            CONTACT,
            SPHERE,
            &tip_actual,
            &none,
            [0.02; 3],
            contact_colour,
            &[],
        );
        let end = tip_actual + force * FORCE_ARROW_SCALE;
        marker(
            c,
            t_ns,
            FORCE,
            ARROW,
            &zero,
            &none,
            [0.005, 0.01, 0.01],
            contact_colour,
            &[tip_actual, end],
        );
        for (i, (point, q)) in walls.iter().enumerate() {
            marker(
                c,
                t_ns,
                WALLS + i as i32,
                CUBE,
                point,
                q,
                [size, size, 0.002],
                GREY,
                &[],
            );
        }
        if let Some(shapes) = &shapes {
            for i in 0..MAX_SCENE_POINTS {
                let (p, shown) = match shapes.points[..shapes.n].get(i) {
                    Some(p) => (*p, 1.0),
                    None => (ScenePoint::default(), 0.0),
                };
                let id = POINTS + 3 * i as i32;
                let alpha = |mut colour: [f32; 4]| {
                    colour[3] = shown;
                    colour
                };
                let at = p.point;
                marker(c, t_ns, id, SPHERE, &at, &none, [0.01; 3], alpha(RED), &[]);
                let ends = [(p.normal_force, RED), (p.friction_force, GREEN)];
                for (j, (f, colour)) in ends.into_iter().enumerate() {
                    marker(
                        c,
                        t_ns,
                        id + 1 + j as i32,
                        ARROW,
                        &zero,
                        &none,
                        [0.003, 0.006, 0.006],
                        alpha(colour),
                        &[at, at + f * FORCE_ARROW_SCALE],
                    );
                }
            }
        }
        for (j, d) in self.drawn.iter().enumerate() {
            let (pose, colour) = if d.servicer {
                (servicer * d.pose, SERVICER_SHAPES)
            } else {
                (d.pose, TARGET_SHAPES)
            };
            let id = SHAPES + 3 * j as i32;
            let q = pose.rotation;
            let at = pose.translation.vector;
            let mut one = |id, kind, at: &Vector3<f64>, scale, points: &[Vector3<f64>]| {
                marker(c, t_ns, id, kind, at, &q, scale, colour, points)
            };
            match &d.look {
                Look::Cube { size, centre } => one(
                    id,
                    CUBE,
                    &(pose * Point3::from(*centre)).coords,
                    (*size).into(),
                    &[],
                ),
                Look::Sphere(d) => one(id, SPHERE, &at, [*d; 3], &[]),
                Look::Cylinder(d, l) => one(id, CYLINDER, &at, [*d, *d, *l], &[]),
                Look::Capsule(d, l) => {
                    one(id, CYLINDER, &at, [*d, *d, *l], &[]);
                    for (m, z) in [(1, -0.5 * l), (2, 0.5 * l)] {
                        let end = (pose * Point3::new(0.0, 0.0, z)).coords;
                        one(id + m, SPHERE, &end, [*d; 3], &[]);
                    }
                }
                Look::Plate(side) => one(id, CUBE, &at, [*side, *side, 0.002], &[]),
                Look::Triangles(points) => one(id, TRIANGLE_LIST, &at, [1.0; 3], points),
            }
        }
        self.shapes = shapes;
        self.walls = walls;
        self.cdr.bytes()
    }

    /// The `/tf` message of one sample: `servicer` and `servicer_actual` in `t`.
    pub fn transforms(&mut self, t_ns: u64, s: &Sample) -> &[u8] {
        let r = &s.record;
        let base = self.origin(&r.tip_position, &r.orientation);
        let base_actual = self.origin(&r.actual_tip_position, &r.actual_orientation);
        let c = self.cdr.begin();
        c.u32(2);
        for (child, p, q) in [
            (FRAME_SERVICER, base, r.orientation),
            (FRAME_SERVICER_ACTUAL, base_actual, r.actual_orientation),
        ] {
            c.header(t_ns, FRAME_TARGET)
                .string(child)
                .vector3(&p)
                .quaternion(&q);
        }
        self.cdr.bytes()
    }
}

/// One `visualization_msgs/Marker` (namespace `hilcontact`, frame `t`, no lifetime).
#[allow(clippy::too_many_arguments)]
fn marker(
    c: &mut Cdr,
    t_ns: u64,
    id: i32,
    kind: i32,
    position: &Vector3<f64>,
    attitude: &UnitQuaternion<f64>,
    scale: [f64; 3],
    colour: [f32; 4],
    points: &[Vector3<f64>],
) {
    c.header(t_ns, FRAME_TARGET)
        .string("hilcontact")
        .i32(id)
        .i32(kind)
        .i32(0);
    c.vector3(position).quaternion(attitude);
    c.vector3(&Vector3::from(scale));
    for v in colour {
        c.f32(v);
    }
    c.i32(0).u32(0); // lifetime: forever
    c.u8(0); // frame_locked
    c.u32(points.len() as u32);
    for p in points {
        c.vector3(p);
    }
    c.u32(0); // colors
    c.string("").string("").u8(0); // text, mesh_resource, mesh_use_embedded_materials
}

const DEF_MARKER: &str = "MSG: visualization_msgs/Marker\n\
int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n\
int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n\
int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n\
int32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\
std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n\
std_msgs/ColorRGBA[] colors\nstring text\nstring mesh_resource\nbool mesh_use_embedded_materials\n";

/// The `ros2msg` schema of a scene channel (the MarkerArray's here, the others'
/// [`schema_text`]).
pub fn scene_schema_text(schema: &str) -> String {
    if schema != "visualization_msgs/msg/MarkerArray" {
        return schema_text(schema);
    }
    let sep = "================================================================================\n";
    let mut text = String::from("visualization_msgs/Marker[] markers\n");
    for dep in [
        DEF_MARKER,
        "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n",
        "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
        "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n",
        "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n",
        "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n",
        "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
        "MSG: std_msgs/ColorRGBA\nfloat32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
        "MSG: builtin_interfaces/Duration\nint32 sec\nuint32 nanosec\n",
    ] {
        text.push_str(sep);
        text.push_str(dep);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use hilcontact_core::shapes::BodyShape;

    fn plan() -> Plan {
        let path = format!(
            "{}/../../python/hilcontact/scenarios/paper-table1.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let scenario: hilcontact_core::Scenario =
            toml::from_str(&std::fs::read_to_string(path).expect("preset")).expect("toml");
        scenario.resolve().expect("plan")
    }

    #[test]
    fn the_servicer_origin_puts_the_rod_tip_where_the_record_says() {
        let plan = plan();
        let scene = Scene::new(&plan, ContactSource::Truth);
        let q = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
        let tip = Vector3::new(0.1, -0.4, 0.25);
        let origin = scene.origin(&tip, &q);
        assert!(((origin + q * plan.system.rod_tip) - tip).norm() < 1e-12);
        assert_eq!(
            scene.every,
            ((1.0 / (30.0 * plan.period)).round() as u64).max(1)
        );
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
        fn f64(&mut self) -> f64 {
            f64::from_le_bytes(self.take(8).try_into().unwrap())
        }
        fn string(&mut self) -> String {
            let n = self.u32() as usize;
            self.1 += n;
            String::from_utf8(self.0[self.1 - n..self.1 - 1].to_vec()).unwrap()
        }
    }

    #[test]
    fn transforms_decode_to_both_servicer_frames_in_t() {
        let plan = plan();
        let mut scene = Scene::new(&plan, ContactSource::Truth);
        let mut s = Sample::default();
        s.record.tip_position = Vector3::new(0.3, 0.1, -0.2);
        s.record.orientation = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
        s.record.actual_tip_position = Vector3::new(0.31, 0.1, -0.2);
        s.record.actual_orientation = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.31);
        let bytes = scene.transforms(1_500_000_000, &s).to_vec();
        let mut r = Reader(&bytes, 4);
        assert_eq!(r.u32(), 2);
        for (child, tip, q) in [
            (FRAME_SERVICER, s.record.tip_position, s.record.orientation),
            (
                FRAME_SERVICER_ACTUAL,
                s.record.actual_tip_position,
                s.record.actual_orientation,
            ),
        ] {
            assert_eq!((r.u32(), r.u32()), (1, 500_000_000)); // 1.5 s
            assert_eq!(r.string(), FRAME_TARGET);
            assert_eq!(r.string(), child);
            let p = Vector3::new(r.f64(), r.f64(), r.f64());
            let rotation = [r.f64(), r.f64(), r.f64(), r.f64()];
            assert!(
                (p + q * plan.system.rod_tip - tip).norm() < 1e-12,
                "{child}"
            );
            assert_eq!(rotation, [q.i, q.j, q.k, q.w]);
        }
        assert_eq!(r.1, bytes.len(), "nothing after the second transform");
    }

    #[test]
    fn the_force_arrow_is_the_contact_force_at_the_actual_tip() {
        let plan = plan();
        let mut scene = Scene::new(&plan, ContactSource::Truth);
        let mut s = Sample::default();
        s.record.actual_tip_position = Vector3::new(0.2, 0.0, 0.1);
        s.record.contact_force = Vector3::new(-150.0, 20.0, 0.0);
        let bytes = scene.markers(0, &s).to_vec();
        let mut r = Reader(&bytes, 4);
        let n = r.u32();
        assert_eq!(n as usize, 4 + plan.system.contact.walls.len());
        let mut kinds = Vec::new();
        for _ in 0..n {
            r.u32();
            r.u32();
            assert_eq!(r.string(), FRAME_TARGET);
            assert_eq!(r.string(), "hilcontact");
            let (id, kind, action) = (r.u32(), r.u32(), r.u32());
            assert_eq!(action, 0);
            let position = Vector3::new(r.f64(), r.f64(), r.f64());
            let _q = [r.f64(), r.f64(), r.f64(), r.f64()];
            let _scale = [r.f64(), r.f64(), r.f64()];
            let colour: Vec<f32> = (0..4)
                .map(|_| f32::from_le_bytes(r.take(4).try_into().unwrap()))
                .collect();
            r.u32();
            r.u32();
            r.take(1);
            let points: Vec<Vector3<f64>> = (0..r.u32())
                .map(|_| Vector3::new(r.f64(), r.f64(), r.f64()))
                .collect();
            assert_eq!(r.u32(), 0);
            r.string();
            r.string();
            r.take(1);
            if id as i32 == FORCE {
                let end = s.record.actual_tip_position + s.record.contact_force * FORCE_ARROW_SCALE;
                assert_eq!(points, vec![s.record.actual_tip_position, end]);
                assert_eq!(colour[3], 1.0, "in contact: shown");
            }
            if id as i32 >= WALLS {
                let wall = plan.system.contact.walls[(id as i32 - WALLS) as usize];
                assert!((position - wall.point).norm() < 1e-12);
            }
            kinds.push(kind as i32);
        }
        assert_eq!(r.1, bytes.len(), "every marker read");
        assert_eq!(kinds[..4], [LINE_STRIP, LINE_STRIP, SPHERE, ARROW]);
        assert!(kinds[4..].iter().all(|k| *k == CUBE));
        let text = scene_schema_text("visualization_msgs/msg/MarkerArray");
        assert!(text.starts_with("visualization_msgs/Marker[] markers\n"));
        assert!(text.contains("MSG: std_msgs/ColorRGBA\n"));
    }

    /// A decoded marker: id, type, position, attitude (x, y, z, w), scale, points.
    type Decoded = (
        i32,
        i32,
        Vector3<f64>,
        [f64; 4],
        Vector3<f64>,
        Vec<Vector3<f64>>,
    );

    /// Decodes a `/hil/scene` message's markers.
    fn decode(bytes: &[u8]) -> Vec<Decoded> {
        let mut r = Reader(bytes, 4);
        let v3 = |r: &mut Reader| Vector3::new(r.f64(), r.f64(), r.f64());
        let out = (0..r.u32())
            .map(|_| {
                r.u32();
                r.u32();
                r.string();
                r.string();
                let (id, kind, _) = (r.u32() as i32, r.u32() as i32, r.u32());
                let position = v3(&mut r);
                let q = [r.f64(), r.f64(), r.f64(), r.f64()];
                let scale = v3(&mut r);
                r.take(16);
                r.u32();
                r.u32();
                r.take(1);
                let points = (0..r.u32()).map(|_| v3(&mut r)).collect();
                r.u32();
                r.string();
                r.string();
                r.take(1);
                (id, kind, position, q, scale, points)
            })
            .collect();
        assert_eq!(r.1, bytes.len(), "every marker read");
        out
    }

    #[test]
    fn spheres_cones_half_spaces_and_large_meshes_are_drawn_in_their_shape_frames() {
        let mut plan = plan();
        let pose = |x: f64, y: f64, z: f64| {
            Isometry3::new(Vector3::new(x, y, z), Vector3::new(0.3, -0.2, 0.5))
        };
        // a zigzag strip of 1100 triangles: over the bound, drawn as its bounding box
        let vertices: Vec<[f64; 3]> = (0..1102)
            .map(|k| [k as f64 * 1e-3, (k % 2) as f64 * 0.01, 0.0])
            .collect();
        let triangles = (0..1100).map(|k| [k, k + 1, k + 2]).collect();
        let shape = |geometry, at| BodyShape::new("s".into(), geometry, at);
        plan.system.contact.shapes.servicer = vec![shape(
            ShapeGeometry::Sphere { radius: 0.05 },
            pose(1.0, 0.0, 0.0),
        )];
        plan.system.contact.shapes.target = vec![
            shape(ShapeGeometry::HalfSpace, pose(0.0, 0.0, -2.0)),
            shape(
                ShapeGeometry::Cone {
                    radius: 0.1,
                    length: 0.3,
                    margin: 0.001,
                },
                pose(0.5, 0.5, 0.5),
            ),
            shape(
                ShapeGeometry::Mesh {
                    vertices,
                    triangles,
                },
                pose(-0.5, 0.2, 0.1),
            ),
        ];
        let mut scene = Scene::new(&plan, ContactSource::Truth);
        assert_eq!(scene.meshes_boxed, 1);
        let mut s = Sample::default();
        s.record.actual_tip_position = Vector3::new(0.2, -0.1, 0.3);
        s.record.actual_orientation = UnitQuaternion::from_euler_angles(0.1, 0.7, -0.4);
        let body = Isometry3::from_parts(
            Translation3::from(
                scene.origin(&s.record.actual_tip_position, &s.record.actual_orientation),
            ),
            s.record.actual_orientation,
        );
        let markers = decode(scene.markers(0, &s));
        let walls = plan.system.contact.walls.len();
        assert_eq!(markers.len(), 4 + walls + 3 * MAX_SCENE_POINTS + 4);
        let shapes: Vec<_> = markers.iter().filter(|m| m.0 >= SHAPES).collect();
        let ids: Vec<i32> = shapes.iter().map(|m| m.0).collect();
        assert_eq!(ids, [SHAPES, SHAPES + 3, SHAPES + 6, SHAPES + 9]);
        let at = |m: &Decoded, p: &Isometry3<f64>| {
            let q = p.rotation;
            let dot = m.3[0] * q.i + m.3[1] * q.j + m.3[2] * q.k + m.3[3] * q.w;
            (m.2 - p.translation.vector).norm() < 1e-12 && (dot.abs() - 1.0).abs() < 1e-12
        };
        // the sphere at the actual servicer's pose ∘ its pose, its diameter
        assert_eq!((shapes[0].1, shapes[0].4), (SPHERE, Vector3::repeat(0.1)));
        assert!(at(shapes[0], &(body * pose(1.0, 0.0, 0.0))));
        // the half-space a plate in its plane
        assert_eq!(shapes[1].1, CUBE);
        assert_eq!(
            shapes[1].4,
            Vector3::new(scene.wall_size, scene.wall_size, 0.002)
        );
        assert!(at(shapes[1], &pose(0.0, 0.0, -2.0)));
        // the cone: its mantle and base as triangles in its frame, apex at +l/2, base rim r
        let (kind, points) = (shapes[2].1, &shapes[2].5);
        assert_eq!((kind, points.len()), (TRIANGLE_LIST, 6 * CONE_SIDES));
        assert!(at(shapes[2], &pose(0.5, 0.5, 0.5)));
        for p in points {
            let on_base = (p.z + 0.15).abs() < 1e-12 && p.xy().norm() <= 0.1 + 1e-12;
            assert!(on_base || *p == Vector3::new(0.0, 0.0, 0.15), "{p:?}");
        }
        assert_eq!(points.iter().filter(|p| p.z > 0.0).count(), CONE_SIDES);
        // the large mesh: its bounding box
        assert_eq!(shapes[3].1, CUBE);
        assert!((shapes[3].4 - Vector3::new(1.101, 0.01, 0.0)).norm() < 1e-12);
        let centre = pose(-0.5, 0.2, 0.1) * Translation3::new(0.5505, 0.005, 0.0);
        assert!(at(shapes[3], &centre));
    }
}
