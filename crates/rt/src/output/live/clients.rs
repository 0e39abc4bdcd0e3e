//! The live view's clients by address. The Foxglove SDK (0.30) gives its listener and service
//! handlers a client id only, never the address; its own log (`tracing`) names the address
//! when a client is registered or unregistered, when its handshake fails and when it sends a
//! message the server cannot parse; at debug level, every error or warning status it answers a
//! client's message with (a message it could not parse, a subscription or a message on a
//! channel that does not exist, an advertisement to publish, which this server does not allow),
//! and when a client's queue is full. A small `tracing` subscriber, installed once per process
//! (unless the process has one already), reads those lines for every live server
//! ([`ClientLog`]): connections are logged with their address (stderr and the run's events),
//! bad input is counted, and an operator's call is named by address when one client is
//! connected (else by the connected addresses). Of the debug lines only those of the SDK's
//! client module are read, each cut at [`MAX_LINE`] characters (a huge bad message costs no
//! more than a short one).

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
    /// Client messages the server answered with an error or warning status (unparsable, a
    /// channel that does not exist, publishing without the capability, ...).
    pub refused_input: AtomicU64,
    /// Client attempts to publish (an advertisement, or data on a channel it may not use):
    /// refused, this server offers no `clientPublish`.
    pub publish_refused: AtomicU64,
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
        refused_input: AtomicU64::new(0),
        publish_refused: AtomicU64::new(0),
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
    /// An error or warning status sent to a client (its address, the text).
    Status(&'a str, &'a str),
    /// Data on a channel the client did not advertise (an attempt to publish).
    UnknownClientChannel,
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
    for prefix in ["Sending error to client ", "Sending warning to client "] {
        if let Some(rest) = message.strip_prefix(prefix) {
            let addr = address_prefix(rest);
            let text = rest.get(addr.len() + 2..).unwrap_or("");
            return Some(Line::Status(addr, text));
        }
    }
    if message.starts_with("Received message for unknown channel") {
        return Some(Line::UnknownClientChannel);
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

/// Longest part of a log line read, characters.
const MAX_LINE: usize = 256;

/// Reads an event's `message` field, at most [`MAX_LINE`] bytes of it.
#[derive(Default)]
struct Message(String);

impl std::fmt::Write for Message {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let room = MAX_LINE.saturating_sub(self.0.len());
        if s.len() <= room {
            self.0.push_str(s);
            return Ok(());
        }
        let mut end = room;
        while !s.is_char_boundary(end) {
            end -= 1;
        }
        self.0.push_str(&s[..end]);
        Err(std::fmt::Error) // the formatting stops here
    }
}

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn Debug) {
        if field.name() == "message" {
            self.0.clear();
            let _ = std::fmt::Write::write_fmt(self, format_args!("{value:?}"));
        }
    }
}

/// The SDK's module whose debug lines are read (its statuses to clients).
const CLIENT_MODULE: &str = "foxglove::websocket::connected_client";

static SPAN_ID: AtomicU64 = AtomicU64::new(1);

impl Subscriber for SdkLog {
    fn enabled(&self, metadata: &Metadata<'_>) -> bool {
        metadata.target().starts_with("foxglove")
            && (*metadata.level() <= Level::INFO
                || (*metadata.level() == Level::DEBUG
                    && metadata.module_path() == Some(CLIENT_MODULE)))
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
                Line::Status(_, text) => {
                    log.refused_input.fetch_add(1, Ordering::Relaxed);
                    if text.contains("clientPublish") {
                        log.publish_refused.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Line::UnknownClientChannel => {
                    log.publish_refused.fetch_add(1, Ordering::Relaxed);
                }
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
        assert_eq!(
            parse("Sending error to client 127.0.0.1:5: Server does not support clientPublish capability"),
            Some(Line::Status(
                "127.0.0.1:5",
                "Server does not support clientPublish capability"
            ))
        );
        assert_eq!(
            parse("Received message for unknown channel: 1"),
            Some(Line::UnknownClientChannel)
        );
        let mut m = Message::default();
        let long = "x".repeat(10 * MAX_LINE);
        let cut = std::fmt::Write::write_fmt(&mut m, format_args!("{long:?}"));
        assert!(cut.is_err());
        assert_eq!(
            m.0,
            format!("\"{}", &long[..MAX_LINE - 1]),
            "cut at MAX_LINE"
        );
        assert_eq!(parse("Started server on 127.0.0.1:8765"), None);
    }
}
