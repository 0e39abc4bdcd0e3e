//! Helpers shared by the loopback tests.
#![allow(dead_code)]

use hilcontact_core::Scenario;
use hilcontact_rt::devices::egm::{EgmEndpointOptions, EgmOptions};
use hilcontact_rt::devices::rdt::{RdtEndpointOptions, RdtOptions};
use hilcontact_rt::devices::{EmulatedRobotOptions, EmulatedSensorOptions};
use hilcontact_rt::safety::SafetyLimits;
use hilcontact_rt::{EmulatorOptions, RobotOptions, RuntimeOptions, SensorOptions};

/// A preset scenario from `python/hilcontact/scenarios/<name>.toml`.
pub fn preset(name: &str) -> Scenario {
    let path = format!(
        "{}/../../python/hilcontact/scenarios/{name}.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    toml::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// A UDP port that was free a moment ago.
pub fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// Emulator and runtime options that meet on loopback, without HTTP (counts given).
pub fn loopback_options() -> (EmulatorOptions, RuntimeOptions) {
    let sensor_port = free_udp_port();
    let egm_port = free_udp_port();
    let sensor = RdtEndpointOptions {
        port: sensor_port,
        http_port: 0,
        ..Default::default()
    };
    let runtime = RuntimeOptions {
        // a generous watchdog: the emulator runs at normal priority and a busy machine can
        // starve it for more than the default 50 ms (the watchdog's own tests set theirs)
        limits: SafetyLimits {
            watchdog_ms: 500.0,
            ..Default::default()
        },
        sensor: SensorOptions::Rdt(RdtOptions {
            port: sensor_port,
            counts_per_force: Some(sensor.counts_per_force),
            counts_per_torque: Some(sensor.counts_per_torque),
            ..Default::default()
        }),
        robot: RobotOptions::Egm(EgmOptions {
            port: egm_port,
            bind_host: "127.0.0.1".into(),
            ..Default::default()
        }),
        ..Default::default()
    };
    let emulator = EmulatorOptions {
        sensor: EmulatedSensorOptions::Rdt(sensor),
        robot: EmulatedRobotOptions::Egm(EgmEndpointOptions {
            port: egm_port,
            ..Default::default()
        }),
        ..Default::default()
    };
    (emulator, runtime)
}

/// A TCP port that was free a moment ago.
pub fn free_tcp_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// [`loopback_options`] with the sensor an SRI M812x box (TCP) instead of a Net F/T.
pub fn loopback_sri_options() -> (EmulatorOptions, RuntimeOptions) {
    use hilcontact_rt::devices::sri::{SriEndpointOptions, SriOptions};
    let (mut emulator, mut runtime) = loopback_options();
    let port = free_tcp_port();
    emulator.sensor = EmulatedSensorOptions::Sri(SriEndpointOptions {
        port,
        ..Default::default()
    });
    runtime.sensor = SensorOptions::Sri(SriOptions {
        port,
        ..Default::default()
    });
    (emulator, runtime)
}

/// Emulator and runtime options that meet on loopback with the robot on KUKA RSI (sensor RDT,
/// without HTTP); the scenario's period must be the RSI cycle (0.004 s).
pub fn rsi_loopback_options() -> (EmulatorOptions, RuntimeOptions) {
    use hilcontact_rt::devices::rsi::{RsiEndpointOptions, RsiOptions};
    let (mut emulator, mut runtime) = loopback_options();
    let port = free_udp_port();
    runtime.robot = RobotOptions::Rsi(RsiOptions {
        port,
        bind_host: "127.0.0.1".into(),
        ..Default::default()
    });
    emulator.robot = EmulatedRobotOptions::Rsi(RsiEndpointOptions {
        port,
        ..Default::default()
    });
    (emulator, runtime)
}
