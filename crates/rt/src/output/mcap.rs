//! MCAP recordings of a run, for robotics viewers (Foxglove, Lichtblick, PlotJuggler) and ROS 2
//! tools (`rosbags`, `mcap-ros2-support`).
//!
//! One writer, [`McapRecorder`], for both kinds of run: an output [`Sink`] (registered in
//! [`super::OUTPUTS`] under the `mcap` option), which the real-time runtime's writer thread
//! feeds every [`Sample`] as it drains the loop's ring buffer (never the loop thread), and a
//! simulation from its finished records ([`super::feed_simulation`]).
//!
//! **Encoding.** ROS 2 messages, CDR-encoded (`message_encoding = "cdr"`), with their `ros2msg`
//! definitions as the schemas (profile `ros2`): `geometry_msgs` for the wrenches, poses,
//! velocities and the contact force, `rcl_interfaces/msg/Log` for the run's events,
//! `tf2_msgs/msg/TFMessage` for the sensor frame, the facility in 3-D as the live view draws it
//! (`/hil/scene` and `/tf`, [`super::scene`], when opened as a run's output: a recording and a
//! live run look the same), and three small `hilcontact_msgs` types (their
//! definitions travel in the file) for the energy, the estimates and the loop's timing. The
//! messages have a fixed layout, so they are encoded here by hand ([`Cdr`]) into one reused
//! buffer. Every message's log and publish time, and its header stamp, is the run's time: tick ×
//! period, from 0 (the virtual time of the time series).
//!
//! **Crash safety.** Messages go into chunks that are closed and written out every
//! [`McapOptions::chunk_interval`] of run time (0.5 s by default) and at most every
//! [`CHUNK_SIZE_LIMIT`] bytes. A chunk is built in memory and written whole, then flushed to
//! the OS, so a process killed mid-run (SIGKILL) leaves a file of complete chunks that a reader
//! which does not need the summary reads up to the last one. [`McapRecorder::finish`] writes the
//! summary (statistics, chunk and message indexes) and the footer. There is no `fsync` during
//! the run (it would stall the writer); the finished file is synced once.
//!
//! **Errors.** Opening the file fails before a run starts ([`McapRecorder::create`]). A write
//! error during the run is counted ([`RecordingStats::write_errors`], with the first error's
//! text) and never stops the run; no method of the recorder panics (the mcap crate's internal
//! checks are caught and turn the recorder into a failed one).

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, ErrorKind};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use mcap::records::{MessageHeader, Metadata};
use mcap::{WriteOptions, Writer};
use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use hilcontact_core::hil::HilRecord;
use hilcontact_core::metrics::Metrics;
use hilcontact_core::Plan;

use super::scene::{scene_schema_text, ContactSource, Scene, SCENE_CHANNELS};
use super::{feed_simulation, time_ns, Event, EventLevel, RunInfo, Sink, SinkContext};
use crate::error::{Result, RtError};
use crate::report::Sample;

/// Where and how a run is recorded as MCAP (`RuntimeOptions::mcap`; `--mcap FILE` on the CLI).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct McapOptions {
    /// The file to write (its folder is created if missing).
    pub path: PathBuf,
    /// Replace an existing file; without it an existing file is refused before the run.
    #[serde(default)]
    pub overwrite: bool,
    /// Run time between two chunks written out, s: what a killed run loses at most.
    #[serde(default = "default_chunk_interval")]
    pub chunk_interval: f64,
}

fn default_chunk_interval() -> f64 {
    0.5
}

impl McapOptions {
    /// Options writing `path` (not replacing it), chunks every 0.5 s of run time.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        McapOptions {
            path: path.into(),
            overwrite: false,
            chunk_interval: default_chunk_interval(),
        }
    }

    /// Checks the values (not the file): `chunk_interval` a positive number.
    pub fn validate(&self) -> Result<()> {
        let v = self.chunk_interval;
        if !(v.is_finite() && v > 0.0) {
            return Err(RtError::option(
                "mcap.chunk_interval",
                format!("must be a positive number of seconds, got {v}"),
            ));
        }
        Ok(())
    }
}

/// Largest uncompressed chunk, bytes: a chunk is closed when it passes this even before
/// [`McapOptions::chunk_interval`] (a very short control period).
pub const CHUNK_SIZE_LIMIT: u64 = 2 * 1024 * 1024;

/// Frame id of the target (mockup) frame `t`, in which positions, velocities and the contact
/// force are expressed.
pub const FRAME_TARGET: &str = "t";
/// Frame id of the force/torque sensor's frame, in which the measured and applied wrenches are
/// expressed (placed in `t` by `/tf_static`).
pub const FRAME_SENSOR: &str = "sensor";

/// Which runs have a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ChannelScope {
    /// Every run: one message per tick.
    Always,
    /// Runs whose compensator identifies the contact (`pic`, `dac`, `pida`): one per tick.
    Estimates,
    /// Real-time runs: one per tick.
    Realtime,
    /// Events: a few per run (start, faults, stop).
    Events,
    /// Once, at the start.
    Once,
}

/// A channel of the recording: topic, ROS 2 type, frame and what it holds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ChannelSpec {
    /// Topic name.
    pub topic: &'static str,
    /// ROS 2 message type (the MCAP schema's name), e.g. `geometry_msgs/msg/WrenchStamped`.
    pub schema: &'static str,
    /// Header frame id (`t` or `sensor`), empty for messages without a header.
    pub frame: &'static str,
    /// Which runs have it.
    pub scope: ChannelScope,
    /// What it holds, with units.
    pub doc: &'static str,
}

/// Index of each channel in [`CHANNELS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Topic {
    MeasuredWrench = 0,
    AppliedWrench,
    ContactForce,
    TipCommanded,
    TipActual,
    VelocityCommanded,
    VelocityActual,
    Energy,
    Estimates,
    LoopTiming,
    Events,
    TfStatic,
}

/// Every channel a recording can have (the one list: docs/realtime.md shows it).
pub const CHANNELS: [ChannelSpec; 12] = [
    ChannelSpec {
        topic: "/hil/measured_wrench",
        schema: "geometry_msgs/msg/WrenchStamped",
        frame: FRAME_SENSOR,
        scope: ChannelScope::Always,
        doc: "the sensor's reading: force on the frame (N) and moment about the sensor origin (N·m)",
    },
    ChannelSpec {
        topic: "/hil/applied_wrench",
        schema: "geometry_msgs/msg/WrenchStamped",
        frame: FRAME_SENSOR,
        scope: ChannelScope::Always,
        doc: "the wrench the compensator fed the virtual dynamics (N, N·m; the sensor's convention)",
    },
    ChannelSpec {
        topic: "/hil/contact_force",
        schema: "geometry_msgs/msg/Vector3Stamped",
        frame: FRAME_TARGET,
        scope: ChannelScope::Always,
        doc: "the contact force on the rod (N); in real time the force on the rod the sensor reports",
    },
    ChannelSpec {
        topic: "/hil/tip/commanded",
        schema: "geometry_msgs/msg/PoseStamped",
        frame: FRAME_TARGET,
        scope: ChannelScope::Always,
        doc: "the rod tip commanded by the virtual dynamics (m) and the servicer's attitude relative to t",
    },
    ChannelSpec {
        topic: "/hil/tip/actual",
        schema: "geometry_msgs/msg/PoseStamped",
        frame: FRAME_TARGET,
        scope: ChannelScope::Always,
        doc: "the robot's actual rod tip (m) and the servicer's actual attitude relative to t",
    },
    ChannelSpec {
        topic: "/hil/tip/commanded_velocity",
        schema: "geometry_msgs/msg/TwistStamped",
        frame: FRAME_TARGET,
        scope: ChannelScope::Always,
        doc: "the commanded rod tip velocity (m/s) and angular velocity (rad/s) relative to t",
    },
    ChannelSpec {
        topic: "/hil/tip/actual_velocity",
        schema: "geometry_msgs/msg/TwistStamped",
        frame: FRAME_TARGET,
        scope: ChannelScope::Always,
        doc: "the robot's actual rod tip velocity (m/s) and angular velocity (rad/s) relative to t",
    },
    ChannelSpec {
        topic: "/hil/energy",
        schema: "hilcontact_msgs/msg/Energy",
        frame: "",
        scope: ChannelScope::Always,
        doc: "kinetic energy of the virtual relative motion and the compensator's observed energy (J; NaN when not observed)",
    },
    ChannelSpec {
        topic: "/hil/estimates",
        schema: "hilcontact_msgs/msg/ContactEstimate",
        frame: "",
        scope: ChannelScope::Estimates,
        doc: "identified contact stiffness (N/m) and damping (N·s/m); NaN before the first estimate",
    },
    ChannelSpec {
        topic: "/hil/loop_timing",
        schema: "hilcontact_msgs/msg/LoopTiming",
        frame: "",
        scope: ChannelScope::Realtime,
        doc: "the tick's wake-up latency, the age of its sensor record and of the newest robot feedback (s)",
    },
    ChannelSpec {
        topic: "/hil/events",
        schema: "rcl_interfaces/msg/Log",
        frame: "",
        scope: ChannelScope::Events,
        doc: "the run's start, faults (lost packets, overruns, socket errors), stop and its reason",
    },
    ChannelSpec {
        topic: "/tf_static",
        schema: "tf2_msgs/msg/TFMessage",
        frame: FRAME_TARGET,
        scope: ChannelScope::Once,
        doc: "the sensor frame in t (the scenario's sensor position and orientation)",
    },
];

/// Whether the run of `info` has a channel of `scope`.
fn has(info: &RunInfo, scope: ChannelScope) -> bool {
    match scope {
        ChannelScope::Estimates => info.estimates_contact,
        ChannelScope::Realtime => info.realtime(),
        _ => true,
    }
}

/// What a recording wrote (`metrics.json` `realtime.mcap` of a real-time run).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RecordingStats {
    /// The file.
    pub path: String,
    /// Messages written.
    pub messages: u64,
    /// Chunks written out.
    pub chunks: u64,
    /// Size of the file once finished, bytes (0 before).
    pub bytes: u64,
    /// Messages, chunks or the summary that could not be written (a full disk, a panic of
    /// the writer); the run goes on.
    pub write_errors: u64,
    /// The first write error, if any.
    pub error: Option<String>,
    /// Whether the summary and footer were written (the file is complete).
    pub complete: bool,
    /// Shapes' contact points the scene did not draw (beyond
    /// [`super::scene::MAX_SCENE_POINTS`] in a message), summed over its messages.
    pub scene_points_dropped: u64,
    /// Meshes the scene draws as their bounding box (over
    /// [`super::scene::MAX_MESH_TRIANGLES`] triangles).
    pub scene_meshes_boxed: u64,
}

/// Encodes CDR (XCDR1, little endian), the encoding of ROS 2 messages: a 4-byte encapsulation
/// header (`00 01 00 00`), then each primitive aligned to its size relative to the end of that
/// header; a string is its length with the terminating NUL (u32), the bytes, the NUL.
pub struct Cdr {
    buf: Vec<u8>,
}

impl Default for Cdr {
    fn default() -> Self {
        Self::new()
    }
}

impl Cdr {
    /// An empty encoder (allocates its buffer once; reused by [`Cdr::begin`]).
    pub fn new() -> Self {
        Cdr {
            buf: Vec::with_capacity(512),
        }
    }

    /// Starts a message: clears the buffer and writes the encapsulation header.
    pub fn begin(&mut self) -> &mut Self {
        self.buf.clear();
        self.buf.extend_from_slice(&[0x00, 0x01, 0x00, 0x00]);
        self
    }

    /// The message so far.
    pub fn bytes(&self) -> &[u8] {
        &self.buf
    }

    fn align(&mut self, n: usize) {
        while !(self.buf.len() - 4).is_multiple_of(n) {
            self.buf.push(0);
        }
    }

    /// A `uint8`.
    pub fn u8(&mut self, v: u8) -> &mut Self {
        self.buf.push(v);
        self
    }

    /// A `float32`.
    pub fn f32(&mut self, v: f32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `uint32`.
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// An `int32`.
    pub fn i32(&mut self, v: i32) -> &mut Self {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `float64`.
    pub fn f64(&mut self, v: f64) -> &mut Self {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A `string` (a NUL inside `s` ends it early for C readers; none is written here).
    pub fn string(&mut self, s: &str) -> &mut Self {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
        self
    }

    /// A `builtin_interfaces/Time` of `t_ns` ns.
    pub fn time(&mut self, t_ns: u64) -> &mut Self {
        self.i32((t_ns / 1_000_000_000) as i32)
            .u32((t_ns % 1_000_000_000) as u32)
    }

    /// A `std_msgs/Header`: stamp `t_ns` (ns) and `frame`.
    pub fn header(&mut self, t_ns: u64, frame: &str) -> &mut Self {
        self.time(t_ns).string(frame)
    }

    /// A `geometry_msgs/Vector3` or `Point`.
    pub fn vector3(&mut self, v: &Vector3<f64>) -> &mut Self {
        self.f64(v.x).f64(v.y).f64(v.z)
    }

    /// A `geometry_msgs/Quaternion` (x, y, z, w).
    pub fn quaternion(&mut self, q: &UnitQuaternion<f64>) -> &mut Self {
        self.f64(q.i).f64(q.j).f64(q.k).f64(q.w)
    }

    /// A `geometry_msgs/msg/WrenchStamped`.
    pub fn wrench_stamped(
        &mut self,
        t_ns: u64,
        frame: &str,
        force: &Vector3<f64>,
        torque: &Vector3<f64>,
    ) -> &mut Self {
        self.begin()
            .header(t_ns, frame)
            .vector3(force)
            .vector3(torque)
    }

    /// A `geometry_msgs/msg/PoseStamped`.
    pub fn pose_stamped(
        &mut self,
        t_ns: u64,
        frame: &str,
        position: &Vector3<f64>,
        orientation: &UnitQuaternion<f64>,
    ) -> &mut Self {
        self.begin()
            .header(t_ns, frame)
            .vector3(position)
            .quaternion(orientation)
    }

    /// A `geometry_msgs/msg/TwistStamped`.
    pub fn twist_stamped(
        &mut self,
        t_ns: u64,
        frame: &str,
        linear: &Vector3<f64>,
        angular: &Vector3<f64>,
    ) -> &mut Self {
        self.begin()
            .header(t_ns, frame)
            .vector3(linear)
            .vector3(angular)
    }

    /// A `geometry_msgs/msg/Vector3Stamped`.
    pub fn vector3_stamped(&mut self, t_ns: u64, frame: &str, v: &Vector3<f64>) -> &mut Self {
        self.begin().header(t_ns, frame).vector3(v)
    }

    /// A message of a header and `values` (`float64` each): the `hilcontact_msgs` types.
    pub fn header_f64s(&mut self, t_ns: u64, frame: &str, values: &[f64]) -> &mut Self {
        self.begin().header(t_ns, frame);
        for v in values {
            self.f64(*v);
        }
        self
    }

    /// An `rcl_interfaces/msg/Log` (no file, function or line).
    pub fn log(&mut self, t_ns: u64, level: EventLevel, name: &str, msg: &str) -> &mut Self {
        self.begin()
            .time(t_ns)
            .u8(level as u8)
            .string(name)
            .string(msg)
            .string("")
            .string("")
            .u32(0)
    }

    /// A `tf2_msgs/msg/TFMessage` of one transform: `child` placed in `parent` at `translation`
    /// with `rotation` (child to parent).
    pub fn tf_message(
        &mut self,
        t_ns: u64,
        parent: &str,
        child: &str,
        translation: &Vector3<f64>,
        rotation: &UnitQuaternion<f64>,
    ) -> &mut Self {
        self.begin()
            .u32(1)
            .header(t_ns, parent)
            .string(child)
            .vector3(translation)
            .quaternion(rotation)
    }
}

// ---- schemas: the ROS 2 message definitions (`ros2msg`), each with its dependencies ----

const SEPARATOR: &str =
    "================================================================================\n";
const DEF_TIME: &str = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n";
const DEF_HEADER: &str = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";
const DEF_VECTOR3: &str = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n";
const DEF_POINT: &str = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n";
const DEF_QUATERNION: &str =
    "MSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n";
const DEF_WRENCH: &str = "MSG: geometry_msgs/Wrench\nVector3 force\nVector3 torque\n";
const DEF_POSE: &str = "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n";
const DEF_TWIST: &str = "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n";
const DEF_TRANSFORM_STAMPED: &str = "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\nTransform transform\n";
const DEF_TRANSFORM: &str =
    "MSG: geometry_msgs/Transform\nVector3 translation\nQuaternion rotation\n";

/// The `ros2msg` schema of a channel: its definition, then each dependency after a separator
/// line (the concatenated form rosbag2 and the MCAP ROS 2 profile use).
pub fn schema_text(schema: &str) -> String {
    let (main, deps): (&str, &[&str]) = match schema {
        "geometry_msgs/msg/WrenchStamped" => (
            "std_msgs/Header header\nWrench wrench\n",
            &[DEF_HEADER, DEF_TIME, DEF_WRENCH, DEF_VECTOR3],
        ),
        "geometry_msgs/msg/PoseStamped" => (
            "std_msgs/Header header\nPose pose\n",
            &[DEF_HEADER, DEF_TIME, DEF_POSE, DEF_POINT, DEF_QUATERNION],
        ),
        "geometry_msgs/msg/TwistStamped" => (
            "std_msgs/Header header\nTwist twist\n",
            &[DEF_HEADER, DEF_TIME, DEF_TWIST, DEF_VECTOR3],
        ),
        "geometry_msgs/msg/Vector3Stamped" => (
            "std_msgs/Header header\nVector3 vector\n",
            &[DEF_HEADER, DEF_TIME, DEF_VECTOR3],
        ),
        "hilcontact_msgs/msg/Energy" => (
            "# hilcontact: energy of a HIL run, J\nstd_msgs/Header header\n\
             float64 energy # kinetic energy of the virtual relative motion, J\n\
             float64 observed_energy # the compensator's observed port energy, J (NaN when not observed)\n",
            &[DEF_HEADER, DEF_TIME],
        ),
        "hilcontact_msgs/msg/ContactEstimate" => (
            "# hilcontact: the compensator's identified contact\nstd_msgs/Header header\n\
             float64 stiffness # N/m (NaN before the first estimate)\n\
             float64 damping # N s/m (NaN before the first estimate)\n",
            &[DEF_HEADER, DEF_TIME],
        ),
        "hilcontact_msgs/msg/LoopTiming" => (
            "# hilcontact: timing of one real-time tick, s\nstd_msgs/Header header\n\
             float64 wake_latency # wake-up latency of the tick, s\n\
             float64 sensor_age # age of the sensor record used, s\n\
             float64 robot_age # age of the newest robot feedback, s\n",
            &[DEF_HEADER, DEF_TIME],
        ),
        "rcl_interfaces/msg/Log" => (
            "byte DEBUG=10\nbyte INFO=20\nbyte WARN=30\nbyte ERROR=40\nbyte FATAL=50\n\
             builtin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\n\
             string function\nuint32 line\n",
            &[DEF_TIME],
        ),
        "tf2_msgs/msg/TFMessage" => (
            "geometry_msgs/TransformStamped[] transforms\n",
            &[
                DEF_TRANSFORM_STAMPED,
                DEF_HEADER,
                DEF_TIME,
                DEF_TRANSFORM,
                DEF_VECTOR3,
                DEF_QUATERNION,
            ],
        ),
        _ => ("", &[]),
    };
    let mut text = main.to_string();
    for dep in deps {
        text.push_str(SEPARATOR);
        text.push_str(dep);
    }
    text
}

/// The name of the events' sender (`rcl_interfaces/msg/Log` `name`).
const EVENT_NAME: &str = "hilcontact";

struct ChannelState {
    id: u16,
    sequence: u32,
}

/// What became of a message ([`write_message`]).
enum Written {
    Ok,
    NoWriter,
    Failed(String),
    Panicked,
}

/// Writes one message on `channel` at run time `t_ns` (its sequence advanced when written),
/// catching the mcap crate's panics.
fn write_message(
    writer: &mut Option<McapWriter>,
    channel: &mut ChannelState,
    t_ns: u64,
    data: &[u8],
) -> Written {
    let Some(writer) = writer.as_mut() else {
        return Written::NoWriter;
    };
    let header = MessageHeader {
        channel_id: channel.id,
        sequence: channel.sequence,
        log_time: t_ns,
        publish_time: t_ns,
    };
    match catch_unwind(AssertUnwindSafe(|| {
        writer.write_to_known_channel(&header, data)
    })) {
        Ok(Ok(())) => {
            channel.sequence = channel.sequence.wrapping_add(1);
            Written::Ok
        }
        Ok(Err(e)) => Written::Failed(e.to_string()),
        Err(_) => Written::Panicked,
    }
}

type McapWriter = Writer<BufWriter<File>>;

/// Writes a run as MCAP: the channels of [`CHANNELS`] that the run has, one message per tick and
/// channel, events, chunks written out every [`McapOptions::chunk_interval`] of run time.
pub struct McapRecorder {
    writer: Option<McapWriter>,
    channels: [Option<ChannelState>; CHANNELS.len()],
    /// The facility in 3-D ([`SCENE_CHANNELS`]), when the recording has it.
    scene: Option<Scene>,
    scene_channels: [Option<ChannelState>; SCENE_CHANNELS.len()],
    /// Samples recorded (the scene is drawn every [`Scene::every`] of them).
    ticks: u64,
    cdr: Cdr,
    info: RunInfo,
    path: PathBuf,
    chunk_interval_ns: u64,
    next_chunk_ns: u64,
    /// Messages written since the last chunk was written out.
    pending: bool,
    /// Run time of the newest message, ns.
    last_ns: u64,
    stats: RecordingStats,
}

impl McapRecorder {
    /// Creates the file (its folder too) and writes the header, the run's metadata
    /// (`hilcontact`: kind, scenario, compensator, period, duration, the resolved scenario as
    /// JSON, the wall-clock time of creation), the schemas, the channels and `/tf_static`, as a first chunk written out at once. Fails, naming the path,
    /// when the file exists (unless `overwrite`) or cannot be created.
    pub fn create(options: &McapOptions, info: &RunInfo) -> Result<Self> {
        Self::create_with(options, info, None)
    }

    /// [`McapRecorder::create`] with the facility in 3-D of `plan` ([`SCENE_CHANNELS`]:
    /// `/hil/scene` and `/tf` at [`super::scene::SCENE_RATE`] of run time), as the live view
    /// draws it: what a run's `mcap` output records.
    pub fn create_with_scene(options: &McapOptions, info: &RunInfo, plan: &Plan) -> Result<Self> {
        Self::create_with(
            options,
            info,
            Some(Scene::new(plan, ContactSource::of(info))),
        )
    }

    fn create_with(options: &McapOptions, info: &RunInfo, scene: Option<Scene>) -> Result<Self> {
        options.validate()?;
        let path = options.path.clone();
        let file = open_file(&path, options.overwrite)?;
        let context = || format!("mcap {}", path.display());
        let writer = WriteOptions::new()
            .compression(None)
            .profile("ros2")
            .library(format!("hilcontact {}", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(CHUNK_SIZE_LIMIT))
            // chunks built in memory and written whole: a killed run leaves complete chunks
            .disable_seeking(true)
            .create(BufWriter::with_capacity(1 << 16, file))
            .map_err(|e| RtError::io_other(context(), e.to_string()))?;
        let chunk_interval_ns = time_ns(options.chunk_interval).max(1);
        let mut recorder = McapRecorder {
            writer: Some(writer),
            channels: Default::default(),
            scene,
            scene_channels: Default::default(),
            ticks: 0,
            cdr: Cdr::new(),
            info: info.clone(),
            path: path.clone(),
            chunk_interval_ns,
            next_chunk_ns: chunk_interval_ns,
            pending: false,
            last_ns: 0,
            stats: RecordingStats {
                path: path.display().to_string(),
                ..RecordingStats::default()
            },
        };
        recorder
            .start()
            .map_err(|e| RtError::io_other(context(), e))?;
        Ok(recorder)
    }

    /// The schemas, channels, metadata and `/tf_static`, written out.
    fn start(&mut self) -> std::result::Result<(), String> {
        let info = self.info.clone();
        let Some(writer) = self.writer.as_mut() else {
            return Err("no writer".into());
        };
        // the metadata first: outside the chunks, before the first one
        let created = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        let metadata = Metadata {
            name: "hilcontact".into(),
            metadata: BTreeMap::from([
                ("kind".to_string(), info.kind.to_string()),
                ("scenario".to_string(), info.scenario.clone()),
                ("compensator".to_string(), info.compensator.to_string()),
                ("period".to_string(), format!("{}", info.period)),
                ("duration".to_string(), format!("{}", info.duration)),
                ("time".to_string(), "run time: tick x period, from 0".into()),
                (
                    "frames".to_string(),
                    "t: target (mockup) frame; sensor: the F/T sensor's frame".into(),
                ),
                ("scenario_json".to_string(), info.scenario_json.clone()),
                ("version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
                ("created_unix_time".to_string(), format!("{created:.3}")),
            ]),
        };
        writer
            .write_metadata(&metadata)
            .map_err(|e| e.to_string())?;
        let mut schemas: BTreeMap<&str, u16> = BTreeMap::new();
        for (i, spec) in CHANNELS.iter().enumerate() {
            if !has(&info, spec.scope) {
                continue;
            }
            let schema_id = match schemas.get(spec.schema) {
                Some(id) => *id,
                None => {
                    let text = schema_text(spec.schema);
                    let id = writer
                        .add_schema(spec.schema, "ros2msg", text.as_bytes())
                        .map_err(|e| e.to_string())?;
                    schemas.insert(spec.schema, id);
                    id
                }
            };
            let mut metadata = BTreeMap::new();
            if !spec.frame.is_empty() {
                metadata.insert("frame_id".to_string(), spec.frame.to_string());
            }
            metadata.insert("description".to_string(), spec.doc.to_string());
            let id = writer
                .add_channel(schema_id, spec.topic, "cdr", &metadata)
                .map_err(|e| e.to_string())?;
            self.channels[i] = Some(ChannelState { id, sequence: 0 });
        }
        if self.scene.is_some() {
            for (i, spec) in SCENE_CHANNELS.iter().enumerate() {
                let schema_id = match schemas.get(spec.schema) {
                    Some(id) => *id,
                    None => {
                        let text = scene_schema_text(spec.schema);
                        let id = writer
                            .add_schema(spec.schema, "ros2msg", text.as_bytes())
                            .map_err(|e| e.to_string())?;
                        schemas.insert(spec.schema, id);
                        id
                    }
                };
                let metadata = BTreeMap::from([
                    ("frame_id".to_string(), spec.frame.to_string()),
                    ("description".to_string(), spec.doc.to_string()),
                ]);
                let id = writer
                    .add_channel(schema_id, spec.topic, "cdr", &metadata)
                    .map_err(|e| e.to_string())?;
                self.scene_channels[i] = Some(ChannelState { id, sequence: 0 });
            }
        }
        self.cdr.tf_message(
            0,
            FRAME_TARGET,
            FRAME_SENSOR,
            &info.sensor_position,
            &info.sensor_orientation,
        );
        self.put(Topic::TfStatic, 0);
        self.write_out_chunk();
        match self.stats.error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// The run so far: messages, chunks, errors.
    pub fn stats(&self) -> &RecordingStats {
        &self.stats
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// One tick: a message on each per-tick channel, at the record's time; writes out the chunk
    /// first when the tick's time has reached the next chunk boundary.
    pub fn sample(&mut self, s: &Sample) {
        let r: &HilRecord = &s.record;
        let t = time_ns(r.time);
        if t >= self.next_chunk_ns {
            self.write_out_chunk();
            self.next_chunk_ns = (t / self.chunk_interval_ns + 1) * self.chunk_interval_ns;
        }
        self.cdr
            .wrench_stamped(t, FRAME_SENSOR, &r.measured_force, &r.measured_moment);
        self.put(Topic::MeasuredWrench, t);
        self.cdr
            .wrench_stamped(t, FRAME_SENSOR, &r.applied_force, &r.applied_moment);
        self.put(Topic::AppliedWrench, t);
        self.cdr.vector3_stamped(t, FRAME_TARGET, &r.contact_force);
        self.put(Topic::ContactForce, t);
        self.cdr
            .pose_stamped(t, FRAME_TARGET, &r.tip_position, &r.orientation);
        self.put(Topic::TipCommanded, t);
        self.cdr.pose_stamped(
            t,
            FRAME_TARGET,
            &r.actual_tip_position,
            &r.actual_orientation,
        );
        self.put(Topic::TipActual, t);
        self.cdr
            .twist_stamped(t, FRAME_TARGET, &r.tip_velocity, &r.angular_velocity);
        self.put(Topic::VelocityCommanded, t);
        self.cdr.twist_stamped(
            t,
            FRAME_TARGET,
            &r.actual_tip_velocity,
            &r.actual_angular_velocity,
        );
        self.put(Topic::VelocityActual, t);
        self.cdr.header_f64s(t, "", &[r.energy, r.observed_energy]);
        self.put(Topic::Energy, t);
        if self.info.estimates_contact {
            self.cdr
                .header_f64s(t, "", &[r.stiffness_estimate, r.damping_estimate]);
            self.put(Topic::Estimates, t);
        }
        if self.info.realtime() {
            self.cdr
                .header_f64s(t, "", &[s.wake_latency, s.sensor_age, s.robot_age]);
            self.put(Topic::LoopTiming, t);
        }
        if let Some(mut scene) = self.scene.take() {
            if scene.due(self.ticks) {
                self.put_scene(0, t, scene.markers(t, s));
                self.put_scene(1, t, scene.transforms(t, s));
            }
            self.scene = Some(scene);
        }
        self.ticks += 1;
    }

    /// An event on `/hil/events` at run time `time` (s; not before the newest message, so that
    /// the file stays in time order).
    pub fn event(&mut self, time: f64, level: EventLevel, text: &str) {
        let t = time_ns(time).max(self.last_ns);
        self.cdr.log(t, level, EVENT_NAME, text);
        self.put(Topic::Events, t);
    }

    /// Run time of the newest message, s.
    pub fn last_time(&self) -> f64 {
        self.last_ns as f64 * 1e-9
    }

    /// Writes the encoded message to a channel (if the run has it), counting a failure.
    fn put(&mut self, topic: Topic, t_ns: u64) {
        let Some(channel) = self.channels[topic as usize].as_mut() else {
            return;
        };
        let written = write_message(&mut self.writer, channel, t_ns, self.cdr.bytes());
        self.written(written, t_ns);
    }

    /// Writes `data` (encoded by the scene) to scene channel `i` of [`SCENE_CHANNELS`].
    fn put_scene(&mut self, i: usize, t_ns: u64, data: &[u8]) {
        let Some(channel) = self.scene_channels[i].as_mut() else {
            return;
        };
        let written = write_message(&mut self.writer, channel, t_ns, data);
        self.written(written, t_ns);
    }

    /// Counts a message written, or its failure.
    fn written(&mut self, written: Written, t_ns: u64) {
        match written {
            Written::Ok => {
                self.stats.messages += 1;
                self.pending = true;
                self.last_ns = self.last_ns.max(t_ns);
            }
            Written::NoWriter => self.stats.write_errors += 1,
            Written::Failed(e) => self.failed(e),
            Written::Panicked => self.panicked(),
        }
    }

    /// Closes the current chunk and hands it to the OS (nothing if no message is pending).
    fn write_out_chunk(&mut self) {
        if !self.pending {
            return;
        }
        let Some(writer) = self.writer.as_mut() else {
            return;
        };
        match catch_unwind(AssertUnwindSafe(|| writer.flush())) {
            Ok(Ok(())) => {
                self.stats.chunks += 1;
                self.pending = false;
            }
            Ok(Err(e)) => self.failed(e.to_string()),
            Err(_) => self.panicked(),
        }
    }

    fn failed(&mut self, error: String) {
        self.stats.write_errors += 1;
        if self.stats.error.is_none() {
            self.stats.error = Some(format!("mcap {}: {error}", self.path.display()));
        }
    }

    /// The mcap writer panicked: it is given up (not dropped: its drop would finish the file
    /// and could panic again), and every later message counts as an error.
    fn panicked(&mut self) {
        if let Some(writer) = self.writer.take() {
            std::mem::forget(writer);
        }
        self.failed("the MCAP writer panicked; the file ends at its last complete chunk".into());
    }

    /// Writes the last chunk, the summary and the footer, syncs the file, and returns what was
    /// written (`complete` false, with the error, if that failed).
    pub fn finish(mut self) -> RecordingStats {
        if let Some(scene) = &self.scene {
            self.stats.scene_points_dropped = scene.points_dropped;
            self.stats.scene_meshes_boxed = scene.meshes_boxed;
        }
        self.write_out_chunk();
        let Some(mut writer) = self.writer.take() else {
            return self.stats;
        };
        match catch_unwind(AssertUnwindSafe(|| writer.finish())) {
            Ok(Ok(summary)) => {
                if let Some(stats) = summary.stats {
                    self.stats.chunks = stats.chunk_count as u64;
                }
            }
            Ok(Err(e)) => {
                self.failed(e.to_string());
                return self.stats;
            }
            Err(_) => {
                std::mem::forget(writer);
                self.failed("the MCAP writer panicked while writing the summary".into());
                return self.stats;
            }
        }
        match writer.into_inner().into_inner() {
            Ok(file) => match file.sync_all().and_then(|_| file.metadata()) {
                Ok(meta) => {
                    self.stats.bytes = meta.len();
                    self.stats.complete = true;
                }
                Err(e) => self.failed(e.to_string()),
            },
            Err(e) => self.failed(e.error().to_string()),
        }
        self.stats
    }

    /// Gives the recording up and removes its file: the run never started (a link that could
    /// not be opened, a peer that did not answer).
    pub fn discard(mut self) {
        if let Some(writer) = self.writer.take() {
            // finish quietly (a drop would too), then remove
            let _ = catch_unwind(AssertUnwindSafe(move || drop(writer)));
        }
        let _ = std::fs::remove_file(&self.path);
    }

    /// A simulation's whole recording from its records and metrics, as every output of a
    /// simulation is fed ([`super::feed_simulation`]: a start event, one message per record and
    /// channel, the end event at the last record's time), then [`McapRecorder::finish`].
    pub fn record_run(mut self, records: &[HilRecord], metrics: &Metrics) -> RecordingStats {
        let info = self.info.clone();
        feed_simulation(&mut self, &info, records, metrics);
        self.finish()
    }
}

/// Opens the run's MCAP recording if its options have `mcap` (`{"path", "overwrite",
/// "chunk_interval"}`): the file is created (or the start refused, naming it) before anything
/// else is opened.
pub fn open(context: &SinkContext<'_>, options: &serde_json::Value) -> Result<Box<dyn Sink>> {
    let options: McapOptions = serde_json::from_value(options.clone())
        .map_err(|e| RtError::option("mcap", e.to_string()))?;
    Ok(Box::new(McapRecorder::create_with_scene(
        &options,
        context.info,
        context.plan,
    )?))
}

impl Sink for McapRecorder {
    fn sample(&mut self, s: &Sample) {
        McapRecorder::sample(self, s);
    }

    fn event(&mut self, e: &Event<'_>) {
        McapRecorder::event(self, e.time, e.level, e.text);
    }

    fn finish(self: Box<Self>) -> serde_json::Value {
        serde_json::to_value(McapRecorder::finish(*self)).unwrap_or_default()
    }

    fn discard(self: Box<Self>) {
        McapRecorder::discard(*self);
    }
}

/// Opens `path` for writing (its folder created): a new file, or an existing one replaced if
/// `overwrite`.
fn open_file(path: &Path, overwrite: bool) -> Result<File> {
    let shown = path.display();
    if path.is_dir() {
        return Err(RtError::option(
            "mcap",
            format!("{shown} is a directory; give a file name, e.g. run.mcap"),
        ));
    }
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .map_err(|e| RtError::io(format!("mcap {shown}: cannot create its folder"), &e))?;
    }
    let mut open = OpenOptions::new();
    open.write(true);
    if overwrite {
        open.create(true).truncate(true);
    } else {
        open.create_new(true);
    }
    open.open(path).map_err(|e| {
        if e.kind() == ErrorKind::AlreadyExists {
            RtError::option(
                "mcap",
                format!("{shown} exists; choose another file, or allow replacing it (--force)"),
            )
        } else {
            RtError::io(format!("mcap {shown}: cannot create it"), &e)
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::start_text;
    use hilcontact_core::{Plan, Scenario};

    /// paper-table1, 1.3 s, with the compensator `kind`.
    fn plan(kind: &str) -> Plan {
        let path = format!(
            "{}/../../python/hilcontact/scenarios/paper-table1.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let text = std::fs::read_to_string(&path).expect("preset");
        let mut value: toml::Value = toml::from_str(&text).expect("toml");
        value["simulation"]["duration"] = toml::Value::Float(1.3);
        value["compensator"] = toml::Value::Table(toml::map::Map::from_iter([(
            "kind".to_string(),
            toml::Value::String(kind.into()),
        )]));
        let scenario: Scenario = value.try_into().expect("scenario");
        scenario.resolve().expect("plan")
    }

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("hilcontact-recording-{}", std::process::id()));
        let _ = std::fs::create_dir_all(&dir);
        let path = dir.join(name);
        let _ = std::fs::remove_file(&path);
        path
    }

    /// Messages per topic of a finished file, read back with the mcap crate's reader, and the
    /// summary's statistics.
    fn counts(path: &Path) -> (BTreeMap<String, u64>, mcap::Summary) {
        let bytes = std::fs::read(path).expect("read");
        let mut counts = BTreeMap::new();
        let mut last = 0;
        for message in mcap::MessageStream::new(&bytes).expect("stream") {
            let message = message.expect("message");
            assert!(message.log_time >= last, "time order");
            last = message.log_time;
            *counts.entry(message.channel.topic.clone()).or_insert(0) += 1;
        }
        let summary = mcap::Summary::read(&bytes)
            .expect("summary")
            .expect("a summary");
        (counts, summary)
    }

    #[test]
    fn recording_wrench_stamped_is_byte_exact() {
        let mut cdr = Cdr::new();
        let force = Vector3::new(1.0, -2.0, 0.5);
        let torque = Vector3::new(0.25, 0.0, -8.0);
        cdr.wrench_stamped(1_500_000_000, "sensor", &force, &torque);
        let mut expected = vec![0x00, 0x01, 0x00, 0x00]; // CDR, little endian
        expected.extend(1i32.to_le_bytes()); // stamp.sec          @0
        expected.extend(500_000_000u32.to_le_bytes()); // stamp.nanosec @4
        expected.extend(7u32.to_le_bytes()); // frame_id length with NUL @8
        expected.extend(b"sensor\0"); // @12..19
        expected.extend([0u8; 5]); // padding to 24 (float64 alignment)
        for v in [1.0f64, -2.0, 0.5, 0.25, 0.0, -8.0] {
            expected.extend(v.to_le_bytes()); // @24..72
        }
        assert_eq!(cdr.bytes(), expected.as_slice());
        assert_eq!(cdr.bytes().len(), 4 + 72);
    }

    #[test]
    fn recording_log_and_tf_layouts() {
        let mut cdr = Cdr::new();
        cdr.log(3, EventLevel::Warn, "ab", "x");
        let mut expected = vec![0, 1, 0, 0];
        expected.extend(0i32.to_le_bytes());
        expected.extend(3u32.to_le_bytes());
        expected.push(30); // level @8
        expected.extend([0u8; 3]); // align the string length to 4 → @12
        expected.extend(3u32.to_le_bytes());
        expected.extend(b"ab\0"); // @16..19
        expected.push(0); // → @20
        expected.extend(2u32.to_le_bytes());
        expected.extend(b"x\0"); // @24..26
        expected.extend([0u8; 2]); // → @28
        expected.extend(1u32.to_le_bytes());
        expected.push(0); // file ""
        expected.extend([0u8; 3]);
        expected.extend(1u32.to_le_bytes());
        expected.push(0); // function ""
        expected.extend([0u8; 3]);
        expected.extend(0u32.to_le_bytes()); // line
        assert_eq!(cdr.bytes(), expected.as_slice());

        let q = UnitQuaternion::identity();
        cdr.tf_message(0, "t", "sensor", &Vector3::new(1.0, 2.0, 3.0), &q);
        // count 4, stamp 8, "t" 4+2 → 18, "sensor" at 20: 4+7 → 31, pad to 32, 7 float64
        assert_eq!(cdr.bytes().len(), 4 + 32 + 56);
        assert_eq!(&cdr.bytes()[4..8], &1u32.to_le_bytes());
        assert_eq!(&cdr.bytes()[4 + 32..4 + 40], &1.0f64.to_le_bytes());
        assert_eq!(&cdr.bytes()[4 + 80..4 + 88], &1.0f64.to_le_bytes()); // w
    }

    #[test]
    fn recording_schemas_name_their_dependencies() {
        for spec in CHANNELS {
            let text = schema_text(spec.schema);
            assert!(!text.is_empty(), "{}", spec.schema);
            if text.contains("std_msgs/Header header") {
                assert!(text.contains("MSG: std_msgs/Header\n"), "{}", spec.schema);
                assert!(
                    text.contains("MSG: builtin_interfaces/Time\n"),
                    "{}",
                    spec.schema
                );
            }
        }
        let wrench = schema_text("geometry_msgs/msg/WrenchStamped");
        assert!(wrench.starts_with("std_msgs/Header header\nWrench wrench\n"));
        assert!(wrench.contains(&format!("{SEPARATOR}MSG: geometry_msgs/Vector3\n")));
    }

    #[test]
    fn a_runs_recording_draws_the_scene_as_the_live_view_does() {
        let plan = plan("pida");
        let info = RunInfo::new(&plan, false);
        let path = temp("scene.mcap");
        let mut recorder = McapRecorder::create_with_scene(&McapOptions::new(&path), &info, &plan)
            .expect("create");
        let n = 100;
        for s in samples(n, plan.period) {
            recorder.sample(&s);
        }
        let stats = recorder.finish();
        assert!(stats.complete, "{stats:?}");
        let (seen, summary) = counts(&path);
        // 30 Hz of run time at 1 ms: ticks 0, 33, 66, 99, on both scene channels
        let every = Scene::new(&plan, ContactSource::Truth).every;
        assert_eq!(every, 33);
        let expected = (n as u64 - 1) / every + 1;
        for spec in SCENE_CHANNELS {
            assert_eq!(seen[spec.topic], expected, "{}", spec.topic);
            let channel = summary
                .channels
                .values()
                .find(|c| c.topic == spec.topic)
                .expect("channel");
            let schema = channel.schema.as_ref().expect("schema");
            assert_eq!(schema.name, spec.schema);
            assert_eq!(
                std::str::from_utf8(&schema.data).unwrap(),
                scene_schema_text(spec.schema)
            );
        }
        // every per-tick channel is there as before
        assert_eq!(seen["/hil/measured_wrench"], n as u64);
        // and a recording created without the scene has none
        let bare = temp("bare.mcap");
        let mut recorder = McapRecorder::create(&McapOptions::new(&bare), &info).expect("create");
        for s in samples(n, plan.period) {
            recorder.sample(&s);
        }
        recorder.finish();
        assert!(!counts(&bare).0.contains_key("/hil/scene"));
    }

    fn samples(n: usize, period: f64) -> Vec<Sample> {
        (0..n)
            .map(|k| {
                let mut s = Sample::default();
                s.record.time = k as f64 * period;
                s.record.measured_force = Vector3::new(k as f64, 0.0, 0.0);
                s.wake_latency = 1e-5;
                s
            })
            .collect()
    }

    #[test]
    fn recording_writes_every_channel_per_tick() {
        let plan = plan("pida");
        let path = temp("every.mcap");
        let info = RunInfo::new(&plan, true);
        let mut recorder = McapRecorder::create(&McapOptions::new(&path), &info).expect("create");
        recorder.event(0.0, EventLevel::Info, &start_text(&info));
        let n = 1201; // 1.2 s at 1 kHz: chunks at 0.5 and 1.0 s, then the last
        for s in samples(n, plan.period) {
            recorder.sample(&s);
        }
        recorder.event(1.2, EventLevel::Info, "end");
        let stats = recorder.finish();
        assert!(stats.complete && stats.write_errors == 0, "{stats:?}");
        // the first chunk (schemas, /tf_static), then 0-0.5, 0.5-1.0, 1.0-1.2 s
        assert_eq!(stats.chunks, 4, "{stats:?}");
        let (counts, summary) = counts(&path);
        for spec in CHANNELS {
            let expected = match spec.scope {
                ChannelScope::Events => 2,
                ChannelScope::Once => 1,
                _ => n as u64,
            };
            assert_eq!(counts.get(spec.topic), Some(&expected), "{}", spec.topic);
        }
        let statistics = summary.stats.expect("statistics");
        assert_eq!(statistics.message_count, stats.messages);
        assert_eq!(statistics.chunk_count, 4);
        assert_eq!(stats.bytes, std::fs::metadata(&path).expect("size").len());
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn recording_of_a_simulation_has_no_timing_and_estimates_only_when_identified() {
        let plan = plan("none");
        let path = temp("sim.mcap");
        let recorder = McapRecorder::create(&McapOptions::new(&path), &RunInfo::new(&plan, false))
            .expect("create");
        let (output, records) = hilcontact_core::sim::simulate_plan_with_records(&plan);
        let stats = recorder.record_run(&records, &output.metrics);
        assert!(stats.complete, "{stats:?}");
        let (counts, _) = counts(&path);
        assert_eq!(
            counts.get("/hil/measured_wrench"),
            Some(&(records.len() as u64))
        );
        assert_eq!(counts.get("/hil/events"), Some(&2));
        assert!(!counts.contains_key("/hil/loop_timing"));
        assert!(!counts.contains_key("/hil/estimates"));
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn recording_refuses_an_existing_file_unless_told_to_replace_it() {
        let plan = plan("none");
        let info = RunInfo::new(&plan, false);
        let path = temp("exists.mcap");
        std::fs::write(&path, b"mine").expect("write");
        let err = McapRecorder::create(&McapOptions::new(&path), &info)
            .err()
            .expect("refused");
        assert!(err.to_string().contains("exists"), "{err}");
        assert_eq!(std::fs::read(&path).expect("read"), b"mine");
        let options = McapOptions {
            overwrite: true,
            ..McapOptions::new(&path)
        };
        let recorder = McapRecorder::create(&options, &info).expect("replaced");
        assert!(recorder.finish().complete);
        // a folder that cannot be created: one error naming the path
        let blocked = path.join("sub").join("x.mcap");
        let err = McapRecorder::create(&McapOptions::new(&blocked), &info)
            .err()
            .expect("refused");
        assert!(
            err.to_string().contains(&blocked.display().to_string()),
            "{err}"
        );
        let bad = McapOptions {
            chunk_interval: 0.0,
            ..McapOptions::new(temp("never.mcap"))
        };
        assert!(McapRecorder::create(&bad, &info).is_err());
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn recording_options_parse_with_their_defaults() {
        let o: crate::RuntimeOptions =
            toml::from_str("[mcap]\npath = \"runs/rt1.mcap\"\n").expect("toml");
        assert_eq!(o.mcap, Some(McapOptions::new("runs/rt1.mcap")));
        assert_eq!(crate::RuntimeOptions::default().mcap, None);
        let o: crate::RuntimeOptions = serde_json::from_str(
            r#"{"mcap": {"path": "a.mcap", "overwrite": true, "chunk_interval": 1.0}}"#,
        )
        .expect("json");
        let m = o.mcap.expect("mcap");
        assert!(m.overwrite && m.chunk_interval == 1.0);
        assert!(
            serde_json::from_str::<crate::RuntimeOptions>(r#"{"mcap": {"file": "a"}}"#).is_err()
        );
    }

    #[test]
    fn recording_cut_after_a_chunk_reads_up_to_it() {
        // what a SIGKILL leaves: the bytes written out so far, without summary or footer
        let plan = plan("none");
        let path = temp("cut.mcap");
        let mut recorder =
            McapRecorder::create(&McapOptions::new(&path), &RunInfo::new(&plan, false))
                .expect("create");
        for s in samples(700, plan.period) {
            recorder.sample(&s);
        }
        // 0-0.5 s written out, 0.5-0.7 s still in memory
        let bytes = std::fs::read(&path).expect("read");
        std::mem::forget(recorder); // no drop: as if killed
        let mut ticks = 0;
        let options = mcap::read::Options::IgnoreEndMagic.into();
        for message in mcap::MessageStream::new_with_options(&bytes, options).expect("stream") {
            match message {
                Ok(m) if m.channel.topic == "/hil/measured_wrench" => ticks += 1,
                Ok(_) => {}
                Err(_) => break,
            }
        }
        assert_eq!(ticks, 500);
        let _ = std::fs::remove_file(&path);
    }
}
