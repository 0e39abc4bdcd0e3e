//! The emulated facility behind the device seam: its options grouped per device kind (TOML and
//! JSON), unknown kinds rejected with the allowed ones, the kind lists shared with the runtime,
//! socket errors counted (never dropped), and I/O errors that keep their kind and errno.

mod common;

use std::io::ErrorKind;
use std::time::{Duration, Instant};

use common::{free_udp_port, preset};
use hilcontact_rt::devices::egm::EgmEndpointOptions;
use hilcontact_rt::devices::rdt::RdtEndpointOptions;
use hilcontact_rt::devices::{
    EmulatedRobotOptions, EmulatedSensorOptions, ROBOT_KINDS, SENSOR_KINDS,
};
use hilcontact_rt::{
    EmulatorOptions, FacilityHandle, RobotOptions, RtError, RuntimeOptions, SensorOptions,
};

#[test]
fn emulator_options_are_grouped_per_device_kind() {
    let text = r#"
        silence_robot_after = 2.5
        [sensor]
        kind = "rdt"
        port = 49153
        http_port = 0
        counts_per_force = 2000000.0
        force_unit = "lbf"
        [robot]
        kind = "egm"
        host = "192.168.1.10"
        port = 6511
        period = 0.008
        offset_mm = [1.0, 2.0, 3.0]
    "#;
    let o: EmulatorOptions = toml::from_str(text).unwrap();
    let EmulatedSensorOptions::Rdt(sensor) = &o.sensor else {
        panic!("{:?}", o.sensor)
    };
    let EmulatedRobotOptions::Egm(robot) = &o.robot else {
        panic!("EGM options expected")
    };
    assert_eq!(
        (sensor.port, sensor.http_port, sensor.bind_host.as_str()),
        (49153, 0, "127.0.0.1")
    );
    assert_eq!(
        (sensor.counts_per_force, sensor.counts_per_torque),
        (2e6, 1e6)
    );
    assert_eq!(
        (sensor.force_unit.as_str(), sensor.torque_unit.as_str()),
        ("lbf", "N-m")
    );
    assert_eq!(
        (robot.host.as_str(), robot.port, robot.local_port),
        ("192.168.1.10", 6511, 0)
    );
    assert_eq!(
        (robot.period, robot.offset_mm, robot.rotation),
        (0.008, [1.0, 2.0, 3.0], [1.0, 0.0, 0.0, 0.0])
    );
    assert_eq!(
        (o.silence_sensor_after, o.silence_robot_after),
        (None, Some(2.5))
    );

    // JSON round trip, and TOML back again
    let json = serde_json::to_value(&o).unwrap();
    assert_eq!(json["sensor"]["kind"], "rdt");
    assert_eq!(json["robot"]["kind"], "egm");
    assert_eq!(json["robot"]["host"], "192.168.1.10");
    assert_eq!(serde_json::from_value::<EmulatorOptions>(json).unwrap(), o);
    let again: EmulatorOptions = toml::from_str(&toml::to_string(&o).unwrap()).unwrap();
    assert_eq!(again, o);

    // the defaults are those of the flat options of earlier versions
    let d = serde_json::to_value(EmulatorOptions::default()).unwrap();
    assert_eq!(
        d["sensor"],
        serde_json::json!({
            "kind": "rdt", "bind_host": "127.0.0.1", "port": 49152, "http_port": 80,
            "counts_per_force": 1e6, "counts_per_torque": 1e6,
            "force_unit": "N", "torque_unit": "N-m",
        })
    );
    assert_eq!(
        d["robot"],
        serde_json::json!({
            "kind": "egm", "host": "127.0.0.1", "port": 6510, "local_port": 0, "period": 0.004,
            "offset_mm": [0.0, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0], "robotware": 7,
        })
    );
    assert_eq!(
        EmulatorOptions::default().robot,
        EmulatedRobotOptions::Egm(EgmEndpointOptions::default())
    );
    assert_eq!(
        EmulatorOptions::default().sensor,
        EmulatedSensorOptions::Rdt(RdtEndpointOptions::default())
    );

    // a key of another kind, a flat key of earlier versions and a missing kind are errors
    for bad in [
        r#"{"robot": {"kind": "egm", "http_port": 80}}"#,
        r#"{"egm_port": 6510}"#,
        r#"{"sensor": {"port": 5}}"#,
    ] {
        assert!(
            serde_json::from_str::<EmulatorOptions>(bad).is_err(),
            "{bad} was accepted"
        );
    }
}

#[test]
fn an_unknown_protocol_is_rejected_naming_the_allowed_ones() {
    for bad in [
        r#"{"robot": {"kind": "fri"}}"#,
        r#"{"sensor": {"kind": "m8128x"}}"#,
    ] {
        let emulator = serde_json::from_str::<EmulatorOptions>(bad)
            .unwrap_err()
            .to_string();
        let runtime = serde_json::from_str::<RuntimeOptions>(bad)
            .unwrap_err()
            .to_string();
        let allowed = if bad.contains("robot") {
            ROBOT_KINDS
        } else {
            SENSOR_KINDS
        };
        for message in [&emulator, &runtime] {
            assert!(message.contains("unknown variant"), "{message}");
            for kind in allowed {
                assert!(
                    message.contains(&format!("`{kind}`")),
                    "{message} lacks {kind}"
                );
            }
        }
    }
}

#[test]
fn the_runtime_and_the_emulator_take_the_same_kinds() {
    // one kind list per device: every kind has a link and an endpoint, and no other kind does
    for kind in SENSOR_KINDS {
        let j = serde_json::json!({ "kind": kind });
        assert!(
            serde_json::from_value::<SensorOptions>(j.clone()).is_ok(),
            "link {kind}"
        );
        assert!(
            serde_json::from_value::<EmulatedSensorOptions>(j).is_ok(),
            "endpoint {kind}"
        );
    }
    for kind in ROBOT_KINDS {
        let j = serde_json::json!({ "kind": kind });
        assert!(
            serde_json::from_value::<RobotOptions>(j.clone()).is_ok(),
            "link {kind}"
        );
        assert!(
            serde_json::from_value::<EmulatedRobotOptions>(j).is_ok(),
            "endpoint {kind}"
        );
    }
    // the error lists the variants: exactly the kinds
    let listed = |e: String| {
        let tail = e.split("expected ").nth(1).unwrap_or("").to_string();
        tail.matches('`').count() / 2
    };
    let unknown = serde_json::json!({ "kind": "?" });
    assert_eq!(
        listed(
            serde_json::from_value::<EmulatedSensorOptions>(unknown.clone())
                .unwrap_err()
                .to_string()
        ),
        SENSOR_KINDS.len()
    );
    assert_eq!(
        listed(
            serde_json::from_value::<EmulatedRobotOptions>(unknown.clone())
                .unwrap_err()
                .to_string()
        ),
        ROBOT_KINDS.len()
    );
    assert_eq!(
        listed(
            serde_json::from_value::<SensorOptions>(unknown.clone())
                .unwrap_err()
                .to_string()
        ),
        SENSOR_KINDS.len()
    );
    assert_eq!(
        listed(
            serde_json::from_value::<RobotOptions>(unknown)
                .unwrap_err()
                .to_string()
        ),
        ROBOT_KINDS.len()
    );
}

fn options(sensor_port: u16, robot_host: &str) -> EmulatorOptions {
    EmulatorOptions {
        sensor: EmulatedSensorOptions::Rdt(RdtEndpointOptions {
            port: sensor_port,
            http_port: 0,
            ..Default::default()
        }),
        robot: EmulatedRobotOptions::Egm(EgmEndpointOptions {
            host: robot_host.into(),
            port: free_udp_port(),
            ..Default::default()
        }),
        ..Default::default()
    }
}

#[test]
fn the_emulators_send_errors_are_counted() {
    // feedback to the broadcast address: the kernel refuses every send (no SO_BROADCAST);
    // each refusal is counted, none is dropped
    let facility = FacilityHandle::start(
        &preset("paper-table1"),
        &options(free_udp_port(), "255.255.255.255"),
    )
    .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10); // generous: a busy machine
    while facility.status().robot.send_errors < 5 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = facility.join();
    let robot = status.robot;
    assert!(robot.send_errors >= 5, "{status:?}");
    assert_eq!(robot.sent, 0, "{status:?}");
    assert_eq!(status.robot.sent, 0);
    assert!(robot.io_errors >= robot.send_errors, "{status:?}");
    assert_eq!(status.io_errors, status.sensor.io_errors + robot.io_errors);
    // one feedback every 4 ms of the emulator's time: every one of them failed and was counted
    let due = status.tick.div_ceil(4);
    assert!(
        robot.send_errors + 1 >= due && robot.send_errors <= due + 1,
        "{status:?}"
    );
    let json = serde_json::to_value(status).unwrap();
    assert_eq!(json["robot"]["send_errors"], robot.send_errors);
    assert_eq!(json["io_errors"], status.io_errors);
    assert_eq!(
        (
            json["sensor_protocol"].as_str(),
            json["robot_protocol"].as_str()
        ),
        (Some("RDT"), Some("EGM"))
    );
}

#[test]
fn a_port_in_use_keeps_its_kind_and_errno() {
    let taken = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let err = FacilityHandle::start(&preset("paper-table1"), &options(port, "127.0.0.1"))
        .err()
        .expect("the sensor's port is in use");
    match &err {
        RtError::Io {
            kind,
            errno,
            context,
            ..
        } => {
            assert_eq!(*kind, ErrorKind::AddrInUse, "{err}");
            assert_eq!(*errno, Some(libc::EADDRINUSE), "{err}");
            assert!(
                context.contains("sensor (RDT)") && context.contains(&port.to_string()),
                "{err}"
            );
        }
        other => panic!("not an I/O error: {other:?}"),
    }
    assert_eq!(err.errno(), Some(libc::EADDRINUSE));
    assert!(err.to_string().contains("cannot bind UDP"), "{err}");
}

#[test]
fn the_robotware_generation_is_6_or_7() {
    let o: EmulatorOptions = toml::from_str("[robot]\nkind = \"egm\"\nrobotware = 6\n").unwrap();
    let EmulatedRobotOptions::Egm(robot) = &o.robot else {
        panic!("EGM options expected")
    };
    assert_eq!(robot.robotware, 6);
    let mut bad = options(free_udp_port(), "127.0.0.1");
    let EmulatedRobotOptions::Egm(robot) = &mut bad.robot else {
        panic!("EGM options expected")
    };
    robot.robotware = 5;
    let err = FacilityHandle::start(&preset("paper-table1"), &bad)
        .err()
        .expect("RobotWare 5 was accepted");
    assert!(matches!(err, RtError::Option { .. }), "{err:?}");
    assert!(err.to_string().contains("must be 6 or 7, got 5"), "{err}");
}

#[test]
fn every_protocol_has_its_defaults_listed() {
    let d = hilcontact_rt::devices::protocol_defaults();
    for side in ["runtime", "facility"] {
        for (link, kinds) in [("sensor", SENSOR_KINDS), ("robot", ROBOT_KINDS)] {
            let listed = d[side][link].as_object().expect("a table per link");
            assert_eq!(listed.len(), kinds.len(), "{side}.{link}: {listed:?}");
            for kind in kinds {
                assert_eq!(listed[*kind]["kind"], *kind, "{side}.{link}.{kind}");
                assert!(
                    listed[*kind]["port"].is_u64(),
                    "{side}.{link}.{kind} has a port"
                );
            }
        }
    }
    // the RSI controller's cycle, used by demo-rt for the loop period of a robot-paced loop
    assert_eq!(d["facility"]["robot"]["rsi"]["period"], 0.004);
    assert_eq!(d["robot_paced"], serde_json::json!(["rsi"]));
}
