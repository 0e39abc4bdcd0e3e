//! The Net F/T's configuration page `/netftapi2.xml` over HTTP: the emulator serves it, the
//! runtime reads the counts per force and torque (`cfgcpf`, `cfgcpt`) and the units they are
//! per (`scfgfu`/`cfgfu`, `scfgtu`/`cfgtu`) from it, as clients of a real sensor do, and
//! converts them to counts per N and per N·m.
//!
//! The page is a flat `<netft>` element with one child per setting. The emulator writes the
//! settings that clients read: `cfgcpf`, `cfgcpt` (counts per configured force and torque
//! unit), `scfgfu`/`scfgtu` (unit names, e.g. `N`, `N-m`), `cfgfu`/`cfgtu` (ATI unit codes,
//! [`ForceUnit::code`], [`TorqueUnit::code`]), `comrdte` (`Enabled`),
//! `comrdtrate` (RDT output rate, Hz), `comrdtbsiz` (records per buffered packet), `runstat`
//! (status word, hex) and `setserial`.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use super::codec::CountsPerUnit;
use crate::error::{Result, RtError};

/// Path of the configuration page.
pub const NETFTAPI_PATH: &str = "/netftapi2.xml";

/// The page's XML for a sensor configured in these units, with `counts` per configured unit
/// (`counts.force` per `force_unit`, `counts.torque` per `torque_unit`, rounded as a real
/// sensor's integers) and this RDT rate (Hz).
pub fn netftapi_xml(
    counts: &CountsPerUnit,
    force_unit: ForceUnit,
    torque_unit: TorqueUnit,
    rdt_rate_hz: f64,
) -> String {
    format!(
        "<?xml version=\"1.0\" encoding=\"ISO-8859-1\"?>\n<netft>\n\
         <setserial>HILC-EMU-0001</setserial>\n\
         <runstat>0x00000000</runstat>\n\
         <cfgcpf>{}</cfgcpf>\n<cfgcpt>{}</cfgcpt>\n\
         <cfgfu>{}</cfgfu>\n<cfgtu>{}</cfgtu>\n\
         <scfgfu>{}</scfgfu>\n<scfgtu>{}</scfgtu>\n\
         <comrdte>Enabled</comrdte>\n<comrdtrate>{}</comrdtrate>\n<comrdtbsiz>1</comrdtbsiz>\n\
         </netft>\n",
        counts.force.round() as i64,
        counts.torque.round() as i64,
        force_unit.code(),
        torque_unit.code(),
        force_unit.name(),
        torque_unit.name(),
        rdt_rate_hz.round() as i64
    )
}

/// N per lbf (exact, from 1 lb = 0.45359237 kg and g = 9.80665 m/s²).
const NEWTONS_PER_LBF: f64 = 4.448_221_615_260_5;
/// N per kgf.
const NEWTONS_PER_KGF: f64 = 9.806_65;
/// N·m per lbf·in.
const NEWTON_METRES_PER_LBF_IN: f64 = 0.112_984_829_027_617;
/// N·m per lbf·ft.
const NEWTON_METRES_PER_LBF_FT: f64 = 1.355_817_948_331_4;
/// N·m per kgf·cm.
const NEWTON_METRES_PER_KGF_CM: f64 = 0.098_066_5;

/// A force unit a Net F/T can be configured in (`cfgfu` code, `scfgfu` name).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForceUnit {
    /// Pound-force (code 1).
    Lbf,
    /// Newton (code 2).
    N,
    /// Kilopound-force (code 3).
    Klbf,
    /// Kilonewton (code 4).
    KN,
    /// Kilogram-force (code 5).
    Kgf,
    /// Gram-force (code 6).
    Gf,
}

impl ForceUnit {
    /// Every force unit, in code order.
    pub const ALL: [ForceUnit; 6] = [
        ForceUnit::Lbf,
        ForceUnit::N,
        ForceUnit::Klbf,
        ForceUnit::KN,
        ForceUnit::Kgf,
        ForceUnit::Gf,
    ];

    /// ATI's code of the unit (`cfgfu`): 1 = lbf, 2 = N, 3 = klbf, 4 = kN, 5 = kgf, 6 = gf.
    pub fn code(self) -> u8 {
        match self {
            ForceUnit::Lbf => 1,
            ForceUnit::N => 2,
            ForceUnit::Klbf => 3,
            ForceUnit::KN => 4,
            ForceUnit::Kgf => 5,
            ForceUnit::Gf => 6,
        }
    }

    /// The unit of an ATI code (`cfgfu`), None if the code is unknown.
    pub fn from_code(code: i64) -> Option<Self> {
        ForceUnit::ALL
            .into_iter()
            .find(|u| i64::from(u.code()) == code)
    }

    /// The unit's name as the page writes it (`scfgfu`), e.g. `"lbf"`, `"N"`.
    pub fn name(self) -> &'static str {
        match self {
            ForceUnit::Lbf => "lbf",
            ForceUnit::N => "N",
            ForceUnit::Klbf => "klbf",
            ForceUnit::KN => "kN",
            ForceUnit::Kgf => "kgf",
            ForceUnit::Gf => "gf",
        }
    }

    /// The unit of a name (`scfgfu`, an option): case and separators are ignored, and the
    /// usual variants are accepted (`"lb"`, `"kg"`, `"g"`); None if unknown.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match compact(name).as_str() {
            "lbf" | "lb" | "lbs" => ForceUnit::Lbf,
            "n" => ForceUnit::N,
            "klbf" | "klb" => ForceUnit::Klbf,
            "kn" => ForceUnit::KN,
            "kgf" | "kg" => ForceUnit::Kgf,
            "gf" | "g" => ForceUnit::Gf,
            _ => return None,
        })
    }

    /// N per unit.
    pub fn newtons(self) -> f64 {
        match self {
            ForceUnit::Lbf => NEWTONS_PER_LBF,
            ForceUnit::N => 1.0,
            ForceUnit::Klbf => 1000.0 * NEWTONS_PER_LBF,
            ForceUnit::KN => 1000.0,
            ForceUnit::Kgf => NEWTONS_PER_KGF,
            ForceUnit::Gf => NEWTONS_PER_KGF / 1000.0,
        }
    }
}

/// A torque unit a Net F/T can be configured in (`cfgtu` code, `scfgtu` name).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TorqueUnit {
    /// Pound-force inch (code 1).
    LbfIn,
    /// Pound-force foot (code 2).
    LbfFt,
    /// Newton metre (code 3).
    Nm,
    /// Newton millimetre (code 4).
    Nmm,
    /// Kilogram-force centimetre (code 5).
    KgfCm,
    /// Kilonewton metre (code 6).
    KNm,
}

impl TorqueUnit {
    /// Every torque unit, in code order.
    pub const ALL: [TorqueUnit; 6] = [
        TorqueUnit::LbfIn,
        TorqueUnit::LbfFt,
        TorqueUnit::Nm,
        TorqueUnit::Nmm,
        TorqueUnit::KgfCm,
        TorqueUnit::KNm,
    ];

    /// ATI's code of the unit (`cfgtu`): 1 = lbf·in, 2 = lbf·ft, 3 = N·m, 4 = N·mm,
    /// 5 = kgf·cm, 6 = kN·m.
    pub fn code(self) -> u8 {
        match self {
            TorqueUnit::LbfIn => 1,
            TorqueUnit::LbfFt => 2,
            TorqueUnit::Nm => 3,
            TorqueUnit::Nmm => 4,
            TorqueUnit::KgfCm => 5,
            TorqueUnit::KNm => 6,
        }
    }

    /// The unit of an ATI code (`cfgtu`), None if the code is unknown.
    pub fn from_code(code: i64) -> Option<Self> {
        TorqueUnit::ALL
            .into_iter()
            .find(|u| i64::from(u.code()) == code)
    }

    /// The unit's name as the page writes it (`scfgtu`), e.g. `"lbf-in"`, `"N-m"`.
    pub fn name(self) -> &'static str {
        match self {
            TorqueUnit::LbfIn => "lbf-in",
            TorqueUnit::LbfFt => "lbf-ft",
            TorqueUnit::Nm => "N-m",
            TorqueUnit::Nmm => "N-mm",
            TorqueUnit::KgfCm => "kgf-cm",
            TorqueUnit::KNm => "kN-m",
        }
    }

    /// The unit of a name (`scfgtu`, an option): case and separators are ignored (`"N-m"`,
    /// `"Nm"`, `"N·m"`), either order of pound and length is accepted (`"in-lb"`) and `"lb"`
    /// or `"kg"` stand for lbf or kgf; None if unknown.
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match compact(name).as_str() {
            "lbfin" | "lbin" | "inlbf" | "inlb" => TorqueUnit::LbfIn,
            "lbfft" | "lbft" | "ftlbf" | "ftlb" => TorqueUnit::LbfFt,
            "nm" => TorqueUnit::Nm,
            "nmm" => TorqueUnit::Nmm,
            "kgfcm" | "kgcm" | "cmkgf" | "cmkg" => TorqueUnit::KgfCm,
            "knm" => TorqueUnit::KNm,
            _ => return None,
        })
    }

    /// N·m per unit.
    pub fn newton_metres(self) -> f64 {
        match self {
            TorqueUnit::LbfIn => NEWTON_METRES_PER_LBF_IN,
            TorqueUnit::LbfFt => NEWTON_METRES_PER_LBF_FT,
            TorqueUnit::Nm => 1.0,
            TorqueUnit::Nmm => 0.001,
            TorqueUnit::KgfCm => NEWTON_METRES_PER_KGF_CM,
            TorqueUnit::KNm => 1000.0,
        }
    }
}

/// A unit name reduced to lowercase ASCII letters and digits (separators such as `-`, `·`,
/// `.`, spaces, and characters lost to the page's ISO-8859-1 encoding, dropped).
fn compact(name: &str) -> String {
    name.chars()
        .filter(char::is_ascii_alphanumeric)
        .map(|c| c.to_ascii_lowercase())
        .collect()
}

/// What a `netftapi2.xml` page says about the sensor's scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorCalibration {
    /// Counts per N and per N·m (converted from the page's counts per configured unit).
    pub counts: CountsPerUnit,
    /// The configured force unit (`cfgcpf` counts per this unit).
    pub force_unit: ForceUnit,
    /// The configured torque unit (`cfgcpt` counts per this unit).
    pub torque_unit: TorqueUnit,
    /// True when the page gives no force or no torque unit (none of `scfgfu`/`cfgfu`, or of
    /// `scfgtu`/`cfgtu`) and N or N·m was assumed: worth a note to the user.
    pub units_assumed: bool,
}

/// The unit of one quantity from its name element (`scfgfu`) and code element (`cfgfu`): the
/// name if present, else the code; both present must agree; a present but unknown value is
/// an error (never a guess). None if neither element is present (or both are empty).
fn page_unit<U: Copy + PartialEq>(
    xml: &str,
    name_tag: &str,
    code_tag: &str,
    from_name: fn(&str) -> Option<U>,
    from_code: fn(i64) -> Option<U>,
    describe: fn(U) -> &'static str,
) -> Result<Option<U>> {
    let name_text = element(xml, name_tag).filter(|text| !text.is_empty());
    let code_text = element(xml, code_tag).filter(|text| !text.is_empty());
    let by_name = match name_text {
        None => None,
        Some(text) => Some(from_name(text).ok_or_else(|| {
            RtError::Protocol(format!(
                "netftapi2.xml: <{name_tag}> is an unknown unit: {text:?}"
            ))
        })?),
    };
    let by_code = match code_text {
        None => None,
        Some(text) => Some(
            text.parse::<i64>()
                .ok()
                .and_then(from_code)
                .ok_or_else(|| {
                    RtError::Protocol(format!(
                        "netftapi2.xml: <{code_tag}> is an unknown unit code: {text:?}"
                    ))
                })?,
        ),
    };
    match (by_name, by_code) {
        (Some(a), Some(b)) if a != b => Err(RtError::Protocol(format!(
            "netftapi2.xml: <{name_tag}> {:?} ({}) and <{code_tag}> {} ({}) disagree",
            name_text.unwrap_or(""),
            describe(a),
            code_text.unwrap_or(""),
            describe(b)
        ))),
        (name, code) => Ok(name.or(code)),
    }
}

/// The text of the first `<tag>...</tag>` element, trimmed.
fn element<'a>(xml: &'a str, tag: &str) -> Option<&'a str> {
    let open = format!("<{tag}>");
    let close = format!("</{tag}>");
    let start = xml.find(&open)? + open.len();
    let end = start + xml[start..].find(&close)?;
    Some(xml[start..end].trim())
}

/// The calibration of a `netftapi2.xml` page: its counts per configured force and torque unit
/// (`cfgcpf`, `cfgcpt`, falling back to `calcpf`, `calcpt`) converted to counts per N and per
/// N·m, with the units (see [`SensorCalibration::units_assumed`] when the page gives none).
pub fn parse_counts(xml: &str) -> Result<SensorCalibration> {
    let read = |primary: &str, fallback: &str| -> Result<f64> {
        let text = element(xml, primary)
            .or_else(|| element(xml, fallback))
            .ok_or_else(|| {
                RtError::Protocol(format!(
                    "netftapi2.xml has no <{primary}> (nor <{fallback}>)"
                ))
            })?;
        let value: f64 = text.parse().map_err(|_| {
            RtError::Protocol(format!(
                "netftapi2.xml: <{primary}> is not a number: {text:?}"
            ))
        })?;
        if value.is_finite() && value > 0.0 {
            Ok(value)
        } else {
            Err(RtError::Protocol(format!(
                "netftapi2.xml: <{primary}> must be > 0, got {value}"
            )))
        }
    };
    let per_force_unit = read("cfgcpf", "calcpf")?;
    let per_torque_unit = read("cfgcpt", "calcpt")?;
    let force_unit = page_unit(
        xml,
        "scfgfu",
        "cfgfu",
        ForceUnit::from_name,
        ForceUnit::from_code,
        ForceUnit::name,
    )?;
    let torque_unit = page_unit(
        xml,
        "scfgtu",
        "cfgtu",
        TorqueUnit::from_name,
        TorqueUnit::from_code,
        TorqueUnit::name,
    )?;
    let units_assumed = force_unit.is_none() || torque_unit.is_none();
    let force_unit = force_unit.unwrap_or(ForceUnit::N);
    let torque_unit = torque_unit.unwrap_or(TorqueUnit::Nm);
    Ok(SensorCalibration {
        counts: CountsPerUnit {
            force: per_force_unit / force_unit.newtons(),
            torque: per_torque_unit / torque_unit.newton_metres(),
        },
        force_unit,
        torque_unit,
        units_assumed,
    })
}

/// Reads `http://host:port/netftapi2.xml` (plain HTTP/1.0 GET) and returns its calibration
/// ([`parse_counts`]: counts per N and per N·m, and the configured units).
pub fn fetch_counts(host: &str, port: u16, timeout: Duration) -> Result<SensorCalibration> {
    let what = format!("http://{host}:{port}{NETFTAPI_PATH}");
    let fail = |e: std::io::Error| RtError::io(what.as_str(), &e);
    let addr: SocketAddr = (host, port)
        .to_socket_addrs()
        .map_err(fail)?
        .next()
        .ok_or_else(|| RtError::io_other(what.as_str(), "no address"))?;
    let mut stream = TcpStream::connect_timeout(&addr, timeout).map_err(fail)?;
    stream.set_read_timeout(Some(timeout)).map_err(fail)?;
    stream.set_write_timeout(Some(timeout)).map_err(fail)?;
    write!(
        stream,
        "GET {NETFTAPI_PATH} HTTP/1.0\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .map_err(fail)?;
    let mut response = Vec::new();
    stream
        .take(1 << 20)
        .read_to_end(&mut response)
        .map_err(fail)?;
    let text = String::from_utf8_lossy(&response);
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head.lines().next().unwrap_or("");
    if status
        .split_whitespace()
        .nth(1)
        .is_none_or(|code| code != "200")
    {
        return Err(RtError::Protocol(format!("{what}: HTTP status {status:?}")));
    }
    parse_counts(body)
}

/// An HTTP server answering `GET /netftapi2.xml` on its own thread. Its socket errors are
/// counted, not dropped ([`NetFtApiServer::take_errors`]).
pub struct NetFtApiServer {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    address: SocketAddr,
    errors: Arc<HttpErrors>,
}

/// Socket errors of the HTTP server since they were last taken.
#[derive(Debug, Default)]
struct HttpErrors {
    /// Accepting or reading a request failed.
    receive: AtomicU64,
    /// Writing a response failed (e.g. the client went away).
    send: AtomicU64,
}

impl NetFtApiServer {
    /// Serves `xml` on `bind` (e.g. `127.0.0.1:80`); other paths get 404.
    pub fn start(bind: SocketAddr, xml: String) -> Result<Self> {
        let server = tiny_http::Server::http(bind)
            .map_err(|e| RtError::io_dyn(format!("HTTP server on {bind}"), e.as_ref()))?;
        let address = server.server_addr().to_ip().unwrap_or(bind);
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let errors = Arc::new(HttpErrors::default());
        let counted = errors.clone();
        let thread = std::thread::Builder::new()
            .name("hil-netftapi".into())
            .spawn(move || {
                let header =
                    tiny_http::Header::from_bytes(&b"Content-Type"[..], &b"text/xml"[..]).ok();
                while !flag.load(Ordering::Relaxed) {
                    let request = match server.recv_timeout(Duration::from_millis(100)) {
                        Ok(Some(request)) => request,
                        Ok(None) => continue,
                        Err(_) => {
                            counted.receive.fetch_add(1, Ordering::Relaxed);
                            continue;
                        }
                    };
                    let path = request.url().split('?').next().unwrap_or("");
                    let response = if path == NETFTAPI_PATH {
                        let mut r = tiny_http::Response::from_string(xml.clone());
                        if let Some(h) = header.clone() {
                            r = r.with_header(h);
                        }
                        r
                    } else {
                        tiny_http::Response::from_string("not found").with_status_code(404)
                    };
                    if request.respond(response).is_err() {
                        counted.send.fetch_add(1, Ordering::Relaxed);
                    }
                }
            })
            .map_err(|e| RtError::io("HTTP server thread", &e))?;
        Ok(NetFtApiServer {
            stop,
            thread: Some(thread),
            address,
            errors,
        })
    }

    /// The address the server listens on.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// The socket errors since the last call: `(receive, send)` (accepting or reading a
    /// request; writing a response). Never allocates.
    pub fn take_errors(&self) -> (u64, u64) {
        (
            self.errors.receive.swap(0, Ordering::Relaxed),
            self.errors.send.swap(0, Ordering::Relaxed),
        )
    }
}

impl Drop for NetFtApiServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A page with these counts and unit elements (None: the element is left out).
    fn page(
        scfgfu: Option<&str>,
        cfgfu: Option<&str>,
        scfgtu: Option<&str>,
        cfgtu: Option<&str>,
    ) -> String {
        let mut xml = String::from("<netft><cfgcpf>1000000</cfgcpf><cfgcpt>1000000</cfgcpt>");
        for (tag, value) in [
            ("scfgfu", scfgfu),
            ("cfgfu", cfgfu),
            ("scfgtu", scfgtu),
            ("cfgtu", cfgtu),
        ] {
            if let Some(v) = value {
                xml.push_str(&format!("<{tag}>{v}</{tag}>"));
            }
        }
        xml + "</netft>"
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12 * b.abs()
    }

    #[test]
    fn page_round_trips_the_counts() {
        let xml = netftapi_xml(
            &CountsPerUnit {
                force: 1_000_000.0,
                torque: 250_000.0,
            },
            ForceUnit::N,
            TorqueUnit::Nm,
            1000.0,
        );
        assert!(
            xml.contains("<cfgcpf>1000000</cfgcpf>")
                && xml.contains("<comrdtrate>1000</comrdtrate>")
                && xml.contains("<scfgfu>N</scfgfu>")
                && xml.contains("<cfgtu>3</cfgtu>")
        );
        assert_eq!(
            parse_counts(&xml).unwrap(),
            SensorCalibration {
                counts: CountsPerUnit {
                    force: 1.0e6,
                    torque: 2.5e5
                },
                force_unit: ForceUnit::N,
                torque_unit: TorqueUnit::Nm,
                units_assumed: false,
            }
        );
    }

    #[test]
    fn page_round_trips_lbf_and_lbf_in() {
        let xml = netftapi_xml(
            &CountsPerUnit {
                force: 1_000_000.0,
                torque: 1_000_000.0,
            },
            ForceUnit::Lbf,
            TorqueUnit::LbfIn,
            1000.0,
        );
        assert!(
            xml.contains("<scfgfu>lbf</scfgfu>")
                && xml.contains("<cfgfu>1</cfgfu>")
                && xml.contains("<scfgtu>lbf-in</scfgtu>")
                && xml.contains("<cfgtu>1</cfgtu>"),
            "{xml}"
        );
        let c = parse_counts(&xml).unwrap();
        assert_eq!(
            (c.force_unit, c.torque_unit, c.units_assumed),
            (ForceUnit::Lbf, TorqueUnit::LbfIn, false)
        );
        // 1e6 counts per lbf = 1e6 / 4.448… counts per N; per lbf·in = 1e6 / 0.1129… per N·m
        assert!(close(c.counts.force, 1.0e6 / 4.448_221_615_260_5), "{c:?}");
        assert!(
            close(c.counts.torque, 1.0e6 / 0.112_984_829_027_617),
            "{c:?}"
        );
        // 100 N of force and 10 N·m of moment, as the sensor counts them, read back in SI
        let counts = [
            (100.0 / 4.448_221_615_260_5 * 1.0e6_f64).round() as i32,
            0,
            0,
            (10.0 / 0.112_984_829_027_617 * 1.0e6_f64).round() as i32,
            0,
            0,
        ];
        let (f, m) = c.counts.to_wrench(&counts);
        assert!(
            (f[0] - 100.0).abs() < 1e-5 && (m[0] - 10.0).abs() < 1e-5,
            "{f:?} {m:?}"
        );
    }

    #[test]
    fn every_force_unit_code_and_name_gives_its_factor() {
        let expected = [
            (1, "lbf", ForceUnit::Lbf, 4.448_221_615_260_5),
            (2, "N", ForceUnit::N, 1.0),
            (3, "klbf", ForceUnit::Klbf, 4_448.221_615_260_5),
            (4, "kN", ForceUnit::KN, 1000.0),
            (5, "kgf", ForceUnit::Kgf, 9.806_65),
            (6, "gf", ForceUnit::Gf, 0.009_806_65),
        ];
        for (code, name, unit, newtons) in expected {
            assert_eq!(ForceUnit::from_code(code), Some(unit));
            assert_eq!((unit.code() as i64, unit.name()), (code, name));
            assert!(close(unit.newtons(), newtons), "{unit:?}");
            for xml in [
                page(Some(name), None, None, None),
                page(None, Some(&code.to_string()), None, None),
                page(Some(name), Some(&code.to_string()), None, None),
            ] {
                let c = parse_counts(&xml).unwrap();
                assert_eq!(c.force_unit, unit, "{xml}");
                assert!(close(c.counts.force, 1.0e6 / newtons), "{xml}: {c:?}");
                // no torque unit on these pages: N·m assumed, and said so
                assert_eq!((c.torque_unit, c.units_assumed), (TorqueUnit::Nm, true));
                assert_eq!(c.counts.torque, 1.0e6);
            }
        }
        for (variant, unit) in [
            ("LBF", ForceUnit::Lbf),
            ("lb", ForceUnit::Lbf),
            (" n ", ForceUnit::N),
            ("KN", ForceUnit::KN),
            ("Kg", ForceUnit::Kgf),
            ("g", ForceUnit::Gf),
            ("Klbf", ForceUnit::Klbf),
        ] {
            assert_eq!(ForceUnit::from_name(variant), Some(unit), "{variant}");
        }
    }

    #[test]
    fn every_torque_unit_code_and_name_gives_its_factor() {
        let expected = [
            (1, "lbf-in", TorqueUnit::LbfIn, 0.112_984_829_027_617),
            (2, "lbf-ft", TorqueUnit::LbfFt, 1.355_817_948_331_4),
            (3, "N-m", TorqueUnit::Nm, 1.0),
            (4, "N-mm", TorqueUnit::Nmm, 0.001),
            (5, "kgf-cm", TorqueUnit::KgfCm, 0.098_066_5),
            (6, "kN-m", TorqueUnit::KNm, 1000.0),
        ];
        for (code, name, unit, newton_metres) in expected {
            assert_eq!(TorqueUnit::from_code(code), Some(unit));
            assert_eq!((unit.code() as i64, unit.name()), (code, name));
            assert!(close(unit.newton_metres(), newton_metres), "{unit:?}");
            for xml in [
                page(Some("N"), None, Some(name), None),
                page(None, Some("2"), None, Some(&code.to_string())),
                page(Some("N"), Some("2"), Some(name), Some(&code.to_string())),
            ] {
                let c = parse_counts(&xml).unwrap();
                assert_eq!((c.torque_unit, c.units_assumed), (unit, false), "{xml}");
                assert!(
                    close(c.counts.torque, 1.0e6 / newton_metres),
                    "{xml}: {c:?}"
                );
                assert_eq!((c.force_unit, c.counts.force), (ForceUnit::N, 1.0e6));
            }
        }
        for (variant, unit) in [
            ("in-lb", TorqueUnit::LbfIn),
            ("lbf·in", TorqueUnit::LbfIn),
            ("in-lbf", TorqueUnit::LbfIn),
            ("LBF-IN", TorqueUnit::LbfIn),
            ("ft-lb", TorqueUnit::LbfFt),
            ("Nm", TorqueUnit::Nm),
            ("N·m", TorqueUnit::Nm),
            ("N m", TorqueUnit::Nm),
            ("Nmm", TorqueUnit::Nmm),
            ("Kg-cm", TorqueUnit::KgfCm),
            ("kNm", TorqueUnit::KNm),
        ] {
            assert_eq!(TorqueUnit::from_name(variant), Some(unit), "{variant}");
        }
    }

    #[test]
    fn a_page_without_units_is_taken_as_n_and_n_m_and_says_so() {
        let c = parse_counts(&page(None, None, None, None)).unwrap();
        assert_eq!(
            c,
            SensorCalibration {
                counts: CountsPerUnit {
                    force: 1.0e6,
                    torque: 1.0e6
                },
                force_unit: ForceUnit::N,
                torque_unit: TorqueUnit::Nm,
                units_assumed: true,
            }
        );
        // empty elements count as absent
        let c = parse_counts(&page(Some(""), Some(" "), Some(""), None)).unwrap();
        assert!(c.units_assumed);
    }

    #[test]
    fn disagreeing_name_and_code_are_an_error() {
        for (xml, tags) in [
            (page(Some("lbf"), Some("2"), None, None), "<scfgfu>"),
            (page(Some("N"), Some("1"), None, None), "<scfgfu>"),
            (page(None, None, Some("N-m"), Some("1")), "<scfgtu>"),
            (page(None, None, Some("lbf-in"), Some("2")), "<scfgtu>"),
        ] {
            let err = parse_counts(&xml).unwrap_err().to_string();
            assert!(err.contains(tags) && err.contains("disagree"), "{err}");
        }
    }

    #[test]
    fn unknown_units_are_an_error_naming_the_tag_and_value() {
        for (xml, tag, value) in [
            (page(Some("mN"), None, None, None), "<scfgfu>", "mN"),
            (page(Some("N"), Some("7"), None, None), "<cfgfu>", "7"),
            (page(None, Some("0"), None, None), "<cfgfu>", "0"),
            (page(None, Some("two"), None, None), "<cfgfu>", "two"),
            (
                page(None, None, Some("oz-in"), Some("1")),
                "<scfgtu>",
                "oz-in",
            ),
            (page(None, None, None, Some("9")), "<cfgtu>", "9"),
        ] {
            let err = parse_counts(&xml).unwrap_err();
            assert!(matches!(err, RtError::Protocol(_)), "{err:?}");
            let text = err.to_string();
            assert!(
                text.contains(tag) && text.contains(value) && text.contains("unknown"),
                "{text}"
            );
        }
    }

    #[test]
    fn bad_pages_are_errors() {
        assert!(parse_counts("<netft></netft>").is_err());
        assert!(parse_counts("<netft><cfgcpf>x</cfgcpf><cfgcpt>1</cfgcpt></netft>").is_err());
        assert!(parse_counts("<netft><cfgcpf>0</cfgcpf><cfgcpt>1</cfgcpt></netft>").is_err());
        let fallback =
            parse_counts("<netft><calcpf>10</calcpf><calcpt>20</calcpt></netft>").unwrap();
        assert_eq!(
            fallback.counts,
            CountsPerUnit {
                force: 10.0,
                torque: 20.0
            }
        );
    }

    #[test]
    fn server_answers_and_client_reads() {
        let server = NetFtApiServer::start(
            "127.0.0.1:0".parse().unwrap(),
            netftapi_xml(
                &CountsPerUnit {
                    force: 123456.0,
                    torque: 654321.0,
                },
                ForceUnit::Kgf,
                TorqueUnit::Nmm,
                1000.0,
            ),
        )
        .unwrap();
        let port = server.address().port();
        let c = fetch_counts("127.0.0.1", port, Duration::from_secs(2)).unwrap();
        assert_eq!(
            (c.force_unit, c.torque_unit),
            (ForceUnit::Kgf, TorqueUnit::Nmm)
        );
        assert!(close(c.counts.force, 123456.0 / 9.806_65), "{c:?}");
        assert!(close(c.counts.torque, 654321.0 / 0.001), "{c:?}");
    }
}
