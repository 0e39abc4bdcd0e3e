//! The live view against a real run on loopback: a minimal Foxglove WebSocket client
//! (`foxglove.sdk.v1`, the SDK's name of `foxglove.websocket.v1`, over `tungstenite`) subscribes to every channel of a run of the
//! loop against the emulated facility, receives every tick of the force channel, the scene, and
//! stops the run through `/hilcontact/stop`; without `live.control` the stop is refused; bad
//! input from another client changes nothing.
#![cfg(feature = "live")]

mod common;

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use common::{delayed, free_tcp_port, loopback_options, start_both};
use hilcontact_core::compensator::CompensatorConfig;
use hilcontact_rt::output::live::LiveOptions;
use serde_json::{json, Value};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

/// A viewer: the socket, the advertised channels (id -> topic) and services (name -> id).
struct Viewer {
    ws: WebSocket<TcpStream>,
    channels: HashMap<u64, String>,
    services: HashMap<String, u64>,
    /// subscription id -> topic
    subscriptions: HashMap<u32, String>,
}

/// What a viewer saw: per topic the log times (ns) of its messages, the service responses and
/// failures (JSON), and the `/hil/events` texts' raw payloads.
#[derive(Debug, Default)]
struct Seen {
    times: BTreeMap<String, Vec<u64>>,
    payloads: BTreeMap<String, Vec<Vec<u8>>>,
    responses: Vec<u32>,
    failures: Vec<Value>,
    clock: Vec<u64>,
}

impl Viewer {
    /// Connects (retrying for 20 s: the server binds when the run starts) and reads the
    /// advertisements.
    fn connect(port: u16) -> Viewer {
        let addr = SocketAddr::from(([127, 0, 0, 1], port));
        let begun = Instant::now();
        let stream = loop {
            match TcpStream::connect_timeout(&addr, Duration::from_secs(1)) {
                Ok(s) => break s,
                Err(e) if begun.elapsed() < Duration::from_secs(20) => {
                    let _ = e;
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => panic!("no live view on {addr}: {e}"),
            }
        };
        stream
            .set_read_timeout(Some(Duration::from_secs(20)))
            .unwrap();
        let mut request = format!("ws://{addr}/").into_client_request().unwrap();
        request
            .headers_mut()
            .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
        let (ws, response) = tungstenite::client::client(request, stream).expect("handshake");
        assert_eq!(
            response.headers()["Sec-WebSocket-Protocol"],
            "foxglove.sdk.v1"
        );
        let mut v = Viewer {
            ws,
            channels: HashMap::new(),
            services: HashMap::new(),
            subscriptions: HashMap::new(),
        };
        while v.channels.is_empty() || v.services.is_empty() {
            let Message::Text(text) = v.ws.read().expect("advertisements") else {
                continue;
            };
            let m: Value = serde_json::from_str(&text).unwrap();
            match m["op"].as_str() {
                Some("advertise") => {
                    for c in m["channels"].as_array().unwrap() {
                        v.channels.insert(
                            c["id"].as_u64().unwrap(),
                            c["topic"].as_str().unwrap().into(),
                        );
                    }
                }
                Some("advertiseServices") => {
                    for s in m["services"].as_array().unwrap() {
                        v.services.insert(
                            s["name"].as_str().unwrap().into(),
                            s["id"].as_u64().unwrap(),
                        );
                    }
                }
                _ => {}
            }
        }
        v
    }

    fn send_json(&mut self, v: Value) {
        self.ws.send(Message::Text(v.to_string().into())).unwrap();
    }

    fn subscribe_all(&mut self) {
        let mut subs = Vec::new();
        for (i, (id, topic)) in self.channels.iter().enumerate() {
            subs.push(json!({"id": i as u32, "channelId": id}));
            self.subscriptions.insert(i as u32, topic.clone());
        }
        self.send_json(json!({"op": "subscribe", "subscriptions": subs}));
    }

    /// A service call (binary op 2: service id, call id, encoding, payload).
    fn call(&mut self, service: &str, call: u32, payload: &[u8]) {
        let id = self.services[service] as u32;
        let mut b = vec![2u8];
        b.extend_from_slice(&id.to_le_bytes());
        b.extend_from_slice(&call.to_le_bytes());
        b.extend_from_slice(&4u32.to_le_bytes());
        b.extend_from_slice(b"json");
        b.extend_from_slice(payload);
        self.ws.send(Message::Binary(b.into())).unwrap();
    }

    /// Reads until the server closes; calls `stop` (once) when the force channel passes
    /// `stop_at` s of run time.
    fn read_all(self, stop_at: Option<f64>) -> Seen {
        self.read_all_calling(stop_at.map(|at| (at, "/hilcontact/stop", b"{}".to_vec())))
    }

    /// Reads until the server closes; calls `service` with `payload` (once, call id 7) when
    /// the force channel passes `at` s of run time.
    fn read_all_calling(mut self, call: Option<(f64, &str, Vec<u8>)>) -> Seen {
        let mut seen = Seen::default();
        let mut stopped = false;
        loop {
            let message = match self.ws.read() {
                Ok(m) => m,
                Err(_) => break, // closed by the server at the run's end
            };
            match message {
                Message::Binary(b) if b[0] == 1 => {
                    let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                    let t = u64::from_le_bytes(b[5..13].try_into().unwrap());
                    let topic = self.subscriptions[&sub].clone();
                    seen.times.entry(topic.clone()).or_default().push(t);
                    if topic == "/hil/events"
                        || topic == "/hil/scene"
                        || topic == "/hil/contact_force"
                    {
                        seen.payloads
                            .entry(topic.clone())
                            .or_default()
                            .push(b[13..].to_vec());
                    }
                    if let Some((at, service, payload)) = &call {
                        if !stopped && topic == "/hil/measured_wrench" && t as f64 * 1e-9 >= *at {
                            stopped = true;
                            self.call(service, 7, payload);
                        }
                    }
                }
                Message::Binary(b) if b[0] == 2 => {
                    seen.clock
                        .push(u64::from_le_bytes(b[1..9].try_into().unwrap()));
                }
                Message::Binary(b) if b[0] == 3 => {
                    seen.responses
                        .push(u32::from_le_bytes(b[5..9].try_into().unwrap()));
                }
                Message::Text(text) => {
                    let m: Value = serde_json::from_str(&text).unwrap();
                    if m["op"] == "serviceCallFailure" {
                        seen.failures.push(m);
                    }
                }
                Message::Close(_) => break,
                _ => {}
            }
        }
        seen
    }
}

/// Runs the loop (PID-free default compensator, 20 ms robot delay) for `duration` s against the
/// emulator with a live view; `viewer` runs in its own thread with the port. Returns the
/// metrics, the viewer's result, the phases the loop was seen in and how long the finish took
/// (the outputs finished after the loop's end).
fn run_live<T: Send + 'static>(
    duration: f64,
    live: LiveOptions,
    viewer: impl FnOnce(u16) -> T + Send + 'static,
) -> (Value, T, Vec<&'static str>, Duration) {
    let s = delayed(CompensatorConfig::default(), duration);
    let (emu, mut rt) = loopback_options();
    let port = free_tcp_port();
    rt.live = Some(LiveOptions {
        port,
        wait: 20.0,
        ..live
    });
    let client = std::thread::spawn(move || viewer(port));
    let (facility, hil) = start_both(&s, &emu, &rt);
    let mut phases = Vec::new();
    let begun = Instant::now();
    while !hil.wait(Duration::from_millis(2)) && begun.elapsed().as_secs_f64() < duration + 30.0 {
        let phase = hil.status().phase;
        if phases.last() != Some(&phase) {
            phases.push(phase);
        }
    }
    assert!(hil.wait(Duration::from_secs(10)), "the run did not end");
    let finishing = Instant::now();
    let out = hil.finish();
    let finish_time = finishing.elapsed();
    let status = facility.join();
    let out = out.unwrap_or_else(|e| panic!("{e}; emulator: {status:?}"));
    (
        out.metrics,
        client.join().expect("viewer"),
        phases,
        finish_time,
    )
}

/// The run times (ns) of every tick of a run of `ticks` ticks (the preset's 1 ms period).
fn tick_times(ticks: u64) -> Vec<u64> {
    let period = delayed(CompensatorConfig::default(), 1.0).simulation.period;
    assert_eq!(period, 0.001);
    (0..ticks)
        .map(|k| hilcontact_rt::output::time_ns(k as f64 * period))
        .collect()
}

#[test]
fn a_viewer_gets_every_force_sample_and_the_scene_and_stops_the_run() {
    let live = LiveOptions {
        control: true,
        ..LiveOptions::default()
    };
    let (m, seen, phases, _) = run_live(4.0, live, |port| {
        let mut v = Viewer::connect(port);
        v.subscribe_all();
        v.read_all(Some(1.0))
    });
    let rt = &m["realtime"];
    // the stop: the operator's, through the force limit's path
    assert_eq!(rt["stop"]["kind"], "operator", "{rt}");
    assert_eq!(rt["stop"]["exit_code"], 3);
    assert_eq!(m["status"], "stopped");
    assert!(phases.contains(&"holding"), "{phases:?}");
    let stopped_at = rt["stop"]["time"].as_f64().unwrap();
    assert!((1.0..3.0).contains(&stopped_at), "{stopped_at}");
    // every tick's force sample, in order, none dropped
    assert_eq!(rt["samples_dropped"], 0);
    let ticks = rt["ticks"].as_u64().unwrap();
    let force = &seen.times["/hil/measured_wrench"];
    assert_eq!(force, &tick_times(ticks), "every tick, in order");
    for topic in [
        "/hil/contact_force",
        "/hil/tip/actual",
        "/hil/energy",
        "/hil/loop_timing",
    ] {
        assert_eq!(seen.times[topic].len() as u64, ticks, "{topic}");
    }
    // the scene at 30 Hz of run time, the server's clock with it
    let scenes = seen.times["/hil/scene"].len() as u64;
    assert_eq!(
        scenes,
        ticks.div_ceil(33),
        "{scenes} scenes in {ticks} ticks"
    );
    assert_eq!(seen.times["/tf"].len() as u64, scenes);
    assert_eq!(seen.times["/tf_static"].len(), 1);
    assert_eq!(seen.clock.len() as u64, scenes);
    // the call answered, logged as an event, counted
    assert_eq!(seen.responses, [7]);
    let events: Vec<String> = seen.payloads["/hil/events"]
        .iter()
        .map(|p| String::from_utf8_lossy(p).into_owned())
        .collect();
    assert!(
        events
            .iter()
            .any(|e| e.contains("operator stop from client")),
        "{events:?}"
    );
    let live = &rt["live"];
    assert_eq!(live["stop_calls"], 1, "{live}");
    assert_eq!(live["refused_calls"], 0);
    assert_eq!(live["connections"], 1);
    // the client by address (read from the SDK's log: its API gives an id only); other tests
    // of this process may have clients connected at the same time ("one of ...")
    assert_eq!(live["addresses_known"], true, "{live}");
    assert!(
        events
            .iter()
            .any(|e| e.contains("client connected from 127.0.0.1:")),
        "{events:?}"
    );
    assert!(
        events
            .iter()
            .any(|e| e.contains("operator stop from client") && e.contains("127.0.0.1:")),
        "{events:?}"
    );
}

#[test]
fn without_control_a_stop_is_refused_and_the_run_goes_on() {
    // 1 s: the uncompensated run meets the force limit later (about 1.3 s)
    let (m, seen, _, _) = run_live(1.0, LiveOptions::default(), |port| {
        let mut v = Viewer::connect(port);
        v.subscribe_all();
        v.read_all(Some(0.3))
    });
    let rt = &m["realtime"];
    assert_eq!(rt["stop"]["kind"], "completed", "{rt}");
    assert_eq!(seen.failures.len(), 1, "{:?}", seen.failures);
    assert!(seen.failures[0]["message"]
        .as_str()
        .unwrap()
        .contains("--live-control"));
    assert_eq!(rt["live"]["refused_calls"], 1);
    assert_eq!(rt["live"]["stop_calls"], 0);
    let events = String::from_utf8_lossy(&seen.payloads["/hil/events"].concat()).into_owned();
    assert!(events.contains("refused from client"), "{events}");
}

#[test]
fn bad_input_on_the_live_port_changes_nothing() {
    let live = LiveOptions {
        control: true,
        ..LiveOptions::default()
    };
    let (m, seen, _, _) = run_live(1.0, live, |port| {
        // a hostile client first: garbage, unknown ops, a huge message, publishing, thousands
        // of subscriptions to channels that do not exist, an unknown service, a raw TCP
        // client that never completes its handshake
        let mut bad = Viewer::connect(port);
        let mut raw = TcpStream::connect(("127.0.0.1", port)).unwrap();
        let _ = raw.write_all(b"GET / HTTP/1.1\r\n\r\n\x00\x01garbage");
        // the server may close the hostile client at any point: its sends may fail
        let service_call = |id: u32, payload: &[u8]| {
            let mut b = vec![2u8];
            b.extend_from_slice(&id.to_le_bytes());
            b.extend_from_slice(&1u32.to_le_bytes());
            b.extend_from_slice(&4u32.to_le_bytes());
            b.extend_from_slice(b"json");
            b.extend_from_slice(payload);
            Message::Binary(b.into())
        };
        let mark = bad.services["/hilcontact/mark"] as u32;
        let mut publish = vec![1u8];
        publish.extend_from_slice(&1u32.to_le_bytes());
        publish.extend_from_slice(b"{\"x\": 1e9}");
        let subs: Vec<Value> = (0..5000)
            .map(|i| json!({"id": i, "channelId": 100000 + i}))
            .collect();
        let hostile = [
            Message::Binary(vec![0xff, 1, 2, 3].into()),
            Message::Binary(vec![2, 0, 0].into()),
            Message::Text("not json".into()),
            Message::Text(json!({"op": "launchMissiles"}).to_string().into()),
            Message::Text(
                json!({"op": "advertise", "channels": [{"id": 1, "topic": "/hil/command",
                    "encoding": "json", "schemaName": "x"}]})
                .to_string()
                .into(),
            ),
            Message::Binary(publish.into()),
            Message::Text(
                json!({"op": "subscribe", "subscriptions": subs})
                    .to_string()
                    .into(),
            ),
            service_call(mark, &vec![b'x'; 2 << 20]),
            service_call(999, b"{}"),
        ];
        let mut sent = 0;
        for m in hostile {
            if bad.ws.send(m).is_ok() {
                sent += 1;
            }
        }
        eprintln!("hostile client: {sent} of 9 messages sent before the server closed it");
        // then a good viewer: it must see every tick
        let mut v = Viewer::connect(port);
        v.subscribe_all();
        let seen = v.read_all(None);
        drop(bad);
        drop(raw);
        seen
    });
    let rt = &m["realtime"];
    assert_eq!(rt["stop"]["kind"], "completed", "{rt}");
    let ticks = rt["ticks"].as_u64().unwrap();
    assert_eq!(seen.times["/hil/measured_wrench"], tick_times(ticks));
    // the huge mark was a mark (its label cut); nothing else was accepted
    assert_eq!(rt["live"]["stop_calls"], 0, "{}", rt["live"]);
    // the bad input counted, as the SDK logs it: messages it could not parse, the raw client's
    // failed handshake (at least: other tests of this process count into it too)
    assert!(
        rt["live"]["invalid_messages"].as_u64().unwrap() >= 1,
        "{}",
        rt["live"]
    );
    assert!(
        rt["live"]["failed_handshakes"].as_u64().unwrap() >= 1,
        "{}",
        rt["live"]
    );
    // every refused message counted (the SDK answered each with an error status): the
    // advertisement and the data of the would-be publisher among them, and the subscriptions
    // to channels that do not exist (as many as reached the server before it closed the client)
    assert!(
        rt["live"]["client_publish_refused"].as_u64().unwrap() >= 1,
        "{}",
        rt["live"]
    );
    assert!(
        rt["live"]["refused_input"].as_u64().unwrap() >= 3,
        "{}",
        rt["live"]
    );
}

#[test]
fn a_viewer_that_stops_reading_neither_slows_the_loop_nor_holds_the_end() {
    // subscribes to everything, then never reads again: its socket buffers and its queue fill
    // (the oldest dropped); the run must end on time and the finish must not wait for it
    // 1 s: the uncompensated run meets the force limit later (about 1.3 s)
    let (m, ended_after, _, finish_time) = run_live(1.0, LiveOptions::default(), |port| {
        let mut v = Viewer::connect(port);
        v.subscribe_all();
        let begun = Instant::now();
        // hold the socket open, unread, until the server gives up on it or the run is over
        std::thread::sleep(Duration::from_secs(8));
        drop(v);
        begun.elapsed()
    });
    let rt = &m["realtime"];
    assert_eq!(rt["stop"]["kind"], "completed", "{rt}");
    assert_eq!(rt["samples_dropped"], 0);
    assert_eq!(rt["ticks"], 1001);
    assert!(ended_after >= Duration::from_secs(8), "{ended_after:?}");
    // the finish (a 0.5 s linger, then at most 1 s for the server's tasks) did not wait for
    // the stalled client, which held its socket for 8 s
    assert!(finish_time < Duration::from_secs(4), "{finish_time:?}");
    assert_eq!(rt["live"]["peak_clients"], 1);
}

/// The three `float64`s of a CDR `geometry_msgs/Vector3Stamped` (after its header).
fn vector3_stamped(payload: &[u8]) -> [f64; 3] {
    let body = &payload[4..]; // the CDR encapsulation
    let len = u32::from_le_bytes(body[8..12].try_into().unwrap()) as usize;
    let at = (12 + len).div_ceil(8) * 8;
    let f = |i: usize| f64::from_le_bytes(body[at + 8 * i..at + 8 * i + 8].try_into().unwrap());
    [f(0), f(1), f(2)]
}

#[test]
fn the_facility_serves_its_truth_and_the_scene_and_its_operator_stop_ends_it() {
    // the emulated facility with a live view; the loop (no live view) runs against it until the
    // viewer stops the facility at 1 s of the facility's time: it stops serving, the loop's
    // watchdog stops the run
    let s = delayed(CompensatorConfig::default(), 4.0);
    let (mut emu, rt) = loopback_options();
    let port = free_tcp_port();
    emu.live = Some(LiveOptions {
        port,
        control: true,
        wait: 20.0,
        ..LiveOptions::default()
    });
    let client = std::thread::spawn(move || {
        let mut v = Viewer::connect(port);
        let topics: Vec<String> = v.channels.values().cloned().collect();
        v.subscribe_all();
        (topics, v.read_all(Some(1.0)))
    });
    let (facility, hil) = start_both(&s, &emu, &rt);
    let begun = Instant::now();
    while !facility.is_finished() && begun.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(10));
    }
    assert!(
        facility.is_finished(),
        "the operator's stop did not end the facility"
    );
    assert!(hil.wait(Duration::from_secs(30)), "the loop did not end");
    let hil_out = hil.finish();
    let (status, report) = facility.join_with_live();
    let (topics, seen) = client.join().expect("viewer");
    assert!(status.operator_stop, "{status:?}");
    assert_eq!(status.live_samples_dropped, 0, "{status:?}");
    // the loop saw its facility go silent: a safety stop, exit 3
    let m = hil_out.expect("the loop's run").metrics;
    assert_eq!(
        m["realtime"]["stop"]["exit_code"], 3,
        "{}",
        m["realtime"]["stop"]
    );
    // the facility's channels: its truth, no virtual dynamics
    for absent in ["/hil/applied_wrench", "/hil/energy", "/hil/estimates"] {
        assert!(
            !topics.iter().any(|t| t == absent),
            "{absent} in {topics:?}"
        );
    }
    let ticks = status.tick;
    assert!(ticks >= 1000, "{ticks}");
    assert_eq!(
        seen.times["/hil/measured_wrench"],
        tick_times(ticks),
        "every period, in order"
    );
    for topic in [
        "/hil/contact_force",
        "/hil/tip/commanded",
        "/hil/tip/actual",
        "/hil/tip/actual_velocity",
        "/hil/loop_timing",
        "/facility/contact_moment",
    ] {
        assert_eq!(seen.times[topic].len() as u64, ticks, "{topic}");
    }
    assert_eq!(seen.times["/hil/scene"].len() as u64, ticks.div_ceil(33));
    assert_eq!(seen.times["/tf"].len() as u64, ticks.div_ceil(33));
    // the server's clock is the facility's time, advertised with each scene
    assert_eq!(seen.clock, seen.times["/hil/scene"]);
    // the contact force is the facility's own: its peak is the status's
    let peak = seen.payloads["/hil/contact_force"]
        .iter()
        .map(|p| {
            let [x, y, z] = vector3_stamped(p);
            (x * x + y * y + z * z).sqrt()
        })
        .fold(0.0, f64::max);
    assert!(peak > 0.0, "no contact before the stop");
    assert!(
        (peak - status.peak_contact_force).abs() <= 1e-9 * peak,
        "{peak} vs {}",
        status.peak_contact_force
    );
    // the call answered, counted, logged
    assert_eq!(seen.responses, [7]);
    let report = report.expect("the live view's report");
    assert_eq!(report["stop_calls"], 1, "{report}");
    assert_eq!(report["connections"], 1, "{report}");
    let events = String::from_utf8_lossy(&seen.payloads["/hil/events"].concat()).into_owned();
    assert!(events.contains("operator stop from client"), "{events}");
    assert!(
        events.contains("facility stopped by the operator"),
        "{events}"
    );
}

#[test]
fn a_mark_is_an_event_of_the_run_its_label_cleaned_and_cut() {
    // a label with a control character and 300 more characters than the 200 kept
    let label = format!("pulse 1\n{}", "a".repeat(300));
    let payload = json!({ "label": label }).to_string().into_bytes();
    let live = LiveOptions {
        control: true,
        ..LiveOptions::default()
    };
    let (m, seen, _, _) = run_live(1.0, live, move |port| {
        let mut v = Viewer::connect(port);
        v.subscribe_all();
        v.read_all_calling(Some((0.3, "/hilcontact/mark", payload)))
    });
    let rt = &m["realtime"];
    // a mark changes nothing of the run
    assert_eq!(rt["stop"]["kind"], "completed", "{rt}");
    let ticks = rt["ticks"].as_u64().unwrap();
    assert_eq!(seen.times["/hil/measured_wrench"], tick_times(ticks));
    assert_eq!(seen.responses, [7]);
    assert!(seen.failures.is_empty(), "{:?}", seen.failures);
    assert_eq!(rt["live"]["mark_calls"], 1, "{}", rt["live"]);
    assert_eq!(rt["live"]["stop_calls"], 0);
    let kept = format!("pulse 1{}", "a".repeat(193));
    let events: Vec<String> = seen.payloads["/hil/events"]
        .iter()
        .map(|p| String::from_utf8_lossy(p).into_owned())
        .collect();
    let mark = events
        .iter()
        .find(|e| e.contains("mark from client"))
        .unwrap_or_else(|| panic!("no mark in {events:?}"));
    // the text ends with the label as kept: no control character, 200 characters
    assert!(mark.contains(&format!(": {kept}\0")), "{mark}");
    assert!(!mark.contains(&format!("{kept}a")), "{mark}");
}
