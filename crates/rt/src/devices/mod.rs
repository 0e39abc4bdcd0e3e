//! Devices: the seam between the real-time loop and the devices' protocols, on both sides of
//! the wire, one folder per device.
//!
//! The loop ([`crate::runtime`]) talks to one [`SensorLink`] (a force/torque sensor) and one
//! [`RobotLink`] (a robot controller's external-motion interface) and names neither device:
//! every protocol detail (ports, codecs, units, counts per unit, pose mapping, the feedback
//! period) lives in the device's folder. The robot link also chooses the loop's [`Pacing`]:
//! the PC's monotonic clock at the scenario's period ([`Pacing::Clock`], ABB EGM), or one tick
//! per robot packet ([`Pacing::Robot`], e.g. KUKA RSI, whose 4 ms packet must be answered).
//! The emulated facility ([`crate::emulator`]) is the devices' side of the same protocols: a
//! [`SensorEndpoint`] serves the sensor's protocol given the physical wrench, a
//! [`RobotEndpoint`] takes the commands and sends the robot's feedback; it names no device
//! either.
//!
//! - `link.rs`: the generic traits and types ([`SensorLink`], [`RobotLink`],
//!   [`SensorEndpoint`], [`RobotEndpoint`], [`LinkStats`], [`Wrench`], [`Pacing`],
//!   [`LinkContext`], [`RobotIdentity`]) and what a protocol implements to be registered
//!   ([`SensorDevice`], [`RobotDevice`], [`EmulatedSensor`], [`EmulatedRobot`]);
//! - `pose.rs`: the scenario's relative motion (`t`, m) as robot poses (mm, quaternion), for
//!   every robot protocol ([`pose::PoseMapping`]);
//! - `transport.rs`: sockets, counted receives, the sequence rule, host checks (written once);
//! - one folder per device, each with its codec (`codec.rs`), its options (parsed once into a
//!   config), its link (the PC's side) and its emulated endpoint (the device's side):
//!   [`rdt`] (ATI Net F/T, RDT over UDP, `/netftapi2.xml` over HTTP), [`sri`] (SRI M812x, AT
//!   commands and binary frames over TCP), [`egm`] (ABB EGM, protobuf over UDP), [`rsi`] (KUKA
//!   RSI, XML over UDP, robot paced).
//!
//! **A new protocol** is one folder `devices/<kind>/` (its codec, its options, its link
//! implementing [`SensorLink`] and [`SensorDevice`] or [`RobotLink`] and [`RobotDevice`], its
//! emulated endpoint implementing [`SensorEndpoint`] and [`EmulatedSensor`] or
//! [`RobotEndpoint`] and [`EmulatedRobot`]), its `pub mod` line below and one line in
//! `registry!` below (`Kind = "kind", kind::Link, kind::Endpoint;`): the option enums ([`SensorOptions`],
//! [`RobotOptions`], [`EmulatedSensorOptions`], [`EmulatedRobotOptions`]) and their parsed
//! forms, [`open_sensor`] / [`open_robot`] / [`open_sensor_endpoint`] /
//! [`open_robot_endpoint`], [`RobotOptions::pacing`], the kind lists ([`SENSOR_KINDS`],
//! [`ROBOT_KINDS`]), [`protocol_defaults`] and the options' JSON Schema all follow from it.
//!
//! **A robot that is a TCP server, or that the PC polls** fits the same traits (worked example,
//! not implemented: Universal Robots RTDE, the PC a TCP client of the controller's port 30004,
//! the robot pushing its state at 500 Hz): `devices/rtde/` with a `RtdeRobot` whose
//! [`RobotDevice::open_parsed`] connects to `robot_host:30004` within
//! [`LinkContext::connect_timeout`] (`TcpStream::connect_timeout`, like the SRI sensor link),
//! negotiates the protocol version and the output/input recipes (blocking, each answer
//! checked), sends `RTDE_CONTROL_PACKAGE_START` and leaves the stream non-blocking;
//! [`RobotDevice::PACING`] is [`Pacing::Clock`] (the state arrives every 2 ms whatever the PC
//! sends; nothing must be answered per packet); [`RobotLink::feedback_period`] is 0.002;
//! [`RobotLink::poll`] reads the stream into a preallocated frame buffer (as the SRI link
//! does), decodes each `DATA_PACKAGE` (`actual_TCP_pose`, `timestamp`) and gives it to
//! [`RobotIdentity::accept`] with a `u32` sequence of its own (TCP neither drops nor reorders,
//! so `lost` and `stale` stay 0) or a timestamp in ms like [`transport::Ipoc`];
//! [`RobotLink::send`] writes the command into the input registers of the recipe (a URScript
//! on the controller servoes to them); [`RobotLink::peer`] is the address connected to,
//! `Some` from `open` on; [`RobotLink::transport`] is [`Transport::TcpClient`]. Its emulated
//! endpoint is a TCP server ([`RobotEndpoint::peer`] None until the PC connects,
//! [`RobotEndpoint::transport`] [`Transport::TcpServer`]), like the emulated SRI box. One
//! `registry!` line, `Rtde = "rtde", rtde::RtdeRobot, rtde::RtdeEndpoint;`, and the loop, the
//! emulator, the options' schema and the CLI's protocol lists take it as they are.
//!
//! Every datagram a link or an endpoint receives is counted in its [`LinkStats`], and so is
//! every socket error, on receive and on send ([`LinkStats::io_errors`]): nothing is dropped
//! uncounted. Polling, serving, sending and holding never allocate.

pub mod egm;
pub mod link;
pub mod pose;
pub mod rdt;
pub mod rsi;
pub mod sri;
pub mod transport;

use serde::{Deserialize, Serialize};

use crate::error::Result;
pub use link::*;
pub(crate) use transport::{check_host, local_addr, resolve};
pub use transport::{recv_counted, sequence_counted, wait_readable};

/// The registry: from one line per protocol, the option enums (tagged by `kind`), their
/// parsed forms, the open functions, the pacing and the kind lists.
macro_rules! registry {
    (
        sensors { $( $(#[doc = $sdoc:literal])+ $sensor:ident = $skind:literal, $slink:ty, $semu:ty; )+ }
        robots { $( $(#[doc = $rdoc:literal])+ $robot:ident = $rkind:literal, $rlink:ty, $remu:ty; )+ }
    ) => {
        /// Sensor protocols, as `[sensor] kind` / `--sensor-protocol` accept them, in the
        /// runtime's options and the emulator's alike (the one list, from the registry).
        pub const SENSOR_KINDS: &[&str] = &[$($skind),+];
        /// Robot protocols, as `[robot] kind` / `--robot-protocol` accept them, in the
        /// runtime's options and the emulator's alike (the one list, from the registry).
        pub const ROBOT_KINDS: &[&str] = &[$($rkind),+];

        /// Options of the sensor link, one variant per protocol (`kind`).
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
        #[serde(tag = "kind")]
        pub enum SensorOptions {
            $( $(#[doc = $sdoc])+ #[serde(rename = $skind)] $sensor(<$slink as SensorDevice>::Options), )+
        }

        /// The sensor link's options once parsed ([`SensorOptions::parse`]), one variant per
        /// protocol: what [`open_sensor`] opens, checked once.
        #[derive(Debug, Clone, PartialEq)]
        pub enum SensorConfig {
            $( $(#[doc = $sdoc])+ $sensor(<$slink as SensorDevice>::Config), )+
        }

        /// Options of the emulated sensor, one variant per protocol (`kind`, the same kinds as
        /// [`SensorOptions`]).
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
        #[serde(tag = "kind")]
        pub enum EmulatedSensorOptions {
            $( $(#[doc = $sdoc])+ #[serde(rename = $skind)] $sensor(<$semu as EmulatedSensor>::Options), )+
        }

        /// The emulated sensor's options once parsed ([`EmulatedSensorOptions::parse`]), one
        /// variant per protocol: what [`open_sensor_endpoint`] opens, checked once.
        #[derive(Debug, Clone, PartialEq)]
        pub enum EmulatedSensorConfig {
            $( $(#[doc = $sdoc])+ $sensor(<$semu as EmulatedSensor>::Config), )+
        }

        /// Options of the robot link, one variant per protocol (`kind`).
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
        #[serde(tag = "kind")]
        pub enum RobotOptions {
            $( $(#[doc = $rdoc])+ #[serde(rename = $rkind)] $robot(<$rlink as RobotDevice>::Options), )+
        }

        /// The robot link's options once parsed ([`RobotOptions::parse`]), one variant per
        /// protocol: what [`open_robot`] opens, checked once.
        #[derive(Debug, Clone, PartialEq)]
        pub enum RobotConfig {
            $( $(#[doc = $rdoc])+ $robot(<$rlink as RobotDevice>::Config), )+
        }

        /// Options of the emulated robot, one variant per protocol (`kind`, the same kinds as
        /// [`RobotOptions`]).
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
        #[serde(tag = "kind")]
        pub enum EmulatedRobotOptions {
            $( $(#[doc = $rdoc])+ #[serde(rename = $rkind)] $robot(<$remu as EmulatedRobot>::Options), )+
        }

        /// The emulated robot's options once parsed ([`EmulatedRobotOptions::parse`]), one
        /// variant per protocol: what [`open_robot_endpoint`] opens, checked once.
        #[derive(Debug, Clone, PartialEq)]
        pub enum EmulatedRobotConfig {
            $( $(#[doc = $rdoc])+ $robot(<$remu as EmulatedRobot>::Config), )+
        }

        impl SensorOptions {
            /// The options of `kind` with its defaults, if `kind` is registered.
            pub fn from_kind(kind: &str) -> Option<Self> {
                match kind { $( $skind => Some(SensorOptions::$sensor(Default::default())), )+ _ => None }
            }

            /// The protocol's `kind`.
            pub fn kind(&self) -> &'static str {
                match self { $( SensorOptions::$sensor(_) => $skind, )+ }
            }

            /// How the link reaches the sensor, known before it is opened.
            pub fn transport(&self) -> Transport {
                match self { $( SensorOptions::$sensor(_) => <$slink as SensorDevice>::TRANSPORT, )+ }
            }

            /// Checks the options that need no socket (the host's form, the protocol's own
            /// values) and types them, once, so that bad input is refused before any file or
            /// socket is created.
            pub fn parse(&self) -> Result<SensorConfig> {
                Ok(match self { $( SensorOptions::$sensor(o) => SensorConfig::$sensor(<$slink as SensorDevice>::parse(o)?), )+ })
            }
        }

        impl SensorConfig {
            /// The checks across the options and the scenario's control period `period` (s),
            /// e.g. a sample rate taken from it; done once, before anything is opened.
            pub fn check_period(&self, period: f64) -> Result<()> {
                match self { $( SensorConfig::$sensor(c) => <$slink as SensorDevice>::check_period(c, period), )+ }
            }
        }

        /// Opens the sensor link of `config` (binds, reads what it needs before the loop
        /// starts).
        pub fn open_sensor(config: &SensorConfig, context: &LinkContext) -> Result<Box<dyn SensorLink>> {
            match config { $( SensorConfig::$sensor(c) => Ok(Box::new(<$slink as SensorDevice>::open_parsed(c, context)?)), )+ }
        }

        impl EmulatedSensorOptions {
            /// The options of `kind` with its defaults, if `kind` is registered.
            pub fn from_kind(kind: &str) -> Option<Self> {
                match kind { $( $skind => Some(EmulatedSensorOptions::$sensor(Default::default())), )+ _ => None }
            }

            /// Checks and types the options, once, before anything is opened.
            pub fn parse(&self) -> Result<EmulatedSensorConfig> {
                Ok(match self { $( EmulatedSensorOptions::$sensor(o) => EmulatedSensorConfig::$sensor(<$semu as EmulatedSensor>::parse(o)?), )+ })
            }
        }

        /// Opens the emulated sensor of `config` (binds its sockets and servers).
        pub fn open_sensor_endpoint(
            config: &EmulatedSensorConfig,
            context: &EndpointContext,
        ) -> Result<Box<dyn SensorEndpoint>> {
            match config { $( EmulatedSensorConfig::$sensor(c) => Ok(Box::new(<$semu as EmulatedSensor>::open_parsed(c, context)?)), )+ }
        }

        impl RobotOptions {
            /// The options of `kind` with its defaults, if `kind` is registered.
            pub fn from_kind(kind: &str) -> Option<Self> {
                match kind { $( $rkind => Some(RobotOptions::$robot(Default::default())), )+ _ => None }
            }

            /// The protocol's `kind`.
            pub fn kind(&self) -> &'static str {
                match self { $( RobotOptions::$robot(_) => $rkind, )+ }
            }

            /// What clocks the loop with this robot, known before it is opened (the opened
            /// link's [`RobotLink::pacing`] says the same; with [`Pacing::Robot`] the
            /// scenario's period must equal the robot's cycle).
            pub fn pacing(&self) -> Pacing {
                match self { $( RobotOptions::$robot(_) => <$rlink as RobotDevice>::PACING, )+ }
            }

            /// How the link reaches the robot, known before it is opened.
            pub fn transport(&self) -> Transport {
                match self { $( RobotOptions::$robot(_) => <$rlink as RobotDevice>::TRANSPORT, )+ }
            }

            /// Checks the options that need no socket (hosts, pose mapping, the protocol's own
            /// values) and types them, once, so that bad input is refused before any file or
            /// socket is created.
            pub fn parse(&self) -> Result<RobotConfig> {
                Ok(match self { $( RobotOptions::$robot(o) => RobotConfig::$robot(<$rlink as RobotDevice>::parse(o)?), )+ })
            }
        }

        /// Opens the robot link of `config` (binds its socket, or connects to the robot).
        pub fn open_robot(config: &RobotConfig, context: &LinkContext) -> Result<Box<dyn RobotLink>> {
            match config { $( RobotConfig::$robot(c) => Ok(Box::new(<$rlink as RobotDevice>::open_parsed(c, context)?)), )+ }
        }

        impl EmulatedRobotOptions {
            /// The options of `kind` with its defaults, if `kind` is registered.
            pub fn from_kind(kind: &str) -> Option<Self> {
                match kind { $( $rkind => Some(EmulatedRobotOptions::$robot(Default::default())), )+ _ => None }
            }

            /// Checks and types the options, once, before anything is opened.
            pub fn parse(&self) -> Result<EmulatedRobotConfig> {
                Ok(match self { $( EmulatedRobotOptions::$robot(o) => EmulatedRobotConfig::$robot(<$remu as EmulatedRobot>::parse(o)?), )+ })
            }
        }

        /// Opens the emulated robot of `config` (binds its socket, resolves where feedback
        /// goes).
        pub fn open_robot_endpoint(
            config: &EmulatedRobotConfig,
            context: &EndpointContext,
        ) -> Result<Box<dyn RobotEndpoint>> {
            match config { $( EmulatedRobotConfig::$robot(c) => Ok(Box::new(<$remu as EmulatedRobot>::open_parsed(c, context)?)), )+ }
        }
    };
}

registry! {
    sensors {
        /// ATI Net F/T over RDT (the emulated one with `/netftapi2.xml` over HTTP).
        Rdt = "rdt", rdt::RdtSensor, rdt::RdtEndpoint;
        /// SRI M812x interface box over TCP.
        Sri = "sri", sri::SriSensor, sri::SriEndpoint;
    }
    robots {
        /// ABB Externally Guided Motion.
        Egm = "egm", egm::EgmRobot, egm::EgmEndpoint;
        /// KUKA RobotSensorInterface over Ethernet.
        Rsi = "rsi", rsi::RsiRobot, rsi::RsiEndpoint;
    }
}

/// The first registered sensor protocol, with its defaults.
impl Default for SensorOptions {
    fn default() -> Self {
        SensorOptions::from_kind(SENSOR_KINDS[0]).expect("a registered kind")
    }
}

/// The first registered robot protocol, with its defaults.
impl Default for RobotOptions {
    fn default() -> Self {
        RobotOptions::from_kind(ROBOT_KINDS[0]).expect("a registered kind")
    }
}

/// The first registered sensor protocol, with its defaults.
impl Default for EmulatedSensorOptions {
    fn default() -> Self {
        EmulatedSensorOptions::from_kind(SENSOR_KINDS[0]).expect("a registered kind")
    }
}

/// The first registered robot protocol, with its defaults.
impl Default for EmulatedRobotOptions {
    fn default() -> Self {
        EmulatedRobotOptions::from_kind(ROBOT_KINDS[0]).expect("a registered kind")
    }
}

/// The default options of every protocol, keyed by kind, for the runtime's links and the
/// emulator's devices: `{"runtime": {"sensor": {"rdt": {...}, "sri": {...}}, "robot": {...}},
/// "facility": {...}, "robot_paced": [KIND, ...], "transport": {"sensor": {"rdt": "udp", "sri":
/// "tcp-client"}, "robot": {...}}}` (each kind's options as `{"kind": KIND}` deserializes them:
/// the one place the defaults live; each link's [`Transport`], for addresses shown to the user).
pub fn protocol_defaults() -> serde_json::Value {
    fn each<T: Serialize + serde::de::DeserializeOwned>(
        kinds: &[&str],
    ) -> serde_json::Map<String, serde_json::Value> {
        kinds
            .iter()
            .filter_map(|kind| {
                let options: T =
                    serde_json::from_value(serde_json::json!({ "kind": kind })).ok()?;
                Some((kind.to_string(), serde_json::to_value(options).ok()?))
            })
            .collect()
    }
    fn transports<T>(
        kinds: &[&str],
        options: impl Fn(&str) -> Option<T>,
        transport: impl Fn(&T) -> Transport,
    ) -> serde_json::Map<String, serde_json::Value> {
        kinds
            .iter()
            .filter_map(|kind| {
                let transport = transport(&options(kind)?);
                Some((kind.to_string(), serde_json::to_value(transport).ok()?))
            })
            .collect()
    }
    let paced: Vec<&str> = ROBOT_KINDS
        .iter()
        .copied()
        .filter(|kind| RobotOptions::from_kind(kind).is_some_and(|o| o.pacing() == Pacing::Robot))
        .collect();
    serde_json::json!({
        "robot_paced": paced,
        "transport": {
            "sensor": transports(SENSOR_KINDS, SensorOptions::from_kind, SensorOptions::transport),
            "robot": transports(ROBOT_KINDS, RobotOptions::from_kind, RobotOptions::transport),
        },
        "runtime": {
            "sensor": each::<SensorOptions>(SENSOR_KINDS),
            "robot": each::<RobotOptions>(ROBOT_KINDS),
        },
        "facility": {
            "sensor": each::<EmulatedSensorOptions>(SENSOR_KINDS),
            "robot": each::<EmulatedRobotOptions>(ROBOT_KINDS),
        },
    })
}
