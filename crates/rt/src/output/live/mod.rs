//! The live view: a Foxglove WebSocket server (protocol `foxglove.websocket.v1`, through the
//! Foxglove SDK, the `foxglove` crate) streaming a run as it happens: the same channels as the
//! MCAP recording ([`super::mcap::CHANNELS`], the same ROS 2 messages in CDR), the facility in
//! 3-D ([`super::scene`]), the server's clock advertised as the run's time, and two services
//! an operator calls from Foxglove's Call Service panel: `/hilcontact/stop` (the run stops as
//! after a force limit: retreat, hold, exit 3, stop `operator`) and `/hilcontact/mark` (an
//! event on `/hil/events`), accepted only with [`LiveOptions::control`].
//!
//! **The loop never waits for a viewer.** The sink lives in the writer thread like every sink
//! (the loop hands samples over through its preallocated ring buffer and never allocates); the
//! SDK queues each message per client (at most [`LiveOptions::backlog`] messages, the oldest
//! dropped when full) and sends from its own threads, so a slow or stalled client costs the
//! writer one bounded queue and never the loop.
//!
//! **Link safety.** The server binds to loopback unless [`LiveOptions::remote`] is set;
//! clients may not publish (no `clientPublish` capability: a client's advertise or message is
//! refused by the SDK); the services refuse every call without [`LiveOptions::control`], and
//! every call, accepted or refused, is an event on `/hil/events`, a line on stderr and a count
//! in the report.
//!
//! **The emulated facility** (`hilcontact facility --live`, [`crate::emulator`]) serves the
//! same view of its own physical truth: a run of kind [`FACILITY_RUN`] has the channels of the
//! recording that a facility knows (measured wrench, contact force, the commanded pose it
//! received and its velocity, the actual pose and velocity, its own loop timing, events) plus
//! [`FACILITY_CHANNELS`], and the scene; not the virtual dynamics' (applied wrench, energy,
//! estimates). Its operator stop ends the facility (it stops serving its devices).
//!
//! The server needs the cargo feature `live` of `hilcontact-rt` (on in the Python extension);
//! without it, the option is refused at start with a message saying so.

use std::net::IpAddr;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::mcap::{ChannelScope, ChannelSpec, FRAME_TARGET};
use super::{Sink, SinkContext};
use crate::error::{Result, RtError};

/// [`super::RunInfo::kind`] of the emulated facility's live view: its samples are the
/// facility's truth (no virtual dynamics), its timing the emulator's, and it is not paced.
pub const FACILITY_RUN: &str = "facility";

/// Topics of the recording a facility does not have (the virtual dynamics' own).
pub const FACILITY_ABSENT: [&str; 3] = ["/hil/applied_wrench", "/hil/energy", "/hil/estimates"];

/// The facility's channels beyond the recording's (the one list; docs/realtime.md shows it).
pub const FACILITY_CHANNELS: [ChannelSpec; 1] = [ChannelSpec {
    topic: "/facility/contact_moment",
    schema: "geometry_msgs/msg/Vector3Stamped",
    frame: FRAME_TARGET,
    scope: ChannelScope::Always,
    doc: "the physical contact's moment on the frame about the sensor origin, t, N·m, per tick",
}];

#[cfg(feature = "live")]
mod clients;
#[cfg(feature = "live")]
mod server;

/// Options of the live view (`--live [HOST:]PORT`, `--live-control`, `--live-remote`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct LiveOptions {
    /// The address the server binds to: an IP address or `localhost` (default `127.0.0.1`:
    /// this machine only; another needs `remote`).
    pub host: String,
    /// The TCP port (0: any free port, reported in `metrics.json` `realtime.live.port`).
    pub port: u16,
    /// Allow a host other than loopback (`--live-remote`): anyone who reaches the port sees the
    /// run, and with `control` can stop it.
    pub remote: bool,
    /// Accept the operator's actions (`--live-control`): the `/hilcontact/stop` and
    /// `/hilcontact/mark` services; without it every call is refused (and logged).
    pub control: bool,
    /// Messages queued per client before the oldest are dropped (the SDK's per-client backlog;
    /// a client's memory bound: backlog × the largest message, about 2 kB).
    #[schemars(range(min = 16, max = 1048576))]
    pub backlog: u32,
    /// A simulation's replay speed (1: real time, 2: twice as fast); a real-time run is always
    /// shown as it happens.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1000.0))]
    pub speed: f64,
    /// Longest wait for a viewer before the run starts, s (`--live-wait`; 0: none): the start
    /// goes on once a client has subscribed to every channel, or after this.
    #[schemars(range(min = 0.0, max = 3600.0))]
    pub wait: f64,
}

impl Default for LiveOptions {
    fn default() -> Self {
        LiveOptions {
            host: "127.0.0.1".into(),
            port: 8765,
            remote: false,
            control: false,
            backlog: 4096,
            speed: 1.0,
            wait: 0.0,
        }
    }
}

impl LiveOptions {
    /// Checks the address rule (loopback unless `remote`) and the numbers; the message names the
    /// option.
    pub fn validate(&self) -> Result<()> {
        let ip: IpAddr = if self.host == "localhost" {
            IpAddr::from([127, 0, 0, 1])
        } else {
            self.host.parse().map_err(|_| {
                RtError::option(
                    "live.host",
                    format!("must be an IP address or localhost, got {:?}", self.host),
                )
            })?
        };
        if !ip.is_loopback() && !self.remote {
            return Err(RtError::option(
                "live.host",
                format!(
                    "{} is not a loopback address: serving other machines needs live.remote \
                     (--live-remote)",
                    self.host
                ),
            ));
        }
        if !(self.speed.is_finite() && self.speed > 0.0 && self.speed <= 1000.0) {
            return Err(RtError::option(
                "live.speed",
                format!("must be a number > 0 and <= 1000, got {}", self.speed),
            ));
        }
        if !(self.wait.is_finite() && (0.0..=3600.0).contains(&self.wait)) {
            return Err(RtError::option(
                "live.wait",
                format!("must be a number from 0 to 3600, got {}", self.wait),
            ));
        }
        if !(16..=1_048_576).contains(&self.backlog) {
            return Err(RtError::option(
                "live.backlog",
                format!(
                    "must be a whole number from 16 to 1048576, got {}",
                    self.backlog
                ),
            ));
        }
        Ok(())
    }
}

/// Opens the live view: parses its options and starts the server (bound before the run
/// starts; a port in use refuses the start naming it).
pub fn open(context: &SinkContext<'_>, options: &Value) -> Result<Box<dyn Sink>> {
    let options: LiveOptions = serde_json::from_value(options.clone())
        .map_err(|e| RtError::option("live", e.to_string()))?;
    options.validate()?;
    start(context, &options)
}

#[cfg(feature = "live")]
fn start(context: &SinkContext<'_>, options: &LiveOptions) -> Result<Box<dyn Sink>> {
    Ok(Box::new(server::LiveSink::start(context, options)?))
}

#[cfg(not(feature = "live"))]
fn start(_: &SinkContext<'_>, _: &LiveOptions) -> Result<Box<dyn Sink>> {
    Err(RtError::option(
        "live",
        "this build of hilcontact has no live view (build hilcontact-rt with the cargo feature \
         `live`)",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_loopback_unless_remote_is_asked_for() {
        let ok = |host: &str, remote: bool| {
            LiveOptions {
                host: host.into(),
                remote,
                ..LiveOptions::default()
            }
            .validate()
        };
        for host in ["127.0.0.1", "localhost", "::1", "127.0.0.2"] {
            assert!(ok(host, false).is_ok(), "{host}");
        }
        for host in ["0.0.0.0", "192.168.1.5", "::"] {
            let err = ok(host, false).expect_err(host).to_string();
            assert!(
                err.contains("live.host") && err.contains("--live-remote"),
                "{err}"
            );
            assert!(ok(host, true).is_ok(), "{host}");
        }
        let err = ok("robot.lab", true).expect_err("a name").to_string();
        assert!(err.contains("IP address"), "{err}");
        for speed in [0.0, -1.0, f64::NAN, 1e4] {
            let o = LiveOptions {
                speed,
                ..LiveOptions::default()
            };
            assert!(o.validate().is_err(), "{speed}");
        }
    }
}
