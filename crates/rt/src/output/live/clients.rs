//! The live view's clients by address. The Foxglove SDK (0.30) gives its listener and service
//! handlers a client id only, never the address; its own log (`tracing`) names the address
//! when a client is registered or unregistered, when its handshake fails and when it sends a
//! message the server cannot parse. A small `tracing` subscriber, installed once per process
//! (unless the process has one already), reads those lines for every live server
//! ([`ClientLog`]): connections are logged with their address (stderr and the run's events),
//! bad input is counted, and an operator's call is named by address when one client is
//! connected (else by the connected addresses).

use std::fmt::Debug;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, Weak};

use tracing::field::{Field, Visit};
use tracing::span::{Attributes, Id, Record};
use tracing::{Event, Level, Metadata, Subscriber};

use crate::output::{EventLevel, RunControl};

/// What the SDK's log says of one server's clients.
#[derive(Debug)]
pub struct ClientLog {
    run: Arc<RunControl>,
    /// Addresses of the clients connected now, in connection order.
    connected: Mutex<Vec<String>>,
    /// Messages from clients the server could not parse (garbage frames, unknown ops).
    pub invalid_messages: AtomicU64,
    /// Connections dropped at the WebSocket handshake (a client that is not one).
    pub failed_handshakes: AtomicU64,
    /// The SDK's "outbox for client ... full" lines (a client's queue full: its oldest
    /// messages dropped; the SDK logs this at most once per 30 s for the whole process).
    pub outbox_full: AtomicU64,
    /// The addresses of those lines, in order, each once.
    lossy: Mutex<Vec<String>>,
}

impl ClientLog {
    /// Who is connected, for an operator's call: the address when one client is, else the
    /// connected addresses ("one of a, b"), or "a client" when the SDK's log is not read
    /// ([`addresses_known`] false).
    pub fn who(&self) -> String {
        let connected = self.connected.lock().map(|c| c.clone()).unwrap_or_default();
        match connected.as_slice() {
            [] => "a client".to_string(),
            [one] => one.clone(),
            many => format!("one of {}", many.join(", ")),
        }
    }

    /// The clients whose queue was reported full (addresses, each once).
    pub fn lossy_clients(&self) -> Vec<String> {
        self.lossy.lock().map(|l| l.clone()).unwrap_or_default()
    }

    fn outbox_full(&self, addr: &str) {
        self.outbox_full.fetch_add(1, Ordering::Relaxed);
        if let Ok(mut l) = self.lossy.lock() {
            if !l.iter().any(|a| a == addr) {
                l.push(addr.to_string());
            }
        }
        self.run.push_event(
            EventLevel::Warn,
            format!("live view: client {addr} falls behind: its oldest messages are dropped"),
        );
    }

    fn connected(&self, addr: &str) {
        if let Ok(mut c) = self.connected.lock() {
            c.push(addr.to_string());
        }
        let text = format!("live view: client connected from {addr}");
        eprintln!("{text}");
        self.run.push_event(EventLevel::Info, text);
    }

    fn disconnected(&self, addr: &str) {
        if let Ok(mut c) = self.connected.lock() {
            if let Some(i) = c.iter().position(|a| a == addr) {
                c.remove(i);
            }
        }
        self.run.push_event(
            EventLevel::Info,
            format!("live view: client {addr} disconnected"),
        );
    }
}

/// The logs of the live servers of this process.
static LOGS: Mutex<Vec<Weak<ClientLog>>> = Mutex::new(Vec::new());

/// Whether the SDK's log is read (our subscriber is the process's).
static INSTALLED: OnceLock<bool> = OnceLock::new();

/// Whether client addresses are known: the subscriber could be installed (a process with
/// another global `tracing` subscriber keeps it, and the addresses are not read).
pub fn addresses_known() -> bool {
    *INSTALLED.get_or_init(|| tracing::subscriber::set_global_default(SdkLog).is_ok())
}

/// A log for one server's clients, fed from the SDK's log until dropped.
pub fn watch(run: Arc<RunControl>) -> Arc<ClientLog> {
    let log = Arc::new(ClientLog {
        run,
        connected: Mutex::new(Vec::new()),
        invalid_messages: AtomicU64::new(0),
        failed_handshakes: AtomicU64::new(0),
        outbox_full: AtomicU64::new(0),
        lossy: Mutex::new(Vec::new()),
    });
    addresses_known();
    if let Ok(mut logs) = LOGS.lock() {
        logs.retain(|l| l.strong_count() > 0);
        logs.push(Arc::downgrade(&log));
    }
    log
}

/// One line of the SDK's log, as it concerns a client.
#[derive(Debug, PartialEq)]
enum Line<'a> {
    Registered(&'a str),
    Unregistered(&'a str),
    Invalid(&'a str),
    Dropped(&'a str),
    OutboxFull(&'a str),
}

/// Reads a line of the SDK's log (`foxglove::websocket` 0.30's texts).
fn parse(message: &str) -> Option<Line<'_>> {
    if let Some(rest) = message.strip_prefix("Registered client ") {
        return Some(Line::Registered(rest.trim()));
    }
    if let Some(rest) = message.strip_prefix("Unregistered client ") {
        return Some(Line::Unregistered(rest.trim()));
    }
    if let Some(rest) = message.strip_prefix("Invalid message from ") {
        return Some(Line::Invalid(address_prefix(rest)));
    }
    if let Some(rest) = message.strip_prefix("Dropping client ") {
        return Some(Line::Dropped(address_prefix(rest)));
    }
    if let Some(rest) = message.strip_prefix("outbox for client ") {
        if let Some(addr) = rest.strip_suffix(" full") {
            return Some(Line::OutboxFull(addr.trim()));
        }
    }
    None
}

/// The `host:port` at the start of `text` followed by `": ..."`.
fn address_prefix(text: &str) -> &str {
    text.find(": ").map_or(text, |i| &text[..i])
}

/// The process's `tracing` subscriber: the SDK's info and error lines only.
struct SdkLog;

/// Reads an event's `message` field.
#[derive(Default)]
struct Message(String);

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn Debug) {
        if field.name() == "message" {
            self.0 = format!("{value:?}");
        }
    }
}

static SPAN_ID: AtomicU64 = AtomicU64::new(1);

impl Subscriber for SdkLog {
    fn enabled(&self, metadata: &Metadata<'_>) -> bool {
        metadata.target().starts_with("foxglove") && *metadata.level() <= Level::INFO
    }

    fn new_span(&self, _: &Attributes<'_>) -> Id {
        Id::from_u64(SPAN_ID.fetch_add(1, Ordering::Relaxed).max(1))
    }

    fn record(&self, _: &Id, _: &Record<'_>) {}

    fn record_follows_from(&self, _: &Id, _: &Id) {}

    fn event(&self, event: &Event<'_>) {
        let mut message = Message::default();
        event.record(&mut message);
        let Some(line) = parse(&message.0) else {
            return;
        };
        let logs: Vec<Arc<ClientLog>> = LOGS
            .lock()
            .map(|l| l.iter().filter_map(Weak::upgrade).collect())
            .unwrap_or_default();
        for log in logs {
            match line {
                Line::Registered(addr) => log.connected(addr),
                Line::Unregistered(addr) => log.disconnected(addr),
                Line::Invalid(_) => {
                    log.invalid_messages.fetch_add(1, Ordering::Relaxed);
                }
                Line::Dropped(_) => {
                    log.failed_handshakes.fetch_add(1, Ordering::Relaxed);
                }
                Line::OutboxFull(addr) => log.outbox_full(addr),
            }
        }
    }

    fn enter(&self, _: &Id) {}

    fn exit(&self, _: &Id) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_sdk_s_lines_about_clients() {
        assert_eq!(
            parse("Registered client 127.0.0.1:5432"),
            Some(Line::Registered("127.0.0.1:5432"))
        );
        assert_eq!(
            parse("Unregistered client [::1]:80"),
            Some(Line::Unregistered("[::1]:80"))
        );
        assert_eq!(
            parse("Invalid message from 10.0.0.2:999: expected value at line 1"),
            Some(Line::Invalid("10.0.0.2:999"))
        );
        assert_eq!(
            parse("Dropping client 10.0.0.2:1000: handshake failed"),
            Some(Line::Dropped("10.0.0.2:1000"))
        );
        assert_eq!(
            parse("outbox for client 127.0.0.1:41000 full"),
            Some(Line::OutboxFull("127.0.0.1:41000"))
        );
        assert_eq!(parse("outbox for client 127.0.0.1:41000"), None);
        assert_eq!(parse("Started server on 127.0.0.1:8765"), None);
    }
}
