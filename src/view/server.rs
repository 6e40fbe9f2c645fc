//! The page's HTTP server: every asset from the binary, the questions answered by
//! [`Viewer`].
//!
//! The page holds a patient's scans and camera pictures, so the server answers only the page
//! itself: a request must name this server by an IP address or localhost in `Host`, so that
//! a site whose name was rebound to this machine reads nothing; a cross-origin
//! request (`Origin` of another site) is refused; and questions must be JSON, which a page of
//! another site cannot send without the browser asking first. Each connection has its own
//! thread, up to [`Limits::connections`], with a deadline for its head and its body and
//! bounded sizes, so one slow or hostile client cannot hold the others up or take the memory.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use super::page;
use super::scene::{Refused, Viewer};

/// What one client may take of the server.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// The request line and headers together (bytes).
    pub head_bytes: usize,
    /// A request's body (bytes; the largest the page sends is a list of keys).
    pub body_bytes: usize,
    /// From the connection's start to its head's end, and again for its body: a client
    /// that trickles a byte at a time is cut off here.
    pub deadline: Duration,
    /// The longest one read may wait for the client's next bytes.
    pub idle: Duration,
    /// Connections answered at once; more are told to come back (503).
    pub connections: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            head_bytes: 16 << 10,
            body_bytes: 4 << 20,
            deadline: Duration::from_secs(10),
            idle: Duration::from_secs(2),
            connections: 16,
        }
    }
}

/// Bind `addr` (port 0: any free one), call `ready` with the address bound, then answer
/// requests until the process ends.
pub fn serve(
    viewer: &Viewer,
    addr: SocketAddr,
    ready: impl FnOnce(SocketAddr),
) -> std::io::Result<()> {
    serve_with(viewer, addr, Limits::default(), ready)
}

/// [`serve`] with other limits.
pub fn serve_with(
    viewer: &Viewer,
    addr: SocketAddr,
    limits: Limits,
    ready: impl FnOnce(SocketAddr),
) -> std::io::Result<()> {
    let listener = TcpListener::bind(addr)?;
    let bound = listener.local_addr()?;
    let port = bound.port();
    ready(bound);
    let active = AtomicUsize::new(0);
    std::thread::scope(|scope| {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { continue };
            if active.fetch_add(1, Ordering::SeqCst) >= limits.connections {
                active.fetch_sub(1, Ordering::SeqCst);
                let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
                let _ = write_reply(&mut stream, &refused(503, "the server is busy: try again"));
                continue;
            }
            let active = &active;
            scope.spawn(move || {
                if let Err(e) = connection(viewer, stream, port, &limits) {
                    eprintln!("view: {e}");
                }
                active.fetch_sub(1, Ordering::SeqCst);
            });
        }
    });
    Ok(())
}

/// Whether `host` (a `Host` header) names this server on `port`: an IP address or
/// `localhost`. A DNS name is refused: a site that rebinds its name to this machine sends
/// its own name here.
fn names_this_server(host: &str, port: u16) -> bool {
    let Some((name, p)) = host.rsplit_once(':') else {
        return false;
    };
    if p.parse::<u16>() != Ok(port) {
        return false;
    }
    let name = name.trim_start_matches('[').trim_end_matches(']');
    name.eq_ignore_ascii_case("localhost") || name.parse::<std::net::IpAddr>().is_ok()
}

/// One reply: status, content type, body.
struct Reply {
    status: u16,
    content_type: &'static str,
    body: Vec<u8>,
}

fn bytes(status: u16, content_type: &'static str, body: Vec<u8>) -> Reply {
    Reply {
        status,
        content_type,
        body,
    }
}

fn json<T: serde::Serialize>(value: &T) -> Reply {
    match serde_json::to_vec(value) {
        Ok(body) => bytes(200, "application/json", body),
        Err(e) => refused(500, &format!("the reply: {e}")),
    }
}

fn refused(status: u16, message: &str) -> Reply {
    let body = serde_json::json!({ "error": message })
        .to_string()
        .into_bytes();
    bytes(status, "application/json", body)
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        408 => "Request Timeout",
        411 => "Length Required",
        413 => "Content Too Large",
        415 => "Unsupported Media Type",
        421 => "Misdirected Request",
        431 => "Request Header Fields Too Large",
        501 => "Not Implemented",
        503 => "Service Unavailable",
        _ => "Error",
    }
}

fn write_reply(stream: &mut TcpStream, reply: &Reply) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        reply.status,
        reason(reply.status),
        reply.content_type,
        reply.body.len()
    );
    stream.write_all(head.as_bytes())?;
    stream.write_all(&reply.body)?;
    stream.flush()
}

/// A request as the server reads it.
struct Request {
    method: String,
    path: String,
    host: Option<String>,
    origin: Option<String>,
    content_type: Option<String>,
    content_length: Option<usize>,
    chunked: bool,
    /// What came after the head in the last read: the body's first bytes.
    rest: Vec<u8>,
}

/// Read until `buf` holds a whole head, within the limits; `Err` is the reply to send.
fn read_head(
    stream: &mut TcpStream,
    limits: &Limits,
    started: Instant,
) -> Result<Option<Request>, Reply> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 4096];
    loop {
        let mut headers = [httparse::EMPTY_HEADER; 64];
        let mut parsed = httparse::Request::new(&mut headers);
        match parsed.parse(&buf) {
            Ok(httparse::Status::Complete(end)) => {
                let find = |name: &str| {
                    parsed
                        .headers
                        .iter()
                        .find(|h| h.name.eq_ignore_ascii_case(name))
                        .map(|h| String::from_utf8_lossy(h.value).trim().to_owned())
                };
                let content_length = match find("content-length") {
                    Some(v) => Some(
                        v.parse::<usize>()
                            .map_err(|_| refused(400, "Content-Length: not a number"))?,
                    ),
                    None => None,
                };
                return Ok(Some(Request {
                    method: parsed.method.unwrap_or("").to_owned(),
                    path: parsed.path.unwrap_or("").to_owned(),
                    host: find("host"),
                    origin: find("origin"),
                    content_type: find("content-type"),
                    content_length,
                    chunked: find("transfer-encoding").is_some(),
                    rest: buf[end..].to_vec(),
                }));
            }
            Ok(httparse::Status::Partial) => {}
            Err(httparse::Error::TooManyHeaders) => {
                return Err(refused(431, "over 64 headers"));
            }
            Err(e) => return Err(refused(400, &format!("the request's head: {e}"))),
        }
        if buf.len() >= limits.head_bytes {
            return Err(refused(
                431,
                &format!("the request's head is over {} bytes", limits.head_bytes),
            ));
        }
        if started.elapsed() > limits.deadline {
            return Err(refused(408, "the request's head came too slowly"));
        }
        let want = chunk.len().min(limits.head_bytes - buf.len());
        match stream.read(&mut chunk[..want]) {
            Ok(0) if buf.is_empty() => return Ok(None),
            Ok(0) => return Err(refused(400, "the connection closed inside the head")),
            Ok(n) => buf.extend_from_slice(&chunk[..n]),
            Err(e) if timed_out(&e) => {
                return Err(refused(408, "the request's head came too slowly"));
            }
            Err(e) => return Err(refused(400, &format!("reading the request: {e}"))),
        }
    }
}

fn timed_out(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
    )
}

/// The body announced by `Content-Length`, read within the deadline.
fn read_body(stream: &mut TcpStream, r: &Request, limits: &Limits) -> Result<Vec<u8>, Reply> {
    if r.chunked {
        return Err(refused(411, "a chunked body: send Content-Length"));
    }
    let Some(length) = r.content_length else {
        return Err(refused(411, "a POST needs Content-Length"));
    };
    if length > limits.body_bytes {
        return Err(refused(
            413,
            &format!("the request is over {} bytes", limits.body_bytes),
        ));
    }
    let started = Instant::now();
    let mut body = r.rest.clone();
    body.truncate(length);
    let mut chunk = [0u8; 16 << 10];
    while body.len() < length {
        if started.elapsed() > limits.deadline {
            return Err(refused(408, "the request's body came too slowly"));
        }
        let want = chunk.len().min(length - body.len());
        match stream.read(&mut chunk[..want]) {
            Ok(0) => return Err(refused(400, "the connection closed inside the body")),
            Ok(n) => body.extend_from_slice(&chunk[..n]),
            Err(e) if timed_out(&e) => {
                return Err(refused(408, "the request's body came too slowly"));
            }
            Err(e) => return Err(refused(400, &format!("reading the request: {e}"))),
        }
    }
    Ok(body)
}

/// Whether the request may be answered: `Err` is the refusal.
fn admitted(r: &Request, port: u16) -> Result<(), Reply> {
    let Some(host) = &r.host else {
        return Err(refused(400, "the request names no Host"));
    };
    if !names_this_server(host, port) {
        return Err(refused(
            421,
            &format!("Host {host:?}: this server answers to its address or localhost, port {port}"),
        ));
    }
    // Same origin: the page of this very host (a browser names the page's origin here).
    if let Some(origin) = &r.origin
        && !origin.eq_ignore_ascii_case(&format!("http://{host}"))
    {
        return Err(refused(
            403,
            &format!("Origin {origin:?}: only the page itself may ask"),
        ));
    }
    if r.method == "POST" {
        let json = r.content_type.as_deref().is_some_and(|c| {
            c.split(';')
                .next()
                .is_some_and(|t| t.trim().eq_ignore_ascii_case("application/json"))
        });
        if !json {
            return Err(refused(
                415,
                "questions are JSON: Content-Type: application/json",
            ));
        }
    }
    Ok(())
}

fn connection(
    viewer: &Viewer,
    mut stream: TcpStream,
    port: u16,
    limits: &Limits,
) -> std::io::Result<()> {
    let started = Instant::now();
    // Each read waits at most `idle`; the deadlines bound the sum.
    stream.set_read_timeout(Some(limits.idle.min(limits.deadline)))?;
    stream.set_write_timeout(Some(limits.deadline))?;
    let reply = match read_head(&mut stream, limits, started) {
        Ok(None) => return Ok(()),
        Ok(Some(request)) => match admitted(&request, port) {
            Err(r) => r,
            Ok(()) if request.method == "POST" => match read_body(&mut stream, &request, limits) {
                Ok(body) => answer(viewer, &request, &body),
                Err(r) => r,
            },
            Ok(()) => answer(viewer, &request, &[]),
        },
        Err(r) => r,
    };
    write_reply(&mut stream, &reply)?;
    if reply.status >= 400 {
        linger(&mut stream);
    }
    Ok(())
}

/// After refusing a request whose rest may still be coming, read and drop it for a moment
/// before closing: closing with unread input resets the connection, and the client would
/// lose the reply that says why.
fn linger(stream: &mut TcpStream) {
    let _ = stream.shutdown(std::net::Shutdown::Write);
    let _ = stream.set_read_timeout(Some(Duration::from_millis(500)));
    let started = Instant::now();
    let mut sink = [0u8; 16 << 10];
    let mut drained = 0usize;
    while started.elapsed() < Duration::from_secs(1) && drained < 16 << 20 {
        match stream.read(&mut sink) {
            Ok(0) | Err(_) => break,
            Ok(n) => drained += n,
        }
    }
}

/// `<camera>/<frame>.png`.
fn camera_frame(rest: &str) -> Option<(&str, u32)> {
    let (cam, f) = rest.rsplit_once('/')?;
    Some((cam, f.strip_suffix(".png")?.parse().ok()?))
}

fn question<T: serde::de::DeserializeOwned>(body: &[u8]) -> Result<T, Refused> {
    serde_json::from_slice(body).map_err(|e| Refused(format!("the request's JSON: {e}")))
}

fn answer(viewer: &Viewer, request: &Request, body: &[u8]) -> Reply {
    let url = request.path.split('?').next().unwrap_or("");
    match (request.method.as_str(), url) {
        ("GET", "/") | ("GET", "/index.html") => {
            bytes(200, "text/html; charset=utf-8", page::INDEX.into())
        }
        ("GET", "/view.js") => bytes(200, "text/javascript", page::SCRIPT.into()),
        ("GET", "/api/scene") => json(&viewer.scene()),
        ("POST", "/api/pose") => match question(body).and_then(|q| viewer.pose(&q)) {
            Ok(r) => json(&r),
            Err(e) => refused(400, &e.0),
        },
        ("POST", "/api/ik") => match question(body).and_then(|q| viewer.ik(&q)) {
            Ok(r) => json(&r),
            Err(e) => refused(400, &e.0),
        },
        ("POST", "/api/animation") => match question(body).and_then(|q| viewer.animation(&q)) {
            Ok(gltf) => bytes(200, "model/gltf+json", gltf),
            Err(e) => refused(400, &e.0),
        },
        ("GET", "/api/timeline") => match viewer.timeline() {
            Some(t) => json(&t),
            None => refused(404, "no capture was given"),
        },
        ("POST", "/api/edit") => match question(body).and_then(|q| viewer.edit(&q)) {
            Ok(r) => json(&r),
            Err(e) => refused(400, &e.0),
        },
        ("POST", "/api/correct") => match question(body).and_then(|q| viewer.correct(&q)) {
            Ok(r) => json(&r),
            Err(e) => refused(400, &e.0),
        },
        ("POST", "/api/retrack") => match question(body).and_then(|q| viewer.retrack(&q)) {
            Ok(r) => json(&r),
            Err(e) => refused(400, &e.0),
        },
        ("GET", "/api/retrack") => match viewer.job() {
            Ok(r) => json(&r),
            Err(e) => refused(404, &e.0),
        },
        ("POST", "/api/retrack/stop") => match viewer.stop() {
            Ok(r) => json(&r),
            Err(e) => refused(404, &e.0),
        },
        ("POST", "/api/first-pose") => match question(body).and_then(|q| viewer.first_pose(&q)) {
            Ok(r) => json(&r),
            Err(e) => refused(400, &e.0),
        },
        ("GET", path) if path.starts_with("/picture/") => {
            // /picture/<camera>/<frame>.png
            match camera_frame(&path["/picture/".len()..]) {
                Some((cam, frame)) => match viewer.picture(cam, frame) {
                    Ok(png) => bytes(200, "image/png", png),
                    Err(e) => refused(404, &e.0),
                },
                None => refused(404, "expected /picture/<camera>/<frame>.png"),
            }
        }
        ("GET", path) if path.starts_with("/mesh/") => {
            let name = path["/mesh/".len()..].trim_end_matches(".bin");
            match viewer.mesh_bytes(name) {
                Some(b) => bytes(200, "application/octet-stream", b),
                None => refused(404, &format!("no mesh {name:?}")),
            }
        }
        ("GET", path) if path.starts_with("/overlay/") => {
            // /overlay/<camera>/<frame>.png
            match camera_frame(&path["/overlay/".len()..]) {
                Some((cam, frame)) => match viewer.overlay(cam, frame) {
                    Ok(png) => bytes(200, "image/png", png),
                    Err(e) => refused(404, &e.0),
                },
                None => refused(404, "expected /overlay/<camera>/<frame>.png"),
            }
        }
        ("GET" | "POST", _) => refused(404, &format!("no such page: {} {url}", request.method)),
        (method, _) => refused(501, &format!("{method}: only GET and POST")),
    }
}

#[cfg(test)]
mod tests {
    use super::names_this_server;

    #[test]
    fn a_host_names_the_server_by_address_or_localhost_and_its_port() {
        for ok in [
            "127.0.0.1:8080",
            "localhost:8080",
            "LocalHost:8080",
            "[::1]:8080",
            "192.168.1.5:8080",
        ] {
            assert!(names_this_server(ok, 8080), "{ok}");
        }
        for bad in [
            "evil.example:8080",
            "127.0.0.1:8081",
            "127.0.0.1",
            "localhost",
            "a.localhost.example:8080",
            "",
        ] {
            assert!(!names_this_server(bad, 8080), "{bad}");
        }
    }
}
