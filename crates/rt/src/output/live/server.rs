//! The live view's server (cargo feature `live`): the Foxglove SDK's WebSocket server, its
//! channels, services and listener, and the sink the writer thread feeds.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use foxglove::websocket::service::{Request, Service, ServiceSchema};
use foxglove::websocket::{Capability, ChannelView, Client, ClientChannel, ServerListener};
use foxglove::{
    ChannelBuilder, Context, PartialMetadata, RawChannel, Schema, WebSocketServer,
    WebSocketServerHandle,
};
use serde::Serialize;
use serde_json::Value;

use super::clients::{self, ClientLog};
use super::{LiveOptions, FACILITY_ABSENT, FACILITY_CHANNELS, FACILITY_RUN};
use crate::error::{Result, RtError};
use crate::output::mcap::{schema_text, Cdr, ChannelScope, CHANNELS, FRAME_SENSOR, FRAME_TARGET};
use crate::output::scene::{scene_schema_text, ContactSource, Scene, SCENE_CHANNELS};
use crate::output::{time_ns, Event, EventLevel, RunControl, RunInfo, Sink, SinkContext};
use crate::report::Sample;

/// The operator's stop service.
pub const STOP_SERVICE: &str = "/hilcontact/stop";
/// The operator's mark service.
pub const MARK_SERVICE: &str = "/hilcontact/mark";
/// How long the server stays up after the run's end while viewers are connected.
const LINGER: Duration = Duration::from_millis(500);
/// Longest wait for the server's tasks to end after the run.
const SHUTDOWN_WAIT: Duration = Duration::from_secs(1);
/// Longest mark label kept, characters (a longer one is cut).
const MAX_LABEL: usize = 200;

/// What the server's threads count (listener and services), read by the sink's report.
#[derive(Debug, Default)]
struct Counters {
    connections: AtomicU64,
    clients: AtomicU64,
    peak_clients: AtomicU64,
    subscriptions: AtomicU64,
    peak_subscriptions: AtomicU64,
    /// Client channel advertisements and messages: refused (no `clientPublish`), counted.
    client_publish: AtomicU64,
    stop_calls: AtomicU64,
    mark_calls: AtomicU64,
    refused_calls: AtomicU64,
}

fn up(counter: &AtomicU64, peak: Option<&AtomicU64>) {
    let n = counter.fetch_add(1, Ordering::Relaxed) + 1;
    if let Some(peak) = peak {
        peak.fetch_max(n, Ordering::Relaxed);
    }
}

fn down(counter: &AtomicU64) {
    let _ = counter.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1));
}

struct Listener(Arc<Counters>);

impl ServerListener for Listener {
    fn on_client_connect(&self) {
        up(&self.0.connections, None);
        up(&self.0.clients, Some(&self.0.peak_clients));
    }
    fn on_client_disconnect(&self) {
        down(&self.0.clients);
    }
    fn on_subscribe(&self, _: Client, _: ChannelView) {
        up(&self.0.subscriptions, Some(&self.0.peak_subscriptions));
    }
    fn on_unsubscribe(&self, _: Client, _: ChannelView) {
        down(&self.0.subscriptions);
    }
    fn on_client_advertise(&self, _: Client, _: &ClientChannel) {
        up(&self.0.client_publish, None);
    }
    fn on_message_data(&self, _: Client, _: &ClientChannel, _: &[u8]) {
        up(&self.0.client_publish, None);
    }
}

/// What the live view reports (`metrics.json` `realtime.live`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct LiveReport {
    /// The address served, `host:port`.
    pub address: String,
    /// The port bound (the one asked for, or the one chosen for 0).
    pub port: u16,
    /// Whether the operator's actions were accepted.
    pub control: bool,
    /// Messages published (to every subscribed client; each client's queue keeps at most
    /// `backlog` of them, the oldest dropped when full).
    pub messages: u64,
    /// Scene messages among them (`/hil/scene` and `/tf`).
    pub scene_messages: u64,
    /// Shapes' contact points the scene did not draw (beyond
    /// [`crate::output::scene::MAX_SCENE_POINTS`] in a message), summed over its messages.
    pub scene_points_dropped: u64,
    /// Meshes the scene draws as their bounding box (over
    /// [`crate::output::scene::MAX_MESH_TRIANGLES`] triangles).
    pub scene_meshes_boxed: u64,
    /// Clients that connected.
    pub connections: u64,
    /// Most clients connected at once.
    pub peak_clients: u64,
    /// Most subscriptions at once (all clients).
    pub peak_subscriptions: u64,
    /// Client advertisements and messages on channels (refused: clients may not publish), as
    /// the listener and the SDK's log see them.
    pub client_publish_refused: u64,
    /// Client messages the server answered with an error or warning status (unparsable, a
    /// subscription to a channel that does not exist, publishing, ...), as the SDK logs them;
    /// 0 when `addresses_known` is false. A call of a service that does not exist is answered
    /// but not logged by the SDK: not counted.
    pub refused_input: u64,
    /// Stop calls accepted.
    pub stop_calls: u64,
    /// Mark calls accepted.
    pub mark_calls: u64,
    /// Calls refused (no `--live-control`).
    pub refused_calls: u64,
    /// Events of the live view (marks, calls, connections) dropped because
    /// [`crate::output::MAX_PENDING_EVENTS`] were waiting for the writer already
    /// ([`RunControl::events_dropped`]): they reached no output.
    pub events_dropped: u64,
    /// Whether clients are known by address (the SDK's log is read: [`clients`]); else the
    /// connections and calls are logged by the SDK's client id.
    pub addresses_known: bool,
    /// Messages from clients the server could not parse (garbage frames, unknown ops), as
    /// the SDK logs them; 0 when `addresses_known` is false.
    pub invalid_messages: u64,
    /// Connections dropped at the WebSocket handshake (not a WebSocket client), as the SDK
    /// logs them; 0 when `addresses_known` is false.
    pub failed_handshakes: u64,
    /// The SDK's "outbox for client ... full" lines: > 0 means at least one client's queue was
    /// full and its oldest messages were dropped. Not a count of messages nor of clients: the
    /// SDK (0.30.3) counts neither and logs this at most once per 30 s for the whole process;
    /// 0 when `addresses_known` is false.
    pub outbox_full_reports: u64,
    /// The clients (addresses) of those lines.
    pub lossy_clients: Vec<String>,
    /// The per-client backlog, messages.
    pub backlog: u32,
}

/// The live view: the server and its channels, fed by the writer thread.
pub struct LiveSink {
    server: Option<WebSocketServerHandle>,
    _context: Arc<Context>,
    channels: Vec<Option<Arc<RawChannel>>>,
    scene_channels: Vec<Arc<RawChannel>>,
    /// [`FACILITY_CHANNELS`]' channels (a facility's run only).
    facility_channels: Vec<Arc<RawChannel>>,
    scene: Scene,
    cdr: Cdr,
    info: RunInfo,
    control: Arc<RunControl>,
    counters: Arc<Counters>,
    clients: Arc<ClientLog>,
    speed: f64,
    wall_start: Option<Instant>,
    tick: u64,
    last_ns: u64,
    report: LiveReport,
}

impl LiveSink {
    /// Binds the server (a port in use refuses the start, naming it), advertises the channels
    /// of the run and the services.
    pub fn start(context: &SinkContext<'_>, options: &LiveOptions) -> Result<Self> {
        let info = context.info.clone();
        let control = info.control.clone();
        let counters = Arc::new(Counters::default());
        let clients = clients::watch(control.clone());
        let ctx = Context::new();
        let raw = |topic: &str, schema: &str, text: String, frame: &str, doc: &str| {
            let mut metadata = BTreeMap::new();
            if !frame.is_empty() {
                metadata.insert("frame_id".to_string(), frame.to_string());
            }
            metadata.insert("description".to_string(), doc.to_string());
            ChannelBuilder::new(topic)
                .context(&ctx)
                .message_encoding("cdr")
                .schema(Schema::new(schema, "ros2msg", text.into_bytes()))
                .metadata(metadata)
                .build_raw()
                .map_err(|e| RtError::io_other(format!("live channel {topic}"), e.to_string()))
        };
        let facility = info.kind == FACILITY_RUN;
        let mut channels = Vec::with_capacity(CHANNELS.len());
        for spec in CHANNELS {
            let wanted = match spec.scope {
                _ if facility && FACILITY_ABSENT.contains(&spec.topic) => false,
                ChannelScope::Estimates => info.estimates_contact,
                ChannelScope::Realtime => info.realtime() || facility,
                _ => true,
            };
            channels.push(if wanted {
                Some(raw(
                    spec.topic,
                    spec.schema,
                    schema_text(spec.schema),
                    spec.frame,
                    spec.doc,
                )?)
            } else {
                None
            });
        }
        let mut scene_channels = Vec::new();
        for spec in SCENE_CHANNELS {
            scene_channels.push(raw(
                spec.topic,
                spec.schema,
                scene_schema_text(spec.schema),
                spec.frame,
                spec.doc,
            )?);
        }
        let mut facility_channels = Vec::new();
        if facility {
            for spec in FACILITY_CHANNELS {
                let text = schema_text(spec.schema);
                facility_channels.push(raw(spec.topic, spec.schema, text, spec.frame, spec.doc)?);
            }
        }
        let services = services(options.control, &control, &counters, &clients);
        let server = WebSocketServer::new()
            .context(&ctx)
            .name(format!("hilcontact {}", info.scenario))
            .bind(options.host.clone(), options.port)
            .capabilities([Capability::Time])
            .supported_encodings(["json"])
            .services(services)
            .message_backlog_size(options.backlog as usize)
            .listener(Arc::new(Listener(counters.clone())))
            .start_blocking()
            .map_err(|e| {
                RtError::option(
                    "live",
                    format!("cannot serve on {}:{}: {e}", options.host, options.port),
                )
            })?;
        let port = server.port();
        // where to connect, once bound (a refused address or port never gets here)
        let shown = if options.host.contains(':') {
            format!("[{}]", options.host)
        } else {
            options.host.clone()
        };
        eprintln!(
            "live view: ws://{shown}:{port} ({}{})",
            if options.control {
                "stop and mark accepted"
            } else {
                "view only: no --live-control"
            },
            if options.wait > 0.0 {
                format!("; waiting up to {} s for a viewer", options.wait)
            } else {
                String::new()
            }
        );
        let advertised =
            channels.iter().flatten().count() + scene_channels.len() + facility_channels.len();
        let begun = Instant::now();
        while begun.elapsed().as_secs_f64() < options.wait
            && (counters.subscriptions.load(Ordering::Relaxed) as usize) < advertised
        {
            std::thread::sleep(Duration::from_millis(10));
        }
        let mut sink = LiveSink {
            server: Some(server),
            _context: ctx,
            channels,
            scene_channels,
            facility_channels,
            scene: Scene::new(context.plan, ContactSource::of(&info)),
            cdr: Cdr::new(),
            info,
            control,
            counters,
            clients,
            speed: options.speed,
            wall_start: None,
            tick: 0,
            last_ns: 0,
            report: LiveReport {
                address: format!("{}:{port}", options.host),
                port,
                control: options.control,
                backlog: options.backlog,
                ..LiveReport::default()
            },
        };
        // the sensor frame in t, as the recording's /tf_static
        let i = CHANNELS.iter().position(|c| c.topic == "/tf_static");
        if let Some(Some(channel)) = i.map(|i| sink.channels[i].clone()) {
            let c = &sink.info;
            sink.cdr.tf_message(
                0,
                FRAME_TARGET,
                FRAME_SENSOR,
                &c.sensor_position,
                &c.sensor_orientation,
            );
            channel.log_with_meta(sink.cdr.bytes(), PartialMetadata::with_log_time(0));
            sink.report.messages += 1;
        }
        Ok(sink)
    }

    /// Publishes the encoded message on channel `i` of [`CHANNELS`] (if the run has it).
    fn put(&mut self, i: usize, t_ns: u64) {
        if let Some(channel) = &self.channels[i] {
            channel.log_with_meta(self.cdr.bytes(), PartialMetadata::with_log_time(t_ns));
            self.report.messages += 1;
        }
    }

    /// Whether the samples are a simulation's, replayed at [`LiveOptions::speed`] (a
    /// real-time run's and a facility's are shown as they happen).
    fn replay(&self) -> bool {
        self.info.kind == "simulation"
    }

    /// A simulation's replay waits until the record's time at the replay speed; a stop from
    /// the operator ends it.
    fn pace(&mut self, time: f64) {
        let start = *self.wall_start.get_or_insert_with(Instant::now);
        let due = start + Duration::from_secs_f64((time / self.speed).max(0.0));
        while !self.control.operator_stop_requested() {
            let now = Instant::now();
            if now >= due {
                break;
            }
            std::thread::sleep((due - now).min(Duration::from_millis(50)));
        }
    }

    fn finish_report(&mut self) -> LiveReport {
        let c = &self.counters;
        let r = &mut self.report;
        r.connections = c.connections.load(Ordering::Relaxed);
        r.peak_clients = c.peak_clients.load(Ordering::Relaxed);
        r.peak_subscriptions = c.peak_subscriptions.load(Ordering::Relaxed);
        r.client_publish_refused = c.client_publish.load(Ordering::Relaxed)
            + self.clients.publish_refused.load(Ordering::Relaxed);
        r.refused_input = self.clients.refused_input.load(Ordering::Relaxed);
        r.stop_calls = c.stop_calls.load(Ordering::Relaxed);
        r.mark_calls = c.mark_calls.load(Ordering::Relaxed);
        r.refused_calls = c.refused_calls.load(Ordering::Relaxed);
        r.events_dropped = self.control.events_dropped();
        r.scene_points_dropped = self.scene.points_dropped;
        r.scene_meshes_boxed = self.scene.meshes_boxed;
        r.addresses_known = clients::addresses_known();
        r.invalid_messages = self.clients.invalid_messages.load(Ordering::Relaxed);
        r.failed_handshakes = self.clients.failed_handshakes.load(Ordering::Relaxed);
        r.outbox_full_reports = self.clients.outbox_full.load(Ordering::Relaxed);
        r.lossy_clients = self.clients.lossy_clients();
        r.clone()
    }

    fn shutdown(&mut self) {
        // the SDK does not flush its per-client queues when stopped: give the viewers a moment
        // to receive the run's last messages (the loop has ended; only the writer waits)
        if self.counters.clients.load(Ordering::Relaxed) > 0 {
            std::thread::sleep(LINGER);
        }
        if let Some(server) = self.server.take() {
            // a stalled client can keep its connection's task from ending: wait for the
            // server's tasks at most SHUTDOWN_WAIT, then leave them to end in the background
            let handle = server.stop();
            let (done, ended) = std::sync::mpsc::channel();
            let waiter = std::thread::Builder::new()
                .name("live-shutdown".into())
                .spawn(move || {
                    handle.wait_blocking();
                    let _ = done.send(());
                });
            if waiter.is_ok() {
                let _ = ended.recv_timeout(SHUTDOWN_WAIT);
            }
        }
    }
}

/// The stop and mark services: each call is logged (stderr, and an event for the run's sinks
/// through [`RunControl`]) with the client (its id, and its address when known:
/// [`ClientLog::who`]); refused without `control`.
fn services(
    control_on: bool,
    run: &Arc<RunControl>,
    counters: &Arc<Counters>,
    clients: &Arc<ClientLog>,
) -> Vec<Service> {
    let who = {
        let clients = clients.clone();
        move |request: &Request| {
            let id = u32::from(request.client_id());
            if clients::addresses_known() {
                format!("client {id} ({})", clients.who())
            } else {
                format!("client {id}")
            }
        }
    };
    let (r, c, name) = (run.clone(), counters.clone(), who.clone());
    let stop = Service::builder(STOP_SERVICE, ServiceSchema::new("hilcontact/Stop")).handler_fn(
        move |request: Request| -> std::result::Result<Vec<u8>, String> {
            let who = name(&request);
            if !control_on {
                up(&c.refused_calls, None);
                let text =
                    format!("live view: {STOP_SERVICE} refused from {who} (no --live-control)");
                eprintln!("{text}");
                r.push_event(EventLevel::Warn, text);
                return Err("refused: the run was started without --live-control".into());
            }
            up(&c.stop_calls, None);
            let text = format!("live view: operator stop from {who}");
            eprintln!("{text}");
            r.push_event(EventLevel::Error, text);
            r.request_operator_stop();
            Ok(br#"{"stopping":true}"#.to_vec())
        },
    );
    let (r, c) = (run.clone(), counters.clone());
    let mark = Service::builder(MARK_SERVICE, ServiceSchema::new("hilcontact/Mark")).handler_fn(
        move |request: Request| -> std::result::Result<Vec<u8>, String> {
            let who = who(&request);
            if !control_on {
                up(&c.refused_calls, None);
                let text =
                    format!("live view: {MARK_SERVICE} refused from {who} (no --live-control)");
                eprintln!("{text}");
                r.push_event(EventLevel::Warn, text);
                return Err("refused: the run was started without --live-control".into());
            }
            up(&c.mark_calls, None);
            let label = serde_json::from_slice::<Value>(request.payload())
                .ok()
                .and_then(|v| v.get("label").and_then(Value::as_str).map(str::to_string))
                .unwrap_or_default();
            let label: String = label
                .chars()
                .filter(|ch| !ch.is_control())
                .take(MAX_LABEL)
                .collect();
            r.push_event(EventLevel::Info, format!("mark from {who}: {label}"));
            Ok(br#"{"marked":true}"#.to_vec())
        },
    );
    vec![stop, mark]
}

impl Sink for LiveSink {
    fn paced(&self) -> bool {
        self.replay()
    }

    fn sample(&mut self, s: &Sample) {
        if self.replay() {
            if self.control.operator_stop_requested() {
                return; // the operator stopped the replay
            }
            self.pace(s.record.time);
        }
        let r = &s.record;
        let t = time_ns(r.time);
        self.last_ns = self.last_ns.max(t);
        self.cdr
            .wrench_stamped(t, FRAME_SENSOR, &r.measured_force, &r.measured_moment);
        self.put(0, t);
        self.cdr
            .wrench_stamped(t, FRAME_SENSOR, &r.applied_force, &r.applied_moment);
        self.put(1, t);
        self.cdr.vector3_stamped(t, FRAME_TARGET, &r.contact_force);
        self.put(2, t);
        self.cdr
            .pose_stamped(t, FRAME_TARGET, &r.tip_position, &r.orientation);
        self.put(3, t);
        self.cdr.pose_stamped(
            t,
            FRAME_TARGET,
            &r.actual_tip_position,
            &r.actual_orientation,
        );
        self.put(4, t);
        self.cdr
            .twist_stamped(t, FRAME_TARGET, &r.tip_velocity, &r.angular_velocity);
        self.put(5, t);
        self.cdr.twist_stamped(
            t,
            FRAME_TARGET,
            &r.actual_tip_velocity,
            &r.actual_angular_velocity,
        );
        self.put(6, t);
        self.cdr.header_f64s(t, "", &[r.energy, r.observed_energy]);
        self.put(7, t);
        self.cdr
            .header_f64s(t, "", &[r.stiffness_estimate, r.damping_estimate]);
        self.put(8, t);
        self.cdr
            .header_f64s(t, "", &[s.wake_latency, s.sensor_age, s.robot_age]);
        self.put(9, t);
        if let Some(channel) = self.facility_channels.first() {
            self.cdr.vector3_stamped(t, FRAME_TARGET, &r.contact_moment);
            channel.log_with_meta(self.cdr.bytes(), PartialMetadata::with_log_time(t));
            self.report.messages += 1;
        }
        if self.scene.due(self.tick) {
            let meta = PartialMetadata::with_log_time(t);
            self.scene_channels[0].log_with_meta(self.scene.markers(t, s), meta);
            self.scene_channels[1].log_with_meta(self.scene.transforms(t, s), meta);
            self.report.messages += 2;
            self.report.scene_messages += 2;
            if let Some(server) = &self.server {
                server.broadcast_time(t);
            }
        }
        self.tick += 1;
    }

    fn event(&mut self, e: &Event<'_>) {
        let t = time_ns(e.time).max(self.last_ns);
        self.cdr.log(t, e.level, "hilcontact", e.text);
        self.put(10, t);
    }

    fn finish(mut self: Box<Self>) -> Value {
        let report = self.finish_report();
        self.shutdown();
        serde_json::to_value(report).unwrap_or(Value::Null)
    }

    fn discard(mut self: Box<Self>) {
        self.shutdown();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_channel_indices_are_those_of_the_recording() {
        let topics: Vec<&str> = CHANNELS.iter().map(|c| c.topic).collect();
        assert_eq!(
            topics[..11],
            [
                "/hil/measured_wrench",
                "/hil/applied_wrench",
                "/hil/contact_force",
                "/hil/tip/commanded",
                "/hil/tip/actual",
                "/hil/tip/commanded_velocity",
                "/hil/tip/actual_velocity",
                "/hil/energy",
                "/hil/estimates",
                "/hil/loop_timing",
                "/hil/events",
            ]
        );
    }
}
