//! A headless Chromium driven over WebDriver (chromedriver), and `jawtrack view` served on a
//! free port: shared by tests/view.rs and benches/view.rs.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use base64::Engine;
use serde_json::{Value, json};

/// A child process killed when the test ends, however it ends.
pub struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

impl Killed {
    /// Whether the process still runs.
    pub fn alive(&mut self) -> bool {
        self.0.try_wait().unwrap().is_none()
    }
}

/// `jawtrack view` (the binary at `exe`) on a free port; its URL.
pub fn serve_with(exe: &std::path::Path, args: &[&str]) -> (Killed, String) {
    serve_logging(exe, args, Stdio::inherit())
}

/// [`serve_with`], its standard error sent to `stderr`.
pub fn serve_logging(exe: &std::path::Path, args: &[&str], stderr: Stdio) -> (Killed, String) {
    let mut child = Command::new(exe)
        .arg("view")
        .args(args)
        .args(["--port", "0"])
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let url = line
        .split_whitespace()
        .find(|w| w.starts_with("http://"))
        .unwrap_or_else(|| panic!("no URL in {line:?}"))
        .to_owned();
    (Killed(child), url)
}

/// A WebDriver session on headless Chromium.
pub struct Browser {
    _driver: Killed,
    base: String,
    session: String,
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

impl Browser {
    pub fn start() -> Browser {
        let port = free_port();
        let driver = Killed(
            Command::new("chromedriver")
                .arg(format!("--port={port}"))
                .args(std::env::var("JAWTRACK_CHROMEDRIVER_LOG").map(|p| format!("--log-path={p}")))
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap(),
        );
        let base = format!("http://127.0.0.1:{port}");
        let started = Instant::now();
        while ureq::get(&format!("{base}/status")).call().is_err() {
            assert!(
                started.elapsed() < Duration::from_secs(20),
                "chromedriver did not start"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        let args = [
            "--headless",
            "--no-sandbox",
            "--use-gl=swiftshader",
            "--enable-unsafe-swiftshader",
            "--window-size=1120,1000",
            // Every host but this machine fails to resolve: the page must need none.
            "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
        ];
        let caps = json!({"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {"binary": which("chromium"), "args": args}
        }}});
        let mut b = Browser {
            _driver: driver,
            base,
            session: String::new(),
        };
        let reply = b.call("POST", "/session", caps);
        b.session = reply["sessionId"]
            .as_str()
            .unwrap_or_else(|| panic!("no session: {reply}"))
            .to_owned();
        b
    }

    pub fn call(&self, method: &str, path: &str, body: Value) -> Value {
        let url = if path == "/session" {
            format!("{}{path}", self.base)
        } else {
            format!("{}/session/{}{path}", self.base, self.session)
        };
        let mut reply = match method {
            "GET" => ureq::get(&url).call(),
            _ => ureq::post(&url).send_json(&body),
        }
        .unwrap_or_else(|e| panic!("WebDriver {method} {path}: {e}"));
        let v: Value = reply.body_mut().read_json().unwrap();
        v["value"].clone()
    }

    pub fn go(&self, url: &str) {
        self.call("POST", "/url", json!({ "url": url }));
        self.wait("return window.view && (window.view.ready || window.view.error)");
        let error = self.js("return window.view.error");
        assert!(error.is_null(), "the page failed: {error}");
    }

    pub fn js(&self, script: &str) -> Value {
        self.call(
            "POST",
            "/execute/sync",
            json!({ "script": script, "args": [] }),
        )
    }

    /// The value of an async script: `done(value)` ends it.
    pub fn js_async(&self, script: &str) -> Value {
        let wrapped = format!(
            "const done = arguments[arguments.length - 1]; (async () => {{ {script} }})().then(done, (e) => done('error: ' + e.message));"
        );
        self.call(
            "POST",
            "/execute/async",
            json!({ "script": wrapped, "args": [] }),
        )
    }

    pub fn wait(&self, condition: &str) {
        let started = Instant::now();
        loop {
            let v = self.js(condition);
            if v.as_bool() == Some(true) || (!v.is_null() && v.as_bool().is_none()) {
                return;
            }
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "waited a minute for `{condition}`"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The canvas as RGBA, from the browser's own screenshot of the element, once two
    /// animation frames have passed (the compositor has shown what was drawn).
    pub fn canvas_shot(&self) -> image::RgbaImage {
        self.js_async(
            "await new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))); return true;",
        );
        let el = self.call(
            "POST",
            "/element",
            json!({"using": "css selector", "value": "#gl"}),
        );
        let id = el
            .as_object()
            .unwrap()
            .values()
            .next()
            .unwrap()
            .as_str()
            .unwrap();
        let b64 = self.call("GET", &format!("/element/{id}/screenshot"), Value::Null);
        let png = base64::engine::general_purpose::STANDARD
            .decode(b64.as_str().unwrap())
            .unwrap();
        image::load_from_memory(&png).unwrap().to_rgba8()
    }

    /// The canvas again, once it differs from `earlier` (or after two seconds, as it is): a
    /// headless browser's element screenshot can come from a frame the compositor presented
    /// before the page's last draw, most often on a loaded machine.
    pub fn canvas_shot_changed_from(&self, earlier: &image::RgbaImage) -> image::RgbaImage {
        let started = Instant::now();
        loop {
            let shot = self.canvas_shot();
            if shot != *earlier || started.elapsed() > Duration::from_secs(2) {
                return shot;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// A real mouse click at `at` (viewport pixels).
    pub fn click(&self, at: [f64; 2]) {
        let (x, y) = (at[0].round() as i64, at[1].round() as i64);
        let actions = vec![
            json!({"type": "pointerMove", "duration": 0, "x": x, "y": y}),
            json!({"type": "pointerDown", "button": 0}),
            json!({"type": "pointerUp", "button": 0}),
        ];
        self.call(
            "POST",
            "/actions",
            json!({"actions": [{"type": "pointer", "id": "mouse",
                "parameters": {"pointerType": "mouse"}, "actions": actions}]}),
        );
    }

    /// A real mouse: press at `from`, move to `to` in steps, release (viewport pixels).
    pub fn drag(&self, from: [f64; 2], to: [f64; 2]) {
        let mut actions = vec![
            json!({"type": "pointerMove", "duration": 0, "x": from[0].round() as i64, "y": from[1].round() as i64}),
            json!({"type": "pointerDown", "button": 0}),
        ];
        for k in 1..=8 {
            let f = k as f64 / 8.0;
            let p = [
                from[0] + (to[0] - from[0]) * f,
                from[1] + (to[1] - from[1]) * f,
            ];
            actions.push(json!({"type": "pointerMove", "duration": 30, "x": p[0].round() as i64, "y": p[1].round() as i64}));
        }
        actions.push(json!({"type": "pointerUp", "button": 0}));
        self.call(
            "POST",
            "/actions",
            json!({"actions": [{"type": "pointer", "id": "mouse",
                "parameters": {"pointerType": "mouse"}, "actions": actions}]}),
        );
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if !self.session.is_empty() {
            let url = format!("{}/session/{}", self.base, self.session);
            let _ = ureq::delete(&url).call();
        }
    }
}

fn which(program: &str) -> String {
    let out = Command::new("sh")
        .arg("-c")
        .arg(format!("command -v {program}"))
        .output()
        .unwrap();
    String::from_utf8_lossy(&out.stdout).trim().to_owned()
}

/// The port of a URL that [`serve_with`] printed.
pub fn port_of(url: &str) -> u16 {
    url.rsplit(':')
        .next()
        .and_then(|r| r.trim_end_matches('/').split('/').next())
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("no port in {url:?}"))
}

/// [`serve_with`] for the jawtrack built with this test or benchmark.
pub fn serve(args: &[&str]) -> (Killed, String) {
    serve_with(std::path::Path::new(env!("CARGO_BIN_EXE_jawtrack")), args)
}
