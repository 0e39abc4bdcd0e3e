//! The emulated facility's real-time thread (`hil-facility`) never allocates once running with
//! its live view on (`hilcontact facility --live`) and a viewer subscribed to every channel: a
//! counting global allocator counts the allocations of that one thread (found by its name in
//! `/proc/self/task`, compared by kernel thread id, so the allocator itself calls nothing that
//! allocates) from the facility's first periods over a window spanning the first collision,
//! while the live view's thread and the SDK's threads (which may allocate) run beside it.
#![cfg(all(feature = "live", target_os = "linux"))]

mod common;
mod thread_alloc;

use thread_alloc::{threads_named, ALLOCATIONS, ARMED, WATCHED_TID};

use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use common::{delayed, free_tcp_port, loopback_options, start_both};
use hilcontact_core::compensator::{CompensatorConfig, ModelParams};
use hilcontact_rt::output::live::LiveOptions;
use serde_json::{json, Value};
use tungstenite::client::IntoClientRequest;
use tungstenite::Message;

/// A viewer that subscribes to every channel and reads until the server closes; returns the
/// messages it received.
fn viewer(port: u16) -> u64 {
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
    let (mut ws, _) = tungstenite::client::client(request, stream).expect("handshake");
    let mut channels = Vec::new();
    while channels.is_empty() {
        if let Message::Text(text) = ws.read().expect("advertisements") {
            let m: Value = serde_json::from_str(&text).unwrap();
            if m["op"] == "advertise" {
                channels.extend(
                    m["channels"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|c| c["id"].clone()),
                );
            }
        }
    }
    let subscriptions: Vec<Value> = channels
        .iter()
        .enumerate()
        .map(|(i, id)| json!({"id": i as u32, "channelId": id}))
        .collect();
    let subscribe = json!({"op": "subscribe", "subscriptions": subscriptions});
    ws.send(Message::Text(subscribe.to_string().into()))
        .unwrap();
    let mut received = 0;
    while let Ok(m) = ws.read() {
        received += u64::from(matches!(m, Message::Binary(_)));
    }
    received
}

#[test]
fn the_facility_s_thread_does_not_allocate_with_its_live_view_on() {
    let s = delayed(CompensatorConfig::Pida(ModelParams::default()), 2.5);
    let (mut emu, rt) = loopback_options();
    let port = free_tcp_port();
    emu.live = Some(LiveOptions {
        port,
        // the facility waits for the viewer's subscriptions before it starts serving
        wait: 20.0,
        ..LiveOptions::default()
    });
    let client = std::thread::spawn(move || viewer(port));
    let (facility, hil) = start_both(&s, &emu, &rt);
    let tids = threads_named("hil-facility");
    assert_eq!(tids.len(), 1, "one facility thread: {tids:?}");
    WATCHED_TID.store(tids[0], Ordering::SeqCst);
    while hil.status().phase != "running" {
        std::thread::sleep(Duration::from_micros(20));
    }
    ARMED.store(true, Ordering::SeqCst);
    let first = facility.status().tick;
    std::thread::sleep(Duration::from_millis(1600));
    ARMED.store(false, Ordering::SeqCst);
    let counted = ALLOCATIONS.load(Ordering::SeqCst);
    let ticks = facility.status().tick - first;
    assert!(hil.wait(Duration::from_secs(30)), "the loop did not end");
    let out = hil.finish().expect("the loop's run");
    let (status, report) = facility.join_with_live();
    let received = client.join().expect("viewer");
    // the facility served the whole window, the live view saw it, a collision happened in it
    assert!(
        ticks >= 1000,
        "the facility ran only {ticks} periods while armed"
    );
    let report = report.expect("the live view's report");
    assert!(
        report["peak_subscriptions"].as_u64() >= Some(10),
        "{report}"
    );
    assert!(received >= ticks, "the viewer received {received} messages");
    assert_eq!(status.live_samples_dropped, 0, "{status:?}");
    assert!(
        !out.metrics["collisions"].as_array().unwrap().is_empty(),
        "{}",
        out.metrics["reason"]
    );
    assert_eq!(
        counted, 0,
        "{counted} allocations on the facility's thread while running"
    );
}
