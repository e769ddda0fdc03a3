//! Headless Chromium driven through the Chrome DevTools protocol: JSON commands over a
//! websocket (tungstenite), one request and its answer at a time. The few commands the browser
//! check needs (navigate, evaluate, mouse, screenshot, downloads) do not justify the large
//! generated protocol crates (chromiumoxide, headless_chrome) nor a WebDriver client with its
//! ICU dependencies.

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use base64::Engine;
use serde_json::{json, Value};
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

use crate::common::view::get;

/// A headless Chromium with software WebGL and a fresh profile, killed when dropped.
pub struct Chrome {
    /// Held, not used: dropping it ends the browser.
    _process: Process,
    /// The browser target (downloads).
    browser: Session,
    /// The page.
    pub page: Session,
}

/// One DevTools connection.
pub struct Session {
    socket: WebSocket<MaybeTlsStream<TcpStream>>,
    next_id: u64,
}

impl Chrome {
    /// Starts `chromium` with a profile in `profile` and a `width` x `height` viewport.
    pub fn start(profile: &Path, width: u32, height: u32) -> Chrome {
        let mut child = Command::new("chromium")
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--use-gl=swiftshader",
                "--enable-unsafe-swiftshader",
                "--disable-background-networking",
                "--no-first-run",
                "--disable-component-update",
                "--disable-sync",
                "--disable-default-apps",
                "--disable-extensions",
                // Screenshots hold the page's own pixel values.
                "--force-color-profile=srgb",
                "--force-device-scale-factor=1",
                "--hide-scrollbars",
                "--remote-debugging-port=0",
                &format!("--window-size={width},{height}"),
                &format!("--user-data-dir={}", profile.display()),
                "about:blank",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("chromium starts (apt-get install chromium)");
        let stderr = BufReader::new(child.stderr.take().unwrap());
        // From here on a failed start ends the browser too.
        let process = Process(child);
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in stderr.lines().map_while(Result::ok) {
                if let Some(at) = line.find("ws://") {
                    let _ = tx.send(line[at..].trim().to_string());
                }
            }
        });
        let browser_url = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("chromium prints its DevTools address");
        // ws://127.0.0.1:PORT/devtools/browser/ID: the page's address comes from /json/list.
        let host = browser_url["ws://".len()..]
            .split('/')
            .next()
            .unwrap()
            .to_string();
        let page_url = wait_for_page(&host);
        let mut chrome = Chrome {
            _process: process,
            browser: Session::connect(&browser_url),
            page: Session::connect(&page_url),
        };
        chrome.page.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": width, "height": height, "deviceScaleFactor": 1, "mobile": false}),
        );
        chrome
    }

    /// Saves downloads into `dir`.
    pub fn download_into(&mut self, dir: &Path) {
        self.browser.call(
            "Browser.setDownloadBehavior",
            json!({"behavior": "allow", "downloadPath": dir.to_str().unwrap()}),
        );
    }
}

/// The browser's process, killed when dropped (also while a failed start unwinds).
struct Process(Child);

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The first page target's websocket address.
fn wait_for_page(host: &str) -> String {
    let started = Instant::now();
    loop {
        let list: Value = serde_json::from_slice(&get(host, "/json/list").body).unwrap();
        if let Some(page) = list
            .as_array()
            .unwrap()
            .iter()
            .find(|t| t["type"] == "page")
        {
            return page["webSocketDebuggerUrl"].as_str().unwrap().to_string();
        }
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "no page target"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

impl Session {
    fn connect(url: &str) -> Session {
        let (socket, _) = tungstenite::connect(url).expect("DevTools connection");
        Session { socket, next_id: 1 }
    }

    /// Calls `method` and returns its result (events in between are skipped).
    pub fn call(&mut self, method: &str, params: Value) -> Value {
        let id = self.next_id;
        self.next_id += 1;
        let request = json!({"id": id, "method": method, "params": params});
        self.socket
            .send(Message::text(request.to_string()))
            .expect("DevTools request");
        loop {
            let message = self.socket.read().expect("DevTools answer");
            let Message::Text(text) = message else {
                continue;
            };
            let answer: Value = serde_json::from_str(text.as_str()).unwrap();
            if answer["id"] == id {
                assert!(answer.get("error").is_none(), "{method}: {answer}");
                return answer["result"].clone();
            }
        }
    }

    /// Evaluates `expression` in the page (promises awaited) and returns its value.
    pub fn eval(&mut self, expression: &str) -> Value {
        let result = self.call(
            "Runtime.evaluate",
            json!({"expression": expression, "returnByValue": true, "awaitPromise": true}),
        );
        assert!(
            result.get("exceptionDetails").is_none(),
            "{expression}: {}",
            result["exceptionDetails"]
        );
        result["result"]["value"].clone()
    }

    /// Waits until `expression` is true.
    pub fn wait_until(&mut self, expression: &str, timeout: Duration) {
        let started = Instant::now();
        while self.eval(expression) != json!(true) {
            assert!(
                started.elapsed() < timeout,
                "still not true after {timeout:?}: {expression}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Opens `url` and waits for its load event.
    pub fn navigate(&mut self, url: &str) {
        self.call("Page.navigate", json!({"url": url}));
        self.wait_until(
            "document.readyState === 'complete'",
            Duration::from_secs(30),
        );
    }

    /// The centre of the element `selector`, in CSS pixels.
    pub fn centre(&mut self, selector: &str) -> (f64, f64) {
        let rect = self.eval(&format!(
            "(() => {{ const r = document.querySelector('{selector}').getBoundingClientRect(); \
             return [r.x + r.width / 2, r.y + r.height / 2]; }})()"
        ));
        (rect[0].as_f64().unwrap(), rect[1].as_f64().unwrap())
    }

    /// A left click at the centre of `selector`.
    pub fn click(&mut self, selector: &str) {
        let (x, y) = self.centre(selector);
        for kind in ["mousePressed", "mouseReleased"] {
            self.mouse(kind, x, y, 1);
        }
    }

    /// A drag with the left button from `(x, y)` by `(dx, dy)` in `steps` moves.
    pub fn drag(&mut self, (x, y): (f64, f64), (dx, dy): (f64, f64), steps: usize) {
        self.mouse("mousePressed", x, y, 1);
        for s in 1..=steps {
            let f = s as f64 / steps as f64;
            self.mouse("mouseMoved", x + f * dx, y + f * dy, 1);
        }
        self.mouse("mouseReleased", x + dx, y + dy, 1);
    }

    /// A turn of the mouse wheel at `(x, y)` (positive: away, zooming out).
    pub fn wheel(&mut self, (x, y): (f64, f64), delta_y: f64) {
        self.call(
            "Input.dispatchMouseEvent",
            json!({"type": "mouseWheel", "x": x, "y": y, "deltaX": 0, "deltaY": delta_y}),
        );
    }

    fn mouse(&mut self, kind: &str, x: f64, y: f64, buttons: u32) {
        let pressed = kind != "mouseReleased";
        self.call(
            "Input.dispatchMouseEvent",
            json!({
                "type": kind, "x": x, "y": y, "button": "left", "clickCount": 1,
                "buttons": if pressed { buttons } else { 0 },
            }),
        );
    }

    /// A PNG screenshot of the element `selector` (the whole page when `None`); the clip is in
    /// the document's coordinates, hence the scroll offsets.
    pub fn screenshot(&mut self, selector: Option<&str>) -> Vec<u8> {
        let mut params =
            json!({"format": "png", "fromSurface": true, "captureBeyondViewport": false});
        if let Some(selector) = selector {
            let rect = self.eval(&format!(
                "(() => {{ const r = document.querySelector('{selector}').getBoundingClientRect(); \
                 return [r.x + window.scrollX, r.y + window.scrollY, r.width, r.height]; }})()"
            ));
            params["clip"] = json!({
                "x": rect[0], "y": rect[1], "width": rect[2], "height": rect[3], "scale": 1,
            });
        }
        let shot = self.call("Page.captureScreenshot", params);
        base64::engine::general_purpose::STANDARD
            .decode(shot["data"].as_str().unwrap())
            .unwrap()
    }
}
