//! The SRI M812x link and the emulated box: an independent client written here from the
//! published protocol (plain `TcpStream`, hand-written parsing, not the crate's codec) talks to
//! the emulated box; the link reads a scripted box that splits, concatenates, corrupts and
//! skips frames; a refusal fails the open naming the command; the TOML kind.

mod common;

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant};

use common::{endpoint_context, free_tcp_port, link_context};
use hilcontact_rt::devices::sri::{SriEndpoint, SriEndpointOptions, SriOptions, SriSensor};
use hilcontact_rt::devices::{EmulatedSensorOptions, SensorEndpoint, SensorLink, Wrench};
use hilcontact_rt::{EmulatorOptions, RtError, RuntimeOptions, SensorOptions};
use nalgebra::Vector3;

/// Runs the emulated box on its own thread, one control period per millisecond, sampling
/// `wrench` (plus k·1e-3 N on Fx at period k); returns the box's address.
fn run_box(stop: Arc<AtomicBool>) -> (std::net::SocketAddr, thread::JoinHandle<SriEndpoint>) {
    let o = SriEndpointOptions {
        port: 0,
        ..Default::default()
    };
    let mut e = SriEndpoint::open(&o, &endpoint_context()).unwrap();
    let address = e.address();
    let handle = thread::spawn(move || {
        let mut k = 0u64;
        while !stop.load(Ordering::Relaxed) {
            e.serve();
            let w = Wrench {
                force: Vector3::new(1.5 + k as f64 * 1e-3, -2.0, 30.0),
                moment: Vector3::new(0.25, -0.5, 0.125),
            };
            e.sample(&w, true);
            k += 1;
            thread::sleep(Duration::from_millis(1));
        }
        e
    });
    (address, handle)
}

/// Reads one `\r\n`-terminated answer line.
fn answer(r: &mut BufReader<TcpStream>) -> String {
    let mut line = String::new();
    r.read_line(&mut line).unwrap();
    line
}

/// The independent client: the M812x protocol as the published clients use it, parsed by
/// hand (header AA 55, length 27 big-endian, package number big-endian, six little-endian
/// f32, the sum of the 24 data bytes as checksum).
#[test]
fn an_independent_client_configures_the_emulated_box_and_reads_its_frames() {
    let stop = Arc::new(AtomicBool::new(false));
    let (address, handle) = run_box(stop.clone());
    let stream = TcpStream::connect(address).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(2)))
        .unwrap();
    let mut w = stream.try_clone().unwrap();
    let mut r = BufReader::new(stream);
    for (command, expected) in [
        ("AT+SMPR=500\r\n", "ACK+SMPR=500$OK\r\n"),
        ("AT+DCKMD=SUM\r\n", "ACK+DCKMD=SUM$OK\r\n"),
        (
            "AT+SGDM=(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)\r\n",
            "ACK+SGDM=(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)$OK\r\n",
        ),
        ("AT+DCPCU=MVPV\r\n", "ACK+DCPCU=MVPV$OK\r\n"),
        ("AT+SMPR=0\r\n", "ACK+SMPR=0$ERROR\r\n"),
    ] {
        w.write_all(command.as_bytes()).unwrap();
        assert_eq!(answer(&mut r), expected, "{command:?}");
    }
    let matrix =
        "(1,0,0,0,0,0);(0,1,0,0,0,0);(0,0,1,0,0,0);(0,0,0,1,0,0);(0,0,0,0,1,0);(0,0,0,0,0,1)";
    w.write_all(format!("AT+DCPM={matrix}\r\n").as_bytes())
        .unwrap();
    assert_eq!(answer(&mut r), format!("ACK+DCPM={matrix}$OK\r\n"));
    w.write_all(b"AT+GSD\r\n").unwrap();
    let mut frames: Vec<(u16, [f32; 6])> = Vec::new();
    let begun = Instant::now();
    while frames.len() < 100 && begun.elapsed() < Duration::from_secs(5) {
        // find the header byte by byte, then read the rest of the frame
        let mut b = [0u8; 1];
        r.read_exact(&mut b).unwrap();
        if b[0] != 0xAA {
            continue;
        }
        r.read_exact(&mut b).unwrap();
        if b[0] != 0x55 {
            continue;
        }
        let mut rest = [0u8; 29];
        r.read_exact(&mut rest).unwrap();
        let length = (rest[0] as usize) * 256 + rest[1] as usize;
        assert_eq!(length, 27);
        let package = (rest[2] as u16) * 256 + rest[3] as u16;
        let data = &rest[4..28];
        let sum = data.iter().map(|b| *b as u32).sum::<u32>() % 256;
        assert_eq!(sum, rest[28] as u32, "checksum of package {package}");
        let mut values = [0f32; 6];
        for (i, v) in values.iter_mut().enumerate() {
            *v = f32::from_le_bytes(data[4 * i..4 * i + 4].try_into().unwrap());
        }
        frames.push((package, values));
    }
    w.write_all(b"AT+GSD=STOP\r\n").unwrap();
    assert_eq!(frames.len(), 100);
    // consecutive package numbers, the emulated wrench in N and N·m
    for pair in frames.windows(2) {
        assert_eq!(pair[1].0, pair[0].0.wrapping_add(1));
    }
    for (_, v) in &frames {
        assert!(v[0] > 1.5 && v[0] < 1.5 + 10.0, "{v:?}");
        assert_eq!(&v[1..], &[-2.0, 30.0, 0.25, -0.5, 0.125]);
    }
    // 500 Hz of a 1 kHz box: Fx grows 2e-3 N per frame
    let step = frames[50].1[0] - frames[49].1[0];
    assert!((step - 2e-3).abs() < 2e-4, "Fx step {step}");
    stop.store(true, Ordering::Relaxed);
    let e = handle.join().unwrap();
    assert_eq!(e.sample_rate(), 500.0);
    assert_eq!(e.matrix().unwrap()[3][3], 1.0);
    assert!(e.stats().invalid >= 1); // SMPR=0
}

/// A scripted box: answers the configuration as the manual's clients expect, then sends
/// what the test scripts once `AT+GSD` arrives.
fn scripted_box(
    script: Vec<Vec<u8>>,
    refuse: Option<&'static str>,
) -> (u16, thread::JoinHandle<Vec<String>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let handle = thread::spawn(move || {
        let (stream, _) = listener.accept().unwrap();
        stream
            .set_read_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        let mut w = stream.try_clone().unwrap();
        let mut r = BufReader::new(stream);
        let mut commands = Vec::new();
        loop {
            let mut line = String::new();
            if r.read_line(&mut line).unwrap_or(0) == 0 {
                return commands;
            }
            let line = line.trim_end().to_string();
            commands.push(line.clone());
            let body = line.strip_prefix("AT+").unwrap();
            if body == "GSD" {
                for chunk in &script {
                    w.write_all(chunk).unwrap();
                    w.flush().unwrap();
                    thread::sleep(Duration::from_millis(5));
                }
            } else if body.starts_with("GSD") {
                // GSD=STOP: no answer
            } else {
                let status = if refuse.is_some_and(|c| body.starts_with(c)) {
                    "ERROR"
                } else {
                    "OK"
                };
                // answers may come split, and after stray bytes of an earlier stream
                let text = format!("ACK+{body}${status}\r\n");
                let (a, b) = text.as_bytes().split_at(5);
                w.write_all(&[0xAA, 0x55, 0x00]).unwrap();
                w.write_all(a).unwrap();
                w.flush().unwrap();
                thread::sleep(Duration::from_millis(2));
                w.write_all(b).unwrap();
            }
        }
    });
    (port, handle)
}

/// One frame, built by hand.
fn frame(package: u16, values: [f32; 6]) -> Vec<u8> {
    let mut out = vec![0xAA, 0x55, 0x00, 27];
    out.extend_from_slice(&package.to_be_bytes());
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    let sum = out[6..].iter().fold(0u8, |s, b| s.wrapping_add(*b));
    out.push(sum);
    out
}

fn poll_until(link: &mut SriSensor, accepted: u64) -> Option<Wrench> {
    let begun = Instant::now();
    let mut newest = None;
    while link.stats().accepted < accepted && begun.elapsed() < Duration::from_secs(3) {
        if let Some(w) = link.poll(0) {
            newest = Some(w);
        }
        thread::sleep(Duration::from_millis(1));
    }
    newest
}

#[test]
fn the_link_configures_the_box_and_counts_split_corrupt_and_missing_frames() {
    let v = |x: f32| [x, 2.0, -3.0, 0.5, -0.25, 0.125];
    let mut bad = frame(3, v(3.0));
    bad[10] ^= 0x01; // checksum no longer matches
    let two = [frame(5, v(5.0)), frame(6, v(6.0))].concat();
    let split = frame(7, v(7.0));
    let script = vec![
        b"ACK+GSD=OK\r\n".to_vec(), // an answer before the first frame: skipped silently
        frame(1, v(1.0)),
        frame(2, v(2.0))[..10].to_vec(),
        frame(2, v(2.0))[10..].to_vec(),
        bad,
        b"junk".to_vec(),
        frame(4, v(4.0)),
        two,
        split[..3].to_vec(),
        split[3..].to_vec(),
        frame(10, v(10.0)), // 8 and 9 lost
        frame(11, [f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]),
        frame(12, v(12.0)),
    ];
    let (port, server) = scripted_box(script, None);
    let mut matrix = [[0.0; 6]; 6];
    for (i, row) in matrix.iter_mut().enumerate() {
        row[i] = 100.0 + i as f64;
    }
    let o = SriOptions {
        port,
        sample_rate: Some(1000.0),
        decoupling_matrix: Some(Box::new(matrix)),
        ..Default::default()
    };
    let mut link = SriSensor::open(&o, &link_context(2.0)).unwrap();
    link.start_streaming();
    let newest = poll_until(&mut link, 8).expect("frames");
    assert_eq!(newest.force, Vector3::new(12.0, 2.0, -3.0));
    assert_eq!(newest.moment, Vector3::new(0.5, -0.25, 0.125));
    let s = *link.stats();
    assert_eq!(s.accepted, 8, "{s:?}"); // 1 2 4 5 6 7 10 12
    assert_eq!(s.malformed, 1, "{s:?}"); // the bad checksum (its body and "junk" skipped)
    assert_eq!(s.invalid, 1, "{s:?}"); // NaN
    assert_eq!(s.lost, 3, "{s:?}"); // 3 (the corrupt one), 8, 9
    assert_eq!(s.io_errors, 0, "{s:?}");
    link.stop_streaming();
    drop(link);
    let commands = server.join().unwrap();
    assert_eq!(
        &commands[..4],
        &[
            "AT+GSD=STOP",
            "AT+DCKMD=SUM",
            "AT+SGDM=(A01,A02,A03,A04,A05,A06);E;1;(WMA:1)",
            "AT+SMPR=1000",
        ]
    );
    assert_eq!(commands[4], "AT+DCPCU=MVPV");
    assert!(
        commands[5].starts_with("AT+DCPM=(100.000000,0.000000,"),
        "{}",
        commands[5]
    );
    assert_eq!(&commands[6..], &["AT+GSD", "AT+GSD=STOP"]);
}

#[test]
fn a_refused_command_fails_the_open_naming_it() {
    let (port, _server) = scripted_box(vec![], Some("SMPR"));
    let o = SriOptions {
        port,
        sample_rate: Some(2000.0),
        ..Default::default()
    };
    let Err(e) = SriSensor::open(&o, &link_context(2.0)) else {
        panic!("a refused AT+SMPR must fail the open")
    };
    let text = e.to_string();
    assert!(matches!(e, RtError::Protocol(_)), "{e:?}");
    assert!(
        text.contains("AT+SMPR=2000") && text.contains("$ERROR"),
        "{text}"
    );

    // nothing listening: a connect error
    let port = free_tcp_port();
    let Err(e) = SriSensor::open(
        &SriOptions {
            port,
            ..Default::default()
        },
        &link_context(2.0),
    ) else {
        panic!("nothing listens")
    };
    assert!(matches!(e, RtError::Connect(_)), "{e:?}");
}

#[test]
fn the_link_reads_the_emulated_box() {
    let stop = Arc::new(AtomicBool::new(false));
    let (address, handle) = run_box(stop.clone());
    let o = SriOptions {
        port: address.port(),
        ..Default::default()
    };
    let mut link = SriSensor::open(&o, &link_context(2.0)).unwrap();
    assert_eq!(link.sample_rate(), 1000);
    link.start_streaming();
    let w = poll_until(&mut link, 200).expect("frames");
    assert_eq!(w.force.y, -2.0);
    assert_eq!(w.moment, Vector3::new(0.25, -0.5, 0.125));
    let s = *link.stats();
    assert_eq!(
        (s.malformed, s.invalid, s.lost, s.io_errors),
        (0, 0, 0, 0),
        "{s:?}"
    );
    link.stop_streaming();
    let report = link.report();
    assert_eq!(report["sensor_rate_command"], "SMPR");
    stop.store(true, Ordering::Relaxed);
    let e = handle.join().unwrap();
    assert!(e.stats().sent >= 200);
}

#[test]
fn sri_is_a_sensor_kind_in_toml() {
    let o: RuntimeOptions = toml::from_str(
        r#"
        [sensor]
        kind = "sri"
        host = "192.168.0.108"
        sample_rate = 500.0
        rate_command = "SMPF"
        "#,
    )
    .unwrap();
    let SensorOptions::Sri(s) = &o.sensor else {
        panic!("{:?}", o.sensor)
    };
    assert_eq!(
        (s.host.as_str(), s.port, s.sample_rate),
        ("192.168.0.108", 4008, Some(500.0))
    );
    let e: EmulatorOptions = toml::from_str("[sensor]\nkind = \"sri\"\nport = 4010\n").unwrap();
    let EmulatedSensorOptions::Sri(s) = &e.sensor else {
        panic!("{:?}", e.sensor)
    };
    assert_eq!(s.port, 4010);
    assert!(
        toml::from_str::<RuntimeOptions>("[sensor]\nkind = \"sri\"\nhttp_port = 80\n").is_err()
    );
}
