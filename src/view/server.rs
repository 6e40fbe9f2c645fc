//! The page's HTTP server: every asset from the binary, the questions answered by
//! [`Viewer`]. One request at a time: each answer takes milliseconds, and the page waits for
//! one before it asks the next.

use std::io::Read;
use std::net::SocketAddr;

use tiny_http::{Header, Method, Request, Response, Server};

use super::page;
use super::scene::{Refused, Viewer};

/// Request bodies above this are refused (the largest is a list of keys).
const MAX_BODY: u64 = 4 << 20;

/// Bind `addr` (port 0: any free one), call `ready` with the address bound, then answer
/// requests until the process ends.
pub fn serve(
    viewer: &Viewer,
    addr: SocketAddr,
    ready: impl FnOnce(SocketAddr),
) -> std::io::Result<()> {
    let server = Server::http(addr).map_err(std::io::Error::other)?;
    let bound = server
        .server_addr()
        .to_ip()
        .ok_or_else(|| std::io::Error::other("the server is not on an IP address"))?;
    ready(bound);
    for request in server.incoming_requests() {
        let reply = answer(viewer, request);
        if let Err(e) = reply {
            eprintln!("view: {e}");
        }
    }
    Ok(())
}

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("a valid header")
}

fn bytes(status: u16, content_type: &str, body: Vec<u8>) -> Response<std::io::Cursor<Vec<u8>>> {
    Response::from_data(body)
        .with_status_code(status)
        .with_header(header("Content-Type", content_type))
        .with_header(header("Cache-Control", "no-store"))
}

fn json<T: serde::Serialize>(value: &T) -> Response<std::io::Cursor<Vec<u8>>> {
    let body = serde_json::to_vec(value).expect("replies serialise");
    bytes(200, "application/json", body)
}

fn refused(status: u16, message: &str) -> Response<std::io::Cursor<Vec<u8>>> {
    let body = serde_json::to_vec(&serde_json::json!({ "error": message })).expect("serialises");
    bytes(status, "application/json", body)
}

fn body<T: serde::de::DeserializeOwned>(request: &mut Request) -> Result<T, Refused> {
    let mut text = Vec::new();
    request
        .as_reader()
        .take(MAX_BODY + 1)
        .read_to_end(&mut text)
        .map_err(|e| Refused(format!("reading the request: {e}")))?;
    if text.len() as u64 > MAX_BODY {
        return Err(Refused(format!("the request is over {MAX_BODY} bytes")));
    }
    serde_json::from_slice(&text).map_err(|e| Refused(format!("the request's JSON: {e}")))
}

fn answer(viewer: &Viewer, mut request: Request) -> std::io::Result<()> {
    let url = request.url().split('?').next().unwrap_or("").to_owned();
    let method = request.method().clone();
    let response = match (&method, url.as_str()) {
        (Method::Get, "/") | (Method::Get, "/index.html") => {
            bytes(200, "text/html; charset=utf-8", page::INDEX.into())
        }
        (Method::Get, "/view.js") => bytes(200, "text/javascript", page::SCRIPT.into()),
        (Method::Get, "/api/scene") => json(&viewer.scene()),
        (Method::Post, "/api/pose") => match body(&mut request).and_then(|q| viewer.pose(&q)) {
            Ok(r) => json(&r),
            Err(e) => refused(400, &e.0),
        },
        (Method::Post, "/api/ik") => match body(&mut request).and_then(|q| viewer.ik(&q)) {
            Ok(r) => json(&r),
            Err(e) => refused(400, &e.0),
        },
        (Method::Post, "/api/animation") => {
            match body(&mut request).and_then(|q| viewer.animation(&q)) {
                Ok(gltf) => bytes(200, "model/gltf+json", gltf),
                Err(e) => refused(400, &e.0),
            }
        }
        (Method::Get, path) if path.starts_with("/mesh/") => {
            let name = path["/mesh/".len()..].trim_end_matches(".bin");
            match viewer.mesh_bytes(name) {
                Some(b) => bytes(200, "application/octet-stream", b),
                None => refused(404, &format!("no mesh {name:?}")),
            }
        }
        (Method::Get, path) if path.starts_with("/overlay/") => {
            // /overlay/<camera>/<frame>.png
            let rest = &path["/overlay/".len()..];
            let parsed = rest
                .rsplit_once('/')
                .and_then(|(cam, f)| Some((cam, f.strip_suffix(".png")?.parse::<u32>().ok()?)));
            match parsed {
                Some((cam, frame)) => match viewer.overlay(cam, frame) {
                    Ok(png) => bytes(200, "image/png", png),
                    Err(e) => refused(404, &e.0),
                },
                None => refused(404, "expected /overlay/<camera>/<frame>.png"),
            }
        }
        _ => refused(404, &format!("no such page: {method} {url}")),
    };
    request.respond(response)
}
