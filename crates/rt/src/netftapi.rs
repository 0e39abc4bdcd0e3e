//! The Net F/T's configuration page `/netftapi2.xml` over HTTP: the emulator serves it, the
//! runtime reads the counts per force and torque (`cfgcpf`, `cfgcpt`) from it, as clients of
//! a real sensor do.
//!
//! The page is a flat `<netft>` element with one child per setting. The emulator writes the
//! settings that clients read: `cfgcpf`, `cfgcpt` (counts per N and per N·m), `scfgfu`/`scfgtu`
//! (`N`, `N-m`), `cfgfu`/`cfgtu` (unit codes 2 = N, 3 = N·m), `comrdte` (`Enabled`),
//! `comrdtrate` (RDT output rate, Hz), `comrdtbsiz` (records per buffered packet), `runstat`
//! (status word, hex) and `setserial`.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use crate::error::{Result, RtError};
use crate::rdt::CountsPerUnit;

/// Path of the configuration page.
pub const NETFTAPI_PATH: &str = "/netftapi2.xml";

/// The page's XML for a sensor with these counts per unit and RDT rate (Hz).
pub fn netftapi_xml(counts: &CountsPerUnit, rdt_rate_hz: f64) -> String {
    format!(
        "<?xml version=\"1.0\" encoding=\"ISO-8859-1\"?>\n<netft>\n\
         <setserial>HILC-EMU-0001</setserial>\n\
         <runstat>0x00000000</runstat>\n\
         <cfgcpf>{}</cfgcpf>\n<cfgcpt>{}</cfgcpt>\n\
         <cfgfu>2</cfgfu>\n<cfgtu>3</cfgtu>\n\
         <scfgfu>N</scfgfu>\n<scfgtu>N-m</scfgtu>\n\
         <comrdte>Enabled</comrdte>\n<comrdtrate>{}</comrdtrate>\n<comrdtbsiz>1</comrdtbsiz>\n\
         </netft>\n",
        counts.force.round() as i64,
        counts.torque.round() as i64,
        rdt_rate_hz.round() as i64
    )
}

/// The text of the first `<tag>...</tag>` element, trimmed.
fn element<'a>(xml: &'a str, tag: &str) -> Option<&'a str> {
    let open = format!("<{tag}>");
    let close = format!("</{tag}>");
    let start = xml.find(&open)? + open.len();
    let end = start + xml[start..].find(&close)?;
    Some(xml[start..end].trim())
}

/// The counts per force and torque of a `netftapi2.xml` page (`cfgcpf`, `cfgcpt`, falling back
/// to `calcpf`, `calcpt`).
pub fn parse_counts(xml: &str) -> Result<CountsPerUnit> {
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
    Ok(CountsPerUnit {
        force: read("cfgcpf", "calcpf")?,
        torque: read("cfgcpt", "calcpt")?,
    })
}

/// Reads `http://host:port/netftapi2.xml` (plain HTTP/1.0 GET) and returns its counts.
pub fn fetch_counts(host: &str, port: u16, timeout: Duration) -> Result<CountsPerUnit> {
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

    #[test]
    fn page_round_trips_the_counts() {
        let xml = netftapi_xml(
            &CountsPerUnit {
                force: 1_000_000.0,
                torque: 250_000.0,
            },
            1000.0,
        );
        assert!(
            xml.contains("<cfgcpf>1000000</cfgcpf>")
                && xml.contains("<comrdtrate>1000</comrdtrate>")
        );
        assert_eq!(
            parse_counts(&xml).unwrap(),
            CountsPerUnit {
                force: 1.0e6,
                torque: 2.5e5
            }
        );
    }

    #[test]
    fn bad_pages_are_errors() {
        assert!(parse_counts("<netft></netft>").is_err());
        assert!(parse_counts("<netft><cfgcpf>x</cfgcpf><cfgcpt>1</cfgcpt></netft>").is_err());
        assert!(parse_counts("<netft><cfgcpf>0</cfgcpf><cfgcpt>1</cfgcpt></netft>").is_err());
        let fallback =
            parse_counts("<netft><calcpf>10</calcpf><calcpt>20</calcpt></netft>").unwrap();
        assert_eq!(
            fallback,
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
                1000.0,
            ),
        )
        .unwrap();
        let port = server.address().port();
        let counts = fetch_counts("127.0.0.1", port, Duration::from_secs(2)).unwrap();
        assert_eq!(
            counts,
            CountsPerUnit {
                force: 123456.0,
                torque: 654321.0
            }
        );
    }
}
